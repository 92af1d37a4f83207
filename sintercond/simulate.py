"""One simulator: a static physics spec, differentiable ``Params``, one step, one rollout.

Every stepping path of the package (``sintercond run``, settling, the
softening fits, prescribed motion, the benchmarks) goes through here; the
flash experiment's readings do too, while its gradient is a hand-written
discrete adjoint over :func:`sintercond.thermal.explicit_update`
(:mod:`fitting.inverse`), tested against reverse mode through :func:`rollout`:

* :class:`Physics` is a frozen, hashable description of *what* is simulated
  (conduction law and neck model, static or dynamic contacts, integrator,
  heat sources, held particles and conducting walls, and room for mechanics).
  :func:`simulator` branches on it in Python, so what a scene does not use is
  not traced, and each distinct spec compiles one step (jax-md
  ``simulate.nve``'s ``(init_fn, apply_fn)`` pattern).
* :class:`Params` is the one differentiable input: conductivities and
  specific heats per material, the conductance law's parameters, and the
  source parameters. ``step_fn(state, params)`` takes it as an argument, so
  one compiled step serves every optimiser iteration, and gradients of any
  observable reach any of its leaves by JAX's own reverse or forward mode.
* :class:`SimState` is the whole state (particles, contacts, step counter and
  time step) as registered frozen dataclasses; a checkpoint holds all of it.
* :func:`simulate_table` advances a table network built once
  (:func:`sintercond.network.contact_table`) without building a state by
  hand: a convenience over :func:`rollout`.
* :func:`rollout` scans the step over ``jax.checkpoint``-ed segments of about
  ``sqrt(n_steps)`` steps and saves observables chosen by :class:`SaveAt`
  (probe temperatures, means, heat flows), not whole states: reverse mode
  then keeps ``O(sqrt(n_steps))`` particle arrays.

The conduction step itself (Rojek et al. 2022, Eqs. 1-4; sources of
Quintana-Ruiz & Campello 2020, Eqs. 28-31, 37-41) is
:func:`sintercond.thermal.explicit_update` (or the backward-Euler solve),
with the heat powers of :func:`sintercond.thermal.heat_power`.

Conductances of contacts
------------------------
``conductance="table"``: a table of ``K_ij`` at unit conductivity, built once
on the host (:func:`sintercond.network.contact_table`), times the
conductivity of the single material. Every law is linear in the
conductivity when there is one material and no contact resistance, so this
is exact; it is the fast path (the gradient with respect to the conductivity
is a scalar reduction per step).

``conductance="lifted"``: the necks of every pair are computed once from the
geometry; the law turns them into conductances from ``params`` at the start
of every rollout (:func:`conductance_lift`), so law parameters (Rojek's
slope, a contact resistance, the fitted law's coefficients) and per-material
conductivities are differentiable. Both give the same numbers and gradients
where both apply (tests/test_simulate.py).

``contacts="dynamic"``: positions move (a prescribed ``motion(t)``, or the
thermo-mechanical step); a Dense neighbour list with a skin (built from a
sorted cell list, jax-md's Dense format; :func:`sintercond.neighbors.neighbor_list`) is updated
inside the step, and whenever it is rebuilt a half pair list (each pair
``i < j`` once, within ``r_i + r_j + skin``;
:class:`sintercond.pair_list.HalfPairs`) is rebuilt from it. The law is
evaluated once per pair of the half list from the current overlaps at every
step, and heat (and force) is added to one end and taken from the other
(:func:`sintercond.pair_list.pair_exchange`): conserved by construction.
Overflow of either list is a flag in the state, recovered by the host
driver (:func:`sintercond.rollout.advance` with :func:`reallocate_neighbors`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from sintercond import materials, mechanics, neck_growth, thermal
from sintercond.conductance import CONDUCTANCE_LAWS, conductance_from_neck
from sintercond.mechanics import MechanicalParams, MechanicalState, Mechanics
from sintercond.neck_growth import NeckState, Sintering
from sintercond.neck import NECK_MODELS
from sintercond.neighbors import did_buffer_overflow, did_rebuild
from sintercond.pair_list import (allocate_half_pairs, half_pair_capacity, half_pair_count, half_pairs, half_pairs_overflowed,
                                  map_pair_blocks, padded_half_pairs, pair_exchange, pair_sum)
from sintercond._deprecation import old_names
from sintercond._validation import all_concrete, fail_where, require_positive
from sintercond.network import ContactTable, network_laplacian
from sintercond.tortuosity import preheating_temperature
from sintercond.state import (Contacts, DynamicContacts, LiftedContacts, ParticleState, TableContacts,  # noqa: F401
                              heat_capacity, pytree_dataclass)
from sintercond.walls import wall_conductance_from_neck, wall_neck_radius

_INTEGRATORS = ("explicit", "implicit")
_CONDUCTANCE_MODES = ("table", "lifted")
_CONTACT_MODES = ("static", "dynamic")
_BEAMS = (None, "laser", "nozzle")


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
      integrator: ``"explicit"`` (Euler; check the stable step) or
        ``"implicit"`` (backward Euler by conjugate gradients; conduction
        and held particles only).
      implicit_tol: relative residual of the implicit CG solve.
      held: some particles are held at fixed temperatures.
      conductivity_table: ``Params.conductivity`` is a :class:`sintercond.materials.Table`, the
        conductivity against temperature (one material): each particle conducts at its own temperature,
        and the conductances are evaluated at every step. Needs ``conductance="lifted"``.
      specific_heat_table: ``Params.specific_heat`` is a :class:`sintercond.materials.Table`, the specific heat
        against temperature (one material): each particle's capacity ``C_i = m_i c(T_i)`` at its temperature at
        the start of every step (explicit Euler: ``sum_i C_i(T^n) (T_i^(n+1) - T_i^n)`` equals the heat in, so
        the enthalpy ``sum_i m_i int c dT`` is kept to first order in the step). Needs the explicit integrator.
      held_ramp: the held particles follow a stepped ramp (``Params.held_ramp``,
        :class:`HeldRampParams`: Rizza & Galati 2024's Eq. 6 preheating) from their
        ``fixed_temperature``; needs ``held``.
      conducting_walls: number of conducting plane walls of a thermal step
        (0: none traced); a mechanical step takes its walls as ``Mechanics.walls``.
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

    def __post_init__(self):
        checks = (("law", self.law, tuple(CONDUCTANCE_LAWS)), ("conductance", self.conductance, _CONDUCTANCE_MODES),
                  ("integrator", self.integrator, _INTEGRATORS))
        for name, value, allowed in checks:
            if value not in allowed:
                raise ValueError(f"Conduction.{name} must be one of {list(allowed)}; got {value!r}")
        if self.neck_model is not None and self.neck_model not in NECK_MODELS:
            raise ValueError(f"Conduction.neck_model must be one of {sorted(NECK_MODELS)} or None; "
                             f"got {self.neck_model!r}")
        if not (isinstance(self.conducting_walls, int) and self.conducting_walls >= 0):
            raise ValueError(f"Conduction.conducting_walls must be an int >= 0; got {self.conducting_walls!r}")
        if self.conductivity_table and (self.conductance != "lifted" or self.integrator != "explicit"):
            raise ValueError("Conduction.conductivity_table evaluates the law at every step: it needs "
                             "conductance='lifted' and the explicit integrator")
        if self.specific_heat_table and self.integrator != "explicit":
            raise ValueError("Conduction.specific_heat_table updates each capacity at every step: it needs the "
                             "explicit integrator")
        if self.held_ramp and not self.held:
            raise ValueError("Conduction.held_ramp ramps the held particles' temperatures: it needs held=True")

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

    :func:`simulator` branches on it in Python: a sub-spec that is ``None`` is
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
      mechanics: :class:`sintercond.mechanics.Mechanics`, the coupled
        thermo-mechanical step (Quintana-Ruiz & Campello 2020, Eqs. 43-46;
        :mod:`sintercond.mechanics`): particles move under contact forces,
        gravity and walls, and heat flows through the contacts the motion
        opens, closes and grows. Needs ``contacts="dynamic"``,
        ``conduction.conductance="lifted"``, the explicit integrator, no
        prescribed ``motion``, ``conduction.conducting_walls=0`` (walls are
        ``Mechanics.walls``) and ``Params.mechanics``. None: the thermal step.
      sintering: :class:`sintercond.neck_growth.Sintering`, necks that grow with each contact's temperature
        history (:mod:`sintercond.neck_growth`: contacts on their own on a packing that does not move, or
        many-body shrinkage that moves the particles). Needs ``conduction.conductance="lifted"``, the explicit
        integrator, the ``"volume_conserving"`` neck model, ``Params.sintering`` and ``SimState.sintering``;
        without mechanics ``contacts="static"`` (the necks on the table), with mechanics the necks live on the
        dynamic half pair list (``MechanicalState.neck``, :func:`sintercond.neck_growth.with_pair_necks`) and
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
            raise ValueError(f"Physics.mechanics must be a sintercond.mechanics.Mechanics or None; got "
                             f"{self.mechanics!r}")
        c = self.conduction
        if self.sintering is not None:
            if not isinstance(self.sintering, Sintering):
                raise ValueError(f"Physics.sintering must be a sintercond.neck_growth.Sintering or None; got "
                                 f"{self.sintering!r}")
            needs = {"contacts": ("dynamic" if self.mechanics is not None else "static", self.contacts),
                     "conduction.conductance": ("lifted", c.conductance),
                     "conduction.integrator": ("explicit", c.integrator),
                     "conduction.neck_model": ("volume_conserving", c.neck)}
            for name, (want, got) in needs.items():
                if got != want:
                    raise ValueError(f"Physics.sintering needs {name}={want!r} (the necks grow by Rojek's "
                                     f"volume-conserving geometry, on a static table or, with the mechanics, on the "
                                     f"dynamic pair list); got {got!r}")
        if self.mechanics is not None:
            needs = {"contacts": ("dynamic", self.contacts), "conduction.conductance": ("lifted", c.conductance),
                     "conduction.integrator": ("explicit", c.integrator)}
            for name, (want, got) in needs.items():
                if got != want:
                    raise ValueError(f"Physics.mechanics needs {name}={want!r}; got {got!r}")
            if self.motion is not None:
                raise ValueError("Physics.mechanics moves the particles itself; motion must be None")
            if c.conducting_walls:
                raise ValueError("Physics.mechanics takes its walls as Mechanics.walls (PlaneWall, mode 'conducting' "
                                 "for heat); conduction.conducting_walls must be 0")
        if self.contacts == "dynamic" and c.conductance != "lifted":
            raise ValueError("Physics.contacts='dynamic' needs conduction.conductance='lifted' (conductances follow "
                             "the motion)")
        if c.integrator == "implicit" and (self.sources.any or self.contacts == "dynamic"):
            raise ValueError("Conduction.integrator='implicit' supports conduction on static contacts and held "
                             "particles only; use 'explicit' with sources or motion")

    @classmethod
    def create(cls, law="rojek", neck_model=None, conductance="table", contacts="static", integrator="explicit",
               held=False, conducting_walls=0, beam=None, convection=False, radiation=False, pulse=False, source=None,
               motion=None, implicit_tol=1e-13, mechanics=False, walls=(), sintering=None, held_ramp=False,
               conductivity_table=False, specific_heat_table=False, **mechanical) -> Physics:
        """The normalising constructor: a :class:`Physics` from flat keywords (the fields of the sub-specs).

        ``mechanics=True`` turns the coupled step on, with ``walls`` and the
        other :class:`sintercond.mechanics.Mechanics` fields in ``mechanical``
        (``gravity``, ``friction``, ``rolling``, ``wall_friction``, ...),
        normalised by :meth:`sintercond.mechanics.Mechanics.create`; without it
        those keywords are refused (nothing would move). ``sintering``: a
        :class:`sintercond.neck_growth.Sintering` or None.
        """
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
                                         specific_heat_table=bool(specific_heat_table)),
                   contacts=contacts, motion=motion,
                   sources=Sources(beam=beam, convection=bool(convection), radiation=bool(radiation),
                                   pulse=bool(pulse), source=source),
                   mechanics=spec, sintering=sintering)

    @property
    def neck(self) -> str:
        """The neck model in use (``conduction.neck``)."""
        return self.conduction.neck


@pytree_dataclass
class BeamParams:
    """A vertical beam moving along a polyline (Quintana-Ruiz & Campello 2020, Eqs. 29-31).

    Attributes:
      intensity: ``I0`` (W/m^2).
      reach: Lambert-Beer attenuation ``mu`` (1/m) for a laser, ``d_max`` (m) for a nozzle.
      spot_radius: beam radius (m).
      absorptance: ``a`` in [0, 1].
      speed: speed along the path (m/s).
      path: ``[k, 2]`` waypoints (x, y) (m), absolute coordinates.
      segments_on: ``[k - 1]`` 1 where the beam heats along a segment, 0 where it jumps (None: always on).
      after_path: 0 (the beam is off once its path is done) or 1 (it stays on at the last waypoint).
    """

    intensity: Any
    reach: Any
    spot_radius: Any
    absorptance: Any
    speed: Any
    path: Any
    segments_on: Any = None
    after_path: Any = 0.0


@pytree_dataclass
class ConvectionParams:
    """Newton cooling (Eqs. 37-39): environment temperature (K), conductivity (W/(m K)), Nusselt number."""

    environment_temperature: Any
    environment_conductivity: Any
    nusselt: Any


@pytree_dataclass
class RadiationParams:
    """Stefan-Boltzmann exchange (Eq. 41): environment temperature (K) and emissivity."""

    environment_temperature: Any
    emissivity: Any


@pytree_dataclass
class PulseParams:
    """A prescribed heat input: ``power`` ``[n]`` (W) while ``t < duration`` (s)."""

    power: Any
    duration: Any


@pytree_dataclass
class HeldRampParams:
    """A stepped temperature ramp of the held particles (Rizza & Galati 2024, Eq. 6, with its erratum).

    Each held particle rises from its ``fixed_temperature`` ``T_0`` to ``end_temperature`` in ``steps`` equal
    steps of ``duration / steps``, each step held at the temperature it ends at (the reading that reproduces their
    Table 1): ``T(t) = T_0 + (T_end - T_0) min(ceil(steps t / duration), steps) / steps`` (K, t in s). ``steps`` is
    a float holding a whole number; the ramp's ``duration`` and ``steps`` have zero gradient (a staircase).
    """

    end_temperature: Any
    duration: Any
    steps: Any


def held_ramp_temperature(ramp: HeldRampParams, start, t):
    """The held temperatures ``[n]`` (K) at time ``t`` (s) of a :class:`HeldRampParams` from ``start`` ``[n]``:
    the level of :func:`sintercond.tortuosity.preheating_temperature` (its reading at the step's end)."""
    level = preheating_temperature(t, 0.0, ramp.duration, 0.0, 1.0, ramp.steps, at_step_end=True)
    return start + (ramp.end_temperature - start) * level


@pytree_dataclass
class Params:
    """The differentiable inputs of a simulation (SI units).

    Attributes:
      conductivity: ``[n_materials]`` solid conductivities (W/(m K)).
      specific_heat: ``[n_materials]`` (J/(kg K)); capacities are ``m_i c``.
      law: the conductance law's parameters in use (e.g. ``{"slope": 1.064}``),
        merged over the law's defaults; ``{}`` for the defaults.
      beam, convection, radiation, pulse: source parameters, or None where
        the physics has no such source.
      mechanics: :class:`sintercond.mechanics.MechanicalParams` (moduli,
        damping, friction, softening) with ``Physics.mechanics``, else None.
      sintering: the kinetic law's parameters in use (e.g. ``{"A": 1e-17, "activation_energy": 40.0}``),
        merged over the law's defaults (:data:`sintercond.sintering.KINETIC_LAWS`), with
        ``Physics.sintering``; else None.
      held_ramp: :class:`HeldRampParams` with ``Conduction.held_ramp``, else None.
    """

    conductivity: Any
    specific_heat: Any
    law: dict = dataclasses.field(default_factory=dict)
    beam: BeamParams | None = None
    convection: ConvectionParams | None = None
    radiation: RadiationParams | None = None
    pulse: PulseParams | None = None
    mechanics: MechanicalParams | None = None
    sintering: dict | None = None
    held_ramp: HeldRampParams | None = None


@pytree_dataclass
class SimState:
    """The whole state of a simulation.

    Attributes:
      particles: positions, radii, temperatures, masses, materials, held flags.
      contacts: the network, one class per mode (:data:`sintercond.state.Contacts`: :class:`TableContacts`,
        :class:`LiftedContacts` or :class:`DynamicContacts`).
      step: int scalar, steps taken (time ``step * dt``).
      dt: the time step (s), scalar.
      overflow: bool scalar, set when a dynamic neighbour list overflowed
        since the last host check (the results after it are invalid).
      mechanics: velocities, spins and contact springs
        (:class:`sintercond.mechanics.MechanicalState`) with
        ``Physics.mechanics``, else None (nothing traced).
      sintering: the start approaches, the growth interval's start temperatures and the stability flag
        (:class:`sintercond.neck_growth.NeckState`) with ``Physics.sintering``, else None; the necks
        themselves are ``contacts.neck``.
    """

    particles: ParticleState
    contacts: Contacts
    step: Any
    dt: Any
    overflow: Any
    mechanics: MechanicalState | None = None
    sintering: NeckState | None = None

    @property
    def temperature(self):
        return self.particles.temperature

    @property
    def time(self):
        """``step * dt`` (s)."""
        return self.step.astype(self.dt.dtype) * self.dt


class Prepared(NamedTuple):
    """What one rollout computes once from ``(state, params)`` and every step reuses."""

    params: Params
    capacity: jax.Array
    conductance: jax.Array | None  # [n, m] static conductances (W/K), or None for dynamic contacts
    scale: jax.Array  # multiplies the table (the conductivity, table mode) or 1
    wall_conductance: jax.Array | None  # [n_walls or 1, n] (W/K)
    wall_temperature: jax.Array | None  # [n_walls or 1, n] broadcastable (K)
    rates: tuple | None = None  # thermal.conduction_rates(scale, capacity) of the static explicit step, or None


class Simulator(NamedTuple):
    """``step_fn(state, params) -> state``; ``prepare_fn``/``advance_fn`` split it for :func:`rollout`."""

    physics: Physics
    step_fn: Callable
    prepare_fn: Callable
    advance_fn: Callable
    heat_power_fn: Callable


# --------------------------------------------------------------------------
# conductances


def merged_law_params(physics: Physics, params: Params) -> dict:
    """The law's default parameters overridden by ``params.law``; unknown names raise."""
    defaults = CONDUCTANCE_LAWS[physics.conduction.law].default_params
    unknown = set(params.law) - set(defaults)
    if unknown:
        raise ValueError(f"Params.law of law {physics.conduction.law!r} must be among {sorted(defaults)}; got {sorted(unknown)}")
    return {**defaults, **params.law}


def conductance_lift(physics: Physics, radii, material, neighbors, neck, overlap, conductivity, law_params):
    """Conductances ``[n, m]`` (W/K) of a padded table from its necks: the one law -> table lift.

    Each slot ``(i, j)`` evaluates the law with the pair in index order
    (``min(i, j)`` first), so both rows of a pair get bitwise the same ``K``
    and the network stays exactly symmetric (heat conserved to round-off).
    Padding slots (``j == i`` or ``j >= n``) have ``h = 0`` and give 0.
    """
    n = radii.shape[0]
    rows = jnp.arange(n, dtype=neighbors.dtype)[:, None]
    valid = (neighbors != rows) & (neighbors < n)
    j = jnp.where(valid, neighbors, rows)
    return _law_on_pairs(physics, radii, material, jnp.minimum(rows, j), jnp.maximum(rows, j), valid, neck, overlap,
                         conductivity, law_params)


def _law_on_pairs(physics, radii, material, lo, hi, valid, neck, overlap, conductivity, law_params):
    """The conductance law on pairs ``(lo, hi)`` (any shape) from their necks (W/K); 0 where not ``valid``."""
    kappa = jnp.asarray(conductivity)
    k = conductance_from_neck(physics.conduction.law, neck, radii[lo], radii[hi], overlap, kappa[material[lo]],
                              kappa[material[hi]], law_params)
    return jnp.where(valid, k, 0.0)


def _wall_lift(physics, particles, contacts, params, law_params):
    """``[n_walls, n]`` conductances to the conducting walls (a neighbour of infinite radius, :mod:`sintercond.walls`)."""
    index, conductivity = conductivity_lookup(physics, params, particles)
    kappa = conductivity[index]
    return wall_conductance_from_neck(physics.conduction.law, contacts.wall_neck, particles.radii, contacts.wall_overlap, kappa,
                                      kappa, law_params)


def particle_capacity(physics: Physics, params: Params, particles: ParticleState):
    """Heat capacities ``C_i = m_i c`` (J/K), Rojek et al. (2022) Eq. 1: ``c`` of each particle's material, or with
    ``Conduction.specific_heat_table`` the table at each particle's temperature."""
    if physics.conduction.specific_heat_table:
        return particles.mass * params.specific_heat(particles.temperature)
    return heat_capacity(particles, params.specific_heat)


def conductivity_lookup(physics: Physics, params: Params, particles: ParticleState):
    """``(index [n], conductivity [k])``: particle ``i`` conducts at ``conductivity[index[i]]`` (W/(m K)).

    The material table (``index`` the materials) or, with ``Conduction.conductivity_table``, each particle's
    conductivity at its own temperature (``index`` the particles): the laws' lifts take either.
    """
    if physics.conduction.conductivity_table:
        return jnp.arange(particles.radii.shape[0]), params.conductivity(particles.temperature)
    return particles.material, jnp.atleast_1d(jnp.asarray(params.conductivity))


def _per_step(physics: Physics) -> bool:
    """Whether a static lifted table's conductances change during a rollout (growing necks, kappa(T))."""
    return physics.sintering is not None or physics.conduction.conductivity_table


def neck_conductance(physics: Physics, state: SimState, params: Params):
    """Conductances ``[n, m]`` (W/K) of a static lifted state from the necks and temperatures it holds now."""
    p, contacts = state.particles, state.contacts
    index, kappa = conductivity_lookup(physics, params, p)
    return conductance_lift(physics, p.radii, index, contacts.neighbors, contacts.neck, contacts.overlap, kappa,
                            merged_law_params(physics, params))


def pair_conductance(physics: Physics, radii, material, geometry, conductivity, law_params):
    """Conductances ``[c]`` (W/K) of the pairs of a half list from their current overlaps: neck, then the law, once per pair.

    ``geometry``: :func:`sintercond.mechanics.pair_geometry` of the list.
    """
    return _law_on_pairs(physics, radii, material, geometry.i, geometry.j, geometry.valid,
                         _pair_neck(physics, radii, geometry), geometry.overlap, conductivity, law_params)


def _pair_neck(physics, radii, g):
    """Neck radii ``[c]`` (m) of the touching pairs of a :class:`sintercond.mechanics.PairGeometry`."""
    return jnp.where(g.touching, NECK_MODELS[physics.neck](radii[g.i], radii[g.j], g.overlap), 0.0)


def mechanical_wall_conductance(physics: Physics, radii, penetration, conductivity, law_params):
    """``[n]`` conductances (W/K) of the particles to a conducting mechanical wall at their ``penetration`` (m):
    the law on the wall's neck (:mod:`sintercond.walls`, ``r_j -> inf``), both halves at the particle's
    ``conductivity``."""
    return wall_conductance_from_neck(physics.conduction.law, wall_neck_radius(physics.neck, radii, penetration),
                                      radii, penetration, conductivity, conductivity, law_params)


def sintered_geometry(geometry, neck_overlap):
    """The :class:`sintercond.mechanics.PairGeometry` the elastic laws see on sintered pairs: each overlap less the
    approach ``H(a)`` its neck accounts for (``neck_overlap`` ``[c]``, m), touching only where that stays positive.

    Sintering moves the spheres together by the neck's approach without loading them (Rojek et al. 2022); the
    elastic contact acts on what is left, as a plastic overlap does in MercuryDPM's sinter species."""
    overlap = geometry.overlap - neck_overlap
    touching = geometry.touching & (overlap > 0)
    return geometry._replace(touching=touching, overlap=jnp.where(touching, overlap, 0.0))


def conducting_geometry(geometry, neck_overlap):
    """The :class:`sintercond.mechanics.PairGeometry` the conductance laws see on sintered pairs: each touching
    pair's overlap, or its neck's approach ``H(a)`` (``neck_overlap`` ``[c]``, m) where that is larger (necks grown
    on pairs that have not moved together: independent contacts, point contacts), so the volume-conserving neck of
    it is ``max(a, neck(delta))``. ``geometry``: with the gap :data:`sintercond.neck_growth.POINT_CONTACT_GAP`."""
    overlap = jnp.where(geometry.touching, jnp.maximum(geometry.overlap, neck_overlap), 0.0)
    return geometry._replace(touching=geometry.touching & (overlap > 0), overlap=overlap)


def sintered_pair_conductance(physics: Physics, state: SimState, params: Params):
    """``(geometry, conductance [c])`` of a mechanical sintering state's half pair list (W/K): what its step
    conducts through (:func:`conducting_geometry`)."""
    p = state.particles
    geometry = conducting_geometry(mechanics.pair_geometry(p.positions, p.radii, state.contacts.pairs.pairs,
                                                           neck_growth.POINT_CONTACT_GAP),
                                   state.mechanics.neck_overlap)
    index, kappa = conductivity_lookup(physics, params, p)
    return geometry, pair_conductance(physics, p.radii, index, geometry, kappa, merged_law_params(physics, params))


def pair_heat_power(conductance, pairs, temperature):
    """Heat power ``[n]`` (W) into each particle through the pairs ``[c, 2]`` of a half list, ``K (T_j - T_i)`` into ``i``.

    Each pair's flow is added to one end and taken from the other: the total is zero to round-off.
    """
    n = temperature.shape[0]
    i, j = jnp.minimum(pairs[:, 0], n - 1), jnp.minimum(pairs[:, 1], n - 1)
    return pair_exchange(pair_heat_flow(conductance, i, j, temperature), pairs, n)


def pair_heat_flow(conductance, i, j, temperature):
    """Heat flow ``K (T_j - T_i)`` (W) from ``j`` to ``i`` of each pair (Rojek et al. 2022, Eq. 3)."""
    return conductance * (temperature[j] - temperature[i])


def follow_contacts(neighbor_fn, positions, radii, contacts: DynamicContacts, history=None):
    """Dynamic contacts at ``positions``: ``(contacts, history, overflow)``.

    Updates the Dense list (it rebuilds once a particle moved half the
    skin); when it rebuilt, rebuilds the half pair list from it and carries
    the per-pair ``history`` (a :class:`sintercond.mechanics.MechanicalState`
    or None) to the new pairs (:func:`sintercond.mechanics.remap_history`),
    all under one ``lax.cond``. ``overflow``: either list ran out of room.
    """
    nbrs = neighbor_fn.update(positions, contacts.neighbor_list)
    old = contacts.pairs

    def rebuild(history):
        new = half_pairs(nbrs.idx, positions, radii, neighbor_fn.skin, old.capacity, old.demand)
        return new, None if history is None else mechanics.remap_history(history, old.pairs, new.pairs)

    half, history = jax.lax.cond(did_rebuild(contacts.neighbor_list, nbrs), rebuild, lambda h: (old, h), history)
    overflow = did_buffer_overflow(nbrs) | half_pairs_overflowed(half)
    return DynamicContacts(neighbor_list=nbrs, pairs=half), history, overflow


# --------------------------------------------------------------------------
# the simulator


def simulator(physics: Physics, neighbor_fn=None) -> Simulator:
    """The step of ``physics``: ``step_fn(state, params) -> state``.

    Args:
      physics: the spec.
      neighbor_fn: for ``contacts="dynamic"``, the neighbour-list
        function (``update(positions, nbrs)``) the state's list came from
        (:func:`dynamic_contacts` builds both).
    """
    if physics.contacts == "dynamic" and neighbor_fn is None:
        raise ValueError("contacts='dynamic' needs the neighbour-list function (see dynamic_contacts)")

    def prepare_fn(state: SimState, params: Params) -> Prepared:
        particles, contacts = state.particles, state.contacts
        params = params_in_precision(params, particles.temperature.dtype)
        capacity = particle_capacity(physics, params, particles)
        wall_k = wall_t = None
        if physics.conduction.conductance == "table":
            conductance, scale = contacts.conductance, jnp.atleast_1d(jnp.asarray(params.conductivity))[0]
            if physics.conduction.conducting_walls:
                wall_k, wall_t = contacts.wall_conductance[None], contacts.wall_temperature[None]
        else:
            law_params = merged_law_params(physics, params)
            scale = jnp.ones((), capacity.dtype)
            conductance = None
            if physics.contacts == "static" and not _per_step(physics):
                conductance = neck_conductance(physics, state, params)
            if physics.conduction.conducting_walls:
                wall_k = _wall_lift(physics, particles, contacts, params, law_params)
                wall_t = contacts.wall_temperature[:, None]
        rates = None
        if (physics.conduction.integrator == "explicit" and physics.contacts == "static" and physics.mechanics is None
                and not physics.conduction.specific_heat_table):
            # computed once per rollout: reverse mode then accumulates their cotangents per particle
            rates = thermal.conduction_rates(scale, capacity)
        return Prepared(params, capacity, conductance, scale, wall_k, wall_t, rates)

    def conduction_power(state: SimState, prep: Prepared, temperature, conductance, neighbors):
        """Heat into each particle through the contacts (None: walls only) and conducting walls (W).

        Dynamic contacts: a half pair list ``[c, 2]`` and its conductances ``[c]``; static: the table.
        """
        power = jnp.zeros_like(temperature)
        if conductance is not None and physics.contacts == "dynamic":
            power = pair_heat_power(conductance, neighbors, temperature)
        elif conductance is not None:
            power = -prep.scale * network_laplacian(conductance, neighbors, temperature)
        if physics.conduction.conducting_walls:
            wall_k = prep.wall_conductance
            if physics.conduction.conductivity_table:  # at the particles' temperatures now
                wall_k = _wall_lift(physics, state.particles, state.contacts, prep.params,
                                    merged_law_params(physics, prep.params))
            power = power + prep.scale * jnp.sum(wall_k * (prep.wall_temperature - temperature), axis=0)
        return power

    def current_network(state: SimState, prep: Prepared):
        """``(state, conductance, neighbors)`` at this step: static tables, or the dynamic list updated."""
        if physics.contacts == "static":
            conductance = neck_conductance(physics, state, prep.params) if _per_step(physics) else prep.conductance
            return state, conductance, state.contacts.neighbors
        particles, contacts = state.particles, state.contacts
        if physics.motion is not None:
            positions = physics.motion(state.time).astype(particles.positions.dtype)
            particles = dataclasses.replace(particles, positions=positions)
        contacts, _, overflow = follow_contacts(neighbor_fn, particles.positions, particles.radii, contacts)
        geometry = mechanics.pair_geometry(particles.positions, particles.radii, contacts.pairs.pairs)
        index, kappa = conductivity_lookup(physics, prep.params, particles)
        conductance = pair_conductance(physics, particles.radii, index, geometry, kappa,
                                       merged_law_params(physics, prep.params))
        state = dataclasses.replace(state, particles=particles, overflow=state.overflow | overflow, contacts=contacts)
        return state, conductance, contacts.pairs.pairs

    def heat_power_fn(state: SimState, prep: Prepared, conductance=None, neighbors=None):
        """Heat power into every particle (W): conduction, walls and sources at the state's time."""
        if conductance is None:
            state, conductance, neighbors = current_network(state, prep)
        temperature = state.particles.temperature
        power = conduction_power(state, prep, temperature, conductance, neighbors)
        return power + thermal.source_power(physics.sources, state, prep.params)

    def mechanical_advance(state: SimState, prep: Prepared) -> SimState:
        """The coupled step (Eqs. 43-46): forces and heat powers at ``t`` from one state, then symplectic Euler."""
        particles, contacts, params = state.particles, state.contacts, prep.params
        mp = params.mechanics
        positions, radii, mass, t = particles.positions, particles.radii, particles.mass, state.time
        contacts, motion, overflow = follow_contacts(neighbor_fn, positions, radii, contacts, state.mechanics)
        state = dataclasses.replace(state, overflow=state.overflow | overflow, contacts=contacts)
        modulus, nu = _elastic_constants(physics, mp, particles)
        index, kappa = conductivity_lookup(physics, params, particles)
        law_params = merged_law_params(physics, params)
        temperature = particles.temperature

        gap = 0.0 if physics.sintering is None else neck_growth.POINT_CONTACT_GAP

        def on_pairs(pairs, spring, rolling, sintered):
            geometry = mechanics.pair_geometry(positions, radii, pairs, gap)
            elastic = geometry if sintered is None else sintered_geometry(geometry, sintered)
            f, t_i, t_j, spring, rolling = mechanics.pair_loads(physics.mechanics, mp, elastic, radii, mass, modulus, nu,
                                                                motion.velocity, motion.spin, spring, rolling,
                                                                state.dt, positions.dtype)
            # heat through the contacts of this geometry (Eqs. 32-36); a sintered neck conducts as its approach does
            if sintered is not None:
                geometry = conducting_geometry(geometry, sintered)
            conductance = pair_conductance(physics, radii, index, geometry, kappa, law_params)
            return f, t_i, t_j, spring, rolling, pair_heat_flow(conductance, geometry.i, geometry.j, temperature)

        pairs = contacts.pairs.pairs
        f, t_i, t_j, spring, rolling, q = map_pair_blocks(on_pairs, pairs, motion.spring, motion.rolling,
                                                          motion.neck_overlap)
        n = radii.shape[0]
        motion = dataclasses.replace(motion, spring=spring, rolling=rolling)
        loads = mechanics.body_loads(physics.mechanics, mp, positions, radii, mass, modulus, nu, motion, t, state.dt,
                                     pair_exchange(f, pairs, n), pair_sum(t_i, t_j, pairs, n))
        power = pair_exchange(q, pairs, n)
        for w, wall in enumerate(physics.mechanics.walls):
            if wall.mode == "conducting":
                k_w = mechanical_wall_conductance(physics, radii, loads.wall_penetration[w], kappa[index], law_params)
                power = power + k_w * (jnp.asarray(wall.temperature, power.dtype) - particles.temperature)
        power = power + thermal.source_power(physics.sources, state, params)
        temperature = explicit_heat(state, prep, power)
        positions, velocity, spin = mechanics.integrate(positions, loads.mechanics, loads.force, loads.torque, mass,
                                                        radii, state.dt)
        particles = dataclasses.replace(particles, positions=positions, temperature=temperature)
        motion = dataclasses.replace(loads.mechanics, velocity=velocity, spin=spin)
        state = dataclasses.replace(state, particles=particles, mechanics=motion, step=state.step + 1)
        return state if physics.sintering is None else grow_pair_necks(state, prep)

    def grow_pair_necks(state: SimState, prep: Prepared) -> SimState:
        """With the mechanics: at the end of a growth interval, the necks on the half pair list grown over it (the
        many-body balance moving the particles) and the stability of the heat step on them."""
        spec = physics.sintering
        law = neck_growth.law_params(spec, prep.params.sintering)
        pairs = state.contacts.pairs.pairs

        def grow(particles, motion, carried):
            radii, n = particles.radii, particles.radii.shape[0]
            elapsed = (state.step - carried.interval_start).astype(state.dt.dtype) * state.dt
            geometry = mechanics.pair_geometry(particles.positions, radii, pairs, neck_growth.POINT_CONTACT_GAP)
            neck, overlap, displacement, unbalanced = neck_growth.grow_pair_necks(
                spec, law, carried, motion.neck, geometry, particles.positions, radii, particles.temperature, elapsed)
            if displacement is not None:
                particles = dataclasses.replace(particles, positions=particles.positions + displacement)
                carried = dataclasses.replace(carried, unbalanced=carried.unbalanced | unbalanced)
            motion = dataclasses.replace(motion, neck=neck, neck_overlap=overlap)
            grown = dataclasses.replace(state, particles=particles, mechanics=motion)
            _, k = sintered_pair_conductance(physics, grown, prep.params)
            total = pair_sum(k, k, pairs, n)
            walls = [w for w in physics.mechanics.walls if w.mode == "conducting"]
            if walls:
                index, kappa = conductivity_lookup(physics, prep.params, particles)
                h = mechanics.wall_penetration(walls, particles.positions, radii, state.time)
                for w in range(len(walls)):
                    total = total + mechanical_wall_conductance(physics, radii, h[w], kappa[index],
                                                                merged_law_params(physics, prep.params))
            if physics.conduction.held:  # held particles are reset every step: their rows do not count
                total = jnp.where(particles.fixed, 0.0, total)
            limit = thermal.explicit_stability_limit(capacity_now(state, prep), total)
            carried = dataclasses.replace(carried, interval_temperature=particles.temperature,
                                          interval_start=state.step, unstable=carried.unstable | jnp.any(state.dt > limit))
            return particles, motion, carried

        args = (state.particles, state.mechanics, state.sintering)
        if spec.every == 1:
            particles, motion, carried = grow(*args)
        else:
            particles, motion, carried = jax.lax.cond(neck_growth.update_interval(spec, state.step), grow,
                                                      lambda *kept: kept, *args)
        return dataclasses.replace(state, particles=particles, mechanics=motion, sintering=carried)

    def capacity_now(state: SimState, prep: Prepared):
        """The capacities (J/K) at this step: the rollout's, or with a specific-heat table at today's temperatures."""
        if physics.conduction.specific_heat_table:
            return particle_capacity(physics, prep.params, state.particles)
        return prep.capacity

    def explicit_heat(state: SimState, prep: Prepared, power):
        """The temperatures after an explicit step with heat power ``power`` (W) in: ``T + dt P / C``, or with a
        specific-heat table the enthalpy's step (:func:`sintercond.thermal.enthalpy_update`)."""
        particles = state.particles
        fixed = particles.fixed if physics.conduction.held else None
        if physics.conduction.specific_heat_table:
            return thermal.enthalpy_update(particles.temperature, power, particles.mass, state.dt,
                                           prep.params.specific_heat, fixed, held_temperature(state, prep))
        return thermal.explicit_update(particles.temperature, power, prep.capacity, state.dt, fixed,
                                       held_temperature(state, prep))

    def held_temperature(state: SimState, prep: Prepared):
        """The held particles' temperatures at the end of the step (K): fixed, or on their ramp."""
        fixed = state.particles.fixed_temperature
        if not physics.conduction.held_ramp:
            return fixed
        return held_ramp_temperature(prep.params.held_ramp, fixed, state.time + state.dt)

    def advance_fn(state: SimState, prep: Prepared) -> SimState:
        if physics.mechanics is not None:
            return mechanical_advance(state, prep)
        state, conductance, neighbors = current_network(state, prep)
        particles = state.particles
        fixed = particles.fixed if physics.conduction.held else None
        if (physics.conduction.integrator == "explicit" and physics.contacts == "static"
                and not physics.conduction.specific_heat_table):
            # the network term inside the update, whose reverse mode is written for the CPU; the pulse apart (its
            # switch, a scalar, is what reverse mode stores per step) and no field of zeros without walls or sources
            terms, pulse = thermal.source_power_parts(physics.sources, state, prep.params)
            if physics.conduction.conducting_walls:
                terms = [conduction_power(state, prep, particles.temperature, None, None)] + terms
            power = functools.reduce(jnp.add, terms) if terms else jnp.zeros((), particles.temperature.dtype)
            temperature = thermal.explicit_update(particles.temperature, power, prep.capacity, state.dt, fixed,
                                                  held_temperature(state, prep), (prep.scale, conductance, neighbors),
                                                  pulse, prep.rates)
        elif physics.conduction.integrator == "explicit":
            power = heat_power_fn(state, prep, conductance, neighbors)
            temperature = explicit_heat(state, prep, power)
        else:
            temperature = thermal.backward_euler_solve(
                particles.temperature, lambda x: prep.scale * network_laplacian(conductance, neighbors, x),
                None if prep.wall_conductance is None else prep.scale * jnp.sum(prep.wall_conductance, axis=0),
                None if prep.wall_conductance is None else prep.scale * jnp.sum(
                    prep.wall_conductance * prep.wall_temperature, axis=0),
                prep.capacity, state.dt, fixed, held_temperature(state, prep), physics.conduction.implicit_tol)
        state = dataclasses.replace(state, particles=dataclasses.replace(particles, temperature=temperature),
                                    step=state.step + 1)
        return state if physics.sintering is None else grow_necks(state, prep)

    def grow_necks(state: SimState, prep: Prepared) -> SimState:
        """At the end of a growth interval, the necks grown over it and the stability of the step on them."""
        spec, carried, particles = physics.sintering, state.sintering, state.particles
        law = neck_growth.law_params(spec, prep.params.sintering)

        def grow(contacts, carried, positions):
            elapsed = (state.step - carried.interval_start).astype(state.dt.dtype) * state.dt
            if spec.shrinkage == "many_body":
                neck, overlap, displacement, unbalanced = neck_growth.balance_table_necks(
                    spec, law, carried, contacts.neck, positions, particles.radii, particles.temperature, elapsed)
                positions = positions + displacement
                carried = dataclasses.replace(carried, unbalanced=carried.unbalanced | unbalanced)
            else:
                neck, overlap = neck_growth.grow_table_necks(spec, law, carried, contacts.neck, particles.radii,
                                                             particles.temperature, elapsed)
            contacts = dataclasses.replace(contacts, neck=neck, overlap=overlap)
            conductance = neck_conductance(physics, dataclasses.replace(state, contacts=contacts), prep.params)
            total = jnp.sum(conductance, axis=1)
            if physics.conduction.conducting_walls:
                wall_k = prep.wall_conductance
                if physics.conduction.conductivity_table:
                    wall_k = _wall_lift(physics, particles, contacts, prep.params,
                                        merged_law_params(physics, prep.params))
                total = total + prep.scale * jnp.sum(wall_k, axis=0)
            if physics.conduction.held:  # held particles are reset every step: their rows do not count
                total = jnp.where(particles.fixed, 0.0, total)
            limit = thermal.explicit_stability_limit(capacity_now(state, prep), total)
            unstable = carried.unstable | jnp.any(state.dt > limit)
            return contacts, dataclasses.replace(carried, interval_temperature=particles.temperature,
                                                 interval_start=state.step, unstable=unstable), positions

        if spec.every == 1:
            contacts, carried, positions = grow(state.contacts, carried, particles.positions)
        else:
            contacts, carried, positions = jax.lax.cond(neck_growth.update_interval(spec, state.step), grow,
                                                        lambda *kept: kept, state.contacts, carried,
                                                        particles.positions)
        if spec.shrinkage == "many_body":
            particles = dataclasses.replace(particles, positions=positions)
        return dataclasses.replace(state, particles=particles, contacts=contacts, sintering=carried)

    def step_fn(state: SimState, params: Params) -> SimState:
        return advance_fn(state, prepare_fn(state, params))

    return Simulator(physics, step_fn, prepare_fn, advance_fn, heat_power_fn)


def params_in_precision(params: Params, dtype) -> Params:
    """``params`` with every floating leaf (Python floats included) in ``dtype``, the state's float type, when that
    is narrower than float64: a float32 state with parameters written as Python floats would otherwise be promoted
    to float64 in the step (and refused by the scan that carries it). Float64 states take their parameters as
    given."""
    if jnp.dtype(dtype) == jnp.float64:
        return params

    def cast(leaf):
        floating = isinstance(leaf, float) or (hasattr(leaf, "dtype") and jnp.issubdtype(leaf.dtype, jnp.floating))
        return jnp.asarray(leaf, dtype) if floating else leaf

    return jax.tree_util.tree_map(cast, params)


def _elastic_constants(physics: Physics, mp, particles: ParticleState):
    """``(E [n], nu [n])`` of each particle: its modulus at its temperature (Eq. 42) and its material's Poisson ratio."""
    modulus = mechanics.particle_modulus(physics.mechanics, mp, particles.temperature, particles.material)
    nu = jnp.broadcast_to(jnp.atleast_1d(jnp.asarray(mp.nu, particles.positions.dtype))[particles.material],
                          particles.radii.shape)
    return modulus, nu


def contact_forces(physics: Physics, state: SimState, params: Params):
    """``(geometry, force [c, 3])`` of a mechanical state's listed pairs: the force on ``i`` from ``j`` (N) that the
    step's contact laws give at this state (Hertz with damping, Mindlin friction and its spring, Quintana-Ruiz &
    Campello 2020 Eqs. 2-13), ``geometry`` the :class:`sintercond.mechanics.PairGeometry` of the pairs."""
    if physics.mechanics is None:
        raise ValueError("contact_forces needs Physics.mechanics")
    particles, motion, mp = state.particles, state.mechanics, params.mechanics
    geometry = mechanics.pair_geometry(particles.positions, particles.radii, state.contacts.pairs.pairs)
    modulus, nu = _elastic_constants(physics, mp, particles)
    f, *_ = mechanics.pair_loads(physics.mechanics, mp, geometry, particles.radii, particles.mass, modulus, nu,
                                 motion.velocity, motion.spin, motion.spring, motion.rolling, state.dt,
                                 particles.positions.dtype)
    return geometry, f


def thermal_time_step(sim: Simulator, state: SimState, params: Params, source_conductance=None):
    """Largest explicit-Euler step with the maximum principle, ``min_i C_i / (sum_j K_ij + sum_w K_iw + G_i)`` (s).

    Static contacts at the state's geometry; ``source_conductance`` ``G_i``
    (W/K, optional) linearises sources that depend on the temperature
    (:func:`sintercond.thermal.source_conductance`). inf for a particle with
    no conductance. At or below it every new temperature is a convex
    combination of old ones and the sources' reference temperatures.
    """
    conduction = sim.physics.conduction
    if conduction.conductivity_table or conduction.specific_heat_table:
        # the tables' largest conductivity and smallest specific heat bound it at every temperature
        if conduction.conductivity_table:
            params = dataclasses.replace(params, conductivity=jnp.max(jnp.asarray(params.conductivity.values))[None])
        if conduction.specific_heat_table:
            params = dataclasses.replace(params, specific_heat=jnp.min(jnp.asarray(params.specific_heat.values))[None])
        conduction = dataclasses.replace(conduction, conductivity_table=False, specific_heat_table=False)
        sim = simulator(dataclasses.replace(sim.physics, conduction=conduction))
    # one compiled program: run op by op, its dozen small operations each cost an XLA compile on the host
    return jax.jit(lambda st, p, g: _stable_step(sim, st, p, g))(state, params, source_conductance)


def _stable_step(sim: Simulator, state: SimState, params: Params, source_conductance):
    """:func:`thermal_time_step`'s limit, traced."""
    prep = sim.prepare_fn(state, params)
    conductance = prep.conductance
    if _per_step(sim.physics):
        conductance = neck_conductance(sim.physics, state, params)
    if conductance is None:
        raise ValueError("thermal_time_step needs static contacts")
    total = prep.scale * jnp.sum(conductance, axis=1)
    if prep.wall_conductance is not None:
        total = total + prep.scale * jnp.sum(prep.wall_conductance, axis=0)
    if source_conductance is not None:
        total = total + source_conductance
    return thermal.explicit_stability_limit(prep.capacity, total)


# --------------------------------------------------------------------------
# building states


def init_state(particles: ParticleState, contacts: Contacts, dt, step=0, mechanics=None, sintering=None) -> SimState:
    """A :class:`SimState` at ``step`` (default 0) with time step ``dt`` (s).

    ``mechanics``: a :class:`sintercond.mechanics.MechanicalState` for
    ``Physics.mechanics`` (:func:`sintercond.mechanics.mechanical_state`).
    ``sintering``: a :class:`sintercond.neck_growth.NeckState` for ``Physics.sintering``
    (:func:`sintercond.neck_growth.neck_state`).
    """
    dtype = particles.temperature.dtype

    def scalar(value, kind):  # a Python number through NumPy: op by op, jnp.asarray(number, dtype) compiles
        return jnp.asarray(np.asarray(value, kind)) if isinstance(value, (int, float, np.number)) else (
            jnp.asarray(value, kind))

    return SimState(particles=particles, contacts=contacts,
                    step=scalar(step, jnp.int64 if jax.config.jax_enable_x64 else jnp.int32), dt=scalar(dt, dtype),
                    overflow=jnp.asarray(np.zeros((), bool)), mechanics=mechanics, sintering=sintering)


def table_contacts(table, wall_conductance=None, wall_temperature=None) -> TableContacts:
    """Contacts of ``conductance="table"`` from a :class:`sintercond.network.ContactTable` at unit conductivity."""
    return TableContacts(neighbors=table.neighbors, conductance=table.conductance,
                         wall_conductance=None if wall_conductance is None else jnp.asarray(wall_conductance),
                         wall_temperature=None if wall_temperature is None else jnp.asarray(wall_temperature))


def lifted_contacts(physics: Physics, centres, radii, walls=(), periodic_box=None, tolerance=1e-9,
                    pairs=None) -> LiftedContacts:
    """Contacts of ``conductance="lifted"``: the neck of every pair and of every conducting wall (host, once).

    Pairs as :func:`sintercond.network.contact_pairs` finds them, necks by
    ``physics.neck``, laid out with :func:`sintercond.network.ell_table`.
    ``walls``: ``(penetration [n], temperature)`` per conducting wall (m, K),
    penetration <= 0 where a particle does not touch it. ``pairs``: the
    :class:`~sintercond.network.ContactPairs` if the caller already searched.
    """
    from sintercond.network import contact_pairs, ell_table

    radii = np.asarray(radii, np.float64)
    p = contact_pairs(centres, radii, tolerance, periodic_box) if pairs is None else pairs
    a = np.where(p.overlap > 0, np.asarray(NECK_MODELS[physics.neck](p.r_i, p.r_j, p.overlap)), 0.0)
    neighbors, neck, overlap = ell_table(p.n_particles, p.i, p.j, a, p.overlap)
    contacts = LiftedContacts(neighbors=jnp.asarray(neighbors, jnp.int32), neck=jnp.asarray(neck),
                              overlap=jnp.asarray(overlap))
    if walls:
        h = np.stack([np.maximum(np.asarray(p, np.float64), 0.0) for p, _ in walls])
        a = np.asarray(wall_neck_radius(physics.neck, radii, h))
        contacts = dataclasses.replace(contacts, wall_neck=jnp.asarray(a), wall_overlap=jnp.asarray(h),
                                       wall_temperature=jnp.asarray([float(t) for _, t in walls]))
    return contacts


def list_region(positions, radii, margin=None):
    """``(lo, hi)`` ``[3]`` corners (m) of the cell grid of :func:`dynamic_contacts`: the packing's extent
    widened by ``margin`` (m, scalar or ``[3]``; default a tenth of the extent plus ``2 r_max`` on every side).

    A particle that leaves the region is still found (it falls into the face cells), so the margin only
    trades crowded face cells against empty ones: a rebuild's cell counts run over the whole region.
    """
    positions, radii = np.asarray(positions, np.float64), np.asarray(radii, np.float64)
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    margin = 0.1 * (hi - lo) + 2.0 * radii.max() if margin is None else margin
    return lo - margin, hi + margin


def dynamic_contacts(positions, radii, skin, capacity_multiplier=1.25, margin=None):
    """Contacts of ``contacts="dynamic"`` and their neighbour-list functions: ``(contacts, neighbor_fns)``.

    A Dense list with a Verlet skin from a sorted cell list (:func:`sintercond.neighbors.neighbor_list`):
    inside the step it is rebuilt only once a particle moved ``skin / 2``,
    and the half pair list (``DynamicContacts.pairs``, the pairs the laws run on)
    with it. Both are sized here with ``capacity_multiplier`` spare room.
    The cell-list region is :func:`list_region` (the packing's extent widened by ``margin``, m). Pass
    ``neighbor_fns`` to :func:`simulator`. The list keeps the float dtype of
    ``positions`` (float32 positions give a float32 list; others float64).
    """
    from sintercond.neighbors import neighbor_list

    dtype = jnp.float32 if np.asarray(positions).dtype == np.float32 else jnp.float64
    positions = np.asarray(positions, np.float64)
    radii = np.asarray(radii, np.float64)
    fns = neighbor_list(radii, skin, *list_region(positions, radii, margin), capacity_multiplier=capacity_multiplier)
    nbrs = fns.allocate(jnp.asarray(positions, dtype))
    half = allocate_half_pairs(nbrs.idx, jnp.asarray(positions, dtype), jnp.asarray(radii, dtype), fns.skin,
                               capacity_multiplier)
    return DynamicContacts(neighbor_list=nbrs, pairs=half), fns


def reallocate_neighbors(neighbor_fns):
    """A ``reallocate(start, end)`` for :func:`sintercond.rollout.advance`: room for the chunk that overflowed.

    The Dense list is allocated at the chunk's end positions, with room for
    the most neighbours and cell-range particles any build of the chunk met
    (never narrower than before); the half pair list grows to
    ``capacity_multiplier`` times the most pairs any build of the chunk
    needed (or the end positions need), if it overflowed. The redone chunk
    starts from ``start``: its pairs and springs are kept (padded to the new
    capacity), and its first update rebuilds both lists at the start
    positions, carrying the springs to them pair by pair, exactly as a roomy
    list would have held them.
    """
    def reallocate(start: SimState, end: SimState) -> SimState:
        old, demand = start.contacts.neighbor_list, tuple(int(d) for d in end.contacts.neighbor_list.demand)
        nbrs = neighbor_fns.allocate(end.particles.positions, demand=demand)
        if nbrs.idx.shape[1] < old.idx.shape[1]:
            nbrs = neighbor_fns.allocate(end.particles.positions, old.idx.shape[1] - nbrs.idx.shape[1], demand)
        nbrs = dataclasses.replace(nbrs, reference_position=jnp.full_like(nbrs.reference_position, jnp.inf))
        half = start.contacts.pairs
        capacity = half.capacity
        if bool(half_pairs_overflowed(end.contacts.pairs)):
            need = max(int(end.contacts.pairs.demand), half_pair_count(nbrs.idx, end.particles.positions,
                                                                       end.particles.radii, neighbor_fns.skin))
            capacity = half_pair_capacity(max(capacity + 1, int(math.ceil(neighbor_fns.capacity_multiplier * need))))
        n = start.particles.radii.shape[0]
        contacts = DynamicContacts(neighbor_list=nbrs, pairs=padded_half_pairs(half, capacity, n))
        motion = start.mechanics
        if motion is not None and capacity > half.capacity:  # the springs stay with their pairs, zeros after them
            pad = lambda x: None if x is None else jnp.concatenate(  # noqa: E731
                [x, jnp.zeros((capacity - half.capacity,) + x.shape[1:], x.dtype)])
            motion = dataclasses.replace(motion, **{f: pad(getattr(motion, f)) for f in mechanics.PAIR_HISTORY})
        return dataclasses.replace(start, contacts=contacts, mechanics=motion)

    return reallocate


def affine_shrinkage(centres, rate):
    """Positions shrinking toward the centroid at a linear strain ``rate`` (1/s): ``c0 + (1 - rate t)(c - c0)``."""
    centres = jnp.asarray(centres)
    centroid = jnp.mean(centres, axis=0)
    return lambda t: centroid + (1.0 - rate * t) * (centres - centroid)


# --------------------------------------------------------------------------
# rollout


@dataclasses.dataclass(frozen=True)
class SaveAt:
    """What :func:`rollout` saves: ``fn(state)`` every ``every`` steps (diffrax ``SaveAt(steps=, fn=)``).

    ``fn=None`` saves the temperatures; see :func:`probe_temperatures`,
    :func:`mean_temperature`. ``fn`` must be hashable (a function or a
    :class:`Observable`).
    """

    every: int = 1
    fn: Callable | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Observable:
    """An observable built from data (e.g. probe indices); hashed by identity."""

    fn: Callable
    data: Any = None

    def __call__(self, state):
        return self.fn(state, self.data)


def probe_temperatures(indices) -> Observable:
    """Temperatures ``[p]`` (K) of the particles ``indices``."""
    return Observable(lambda state, idx: state.particles.temperature[idx], jnp.asarray(indices))


def mean_temperature(state: SimState):
    """Mass-weighted mean temperature (K) of the free particles (all if none is held)."""
    p = state.particles
    weight = jnp.where(p.fixed, 0.0, p.mass)
    weight = jnp.where(jnp.sum(weight) > 0, weight, p.mass)
    return jnp.sum(weight * p.temperature) / jnp.sum(weight)


def _small_observable(shapes, state) -> bool:
    """Whether the observable holds at most 1/16 of the temperatures' elements (e.g. a few probes):
    cheap enough to write after every step."""
    size = sum(math.prod(x.shape) for x in jax.tree.leaves(shapes))
    return 16 * size <= math.prod(state.particles.temperature.shape)


MAX_INITIAL_OVERLAP = 0.5
"""Deepest sphere-sphere overlap a mechanical run may start from, as a fraction of the smaller radius: Hertz's law
(a small-strain law) would blow such spheres apart."""


def _checked_property(name, value, tabulated, symbol, unit, bound, needs):
    """``[n_materials]`` values of ``Params.<name>``, a :class:`sintercond.materials.Table` where the spec's
    ``<name>_table`` says so (one material: its first node's value); raises ``ValueError`` naming the field."""
    field = f"Params.{name}"
    if tabulated:
        if not isinstance(value, materials.Table):
            raise ValueError(f"Conduction.{name}_table needs {field} as a sintercond.materials.Table "
                             f"(materials.tabulated(T, {symbol})); got {value!r}")
        if value.extrapolate:
            raise ValueError(f"{field} (a table) must clamp at its ends (extrapolate=False): the stable step is "
                             f"bounded by the table's {bound}")
        nodes, values = np.asarray(value.temperatures, np.float64), np.asarray(value.values, np.float64)
        require_positive(f"{field} table's temperatures (K)", nodes)
        if nodes.ndim != 1 or nodes.shape != values.shape or len(nodes) < 2 or not np.all(np.diff(nodes) > 0):
            raise ValueError(f"{field} (a table) needs >= 2 strictly increasing temperatures (K) and as many "
                             f"values; got {nodes.tolist()} and {values.tolist()}")
        require_positive(f"{field} table's values ({unit})", values)
        return values[:1]  # one material
    if isinstance(value, materials.Table):
        raise ValueError(f"{field} is a table: set Conduction.{name}_table=True{needs}")
    return np.atleast_1d(np.asarray(value, np.float64))


def validate_inputs(sim: Simulator, state: SimState, params: Params) -> None:
    """Raise ``ValueError`` naming the field and the allowed range unless ``(state, params)`` can run on ``sim``.

    Checked on concrete input, before anything compiles (:func:`rollout` calls it
    when nothing is traced, :func:`sintercond.rollout.advance` always): the
    time step finite and > 0; conductivities and specific heats finite and > 0,
    one per material, every particle's material among them; finite positions
    and temperatures > 0 K; with mechanics the contact parameters
    (:func:`sintercond.mechanics.validate_mechanical_params`, the scene's rules),
    finite velocities and spins, and no two listed spheres at the same centre
    or overlapping by more than :data:`MAX_INITIAL_OVERLAP` of the smaller
    radius. Traced leaves are skipped (under ``jit`` they are the caller's).
    """
    kinds = {"beam": BeamParams, "convection": ConvectionParams, "radiation": RadiationParams, "pulse": PulseParams}
    for name, kind in kinds.items():
        if getattr(sim.physics.sources, name) not in (None, False) and getattr(params, name) is None:
            raise ValueError(f"Physics.sources.{name} is on but Params.{name} is None; give a simulate.{kind.__name__}")
    if not all_concrete(state, params):
        return
    dt = np.asarray(state.dt, np.float64)
    if not (dt.shape == () and np.isfinite(dt) and dt > 0):
        raise ValueError(f"SimState.dt (the time step) must be finite and > 0 s; got {state.dt!r}")
    conduction = sim.physics.conduction
    kappa = _checked_property("conductivity", params.conductivity, conduction.conductivity_table, "kappa",
                              "W/(m K)", "largest conductivity", " (with conductance='lifted')")
    heat = _checked_property("specific_heat", params.specific_heat, conduction.specific_heat_table, "c",
                             "J/(kg K)", "smallest specific heat", "")
    if kappa.ndim != 1 or heat.shape != kappa.shape:
        raise ValueError(f"Params.conductivity and Params.specific_heat must be [n_materials] each; got shapes "
                         f"{kappa.shape} and {heat.shape}")
    require_positive("Params.conductivity (W/(m K))", kappa)
    require_positive("Params.specific_heat (J/(kg K))", heat)
    p = state.particles
    material = np.asarray(p.material)
    if material.size and not (0 <= material.min() and material.max() < len(kappa)):
        raise ValueError(f"particle materials must index Params.conductivity ({len(kappa)} materials); got "
                         f"materials {material.min()}..{material.max()}")
    fail_where(~np.isfinite(np.asarray(p.positions)).all(axis=1),
               lambda i: f"particle positions must be finite; particle {i[0]} is not")
    require_positive("particle temperatures (K)", np.asarray(p.temperature, np.float64))
    if sim.physics.conduction.held_ramp:
        ramp = params.held_ramp
        if ramp is None:
            raise ValueError("Conduction.held_ramp needs Params.held_ramp (simulate.HeldRampParams)")
        if all_concrete(ramp):
            require_positive("Params.held_ramp.end_temperature (K)", np.asarray(ramp.end_temperature, np.float64))
            require_positive("Params.held_ramp.duration (s)", np.asarray(ramp.duration, np.float64))
            steps = np.asarray(ramp.steps, np.float64)
            if not (steps.shape == () and steps >= 1 and steps == np.round(steps)):
                raise ValueError(f"Params.held_ramp.steps must be a whole number >= 1; got {ramp.steps!r}")
    if sim.physics.sintering is not None:
        if state.sintering is None:
            raise ValueError("Physics.sintering needs SimState.sintering (simulate.init_state(..., "
                             "sintering=neck_growth.neck_state(contacts, temperature)))")
        neck_growth.validate_sintering(sim.physics.sintering, params.sintering, state.contacts, p.radii,
                                       state.sintering)
        if sim.physics.mechanics is not None:
            neck_growth.validate_pair_necks(state.mechanics, p.radii, state.contacts.pairs.pairs)
    if sim.physics.mechanics is None:
        return
    if params.mechanics is None:
        raise ValueError("Physics.mechanics needs Params.mechanics (sintercond.mechanics.MechanicalParams)")
    mechanics.validate_mechanical_params(params.mechanics, len(kappa))
    m = state.mechanics
    for name in ("velocity", "spin"):
        value = np.asarray(getattr(m, name), np.float64)
        fail_where(~np.isfinite(value).all(axis=-1), lambda i, name=name: f"MechanicalState.{name} must be finite; "
                                                                          f"particle {i[0]} is not")
    pairs = np.asarray(state.contacts.pairs.pairs)
    n = p.radii.shape[0]
    pairs = pairs[(pairs[:, 0] < n) & (pairs[:, 1] < n)]
    if len(pairs):
        x, r = np.asarray(p.positions, np.float64), np.asarray(p.radii, np.float64)
        i, j = pairs[:, 0], pairs[:, 1]
        distance = np.linalg.norm(x[i] - x[j], axis=1)
        depth = (r[i] + r[j] - distance) / np.minimum(r[i], r[j])
        _warn_float32_positions(p.positions, r[i] + r[j] - distance)
        deep = depth > MAX_INITIAL_OVERLAP
        if deep.any():
            k = int(np.argmax(depth))
            where = "at the same centre" if distance[k] <= 1e-12 * (r[i[k]] + r[j[k]]) else (
                f"overlapping by {depth[k]:.3g} of the smaller radius ({r[i[k]] + r[j[k]] - distance[k]:.3g} m)")
            raise ValueError(f"particles {int(i[k])} and {int(j[k])} are {where}; a mechanical run may start from "
                             f"overlaps of at most {MAX_INITIAL_OVERLAP:g} of the smaller radius (Hertz's law would "
                             "blow them apart): move them apart")


class PrecisionWarning(UserWarning):
    """The state's dtype cannot resolve what the run must resolve (float32 positions and nanometre overlaps)."""


FLOAT32_OVERLAP_STEPS = 64
"""Fewest float32 steps of the positions a touching pair's overlap should span before :class:`PrecisionWarning`."""


def _warn_float32_positions(positions, overlaps):
    """Warn when float32 positions resolve the contacts' overlaps in a few float32 steps only: contacts then open
    and close on round-off (a stiff settled bed loses a third of its touching pairs), where float64 positions with
    float32 laws (``Mechanics(force_dtype="float32")``) keep them."""
    if positions.dtype != jnp.float32:
        return
    touching = overlaps[overlaps > 0]
    if not touching.size:
        return
    ulp = float(np.spacing(np.float32(np.max(np.abs(np.asarray(positions))))))
    smallest = float(np.median(touching))
    if smallest < FLOAT32_OVERLAP_STEPS * ulp:
        warnings.warn(f"float32 positions resolve the contacts' overlaps (median {smallest:.3g} m) in "
                      f"{smallest / ulp:.0f} float32 steps of {ulp:.3g} m only: contacts will open and close on "
                      "round-off. Run with float64 positions (SINTERCOND_ENABLE_X64=1, the default) and "
                      "Mechanics(force_dtype='float32') for float32 contact laws", PrecisionWarning, stacklevel=3)


def segment_length(n_steps: int) -> int:
    """``ceil(sqrt(n_steps))``: steps between the states reverse mode keeps."""
    return max(1, math.isqrt(max(n_steps, 1) - 1) + 1)


def rollout(sim: Simulator, state: SimState, params: Params, n_steps: int, saveat: SaveAt = SaveAt(),
            checkpoint: bool = True, step_checkpoint: bool = False):
    """Advance ``n_steps`` steps; returns ``(final state, saved)`` with ``saved[k] = fn(state after (k+1) every steps)``.

    ``lax.scan`` over ``jax.checkpoint``-ed segments of about ``sqrt(n_steps)``
    steps (``checkpoint=False``: one plain scan), so reverse mode through the
    rollout keeps ``O(sqrt(n_steps))`` states and recomputes each segment
    once. ``n_steps`` must be a multiple of ``saveat.every``. Pure and
    traceable: wrap it in ``jax.jit`` (with ``sim``, ``n_steps`` and
    ``saveat`` static) or call it inside a jitted loss.

    ``step_checkpoint=True`` also wraps each step in ``jax.checkpoint``:
    reverse mode then keeps only the state after every step of the segment
    it is working on and recomputes the step on the way back, instead of
    stacking every intermediate of every step (hundreds of small arrays per
    step for the coupled step): one more run of the step instead of a
    write and a read of each of them. The numbers are the same to
    round-off (tests/test_fit_softening.py: the bed's gradient against
    central differences); memory falls; the forward run is unchanged.
    """
    every = saveat.every
    if not (isinstance(n_steps, int) and isinstance(every, int) and n_steps >= 1 and every >= 1):
        raise ValueError(f"n_steps and saveat.every must be integers >= 1; got {n_steps!r}, {every!r}")
    if n_steps % every:
        raise ValueError(f"n_steps ({n_steps}) must be a multiple of saveat.every ({every}); "
                         f"{n_steps // every * every} or {(n_steps // every + 1) * every} would do")
    observe = (lambda s: s.particles.temperature) if saveat.fn is None else saveat.fn
    validate_inputs(sim, state, params)
    if sim.physics.mechanics is not None and params.mechanics is not None:
        mechanics.check_wall_coefficients(sim.physics.mechanics, params.mechanics)
    prep = sim.prepare_fn(state, params)
    seg = segment_length(n_steps) if checkpoint else n_steps

    # leaves the step passes through unchanged (a static table, radii, masses) stay out of the loops' carries:
    # reverse mode would keep a copy of them at every checkpoint
    leaves, treedef = jax.tree.flatten(state)
    still = _unchanged_leaves(sim, prep, leaves, treedef)

    def full(moving):
        moving = iter(moving)
        return treedef.unflatten([x if kept else next(moving) for x, kept in zip(leaves, still)])

    def moving(s):
        return [x for x, kept in zip(treedef.flatten_up_to(s), still) if not kept]

    observe_state = observe
    observe = lambda m: observe_state(full(m))  # noqa: E731
    state = moving(state)

    def advance(s, _):
        return moving(sim.advance_fn(full(s), prep)), None

    if step_checkpoint:
        advance = jax.checkpoint(advance, prevent_cse=False)

    def run_steps(s, length):
        if length <= seg:
            return jax.lax.scan(advance, s, None, length=length)[0] if length else s
        # ceil(length / seg) checkpointed segments of equal size (<= seg); the unchecked rest is shorter
        # than their number, so over many saves it stays O(sqrt(n_steps)) steps
        count = -(-length // seg)
        size, r = divmod(length, count)
        s = jax.lax.scan(jax.checkpoint(lambda c, _: (run_steps(c, size), None), prevent_cse=False), s, None,
                         length=count)[0]
        return run_steps(s, r)

    def one_save(s, _):
        s = run_steps(s, every)
        return s, observe(s)

    def saving_steps(s, n_saved):
        """``n_saved * every`` steps in one flat scan, the observable written into a buffer every ``every`` steps.

        A scan over saves of a scan over steps would stack the per-step
        residuals of reverse mode twice (and copy them between the levels).
        """
        shapes = jax.eval_shape(observe, s)
        buffer = jax.tree.map(lambda x: jnp.zeros((n_saved,) + x.shape, x.dtype), shapes)

        def save(s, buffer, k):
            return jax.tree.map(lambda b, x: jax.lax.dynamic_update_index_in_dim(b, x, k // every, 0), buffer,
                                observe(s))

        def step(carry, k):
            s, buffer = carry
            s = advance(s, None)[0]
            if _small_observable(shapes, full(s)):
                # written after every step, the last write of an interval standing: no branch, whose transpose
                # adds a zero field to the state's cotangent at every step
                buffer = save(s, buffer, k)
            else:
                buffer = jax.lax.cond((k + 1) % every == 0, save, lambda s, b, k: b, s, buffer, k)
            return (s, buffer), None

        (s, buffer), _ = jax.lax.scan(step, (s, buffer), jnp.arange(n_saved * every))
        return s, buffer

    n_saves = n_steps // every
    group = max(1, seg // every)
    if group <= 1:
        if checkpoint and 1 < every <= seg < n_steps:
            # one save per segment: the segment is the save interval (unchecked, reverse mode would keep
            # every step of the run)
            state, saved = jax.lax.scan(jax.checkpoint(one_save, prevent_cse=False), state, None, length=n_saves)
        else:
            state, saved = jax.lax.scan(one_save, state, None, length=n_saves)
        return full(state), saved
    if group >= n_saves:
        state, saved = saving_steps(state, n_saves)
        return full(state), saved
    q, r = divmod(n_saves, group)
    state, saved = jax.lax.scan(jax.checkpoint(lambda s, _: saving_steps(s, group), prevent_cse=False), state, None,
                                length=q)
    saved = jax.tree.map(lambda x: x.reshape((q * group,) + x.shape[2:]), saved)
    if r:
        state, tail = saving_steps(state, r)
        saved = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), saved, tail)
    return full(state), saved


def _unchanged_leaves(sim, prep, leaves, treedef):
    """Per leaf of the flattened state: whether one step returns it unchanged (the same value, untouched)."""
    jaxpr = jax.make_jaxpr(lambda *xs: jax.tree.leaves(sim.advance_fn(treedef.unflatten(xs), prep)))(*leaves).jaxpr
    return [out is var for var, out in zip(jaxpr.invars, jaxpr.outvars)]


@dataclasses.dataclass(frozen=True)
class _TemperatureSource:
    """Adapts a ``source(temperature, t)`` callable to the simulator's ``fn(state, t, params)``."""

    source: object

    def __call__(self, state, t, params):
        return self.source(state.particles.temperature, t)


def simulate_table(temperature, table: ContactTable, capacity, dt, n_steps, save_every=1, fixed_mask=None,
             fixed_temperature=None, method="explicit", source=None, start_step=0, probes=None):
    """Advance a table network ``n_steps`` steps; returns ``(final, saved [n_steps // save_every, n])``.

    A convenience over :func:`rollout` for a network
    already built at its conductivity: ``method`` ``"explicit"`` (check
    ``dt <= thermal.table_time_step`` first) or ``"implicit"`` (backward Euler, any
    ``dt``; conduction only). ``source(temperature, t)``: heat powers (W), a
    hashable callable (explicit only), called with the time
    ``(start_step + k) dt`` of step ``k``. ``probes``: indices of the
    particles to save (``saved`` is then ``[.., len(probes)]``); None saves
    all. ``n_steps`` must be a multiple of ``save_every``.
    """
    if method not in ("explicit", "implicit"):
        raise ValueError(f"method must be 'explicit' or 'implicit'; got {method!r}")
    if not (isinstance(n_steps, int) and isinstance(save_every, int) and n_steps >= 1 and save_every >= 1):
        raise ValueError(f"n_steps and save_every must be integers >= 1; got {n_steps!r}, {save_every!r}")
    if n_steps % save_every:
        raise ValueError(f"n_steps ({n_steps}) must be a multiple of save_every ({save_every})")
    for name, value in (("dt (s)", dt), ("capacity (J/K)", capacity)):
        if all_concrete(value):
            require_positive(name, np.atleast_1d(np.asarray(value, np.float64)))
    return _simulate_table(temperature, table, capacity, dt, n_steps, save_every, fixed_mask, fixed_temperature,
                           method, source, start_step, probes)


@functools.partial(jax.jit, static_argnames=("n_steps", "save_every", "method", "source"))
def _simulate_table(temperature, table, capacity, dt, n_steps, save_every, fixed_mask, fixed_temperature, method,
                    source, start_step, probes):
    if method == "implicit" and source is not None:
        raise ValueError("source terms need method='explicit'")
    walls = table.wall_conductance is not None
    physics = Physics(conduction=Conduction(conductance="table", integrator=method, held=fixed_mask is not None,
                                            conducting_walls=int(walls)),
                      sources=Sources(source=None if source is None else _TemperatureSource(source)))
    n = temperature.shape[0]
    capacity = jnp.broadcast_to(jnp.asarray(capacity, temperature.dtype), (n,))
    fixed = jnp.zeros(n, bool) if fixed_mask is None else jnp.broadcast_to(fixed_mask, (n,))
    held = temperature if fixed_temperature is None else jnp.broadcast_to(
        jnp.asarray(fixed_temperature, temperature.dtype), (n,))
    particles = ParticleState(positions=jnp.zeros((n, 3), temperature.dtype), radii=jnp.ones(n, temperature.dtype),
                              temperature=temperature, mass=capacity, material=jnp.zeros(n, jnp.int32), fixed=fixed,
                              fixed_temperature=held)
    contacts = table_contacts(table, table.wall_conductance, table.wall_temperature)
    state = init_state(particles, contacts, dt, start_step)
    params = Params(conductivity=jnp.ones(1, temperature.dtype), specific_heat=jnp.ones(1, temperature.dtype))
    saveat = SaveAt(save_every, None if probes is None else probe_temperatures(probes))
    sim = simulator(physics)
    final, saved = rollout(sim, state, params, n_steps, saveat)
    return final.particles.temperature, saved


# Old names, kept for one release: each time-step function has its own name (issue 24).
__getattr__ = old_names("sintercond.simulate", {
    "stable_time_step": ("sintercond.simulate", "thermal_time_step"),
})
