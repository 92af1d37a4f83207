"""The scene schema: every key of a scene file with its type, range, unit, default and meaning (:class:`Key`),
the limits of a run, and the checks of one value against its key. ``docs/scenes.md`` is generated from it
(:mod:`sintercond.scene.reference`)."""

from __future__ import annotations

import difflib
import math
from typing import NamedTuple


from sintercond.laws.conductance import CONDUCTANCE_LAWS
from sintercond.sim.mechanics import PARAMETER_RANGES
from sintercond.laws.neck import NECK_MODELS
from sintercond.laws.sintering import KINETIC_LAWS


class SceneError(ValueError):
    """An invalid scene: the message names the key and the allowed range."""


class Key(NamedTuple):
    """One scene key: its type, allowed range, unit, default and meaning (the scene reference is made from these)."""

    kind: type  # float, int, str, bool, list or dict
    rule: tuple | None  # (text, predicate) or None
    required: bool
    unit: str = ""
    default: object = None
    doc: str = ""


def _within(low, high, unit="", low_open=False):
    text = f"in {'(' if low_open else '['}{low:g}, {high:g}]" + (f" {unit}" if unit else "")
    return text, (lambda v: (low < v if low_open else low <= v) and v <= high)


def _choice(*options):
    return "one of " + ", ".join(repr(o).replace("'", '"') for o in options), (lambda v: v in options)


def _parameter(field):
    """The scene rule of a :class:`sintercond.sim.mechanics.MechanicalParams` field: the Python API's range."""
    low, high, unit = PARAMETER_RANGES[field]
    return _within(low, high, unit)


# scene key -> the MechanicalParams field it sets (mechanics and softening sections)
MECHANICAL_FIELDS = {
    "mechanics.young_modulus": "E0", "mechanics.poisson_ratio": "nu", "mechanics.friction": "mu",
    "mechanics.rolling_friction": "mu_r", "mechanics.wall_friction": "mu_wall",
    "mechanics.wall_rolling_friction": "mu_r_wall", "mechanics.damping": "xi_con",
    "mechanics.tangential_damping": "xi_fric", "mechanics.rolling_damping": "xi_rol",
    "softening.onset_temperature": "theta_star", "softening.rate": "rate", "softening.min_modulus": "E_min",
}


TEMPERATURE = _within(1.0, 1e4, "K")


PACKING_KINDS = ("powder_bed", "simple_cubic", "spheres", "poured", "file")


PACKING_METHODS = ("roll", "relax", "dem")
"""How a ``powder_bed`` is made (``packing.method``): rolled down the pile (the default), harmonic relaxation, or
poured with the DEM of [mechanics]."""


MAX_POURED_PARTICLES = 20_000
"""Spheres of a ``poured`` packing: each costs a DEM settle (~1e4-1e5 steps)."""


MAX_LISTED_SPHERES = 10_000
"""Most spheres of a ``kind = "spheres"`` packing (they are listed in the scene file)."""


FRACTION = _within(0.0, 1.0)


# Limits of a run, checked before anything is built (``run.override_limits = true`` lifts the last three).
MAX_LATTICE_PARTICLES = 2_000_000
"""Largest ``simple_cubic`` lattice (memory of the network build, ~4 kB a particle)."""


MAX_STEPS = 10_000_000
"""Most time steps of a run (estimated from the scene: ``duration`` over the (estimated stable) step)."""


MAX_FRAMES = 10_000
"""Most output frames of a run (``steps / output_every + 1``): files in ``vtp/``, frames of the dump."""


MAX_OUTPUT_BYTES = 2e9
"""Most bytes of outputs of a run (about 230 B a particle and frame in VTP, 140 B in the LAMMPS dump)."""


DEFAULT_OUTPUTS = 100
"""Outputs of a run whose scene gives no ``run.output_every`` (:func:`output_interval`)."""


DEFAULT_CHECKPOINT_OUTPUTS = 10
"""Outputs between two checkpoints of a run whose scene gives no ``run.checkpoint_every``."""


def output_interval(run, steps) -> tuple[int, int]:
    """``(output_every, checkpoint_every)`` (steps) of a validated ``[run]`` table for a run of ``steps`` steps: the
    scene's, or :data:`DEFAULT_OUTPUTS` outputs over the run and a checkpoint every
    :data:`DEFAULT_CHECKPOINT_OUTPUTS` of them."""
    every = run.get("output_every") or max(1, math.ceil(steps / DEFAULT_OUTPUTS))
    return every, run.get("checkpoint_every") or every * DEFAULT_CHECKPOINT_OUTPUTS


MAX_MEMORY_BYTES = 8e9
"""Most memory of the network build (about 4 kB a particle)."""


_SCHEMA = {
    "material": {
        "density": Key(float, _within(1.0, 1e5, "kg/m^3"), True, "kg/m^3", doc="solid density"),
        "specific_heat": Key(float, _within(1.0, 1e5, "J/(kg K)"), True, "J/(kg K)",
                             doc="specific heat capacity (with specific_heat_table: the one number the run's "
                                 "estimate takes)"),
        "specific_heat_table": Key(list, ("a list of at least 2 [T, c] pairs, T strictly increasing in (0, 1e5] K, "
                                          "c in [1, 100000] J/(kg K)", lambda v: True), False, "K, J/(kg K)",
                                   doc="c(T): each particle's capacity at its own temperature, piecewise linear "
                                       "between the pairs and clamped beyond them; the run steps the enthalpy int c "
                                       "dT, so heat is conserved to round-off (sintercond.sim.thermal.enthalpy_update)"),
        "conductivity": Key(float, _within(1e-6, 1e4, "W/(m K)"), True, "W/(m K)",
                            doc="solid conductivity kappa (with conductivity_table: the one number sintercond "
                                "effective and the run's estimate take)"),
        "conductivity_table": Key(list, ("a list of at least 2 [T, kappa] pairs, T strictly increasing in (0, "
                                         "1e5] K, kappa in [1e-06, 10000] W/(m K)", lambda v: True), False,
                                  "K, W/(m K)",
                                  doc="kappa(T): each particle conducts at its own temperature, piecewise linear "
                                      "between the pairs and clamped beyond them (sintercond.laws.materials.Table); the "
                                      "run's conductances are then evaluated at every step"),
        "melting_point": Key(float, TEMPERATURE, False, "K",
                             doc="melting point (or solidus): the model has no melting, so a run whose hottest "
                                 "particle crosses it stops (or warns, material.on_melting), naming it"),
        "on_melting": Key(str, _choice("stop", "warn"), False, default="stop",
                          doc="what a run crossing material.melting_point does"),
    },
    "conduction": {
        "law": Key(str, _choice(*sorted(CONDUCTANCE_LAWS)), True, doc="pair conductance law"),
        "neck_model": Key(str, _choice(*sorted(NECK_MODELS)), False, default="the law's",
                          doc="neck (contact) radius the law takes"),
        "params": Key(dict, None, False, default="the law's", doc="the law's parameters, see [conduction.params]"),
        "coupling": Key(str, _choice("none", "sphere"), False, default="none",
                        doc="the network the transient steps with (k* is measured on sintering.k_star_coupling's): "
                            "none, each neck's pair law as if it were alone on its sphere; sphere, the necks that "
                            "share a sphere coupled through its surface (sintercond.contacts.sphere_coupling; the "
                            "run's conductances are lifted; static packings, necks that stay or grow independently "
                            "(not sintering.shrinkage = \"many_body\"), property tables, no conducting walls or "
                            "physics.mechanics, held walls on one axis, the explicit integrator; a packing whose "
                            "necks' discs overlap is refused, and a sphere whose growing necks' discs come to "
                            "overlap keeps its pair laws' halves)"),
    },
    "initial": {"temperature": Key(float, TEMPERATURE, True, "K",
                                   doc="initial temperature of every particle (with from_file: of held particles "
                                       "that take it, and of the settling)"),
                "from_file": Key(bool, None, False, default=False,
                                 doc="true: each particle starts at the temperature of the packing file's "
                                     "temperature column (packing.kind = \"file\": a table's header column T or "
                                     "temperature, a dump's temperature or f_Temp)")},
    "boundary": {"floor_temperature": Key(float, TEMPERATURE, False, "K",
                                          doc="shorthand for a held wall at the bottom (axis 2, min)")},
    "beam": {
        "kind": Key(str, _choice("laser", "nozzle"), False, default="laser",
                    doc="laser: Lambert-Beer attenuation; nozzle: linear attenuation to max_depth"),
        "intensity": Key(float, _within(0.0, 1e12, "W/m^2"), False, "W/m^2",
                         doc="I0, power per unit spot area (give it or beam.power)"),
        "power": Key(float, _within(0.0, 1e6, "W"), False, "W",
                     doc="the beam's power, I0 pi spot_radius^2 (give it or beam.intensity)"),
        "attenuation": Key(float, _within(0.0, 1e9, "1/m"), False, "1/m", doc="mu of a laser (required for it)"),
        "max_depth": Key(float, _within(1e-9, 1.0, "m"), False, "m", doc="reach d_max of a nozzle (required for it)"),
        "spot_radius": Key(float, _within(1e-9, 1.0, "m"), True, "m",
                           doc="a particle is heated when its centre lies within spot_radius + r of the beam axis"),
        "absorptance": Key(float, FRACTION, True, doc="absorbed fraction a"),
        "speed": Key(float, _within(0.0, 1e3, "m/s"), True, "m/s", doc="speed along the path"),
        "path": Key(list, ("a non-empty list of [x, y] points (m)", lambda v: True), True, "m",
                    doc="[[x, y], ...] waypoints in absolute coordinates of the packing "
                        "(the container's corner or the lattice's first sphere side at 0), "
                        "each within the packing's lateral extent widened by spot_radius"),
        "segments_on": Key(list, ("a list of booleans, one per segment of beam.path", lambda v: True), False,
                           doc="whether the beam heats along each segment of the path (false: a jump between "
                               "hatch lines); default: every segment"),
        "after_path": Key(str, _choice("off", "stay"), False, default="off",
                          doc="off: the beam stops heating once its path is done; stay: it heats on at the last "
                              "waypoint (a path of one point is a stationary spot, on throughout)"),
    },
    "convection": {
        "environment_temperature": Key(float, TEMPERATURE, True, "K", doc="T_E of the gas"),
        "environment_conductivity": Key(float, _within(1e-6, 1e3, "W/(m K)"), True, "W/(m K)",
                                        doc="k_E of the gas"),
        "nusselt": Key(float, _within(0.0, 1e4, low_open=True), False, default=2.0,
                       doc="Nu of h = Nu k_E / (2 r); or give reynolds and prandtl"),
        "reynolds": Key(float, _within(0.0, 1e6), False, doc="Re of Whitaker's correlation (with prandtl)"),
        "prandtl": Key(float, _within(1e-3, 1e5), False, doc="Pr of Whitaker's correlation (with reynolds)"),
    },
    "radiation": {
        "environment_temperature": Key(float, TEMPERATURE, True, "K", doc="T_E of the surroundings"),
        "emissivity": Key(float, FRACTION, True, doc="epsilon"),
    },
    "physics": {
        "mechanics": Key(bool, None, False, default=False,
                         doc="true: the coupled thermo-mechanical step (Quintana-Ruiz & Campello 2020, Eqs. 43-46): "
                             "particles move under Hertz contacts, friction, rolling resistance, gravity and the "
                             "walls, "
                             "and heat flows through the contacts the motion opens and grows; needs [mechanics]. "
                             "false: the packing stays put (the fast thermal path)"),
        "gravity": Key(list, ("a list of 3 numbers in [-1000, 1000] m/s^2", lambda v: True), False, "m/s^2",
                       default=[0.0, 0.0, -9.81], doc="acceleration of gravity (with mechanics)"),
        "shear": Key(str, _choice("paper", "mindlin"), False, default="paper",
                     doc="effective shear modulus G*: the paper's Eq. 9 or Mindlin's 1/G* = sum (2 - nu)/G"),
        "slip_direction": Key(str, _choice("trial", "velocity"), False, default="trial",
                              doc="direction of a slipping friction force: along the trial force (LAMMPS) or the "
                                  "sliding velocity (MECHANICS.md erratum 3)"),
        "rolling_projection": Key(bool, None, False, default=False,
                                  doc="roll on the tangential part of the relative spin only (LAMMPS sds; erratum 5)"),
        "damping_clamp": Key(bool, None, False, default=False,
                             doc="no tensile normal force while a contact opens (LAMMPS limit_damping)"),
        "container": Key(bool, None, False, default=True,
                         doc="with a powder_bed: its box [0, lateral_size]^2 over the floor z = 0 holds the moving "
                             "particles, an insulated wall on each face the scene gives no [[walls]] of its own "
                             "(sintercond.beds.settle.box_walls); false: only the scene's walls, and the bed spreads. A "
                             "run warns (PackingBoxWarning) when particles leave the box"),
        "skin": Key(float, _within(0.0, 10.0, low_open=True), False, "largest radii", default=0.1,
                    doc="Verlet skin of the contact list; it is rebuilt once a particle moved half of it"),
        "impact_velocity": Key(float, _within(0.0, 1e3, "m/s", low_open=True), False, "m/s", default=0.05,
                               doc="largest approach speed of two particles (or of a particle and a wall, beyond the "
                                   "wall's own speed) the automatic time step is sized for (Eq. 47 and MECHANICS.md "
                                   "erratum 8); a faster contact stops the run"),
    },
    "mechanics": {
        "young_modulus": Key(float, _parameter("E0"), True, "Pa",
                             doc="E0, Young's modulus (below the softening onset)"),
        "poisson_ratio": Key(float, _parameter("nu"), True, doc="nu"),
        "friction": Key(float, _parameter("mu"), False, default=0.0,
                        doc="mu, Coulomb friction between particles (Eq. 8); > 0 turns Mindlin friction on"),
        "rolling_friction": Key(float, _parameter("mu_r"), False, default=0.0,
                                doc="mu_r, rolling resistance between particles (Eq. 16); > 0 turns it on"),
        "wall_friction": Key(float, _parameter("mu_wall"), False, default="friction",
                             doc="mu against every wall"),
        "wall_rolling_friction": Key(float, _parameter("mu_r_wall"), False, default="rolling_friction",
                                     doc="mu_r against every wall"),
        "damping": Key(float, _parameter("xi_con"), False, default=1.0,
                       doc="xi_con, normal damping ratio (Eq. 6; 1 critical for the linearised contact); or give "
                           "restitution"),
        "restitution": Key(float, _within(0.0, 1.0, low_open=True), False,
                           doc="coefficient of restitution e instead of damping: xi_con = sqrt(5/6) beta, "
                               "beta = -ln e / sqrt(pi^2 + ln^2 e) (Tsuji's form, as LAMMPS)"),
        "tangential_damping": Key(float, _parameter("xi_fric"), False, default=1.0, doc="xi_fric (Eq. 11)"),
        "rolling_damping": Key(float, _parameter("xi_rol"), False, default=0.0, doc="xi_rol (Eq. 18)"),
        "quasi_static": Key(bool, None, False, default=False,
                            doc="sintering at the material's real modulus (needs sintering.shrinkage = "
                                "\"many_body\"): no inertia; the particles move at the neck updates by the necks' "
                                "many-body balance, which leaves the elastic overlaps (and the weight they carry) as "
                                "they were, and the step is the thermal one, not the elastic one (Eq. 47). The "
                                "tangential and damping laws, softening and physics.impact_velocity then do not act "
                                "on the motion. false: Newton's law at the elastic step (docs/simulator.md, "
                                "quasi-static sintering)"),
    },
    "softening": {
        "onset_temperature": Key(float, _parameter("theta_star"), True, "K",
                                 doc="theta*, where softening starts (Eq. 42)"),
        "rate": Key(float, _parameter("rate"), False, default=1.0,
                    doc="r of E = max(E_min, E0 exp(min(0, r (1 - theta/theta*)))) (MECHANICS.md erratum 6; "
                        "1: the printed Eq. 42)"),
        "min_modulus": Key(float, _parameter("E_min"), False, "Pa", default=0.0,
                           doc="E_min, the floor (at most mechanics.young_modulus)"),
    },
    "sintering": {
        "law": Key(str, _choice(*sorted(KINETIC_LAWS)), False, default="grain_boundary",
                   doc="kinetic law of the necks (sintercond.laws.sintering): grain_boundary (Bouvard & McMeeking; "
                       "Nosewicz et al. 2013), power_law (d(a^n)/dt = K0 exp(-Q/RT) (r*/r_ref)^p) or viscous "
                       "(Frenkel)"),
        "every": Key(int, _within(1, 1e6), False, "steps", default=1,
                     doc="thermal steps between two neck updates; each grows the necks over those steps at the "
                         "mean of the pair temperatures at their start and end. With neck_rtol: the longest "
                         "interval"),
        "neck_rtol": Key(float, _within(0.0, 0.5, low_open=True), False,
                         doc="the necks at their own pace (explicit stepping): the interval between two neck updates "
                             "follows the necks' largest relative growth in the last one, scaled to this (from one "
                             "step, at most doubling, at most sintering.every); unset: every sintering.every steps "
                             "(sintercond.sim.neck_growth.Sintering)"),
        "params": Key(dict, None, False, default="the law's",
                      doc="the kinetic law's parameters, see [sintering.params]"),
        "shrinkage": Key(str, _choice("independent", "many_body"), False, default="independent",
                         doc="independent: the packing stays, each contact's approach H(a) recorded (first stage); "
                             "many_body: the overdamped balance of the contacts' sintering forces and dashpots moves "
                             "the particles at each neck update, those resting on a floor (a wall on axis 2, side min) held "
                             "vertically "
                             "(sintercond.sim.neck_growth)"),
        "start_necks": Key(str, _choice("point", "overlap"), False,
                           doc="with physics.mechanics (point if not given): point, every contact starts as a point "
                               "contact and its overlap stays elastic (the bed keeps its load); overlap, every "
                               "overlap is taken as a sintered neck (the volume-conserving neck of it) that carries "
                               "no elastic load. Without the mechanics the necks start from the packing's overlaps"),
        "k_star_axis": Key(int, _choice(0, 1, 2), False,
                           doc="history.csv gains k_star_W_mK: the effective conductivity along this axis from a "
                               "steady solve on the grown necks at each output, in the box of sintercond effective "
                               "(sintercond.beds.packing.measurement_box): a powder bed's container up to its mean "
                               "surface height (along z its floor's layer held hot and the particles reaching above "
                               "the mean surface cold), a lattice's end layers, any other packing's face layers; "
                               "each particle at its conductivity "
                               "(material.conductivity_table at its temperature, or material.conductivity); and "
                               "k_star_uncoupled, the particles with two necks closer than their discs' half-widths "
                               "(kept at the pair law's halves by the coupled network)"),
        "k_star_coupling": Key(str, _choice("sphere", "none"), False, default="sphere",
                               doc="the network k_star_W_mK is measured on, whatever conduction.coupling the run "
                                   "steps with: sphere, the necks that share a sphere coupled through its surface "
                                   "(sintercond.contacts.sphere_coupling; within 2 % of full-field solves where the "
                                   "isolated network reads 2-14 % high on BCC and 11-39 % on FCC cells at a/r "
                                   "0.16-0.4), a particle whose necks' discs overlap at its pair laws' halves; none, "
                                   "each neck's pair law alone on its sphere (the isolated pipe network)"),
    },
    "preheating": {
        "end_temperature": Key(float, TEMPERATURE, True, "K", doc="the temperature the held particles reach"),
        "duration": Key(float, _within(0.0, 1e6, "s", low_open=True), True, "s", doc="the ramp's duration"),
        "steps": Key(int, _within(1, 1e6), False, default=25,
                     doc="equal steps of the ramp (25: Rizza & Galati 2024's Eq. 6), each held at the temperature "
                         "it ends at"),
        "hold": Key(str, _choice("walls", "all"), False, default="walls",
                    doc="walls: the particles of the held walls follow the ramp from the wall's temperature; all: "
                        "every particle is held and follows it from initial.temperature (an isothermal cell, as "
                        "Rizza & Galati's REVs)"),
    },
    "run": {
        "duration": Key(float, _within(0.0, 1e6, "s", low_open=True), True, "s",
                        doc="simulated time; the run ends exactly there"),
        "dt": Key(object, ('"auto" or a number in (0, 1e3] s', lambda v: v == "auto" or (
            not isinstance(v, (bool, str)) and isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= 1e3)),
            False, "s", default="auto", doc='explicit step; "auto" = 0.9 x the stable step'),
        "integrator": Key(str, _choice("auto", "explicit", "implicit"), False, default="auto",
                          doc='explicit: Euler at run.dt; implicit: adaptive TR-BDF2 (docs/simulator.md) within '
                              'run.rtol / run.atol, each output interval stepped as its error allows (static '
                              'packings without mechanics or coupled necks); auto: implicit where the run has no '
                              'inertial mechanics, coupled necks or beam and would take at least 100,000 explicit '
                              'steps, explicit otherwise (the log says which and why)'),
        "rtol": Key(float, _within(0.0, 0.1, low_open=True), False, default=1e-5,
                    doc="implicit: the relative local error bound of a step, |e_i| <= atol + rtol |T_i|"),
        "atol": Key(float, _within(0.0, 100.0, "K", low_open=True), False, "K", default=1e-3,
                    doc="implicit: the absolute local error bound of a step"),
        "output_every": Key(int, _within(1, 1e9), False, "steps", default=f"about {DEFAULT_OUTPUTS} outputs",
                            doc=f"steps between output frames; not given, the run's steps / {DEFAULT_OUTPUTS} (rounded "
                                "up), so that the outputs follow run.duration (and --duration)"),
        "checkpoint_every": Key(int, _within(1, 1e9), False, "steps",
                                default=f"{DEFAULT_CHECKPOINT_OUTPUTS} outputs",
                                doc="steps between checkpoints, a multiple of output_every (given only with it); not "
                                    f"given, every {DEFAULT_CHECKPOINT_OUTPUTS} outputs"),
        "formats": Key(list, ("a non-empty list of distinct names from ['lammps', 'vtp']", lambda v: True), False,
                       default=["vtp"],
                       doc='non-empty list of distinct "vtp" (ParaView) and "lammps" (OVITO)'),
        "contact_network": Key(bool, None, False, default=False,
                               doc="true: with vtp, each output also writes the contact network, vtp/network_*.vtp "
                                   "(network.pvd): a line per contact carrying its neck_radius (m), conductance "
                                   "(W/K) and heat_flow (W, from its lower to its higher index)"),
        "vtp_encoding": Key(str, _choice("binary", "ascii"), False, default="binary",
                            doc="binary: point data appended and zlib-compressed (VTK's own layout); ascii: text"),
        "override_limits": Key(bool, None, False, default=False,
                               doc="true lifts the limits on steps, frames and output bytes (MAX_STEPS, "
                                   "MAX_FRAMES, MAX_OUTPUT_BYTES)"),
    },
}


SOFT_MODULUS = Key(float, _within(1.0, 1e12, "Pa"), False, "Pa",
                   doc="pour at this Young's modulus first, below mechanics.young_modulus, then carry the settled "
                       "bed to the real one with every contact deformation scaled by (soft_modulus / E)^(2/3) (the "
                       "same forces; sintercond.beds.settle.stiffen) and settle it there: a metal's real stiffness "
                       "(110 GPa) makes a direct pour take millions of steps; 1e7 Pa settles 45-105 um Ti6Al4V; "
                       "absent: pour at the real modulus")
"""A poured packing's soft stage (both pouring kinds take it)."""

POUR_START = Key(str, _choice("relaxed", "deposit", "rolled"), False, default="relaxed",
                 doc="deposit: the DEM collapses the loose pile itself (a real pour); relaxed: the pile is first "
                     "collapsed without friction, then the DEM settles it (cheaper, denser); rolled: the spheres "
                     "are first rolled down the pile to rest on their supports (point contacts, sintercond.beds.rolling), "
                     "then the DEM settles them")
"""Where the DEM of a pour starts from (sintercond.beds.packing.pour's ``start``)."""


_PACKING = {
    "powder_bed": {
        "kind": Key(str, _choice(*PACKING_KINDS), True, doc="the packing"),
        "lateral_size": Key(float, _within(1e-7, 1.0, "m"), True, "m", doc="side of the square container"),
        "height": Key(float, _within(1e-7, 1.0, "m"), True, "m",
                      doc="bed height to fill, >= the largest diameter: a rolled bed is dropped until its mean surface "
                          "height reaches it; a relaxed or DEM bed holds 0.62 of this volume"),
        "diameter_range": Key(list, ("a list [low, high] of numbers in [1e-08, 1] m", lambda v: True), True, "m",
                              doc="[low, high] diameters, uniform by volume, 1e-8 <= low <= high < lateral_size"),
        "seed": Key(int, _within(0, 2**63 - 1), False, default=0, doc="random seed"),
        "method": Key(str, _choice(*PACKING_METHODS), False, default="roll",
                      doc="how the bed is made: roll (spheres dropped one by one that roll down the pile to rest "
                          "on three supports, the bed of a poured frictional powder, solid fraction ~0.6; "
                          "sintercond.beds.rolling; up to 1e6 spheres), relax (a ballistic deposit collapsed without "
                          "friction by damped harmonic repulsion, denser, ~0.66; its dynamics take ~1e5 steps, "
                          "minutes for 1e3 spheres, ~15 min for 1e4; up to 20,000) or dem (poured and settled "
                          "with the contact laws of the [mechanics] section, which it then needs; "
                          "sintercond.beds.packing.pour; SI units; up to 20,000)"),
        "soft_modulus": SOFT_MODULUS,
        "start": POUR_START._replace(default=None, doc="with method = \"dem\" (relaxed if not given): "
                                     + POUR_START.doc),
        "sinter_swelling": Key(float, _within(0.0, 0.05), False, default=0.0,
                               doc="relative radius increase after settling that turns contacts into sintered "
                                   "necks (overlap h = 2 r s for equal spheres)"),
    },
    "simple_cubic": {
        "kind": Key(str, _choice(*PACKING_KINDS), True, doc="the packing"),
        "counts": Key(list, ("a list of 3 integers in [1, 10000]", lambda v: True), True,
                      doc="[nx, ny, nz] spheres per axis, integers >= 1; at most "
                          f"{MAX_LATTICE_PARTICLES} in all"),
        "spacing": Key(float, _within(1e-8, 1.0, "m"), True, "m", doc="centre distance of neighbours"),
        "radius": Key(float, _within(1e-8, 1.0, "m"), True, "m",
                      doc="sphere radius; the lattice conducts only for radius > spacing/2 (overlap "
                          "h = 2 radius - spacing > 0), up to the neck model's largest overlap "
                          "(0.75 spacing for the volume-conserving neck)"),
    },
    "poured": {
        "kind": Key(str, _choice(*PACKING_KINDS), True, doc="the packing"),
        "particles": Key(int, _within(2, MAX_POURED_PARTICLES), True, doc="number of spheres"),
        "radius_mean": Key(float, _within(1e-6, 0.1, "m"), True, "m", doc="mean of the normal radius distribution"),
        "radius_std": Key(float, _within(0.0, 0.1, "m"), False, "m", default=0.0,
                          doc="standard deviation of the radius distribution (0: equal spheres)"),
        "truncation": Key(float, _within(0.0, 10.0, low_open=True), False, "standard deviations", default=3.0,
                          doc="radii beyond mean +- truncation std are redrawn; every radius must stay > 0"),
        "lateral_size": Key(float, _within(1e-5, 10.0, "m"), True, "m",
                            doc="side of the open square box [0, L]^2 the spheres are poured into, > 2 max radius"),
        "seed": Key(int, _within(0, 2**63 - 1), False, default=0, doc="random seed (radii and the deposit)"),
        "start": POUR_START,

        "soft_modulus": SOFT_MODULUS,
    },
    "file": {
        "kind": Key(str, _choice(*PACKING_KINDS), True, doc="the packing"),
        "path": Key(str, ("a file name", lambda v: bool(v)), True,
                    doc="the packing's file, relative to the scene file's folder (or absolute); no particle cap"),
        "format": Key(str, _choice("auto", "table", "lammps_data", "lammps_dump"), False, default="auto",
                      doc="table: CSV or whitespace rows x y z r (an optional header naming x, y, z and r, radius, "
                          "d or diameter); lammps_data: atom_style sphere (id type diameter density x y z); "
                          "lammps_dump: a LAMMPS or LIGGGHTS dump's last frame (radius or diameter, x y z); "
                          "auto: from the name (*.data, *.dump, *.lammpstrj, else a table)"),
        "length_unit": Key(str, _choice("m", "mm", "um", "nm"), False, default="m",
                           doc="unit of the file's lengths"),
    },
    "spheres": {
        "kind": Key(str, _choice(*PACKING_KINDS), True, doc="the packing"),
        "centres": Key(list, (f"a list of at most {MAX_LISTED_SPHERES} [x, y, z] points (m)", lambda v: True), True,
                       "m", doc="sphere centres in absolute coordinates"),
        "radii": Key(object, ("a number in [1e-08, 1] m or a list of them, one per centre", lambda v: True), True,
                     "m", doc="one radius for all, or one per centre"),
    },
}


_WALL = {
    "axis": Key(int, _choice(0, 1, 2), True, doc="normal axis of the wall"),
    "side": Key(str, _choice("min", "max"), True, doc="which face of the packing"),
    "mode": Key(str, _choice("held", "conducting", "insulated"), True,
                doc="held: touching particles held at temperature; conducting: they exchange heat with a wall "
                    "at temperature through the conduction law (a sphere 1000 x the largest radius); "
                    "insulated: no flux (the default of any face)"),
    "temperature": Key(float, TEMPERATURE, False, "K", doc="wall temperature (required unless insulated)"),
    "penetration": Key(float, _within(0.0, 0.2), False, "mean radii", default=0.02,
                       doc="the wall plane lies at the packing's extreme along the axis moved this many mean "
                           "radii into the packing: the particles it cuts touch the wall (with mechanics, 0 places "
                           "it touching without pushing); 0.1 on a powder bed, whose face layer spreads over about "
                           "a tenth of a radius; the run reports how many particles each wall touches"),
    "velocity": Key(list, ("a list of 3 numbers in [-1000, 1000] m/s", lambda v: True), False, "m/s",
                    default=[0.0, 0.0, 0.0],
                    doc="with mechanics: the wall moves at this velocity (its plane along its normal component, "
                        "its surface rubbing along the rest)"),
}


# the laws' parameters in a scene: physical ranges (the API only requires them finite, > 0 or >= 0)
_LAW_PARAMS = {
    "slope": Key(float, _within(0.0, 100.0, low_open=True), False, doc="s of K_i = s kappa pi a (Rojek Eq. 43)"),
    "contact_resistance": Key(float, _within(0.0, 1e12, "K/W"), False, "K/W", default=0.0,
                              doc="R_c in series with the halves (Rojek Eq. 8)"),
    "thickness": Key(float, _within(0.0, 1e3, "m", low_open=True), False, "m", default=1.0,
                     doc="out-of-plane thickness of Feng's 2-D law"),
    **{c: Key(float, _within(-1e3, 1e3), False, doc="coefficient of the fitted smooth law")
       for c in ("c1", "c2", "c3", "c4")},
}


# the kinetic laws' parameters in a scene: physical ranges
_SINTERING_PARAMS = {
    "A": Key(float, _within(0.0, 1e6, "m^4 K/s", low_open=True), False, "m^4 K/s",
             doc="Omega delta_b D_0b gamma_s / k_B of the grain-boundary law (sintercond.laws.sintering.grain_boundary_a)"),
    "activation_energy": Key(float, _within(0.0, 1e4, "kJ/mol"), False, "kJ/mol", doc="Q of exp(-Q / (R T))"),
    "dihedral_angle": Key(float, _within(0.0, 180.0, "degrees", low_open=True), False, "degrees",
                          doc="psi; the grain-boundary neck stops at the equilibrium neck r_min sin(psi/2)"),
    "K0": Key(float, _within(0.0, 1e300, "m^n/s", low_open=True), False, "m^n/s", doc="K0 of the power law"),
    "exponent": Key(float, _within(0.0, 20.0, low_open=True), False, doc="n of the power law (6 grain boundary, "
                                                                         "5 volume, 2 viscous)"),
    "size_exponent": Key(float, _within(-20.0, 20.0), False, doc="p of the power law's (r*/r_ref)^p"),
    "reference_radius": Key(float, _within(0.0, 1.0, "m", low_open=True), False, "m", doc="r_ref of the power law"),
    "max_neck_ratio": Key(float, _within(0.0, 1.0, low_open=True), False,
                          doc="the power law's and viscous flow's neck stops at this fraction of min(r_i, r_j)"),
    "surface_energy": Key(float, _within(0.0, 100.0, "N/m", low_open=True), False, "N/m",
                          doc="gamma_s of viscous flow"),
    "viscosity": Key(float, _within(0.0, 1e30, "Pa s", low_open=True), False, "Pa s",
                     doc="eta0 of viscous flow, eta = eta0 exp(Q / (R T))"),
}


_SECTIONS = ("packing", "material", "conduction", "initial", "boundary", "walls", "beam", "convection", "radiation",
             "physics", "mechanics", "softening", "sintering", "preheating", "run")


_REQUIRED_SECTIONS = ("packing", "material", "conduction", "initial", "run")


def _suggest(name, allowed):
    close = difflib.get_close_matches(name, allowed, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _describe(key: Key) -> str:
    kind = {float: "a number", int: "an integer", str: "a string", bool: "true or false", list: "a list",
            dict: "a table", object: "a value"}[key.kind]
    if key.rule is None:
        return kind
    return key.rule[0] if key.kind in (str, object, list) or key.rule[0].startswith("one of") else f"{kind} {key.rule[0]}"


def _value(name, value, key: Key):
    """``value`` checked against ``key``; raises :class:`SceneError` naming ``name`` and the range."""
    if key.kind is float:
        ok = not isinstance(value, bool) and isinstance(value, (int, float))
        value = float(value) if ok else value
        ok = ok and math.isfinite(value)
    elif key.kind is int:
        ok = not isinstance(value, bool) and isinstance(value, int)
    elif key.kind is object:
        ok = True
    else:
        ok = isinstance(value, key.kind)
    if not ok or (key.rule is not None and not key.rule[1](value)):
        raise SceneError(f"{name} must be {_describe(key)}; got {value!r}")
    return value


def _check_keys(name, table, schema):
    for key in table:
        if key not in schema:
            raise SceneError(f"unknown key {name}.{key}{_suggest(key, schema)}; allowed keys: {sorted(schema)}")


def _check_section(name, table, schema):
    if not isinstance(table, dict):
        raise SceneError(f"[{name}] must be a table of keys {sorted(schema)}; got {table!r}")
    _check_keys(name, table, schema)
    out = {key: _value(f"{name}.{key}", table[key], spec) for key, spec in schema.items() if key in table}
    for key, spec in schema.items():
        if key not in table and spec.required:
            raise SceneError(f"missing key {name}.{key} ({_describe(spec)})")
    return out


def _numbers(name, value, length, rule, integer=False):
    what = "integers" if integer else "numbers"
    if not isinstance(value, list) or len(value) != length:
        raise SceneError(f"{name} must be a list of {length} {what} {rule[0]}; got {value!r}")
    for v in value:
        bad_type = isinstance(v, bool) or not isinstance(v, int if integer else (int, float))
        if bad_type or not math.isfinite(v) or not rule[1](v):
            raise SceneError(f"{name} must be a list of {length} {what} {rule[0]}; got {value!r}")
    return [int(v) if integer else float(v) for v in value]


def file_packing(packing):
    """``(centres, radii)`` (m) of a ``kind = "file"`` packing (:func:`sintercond.beds.packing_files.read_packing`, read
    once per file version); a file that cannot be read raises :class:`SceneError` naming ``packing.path``."""
    from sintercond.beds.packing_files import PackingFileError, read_packing

    try:
        return read_packing(packing["path"], packing.get("format", "auto"), packing.get("length_unit", "m"))
    except PackingFileError as err:
        raise SceneError(f"packing.path: {err}") from None


def file_temperatures(packing):
    """``[n]`` start temperatures (K) of a ``kind = "file"`` packing's temperature column
    (:func:`sintercond.beds.packing_files.read_temperatures`); :class:`SceneError` naming ``initial.from_file`` if the file
    has none."""
    from sintercond.beds.packing_files import PackingFileError, read_temperatures

    try:
        return read_temperatures(packing["path"], packing.get("format", "auto"))
    except PackingFileError as err:
        raise SceneError(f"initial.from_file: {err}") from None


def restitution_damping_ratio(e):
    """Normal damping ratio ``xi_con`` (Eq. 6) of a restitution coefficient ``e`` in (0, 1].

    ``xi = sqrt(5/6) beta`` with ``beta = -ln e / sqrt(pi^2 + ln^2 e)``: the
    ``delta^(1/4)`` (Tsuji) damping LAMMPS' ``hertz/material`` derives from
    ``e`` (MECHANICS.md, "What users comparing with LAMMPS will see"); it
    makes the paper's ``d_con = 2 xi sqrt(2 E* m* sqrt(r*)) delta^(1/4)``
    equal LAMMPS' ``2 sqrt(5/6) beta sqrt(k_n m*)``, ``k_n = 2 E* sqrt(r* delta)``.
    ``e = 1``: 0 (elastic).
    """
    log_e = math.log(e)
    return math.sqrt(5.0 / 6.0) * -log_e / math.sqrt(math.pi**2 + log_e**2)

