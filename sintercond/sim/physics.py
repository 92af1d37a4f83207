"""What is simulated: :class:`Physics`, a static, hashable spec in sub-specs (:class:`Conduction`,
:class:`Sources`, :class:`sintercond.sim.mechanics.Mechanics`, :class:`sintercond.sim.neck_growth.Sintering`) that mirror
:class:`sintercond.sim.state.Params`.

The step (:func:`sintercond.sim.step.simulator`) branches on it in Python: a sub-spec that is ``None`` is off and
nothing of it is traced, and each distinct spec compiles one step. The combinations the step supports are checked
here, when the spec is made.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from sintercond.laws.conductance import CONDUCTANCE_LAWS
from sintercond.sim.mechanics import Mechanics
from sintercond.laws.neck import NECK_MODELS
from sintercond.sim.neck_growth import Sintering

_INTEGRATORS = ("explicit", "implicit")
_CONDUCTANCE_MODES = ("table", "lifted")
_CONTACT_MODES = ("static", "dynamic")
_BEAMS = (None, "laser", "nozzle")
COUPLINGS = ("none", "sphere")
"""Values of ``Conduction.coupling``: the isolated pipe network, or necks coupled through their sphere."""


@dataclasses.dataclass(frozen=True)
class Conduction:
    """How heat moves through the contacts: the conduction sub-spec of :class:`Physics` (static, hashable).

    Its differentiable counterparts are ``Params.conductivity``, ``Params.specific_heat`` and ``Params.law``.

    Attributes:
      law: conductance law, a key of :data:`sintercond.CONDUCTANCE_LAWS`.
      neck_model: neck model key, or None for the law's default.
      conductance: ``"table"`` (precomputed at unit conductivity; one
        material, no contact resistance) or ``"lifted"`` (necks stored, law
        applied to ``params`` at each rollout; any materials and law
        parameters).
      integrator: ``"explicit"`` (Euler; check the stable step) or ``"implicit"``: the host loop
        (:func:`sintercond.sim.rollout.advance`, ``sintercond run``) and :func:`sintercond.sim.adaptive.integrate`
        step it adaptively by TR-BDF2 (Hosea & Shampine 1996) within ``rtol`` / ``atol``; one fixed step of
        ``step_fn`` is backward Euler by conjugate gradients (conduction and held particles) or, with sources,
        sintering or property tables, one TR-BDF2 step of ``dt``. Static contacts without mechanics only.
        (``"auto"`` is :meth:`Physics.create`'s, resolved there.)
      implicit_tol: relative residual of the implicit CG solve of the fixed backward-Euler step.
      rtol, atol: the adaptive step's local error bound per step, ``|e_i| <= atol + rtol |T_i|`` (atol in K):
        ``rtol`` in (0, 0.1], ``atol`` in (0, 100] K.
      picard: fixed-point (simplified Newton) iterations per implicit stage (1 to 20): the necks, ``c(T)``,
        ``kappa(T)`` and radiation at the stage's last iterate; a linear problem takes one whatever it says.
      held: some particles are held at fixed temperatures.
      conductivity_table: ``Params.conductivity`` is a :class:`sintercond.laws.materials.Table`, the
        conductivity against temperature (one material): each particle conducts at its own temperature,
        and the conductances are evaluated at every step. Needs ``conductance="lifted"``.
      specific_heat_table: ``Params.specific_heat`` is a :class:`sintercond.laws.materials.Table`, the specific heat
        against temperature (one material): each particle's capacity ``C_i = m_i c(T_i)`` at its temperature at
        the start of every step (explicit Euler: ``sum_i C_i(T^n) (T_i^(n+1) - T_i^n)`` equals the heat in, so
        the enthalpy ``sum_i m_i int c dT`` is kept to first order in the step; the implicit stages step the enthalpy
        itself, so it is kept to round-off).
      held_ramp: the held particles follow a stepped ramp (``Params.held_ramp``,
        :class:`HeldRampParams`: Rizza & Galati 2024's Eq. 6 preheating) from their
        ``fixed_temperature``; needs ``held``.
      conducting_walls: number of conducting plane walls of a thermal step
        (0: none traced); a mechanical step takes its walls as ``Mechanics.walls``.
      coupling: ``"none"`` (each neck's pair law as if it were alone on its sphere) or ``"sphere"`` (the necks
        that share a sphere coupled through its surface Green function, :mod:`sintercond.contacts.sphere_coupling`,
        neck temperatures massless, :mod:`sintercond.sim.terms.coupling`). ``"sphere"`` needs
        ``conductance="lifted"`` and the explicit integrator, on static contacts (necks that stay, or grow by
        ``Sintering(shrinkage="independent")``), property tables allowed, without conducting walls or mechanics (not
        supported yet). The measurements of k* (:mod:`sintercond.sim.steady`) take their own ``coupling=``.
    """

    law: str = "rojek"
    neck_model: str | None = None
    conductance: str = "table"
    integrator: str = "explicit"
    implicit_tol: float = 1e-13
    held: bool = False
    conducting_walls: int = 0
    held_ramp: bool = False
    conductivity_table: bool = False
    specific_heat_table: bool = False
    coupling: str = "none"
    rtol: float = 1e-5
    atol: float = 1e-3
    picard: int = 2

    def __post_init__(self):
        checks = (("law", self.law, tuple(CONDUCTANCE_LAWS)), ("conductance", self.conductance, _CONDUCTANCE_MODES),
                  ("integrator", self.integrator, _INTEGRATORS), ("coupling", self.coupling, COUPLINGS))
        if self.integrator == "auto":
            raise ValueError("Conduction.integrator='auto' is resolved by Physics.create(integrator='auto') or the "
                             "scene build (implicit without inertial mechanics, explicit with it); the spec takes "
                             f"one of {list(_INTEGRATORS)}")
        for name, value, allowed in checks:
            if value not in allowed:
                more = " (or 'auto' through Physics.create)" if name == "integrator" else ""
                raise ValueError(f"Conduction.{name} must be one of {list(allowed)}{more}; got {value!r}")
        if self.neck_model is not None and self.neck_model not in NECK_MODELS:
            raise ValueError(f"Conduction.neck_model must be one of {sorted(NECK_MODELS)} or None; "
                             f"got {self.neck_model!r}")
        if not (isinstance(self.conducting_walls, int) and self.conducting_walls >= 0):
            raise ValueError(f"Conduction.conducting_walls must be an int >= 0; got {self.conducting_walls!r}")
        for name, low, high, unit in (("rtol", 0.0, 0.1, ""), ("atol", 0.0, 100.0, " K")):
            value = getattr(self, name)
            if not (isinstance(value, (int, float, np.floating)) and not isinstance(value, bool)
                    and low < value <= high):
                raise ValueError(f"Conduction.{name} must be a number in ({low:g}, {high:g}]{unit}; got {value!r}")
        if not (isinstance(self.picard, (int, np.integer)) and not isinstance(self.picard, bool)
                and 1 <= self.picard <= 20):
            raise ValueError(f"Conduction.picard must be an integer in [1, 20]; got {self.picard!r}")
        if self.conductivity_table and self.conductance != "lifted":
            raise ValueError("Conduction.conductivity_table evaluates the law at every step: it needs "
                             "conductance='lifted'")
        if self.held_ramp and not self.held:
            raise ValueError("Conduction.held_ramp ramps the held particles' temperatures: it needs held=True")
        if self.coupling == "sphere":
            needs = {"conductance": ("lifted", self.conductance), "integrator": ("explicit", self.integrator),
                     "conducting_walls": (0, self.conducting_walls)}
            for name, (want, got) in needs.items():
                if got != want:
                    raise ValueError(f"Conduction.coupling='sphere' needs Conduction.{name}={want!r} (the coupled "
                                     f"neck network runs on lifted static necks with the explicit step; the rest is "
                                     f"not supported yet, use coupling='none'); got {got!r}")

    @property
    def neck(self) -> str:
        """The neck model in use."""
        return CONDUCTANCE_LAWS[self.law].neck_model if self.neck_model is None else self.neck_model


@dataclasses.dataclass(frozen=True)
class Sources:
    """The heat sources of :class:`Physics` (static, hashable); their parameters are ``Params.beam``,
    ``Params.convection``, ``Params.radiation`` and ``Params.pulse``.

    Attributes:
      beam: ``None``, ``"laser"`` (Lambert-Beer) or ``"nozzle"`` (linear attenuation).
      convection, radiation: convective / radiative exchange with the environment.
      pulse: a prescribed power per particle while ``t < params.pulse.duration``.
      source: extra heat power ``fn(state, t, params) -> [n]`` W (hashable
        callable), or None.
    """

    beam: str | None = None
    convection: bool = False
    radiation: bool = False
    pulse: bool = False
    source: Callable | None = None

    def __post_init__(self):
        if self.beam not in _BEAMS:
            raise ValueError(f"Sources.beam must be one of {list(_BEAMS)}; got {self.beam!r}")

    @property
    def any(self) -> bool:
        """Whether any source is on."""
        return bool(self.beam or self.convection or self.radiation or self.pulse or self.source is not None)


@dataclasses.dataclass(frozen=True)
class Physics:
    """What is simulated: a static, hashable spec (nothing here is an array), in sub-specs that mirror :class:`Params`.

    :func:`sintercond.sim.step.simulator` branches on it in Python: a sub-spec that is ``None`` is
    off and nothing of it is traced, and each distinct spec compiles one step.
    Write it nested, or from flat keywords with the normalising constructor
    :meth:`create`::

        Physics(conduction=Conduction(law="rojek", conductance="lifted"), contacts="dynamic",
                mechanics=Mechanics.create(walls=[floor], friction=True))
        Physics.create(law="rojek", conductance="lifted", contacts="dynamic", mechanics=True,
                       walls=[floor], friction=True)   # the same spec

    Attributes:
      conduction: :class:`Conduction`: law, neck model, table or lifted
        conductances, integrator, held particles, conducting walls.
      contacts: ``"static"`` (the packing does not move) or ``"dynamic"``.
      motion: prescribed positions ``fn(t) -> [n, 3]`` (m) for dynamic
        contacts, or None (positions stay).
      sources: :class:`Sources`: beam, convection, radiation, pulse, a custom source.
      mechanics: :class:`sintercond.sim.mechanics.Mechanics`, the coupled
        thermo-mechanical step (Quintana-Ruiz & Campello 2020, Eqs. 43-46;
        :mod:`sintercond.sim.mechanics`): particles move under contact forces,
        gravity and walls, and heat flows through the contacts the motion
        opens, closes and grows. Needs ``contacts="dynamic"``,
        ``conduction.conductance="lifted"``, the explicit integrator, no
        prescribed ``motion``, ``conduction.conducting_walls=0`` (walls are
        ``Mechanics.walls``) and ``Params.mechanics``. None: the thermal step.
      sintering: :class:`sintercond.sim.neck_growth.Sintering`, necks that grow with each contact's temperature
        history (:mod:`sintercond.sim.neck_growth`: contacts on their own on a packing that does not move, or
        many-body shrinkage that moves the particles). Needs ``conduction.conductance="lifted"``, the
        ``"volume_conserving"`` neck model, ``Params.sintering`` and ``SimState.sintering`` (either integrator:
        the implicit one grows the necks within its stages); without mechanics ``contacts="static"`` (the necks
        on the table), with mechanics the necks live on the
        dynamic half pair list (``MechanicalState.neck``, :func:`sintercond.sim.neck_growth.with_pair_necks`) and
        the elastic laws act on each overlap less its neck's approach. None: the necks stay.
    """

    conduction: Conduction = Conduction()
    contacts: str = "static"
    motion: Callable | None = None
    sources: Sources = Sources()
    mechanics: Mechanics | None = None
    sintering: Sintering | None = None

    def __post_init__(self):
        for name, kind in (("conduction", Conduction), ("sources", Sources)):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(f"Physics.{name} must be a {kind.__name__}; got {getattr(self, name)!r}")
        if self.contacts not in _CONTACT_MODES:
            raise ValueError(f"Physics.contacts must be one of {list(_CONTACT_MODES)}; got {self.contacts!r}")
        if self.mechanics is not None and not isinstance(self.mechanics, Mechanics):
            raise ValueError(f"Physics.mechanics must be a sintercond.sim.mechanics.Mechanics or None; got "
                             f"{self.mechanics!r}")
        c = self.conduction
        if self.sintering is not None:
            if not isinstance(self.sintering, Sintering):
                raise ValueError(f"Physics.sintering must be a sintercond.sim.neck_growth.Sintering or None; got "
                                 f"{self.sintering!r}")
            needs = {"contacts": ("dynamic" if self.mechanics is not None else "static", self.contacts),
                     "conduction.conductance": ("lifted", c.conductance),
                     "conduction.neck_model": ("volume_conserving", c.neck)}
            for name, (want, got) in needs.items():
                if got != want:
                    raise ValueError(f"Physics.sintering needs {name}={want!r} (the necks grow by Rojek's "
                                     f"volume-conserving geometry, on a static table or, with the mechanics, on the "
                                     f"dynamic pair list); got {got!r}")
        if self.mechanics is not None:
            if c.integrator != "explicit":
                raise ValueError("Physics.mechanics needs conduction.integrator='explicit': the implicit integrator "
                                 "steps the slow physics (conduction, sources, necks) and the mechanics is inertial, "
                                 f"its step bounded by the contact stiffness; got {c.integrator!r}")
            needs = {"contacts": ("dynamic", self.contacts), "conduction.conductance": ("lifted", c.conductance)}
            for name, (want, got) in needs.items():
                if got != want:
                    raise ValueError(f"Physics.mechanics needs {name}={want!r}; got {got!r}")
            if self.motion is not None:
                raise ValueError("Physics.mechanics moves the particles itself; motion must be None")
            if self.mechanics.quasi_static and (self.sintering is None
                                                            or self.sintering.shrinkage != "many_body"):
                raise ValueError("Mechanics(quasi_static=True) moves the particles by the many-body balance of "
                                 "the sintering necks: it needs sintering=Sintering(shrinkage='many_body')")
            for k, wall in enumerate(self.mechanics.walls if self.mechanics.quasi_static else ()):
                if any(wall.velocity):
                    raise ValueError(f"Mechanics.walls[{k}].velocity must be (0, 0, 0) with quasi_static=True: a "
                                     f"moving wall pushes by contact forces, which need the inertial step; got "
                                     f"{wall.velocity}")
            if c.conducting_walls:
                raise ValueError("Physics.mechanics takes its walls as Mechanics.walls (PlaneWall, mode 'conducting' "
                                 "for heat); conduction.conducting_walls must be 0")
        if c.coupling == "sphere":
            moves = self.sintering is not None and self.sintering.shrinkage != "independent"
            many_body = self.sintering if moves else None
            for name, value in (("contacts", self.contacts if self.contacts != "static" else None),
                                ("mechanics", self.mechanics), ("sintering", many_body), ("motion", self.motion)):
                if value is not None:
                    raise ValueError(f"Conduction.coupling='sphere' runs on static contacts (necks growing by "
                                     f"independent shrinkage at most); Physics.{name}={value!r} is not supported with "
                                     f"it yet (use coupling='none')")
        if self.contacts == "dynamic" and c.conductance != "lifted":
            raise ValueError("Physics.contacts='dynamic' needs conduction.conductance='lifted' (conductances follow "
                             "the motion)")
        if c.integrator == "implicit" and self.contacts == "dynamic":
            raise ValueError("Conduction.integrator='implicit' steps static contacts (conduction, sources, necks, "
                             "property tables); use 'explicit' with dynamic contacts or motion")

    @classmethod
    def create(cls, law="rojek", *, neck_model=None, conductance="table", contacts="static", integrator="explicit",
               held=False, conducting_walls=0, beam=None, convection=False, radiation=False, pulse=False, source=None,
               motion=None, implicit_tol=1e-13, mechanics=False, walls=(), sintering=None, held_ramp=False,
               conductivity_table=False, specific_heat_table=False, coupling="none", rtol=1e-5, atol=1e-3, picard=2,
               **mechanical) -> Physics:
        """The normalising constructor: a :class:`Physics` from flat keywords (the fields of the sub-specs).

        ``mechanics=True`` turns the coupled step on, with ``walls`` and the
        other :class:`sintercond.sim.mechanics.Mechanics` fields in ``mechanical``
        (``gravity``, ``friction``, ``rolling``, ``wall_friction``, ...),
        normalised by :meth:`sintercond.sim.mechanics.Mechanics.create`; without it
        those keywords are refused (nothing would move). ``sintering``: a
        :class:`sintercond.sim.neck_growth.Sintering` or None. ``coupling``: ``Conduction.coupling``.
        ``integrator="auto"`` is resolved here (:func:`resolve_integrator`): implicit without inertial mechanics on
        static contacts, uncoupled necks and no beam, explicit otherwise.
        """
        if integrator == "auto":  # any other value is Conduction's to check
            moving = "quasi_static" if mechanics and mechanical.get("quasi_static") else bool(mechanics)
            integrator = resolve_integrator(moving, contacts, motion, coupling, beam)[0]
        if not isinstance(mechanics, (bool, np.bool_)):
            raise ValueError(f"Physics.create(mechanics=...) must be True or False; got {mechanics!r}")
        if mechanics:
            spec = Mechanics.create(walls, **mechanical)
        elif walls or mechanical:
            given = ["walls"] * bool(walls) + sorted(mechanical)
            raise ValueError(f"Physics.create: {', '.join(given)} belong to the mechanical step (mechanics=True; "
                             "walls there are mechanical walls); for heat alone use conducting_walls")
        else:
            spec = None
        return cls(conduction=Conduction(law=law, neck_model=neck_model, conductance=conductance,
                                         integrator=integrator, implicit_tol=implicit_tol, held=bool(held),
                                         conducting_walls=conducting_walls, held_ramp=bool(held_ramp),
                                         conductivity_table=bool(conductivity_table),
                                         specific_heat_table=bool(specific_heat_table), coupling=coupling,
                                         rtol=rtol, atol=atol, picard=picard),
                   contacts=contacts, motion=motion,
                   sources=Sources(beam=beam, convection=bool(convection), radiation=bool(radiation),
                                   pulse=bool(pulse), source=source),
                   mechanics=spec, sintering=sintering)

    @property
    def neck(self) -> str:
        """The neck model in use (``conduction.neck``)."""
        return self.conduction.neck


def resolve_integrator(mechanics: bool | str, contacts: str = "static", motion=None, coupling: str = "none",
                       beam=None) -> tuple[str, str]:
    """``(integrator, why)``: what ``integrator="auto"`` means for a spec: ``"implicit"`` (adaptive TR-BDF2) where
    nothing is inertial, the contacts are static, the necks are not coupled and no beam scans, ``"explicit"``
    otherwise; ``why`` says which case it is. ``mechanics``: a bool, or ``"quasi_static"`` (``Mechanics.quasi_static``)."""
    if mechanics == "quasi_static":
        return "explicit", ("the mechanics is quasi-static: the necks' balance moves the particles and the contacts "
                            "follow them (the pair list rebuilds), and the implicit integrator needs static contacts; "
                            "the step is the thermal one")
    if mechanics:
        return "explicit", ("the mechanics is inertial: its step is bounded by the contact stiffness, and the heat "
                            "follows it explicitly")
    if contacts != "static" or motion is not None:
        return "explicit", "the contacts move (prescribed motion): the implicit integrator needs static contacts"
    if coupling == "sphere":
        return "explicit", ("the coupled necks (conduction.coupling = \"sphere\") are stepped explicitly, one sweep "
                            "a step: the implicit stages do not carry their coupling")
    if beam is not None:
        return "explicit", ("a scanning beam sets the step: its spot crosses a particle in a few explicit steps, and "
                            "the adaptive step, following it, costs more (benchmarks/RESULTS.md, integrator_choice)")
    return "implicit", ("no inertial mechanics and static contacts: the slow physics is stepped adaptively "
                        "(TR-BDF2) within rtol / atol, not at the explicit conduction limit")
