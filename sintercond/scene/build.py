"""A validated scene to the model a run steps: packing, contacts, walls, sources, time step, simulator, parameters
and initial state (:func:`build_model`), built once; the scene's walls as planes and the particles they hold."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple
import math
import time
import warnings
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from sintercond import simulate
from sintercond.beds import packing, settle
from sintercond.contacts import network
from sintercond.laws import heat_sources, materials, walls
from sintercond.sim import mechanics, neck_growth, thermal
from sintercond.scene.schema import output_interval
from sintercond.scene.estimate import RAMP_STEP_FRACTION, check_sintering_every, ramp_step
from sintercond.scene.integrator import auto_by_steps, scene_integrator
from sintercond.scene.typed import Wall, typed_scene
from sintercond.scene.validate import check_distinct_centres
from sintercond.scene import (BEAM_STEP_FRACTION, WALL_STEP_FRACTION, SceneError, advance_speed, beam_step,
                              default_penetration, file_packing, file_temperatures, restitution_damping_ratio)
from sintercond.laws.conductance import validate_pair_conductance_inputs
from sintercond.state import particle_state



@dataclasses.dataclass(frozen=True)
class Model:
    """Everything a run needs, built from a scene: the simulator, its parameters and initial state."""

    sim: simulate.Simulator
    params: simulate.Params
    state: simulate.SimState
    n_steps: int
    contacts: int
    stable_step: float = float("inf")
    bed: dict = dataclasses.field(default_factory=dict)
    reallocate: Any = None  # simulate.reallocate_neighbors of a dynamic contact list, for advance
    wall_heat: tuple = ()  # (column, index of the scene wall, mode, held mask) of each held or conducting wall
    limits: dict = dataclasses.field(default_factory=dict)  # {"thermal", "mechanical", "wall", "beam": s} bounds
    sized_speed: float | None = None  # with mechanics: the approach speed (m/s) the mechanical step is sized for
    k_star_axis: int | None = None  # with [sintering] k_star_axis: the axis of k* at each output
    lattice: bool = False  # a simple cubic packing (k* between its end layers)
    bed_size: float | None = None  # a powder bed's lateral size (m): k* in sintercond.beds.packing.bed_box
    output_every: int = 1  # steps between outputs: run.output_every, or about DEFAULT_OUTPUTS over the run
    checkpoint_every: int = 1  # steps between checkpoints (run.checkpoint_every or DEFAULT_CHECKPOINT_OUTPUTS outputs)
    planes: tuple = ()  # the scene's walls as sintercond.laws.walls.PlaneWall at the packing built (scene_walls), once
    k_star_coupling: str = "sphere"  # sintering.k_star_coupling: the network k* is measured on

    @property
    def physics(self) -> simulate.Physics:
        return self.sim.physics

    @property
    def dt(self) -> float:
        return float(self.state.dt)

    @property
    def centres(self) -> np.ndarray:
        return np.asarray(self.state.particles.positions)

    @property
    def radii(self) -> np.ndarray:
        return np.asarray(self.state.particles.radii)


PROGRESS_EVERY_S = 5.0
"""Seconds between two progress lines of a bed that settles (relaxation or DEM)."""


class SettlingProgress:
    """``progress(phase, steps, max_steps, figure, target)`` for :mod:`sintercond.beds.packing`: a line through ``log``
    at most every :data:`PROGRESS_EVERY_S` seconds with the steps taken, the settling figure against its target
    and an estimate of the time left from the figure's recent rate of decay (it falls about exponentially); a
    rolled bed (phase ``"rolling"``) gives the spheres down and the time left at their rate; ``worst``, the sphere
    the net force is largest on (:func:`sintercond.beds.settle.sphere_text`)."""

    def __init__(self, log, particles):
        self.log, self.particles = log, particles
        self.start = self.last = time.perf_counter()
        self.points = []  # (seconds, ln figure) at the lines written

    def __call__(self, phase, steps, max_steps, figure, target, worst=None):
        now = time.perf_counter()
        if now - self.last < PROGRESS_EVERY_S:
            return
        self.last = now
        if phase == "rolling":  # spheres placed at a steady rate: the time left in proportion
            left = (f", about {(now - self.start) * (max_steps - steps) / max(steps, 1):.0f} s left"
                    if steps < max_steps else "")
            self.log(f"packing: rolling {max_steps:,} spheres down the pile: {steps:,} down, "
                     f"{now - self.start:.0f} s{left}")
            return
        self.points.append((now - self.start, math.log(max(figure, 1e-300))))
        left = ""
        if len(self.points) >= 2:
            (t0, y0), (t1, y1) = self.points[max(0, len(self.points) - 4)], self.points[-1]
            rate = (y0 - y1) / (t1 - t0)  # decay of ln figure per second
            if rate > 0 and figure > target:
                left = f", about {(y1 - math.log(target)) / rate:.0f} s left at this rate"
        what = (f"largest net force {figure:.3g} of a sphere's weight" if phase == "relaxing" else
                f"kinetic energy and net force at {figure:.3g} times their thresholds")
        on = "" if worst is None else f", largest on {worst}"
        self.log(f"packing: {phase} {self.particles:,} spheres: {steps:,} steps (at most {max_steps:,}), {what} "
                 f"(settled below {target:g}{on}), {now - self.start:.0f} s{left}")


def initial_temperatures(scene):
    """The particles' start temperatures (K): ``initial.temperature``, or with ``initial.from_file`` the packing
    file's temperature column (:func:`sintercond.beds.packing_files.read_temperatures`)."""
    scene = typed_scene(scene)
    if scene.initial.from_file:
        return np.array(file_temperatures(scene.packing))
    return scene.initial.temperature


def build_packing(scene, log=None):
    """``(centres, radii, bed)`` of a validated scene: listed spheres as given, else
    :func:`sintercond.beds.packing.from_scene`; a bed that settles reports its progress through ``log``
    (:class:`SettlingProgress`).

    ``bed``: the bed's figures for the summary (empty for listed spheres).
    """
    return _scene_packing(scene, log)[:3]


def _scene_packing(scene, log=None):
    """:func:`build_packing` and the :class:`sintercond.beds.settle.DemSettled` state of a DEM pour (None for any other
    packing, or one whose radii were changed after it settled)."""
    scene = typed_scene(scene)
    p = scene.packing
    if p.kind == "spheres":
        return np.asarray(p.centres, np.float64), np.asarray(p.radii, np.float64), {}, None
    if p.kind == "file":
        centres, radii = file_packing(p)
        return np.array(centres), np.array(radii), {}, None
    if p.kind == "poured":
        rng = np.random.default_rng(p.seed)
        radii = packing.truncated_normal_radii(p.particles, p.radius_mean, p.radius_std, p.truncation, rng)
        packed = packing.pour(radii, p.lateral_size, dem_material(scene), seed=rng, start=p.start,
                              temperature=scene.initial.temperature,
                              progress=SettlingProgress(log, len(radii)) if log else None, soft_modulus=p.soft_modulus)
    else:
        count = packing.bed_particle_count(p.lateral_size, p.height, p.diameter_range) if p.kind == "powder_bed" else 0
        progress = SettlingProgress(log, count) if log and count else None
        if p.get("method") == "dem":
            packed = packing.powder_bed(p.lateral_size, p.height, tuple(p.diameter_range), seed=p.seed, method="dem",
                                        material=dem_material(scene), progress=progress, soft_modulus=p.soft_modulus,
                                        start=p.start)
            if p.sinter_swelling:  # swollen spheres overlap more than the settled springs saw: start unloaded
                packed = dataclasses.replace(packed, radii=packed.radii * (1.0 + p.sinter_swelling), settled=None)
        else:
            packed = packing.from_scene(p, progress=progress)
    return packed.centres, packed.radii, {k: v for k, v in packed.summary().items() if k != "particles"}, packed.settled


def _nusselt(convection):
    if convection.reynolds is not None:
        return float(heat_sources.whitaker_nusselt(convection.reynolds, convection.prandtl))
    return convection.nusselt


def scene_physics(scene, walls=0) -> simulate.Physics:
    """The static physics spec of a validated scene; ``run.integrator = "auto"`` resolved by the kind of physics
    (:func:`sintercond.scene.integrator.scene_integrator`: :func:`build_model` then makes a short run explicit)."""
    scene = typed_scene(scene)
    c, s, ramp, m = scene.conduction, scene.sintering, scene.preheating, scene.material
    held = any(w.mode == "held" for w in _walls(scene)) or (ramp is not None and ramp.hold == "all")
    # a contact resistance makes the law nonlinear in the conductivity, growing necks and kappa(T) change it: lift it
    table = m.conductivity_table is not None
    coupling = c.coupling or "none"
    lifted = (c.params or {}).get("contact_resistance", 0.0) or s is not None or table or coupling == "sphere"
    run = scene.run
    return simulate.Physics(
        conduction=simulate.Conduction(
            law=c.law, neck_model=c.neck_model, conductance="lifted" if lifted else "table",
            held=held, conducting_walls=walls, held_ramp=ramp is not None, conductivity_table=table,
            specific_heat_table=m.specific_heat_table is not None, coupling=coupling,
            integrator=scene_integrator(scene)[0], rtol=run.rtol, atol=run.atol),
        sources=simulate.Sources(beam=None if scene.beam is None else scene.beam.kind,
                                 convection=scene.convection is not None, radiation=scene.radiation is not None),
        sintering=None if s is None else neck_growth.Sintering(law=s.law, every=s.every, shrinkage=s.shrinkage,
                                                                neck_rtol=s.neck_rtol))


def mechanics_on(scene) -> bool:
    """Whether a validated scene runs the coupled thermo-mechanical step."""
    return bool(typed_scene(scene).physics.mechanics)


def contact_material(scene) -> dict:
    """The ``[mechanics]`` section as :class:`~sintercond.sim.mechanics.MechanicalParams` names (floats, SI).

    ``mechanics.restitution`` e becomes ``xi_con``
    (:func:`sintercond.scene.restitution_damping_ratio`); wall coefficients
    default to the particles'.
    """
    m = typed_scene(scene).mechanics
    xi_con = restitution_damping_ratio(m.restitution) if m.restitution is not None else m.damping
    return dict(E0=m.young_modulus, nu=m.poisson_ratio, xi_con=xi_con, xi_fric=m.tangential_damping,
                xi_rol=m.rolling_damping, mu=m.friction, mu_r=m.rolling_friction, mu_wall=m.wall_friction,
                mu_r_wall=m.wall_rolling_friction)


def mechanical_params(scene) -> mechanics.MechanicalParams | None:
    """The contact material of a validated scene (:func:`contact_material`, ``[softening]``), or None without mechanics."""
    scene = typed_scene(scene)
    if not mechanics_on(scene):
        return None
    soft = scene.softening
    f = lambda x: jnp.asarray(float(x))  # noqa: E731
    return mechanics.MechanicalParams(
        **{k: f(v) for k, v in contact_material(scene).items()}, theta_star=f(soft.onset_temperature if soft else 400.0),
        rate=f(soft.rate if soft else 1.0), E_min=f(soft.min_modulus if soft else 0.0))


def dem_material(scene) -> settle.DemMaterial:
    """The contact material a poured packing settles with: :func:`contact_material` and ``material.density``."""
    scene = typed_scene(scene)
    c = contact_material(scene)
    return settle.DemMaterial(density=scene.material.density, **{("E" if k == "E0" else k): float(v)
                                                                 for k, v in c.items()})


def mechanical_physics(scene, thermal_physics, planes) -> simulate.Physics:
    """The coupled spec of a validated scene with mechanics: ``thermal_physics`` made dynamic, the walls pushing.

    Every wall of the scene is a :class:`~sintercond.laws.walls.PlaneWall` of
    ``Mechanics.walls``; a held wall pushes as an insulated one (its
    particles are held by ``Conduction.held``, :func:`_apply_walls`).
    """
    scene = typed_scene(scene)
    p, c = scene.physics, contact_material(scene)
    walls_ = tuple(dataclasses.replace(w, mode="insulated", temperature=None) if w.mode == "held" else w
                   for w in planes) + container_walls(scene)
    spec = mechanics.Mechanics.create(
        walls_, gravity=p.gravity, shear=p.shear, slip_direction=p.slip_direction,
        rolling_projection=p.rolling_projection, damping_clamp=p.damping_clamp, softening=scene.softening is not None,
        friction=c["mu"] > 0 or c["mu_wall"] > 0, rolling=c["mu_r"] > 0 or c["mu_r_wall"] > 0,
        wall_friction=c["mu_wall"] > 0, wall_rolling=c["mu_r_wall"] > 0, quasi_static=scene.mechanics.quasi_static)
    conduction = dataclasses.replace(thermal_physics.conduction, conductance="lifted", conducting_walls=0)
    return dataclasses.replace(thermal_physics, conduction=conduction, contacts="dynamic", mechanics=spec)


_BOX_FACES = ((2, "min"), (0, "min"), (0, "max"), (1, "min"), (1, "max"))
"""The faces of :func:`sintercond.beds.settle.box_walls`, in its order: floor, x = 0, x = L, y = 0, y = L."""


def packing_box(scene):
    """``(lo [3], hi [3])`` (m) of the box a validated scene's packing fills, ``hi[2]`` infinite (an open top), or
    None for a packing without one (a powder bed's container ``[0, lateral_size]^2`` over ``z = 0``)."""
    p = typed_scene(scene).packing
    if p.kind != "powder_bed":
        return None
    return np.zeros(3), np.array([p.lateral_size, p.lateral_size, np.inf])


def packing_size(scene) -> float | None:
    """A powder bed's lateral size (m) (its container ``[0, L]^2``), None for any other packing."""
    box = packing_box(scene)
    return None if box is None else float(box[1][0])


def container_walls(scene) -> tuple:
    """With mechanics, the insulated walls of a powder bed's box (:func:`sintercond.beds.settle.box_walls`) on each face
    the scene gives no wall of its own (``physics.container``, true by default): without them the moving bed
    spreads over the floor, or falls."""
    scene = typed_scene(scene)
    if not scene.physics.container or packing_box(scene) is None:  # filled with the mechanics
        return ()
    given = {(w.axis, w.side) for w in _walls(scene)}
    box = settle.box_walls(scene.packing.lateral_size)
    return tuple(wall for face, wall in zip(_BOX_FACES, box) if face not in given)


def escaped_particles(scene, positions, radii) -> np.ndarray:
    """Indices of the particles whose centres lie more than their radius outside the packing's box
    (:func:`packing_box`): they left it; empty for a packing without a box."""
    box = packing_box(scene)
    if box is None:
        return np.zeros(0, int)
    lo, hi = box
    r = np.asarray(radii)[:, None]
    outside = (np.asarray(positions) < lo - r) | (np.asarray(positions) > hi + r)
    return np.flatnonzero(outside.any(axis=1))


class PackingBoxWarning(UserWarning):
    """Particles of a moving packing left the box it was made in."""


def scene_params(scene) -> simulate.Params:
    """The differentiable parameters of a validated scene."""
    scene = typed_scene(scene)
    m, beam, conv, rad, ramp = scene.material, scene.beam, scene.convection, scene.radiation, scene.preheating
    f = jnp.asarray
    return simulate.Params(
        mechanics=mechanical_params(scene),
        conductivity=f([m.conductivity]) if m.conductivity_table is None else materials.tabulated(
            *np.asarray(m.conductivity_table, np.float64).T),
        specific_heat=f([m.specific_heat]) if m.specific_heat_table is None else materials.tabulated(
            *np.asarray(m.specific_heat_table, np.float64).T),
        law={k: f(v) for k, v in (scene.conduction.params or {}).items()},
        sintering=None if scene.sintering is None else {k: f(v) for k, v in (scene.sintering.params or {}).items()},
        held_ramp=None if ramp is None else simulate.HeldRampParams(f(ramp.end_temperature), f(ramp.duration),
                                                                   f(float(ramp.steps))),
        beam=None if beam is None else simulate.BeamParams(
            intensity=f(beam.intensity), reach=f(beam.attenuation if beam.kind == "laser" else beam.max_depth),
            spot_radius=f(beam.spot_radius), absorptance=f(beam.absorptance), speed=f(beam.speed),
            path=f(beam.path, dtype=float),
            segments_on=None if beam.segments_on is None else f(beam.segments_on, dtype=float),
            after_path=f(1.0 if beam.after_path == "stay" else 0.0)),
        convection=None if conv is None else simulate.ConvectionParams(
            f(conv.environment_temperature), f(conv.environment_conductivity), f(_nusselt(conv))),
        radiation=None if rad is None else simulate.RadiationParams(f(rad.environment_temperature), f(rad.emissivity)))


def build_model(scene, centres=None, radii=None, log=None) -> Model:
    """Packing, network, held particles, sources, time step and simulator of a validated scene.

    The time step: ``run.dt`` or, for ``"auto"``, 0.9 of the stable step
    ``min_i C_i / (sum_j K_ij + sum_w K_iw + G_i)`` where ``G_i`` linearises
    convection and radiation (:func:`sintercond.sim.thermal.source_conductance`);
    with mechanics, of the smaller of that (at the initial contacts) and the
    mechanical step (:func:`sintercond.sim.mechanics.mechanical_time_step`: Eq. 47
    and the tangential and rotational bounds of MECHANICS.md erratum 8, at
    the approach speed ``physics.impact_velocity`` plus the fastest wall's
    normal speed, at the unsoftened modulus: ``E_min <= E0``, so no state
    the run reaches is stiffer); with moving walls, the step in which the
    fastest moves :data:`sintercond.scene.WALL_STEP_FRACTION` of the smallest radius; with a
    beam, the step in which its spot moves :data:`sintercond.scene.BEAM_STEP_FRACTION` of
    its radius. A ``run.dt`` above any of them is refused, naming it and
    the key that sets it. Then the step is shortened to ``duration / n_steps`` so that
    the run ends exactly at ``run.duration``. ``log(message)`` reports each phase.
    """
    scene = typed_scene(scene)
    log = log or (lambda message: None)
    bed, settled = {}, None
    if centres is None:
        log("packing: building the scene's packing")
        start = time.perf_counter()
        centres, radii, bed, settled = _scene_packing(scene, log)
        log(f"packing: {len(radii):,} particles in {time.perf_counter() - start:.1f} s")
    check_distinct_centres(None, centres)  # a pour, a bed, or a run folder's packing.npz as well
    physics = scene_physics(scene)
    integrator, why = scene_integrator(scene)
    planes = scene_walls(scene, centres, radii)  # built once: the run and its observations take them from the model
    fixed_mask, fixed_temperature, conducting = _apply_walls(planes, centres, radii)
    if scene.preheating is not None and scene.preheating.hold == "all":  # an isothermal cell on the ramp
        fixed_mask = np.ones(len(radii), bool)
        fixed_temperature = np.full(len(radii), scene.initial.temperature)
    touching_walls = wall_contacts(scene, centres, radii, log, planes=planes)
    particles = particle_state(centres, radii, initial_temperatures(scene), scene.material.density,
                               scene.material.specific_heat, fixed=fixed_mask, fixed_temperature=fixed_temperature)
    params = scene_params(scene)
    if mechanics_on(scene):
        built = _coupled_model(scene, physics, planes, particles, params, settled, log)
    else:
        built = _static_model(scene, physics, planes, particles, params, conducting, log)
    physics, sim = built.physics, built.sim
    sources = jax.jit(thermal.source_conductance, static_argnums=0)(physics.sources, particles.radii, params,
                                                                     _highest_temperature(scene))
    # every particle held (an isothermal cell on a ramp): no conduction to keep stable
    thermal_limit = np.inf if fixed_mask.all() else float(simulate.thermal_time_step(sim, built.limiting, params,
                                                                                      sources))
    at_cap = " on the necks at the kinetic law's cap" if built.necks is not None else ""
    bounds = {"thermal": (thermal_limit, f"the explicit stability limit min(C_i / (sum_j K_ij + G_i)) = "
                                         f"{thermal_limit:.6g} s{at_cap} (G_i: linearised convection and "
                                         "radiation)")}
    if scene.preheating is not None:
        every = scene.sintering.every if scene.sintering is not None else 1  # a growth interval spans every steps
        step = ramp_step(scene)
        bounds["preheating"] = (step, f"{step:.6g} s, in which {every} step(s) (sintering.every) span "
                                      f"{RAMP_STEP_FRACTION:g} of a step of the preheating ramp "
                                      "(preheating.duration / preheating.steps)")
    bounds.update(built.bounds)
    bounds.update(_beam_bound(scene))
    integrator, why = auto_by_steps(scene, integrator, why, _explicit_steps(scene.run, bounds))
    log(f"integrator: {integrator} ({why})")
    if integrator != physics.conduction.integrator:
        physics = dataclasses.replace(physics, conduction=dataclasses.replace(physics.conduction,
                                                                              integrator=integrator))
        sim = simulate.simulator(physics)
    explicit_limit = _smallest_bound(bounds)
    if integrator == "implicit" and scene.run.dt != "auto":
        # the adaptive step is bounded by its error estimate and ends on the ramp's jumps: run.dt is the output clock
        bounds = {kind: bound for kind, bound in bounds.items() if kind not in ("thermal", "preheating")}
    dt, n_steps, limit = _time_step(scene.run, bounds, physics.mechanics is None)
    limit = min(limit, explicit_limit)  # reported as the stable step: the explicit one, whichever integrator runs
    check_sintering_every(scene, n_steps)
    state = simulate.init_state(particles, built.contacts, dt, mechanics=built.motion, sintering=built.necks,
                                adaptive_step=0.0 if integrator == "implicit" else None)
    bed = {**bed, **{f"wall{k}_particles": count for k, count in touching_walls.items()}}
    return Model(sim, params, state, n_steps, built.contact_count, limit, bed, built.reallocate,
                 _wall_heat_specs(planes, centres, radii),
                 {kind: bound for kind, (bound, _) in bounds.items()}, built.v_rel,
                 None if scene.sintering is None else scene.sintering.k_star_axis,
                 scene.packing.kind == "simple_cubic", packing_size(scene), *output_interval(scene.run, n_steps),
                 tuple(planes), "sphere" if scene.sintering is None else scene.sintering.k_star_coupling)


class _Built(NamedTuple):
    """The part of :func:`build_model` that depends on the contacts: the one spec and simulator of the run, its
    contacts and start state pieces, the state its explicit limit is taken on (necks at the kinetic law's cap when
    sintering), and the step bounds the contacts set; with the mechanics, the reallocation and the approach speed
    the step is sized for (m/s)."""

    physics: simulate.Physics
    sim: simulate.Simulator
    contacts: object
    motion: object
    necks: object
    limiting: object
    contact_count: int
    bounds: dict
    reallocate: object = None
    v_rel: float | None = None


def _scene_pairs(scene, centres, radii, log):
    """The contacts of the packing (:func:`sintercond.contacts.network.contact_pairs`), the conduction law's domain checked
    on them (a :class:`SceneError` naming the contact)."""
    m, c = scene.material, scene.conduction
    log(f"network: contacts and conductances of {len(radii):,} particles")
    start = time.perf_counter()
    try:
        pairs = network.contact_pairs(centres, radii)
        if len(pairs.i):
            kappa = np.broadcast_to(np.asarray(m.conductivity, np.float64), pairs.overlap.shape)
            validate_pair_conductance_inputs(c.law, pairs.r_i, pairs.r_j, pairs.overlap, kappa, kappa, c.params,
                                             c.neck_model)
    except ValueError as err:
        raise SceneError(f"the packing does not fit the conduction model: {err}") from None
    log(f"network: {len(pairs.i):,} contacts in {time.perf_counter() - start:.1f} s")
    return pairs


def _static_model(scene, physics, planes, particles, params, conducting, log) -> _Built:
    """The contacts of a static packing (no mechanics): the contact table at unit conductivity, or the lifted
    necks (and the necks' state when sintering)."""
    centres, radii = np.asarray(particles.positions, np.float64), np.asarray(particles.radii, np.float64)
    lifted = physics.conduction.conductance == "lifted"
    physics = dataclasses.replace(physics, conduction=dataclasses.replace(
        physics.conduction, conducting_walls=len(conducting) if lifted else int(bool(conducting))))
    pairs = _scene_pairs(scene, centres, radii, log)
    held = held_axis = None
    if not lifted:
        c = scene.conduction
        table = network.contact_table(centres, radii, 1.0, c.law, c.params, c.neck_model)
        k_wall, t_wall = _merged_wall_conductance(scene, radii, conducting)
        contacts = simulate.table_contacts(table, k_wall, t_wall)
    else:
        if physics.conduction.coupling == "sphere":  # held spheres at one temperature share a mirror plane's label
            fixed = np.asarray(particles.fixed, bool)
            levels = np.asarray(particles.fixed_temperature, np.float64)
            held = np.zeros(len(radii), np.int64)
            held[fixed] = np.unique(levels[fixed], return_inverse=True)[1].reshape(-1) + 1
            held_axis = next((w.axis for w in _walls(scene) if w.mode == "held"), 0)
        try:
            contacts = simulate.lifted_contacts(physics, centres, radii,
                                                [(penetration, wall.temperature)
                                                 for _, wall, penetration in conducting], pairs=pairs,
                                                held=held, held_axis=held_axis or 0)
        except ValueError as err:
            raise SceneError(f"conduction.coupling: {err}") from None
    necks, limiting = None, contacts
    if physics.sintering is not None:
        many_body = physics.sintering.shrinkage == "many_body"
        necks = neck_growth.neck_state(contacts, particles.temperature,
                                       supports=wall_supports(scene, centres, radii, planes) if many_body else None,
                                       positions=particles.positions if many_body else None)
        # growing necks only raise the conductances: the step is taken on the necks at the kinetic law's cap
        limiting = neck_growth.necks_at_cap(physics.sintering, params.sintering, contacts, particles.radii)
        if physics.conduction.coupling == "sphere":  # every contact that can grow a neck; the domain at each step
            contacts = simulate.coupled_contacts(contacts, centres, radii, np.asarray(limiting.neck), held=held,
                                                 held_axis=held_axis or 0, beyond_domain="isolated")
            limiting = dataclasses.replace(limiting, sphere=contacts.sphere)
    return _Built(physics, simulate.simulator(physics), contacts, None, necks,
                  simulate.init_state(particles, limiting, 1.0, sintering=necks), len(pairs.i), {})


def _coupled_model(scene, physics, planes, particles, params, settled, log) -> _Built:
    """The coupled thermo-mechanical part of :func:`build_model` (``physics.mechanics = true``): one spec, its
    simulator on dynamic contacts, the mechanical state (continuing a DEM pour's ``settled`` state, with the necks
    on the pair list when sintering), the mechanical and wall step bounds."""
    centres, radii = np.asarray(particles.positions, np.float64), np.asarray(particles.radii, np.float64)
    pairs = _scene_pairs(scene, centres, radii, log)
    log("mechanics: contact list and the mechanical time step")
    bounds = {}
    physics = mechanical_physics(scene, physics, planes)
    skin = scene.physics.skin * float(np.max(radii))
    contacts, fns = simulate.dynamic_contacts(centres, radii, skin)
    impact = scene.physics.impact_velocity
    wall_speed, fastest = _fastest_wall(scene)
    v_rel = impact + wall_speed
    if not physics.mechanics.quasi_static:  # quasi-static particles have no inertia to bound the step
        mechanical_limit = float(mechanics.mechanical_time_step(physics.mechanics, particles, contacts.neighbors,
                                                            params.mechanics, v_rel))
        speed_source = f"physics.impact_velocity = {impact:g} m/s" + (
            f" plus walls[{fastest}].velocity's normal speed {wall_speed:g} m/s" if wall_speed > 0 else "")
        bounds["mechanical"] = (mechanical_limit, f"the mechanical time step {mechanical_limit:.6g} s (Eq. 47 and "
                                                  f"the symplectic-Euler bounds of the stiffest contact, unsoftened, "
                                                  f"at the approach speed {v_rel:g} m/s: {speed_source})")
    else:
        v_rel = None
    if wall_speed > 0:
        step = WALL_STEP_FRACTION * float(np.min(radii)) / wall_speed
        bounds["wall"] = (step, f"{step:.6g} s, in which walls[{fastest}] (walls[{fastest}].velocity, normal "
                                f"speed {wall_speed:g} m/s) moves {WALL_STEP_FRACTION:g} of the smallest radius")
    motion = mechanics.mechanical_state(physics.mechanics, centres, contacts)
    if settled is not None:
        motion = _settled_motion(settled, physics.mechanics, motion, contacts)
        if physics.mechanics.quasi_static:  # the pour's last velocities: no inertia carries them on
            motion = dataclasses.replace(motion, velocity=jnp.zeros_like(motion.velocity),
                                         spin=jnp.zeros_like(motion.spin))
    necks, limiting = None, motion
    if physics.sintering is not None:  # the necks on the half pair list, carried as the springs are
        motion = neck_growth.with_pair_necks(motion, contacts, centres, radii,
                                             scene.sintering.start_necks or "point")
        many_body = physics.sintering.shrinkage == "many_body"
        necks = neck_growth.neck_state(contacts, particles.temperature,
                                       supports=wall_supports(scene, centres, radii, planes) if many_body else None,
                                       positions=particles.positions)
        # growing necks only raise the conductances: the step is taken on the necks at the kinetic law's cap
        limiting = neck_growth.pair_necks_at_cap(physics.sintering, params.sintering, motion, contacts, centres,
                                                 radii)
    return _Built(physics, simulate.simulator(physics, fns), contacts, motion, necks,
                  simulate.init_state(particles, contacts, 1.0, mechanics=limiting, sintering=necks), len(pairs.i),
                  bounds, simulate.reallocate_neighbors(fns), v_rel)


def _settled_motion(settled, spec, motion, contacts):
    """``motion`` continuing a DEM pour's settled state (:class:`sintercond.beds.settle.DemSettled`): its velocities and
    spins, its pair springs carried to the run's half pair list by ``(i, j)`` (:func:`sintercond.sim.mechanics.remap_history`),
    and the springs against each of its walls on the run's wall in the same plane; a wall the pour did not have
    starts unloaded. The packing then carries the tangential and rolling loads it settled with, as a resumed run
    does, instead of slipping into the run from unloaded springs."""
    old = settled.state.mechanics
    carried = mechanics.remap_history(old, settled.state.contacts.pairs.pairs, contacts.pairs.pairs)
    dtype = motion.velocity.dtype
    fields = {"velocity": jnp.asarray(old.velocity, dtype), "spin": jnp.asarray(old.spin, dtype)}
    for name in ("spring", "rolling"):
        if getattr(motion, name) is not None and getattr(carried, name) is not None:
            fields[name] = jnp.asarray(getattr(carried, name), getattr(motion, name).dtype)
    poured_walls = settled.sim.physics.mechanics.walls
    for name in ("wall_spring", "wall_rolling"):
        springs, before = getattr(motion, name), getattr(old, name)
        if springs is None or before is None:
            continue
        for w, wall in enumerate(spec.walls):
            same = [k for k, poured in enumerate(poured_walls) if _same_plane(poured, wall)]
            if same:
                springs = springs.at[w].set(jnp.asarray(before[same[0]], springs.dtype))
        fields[name] = springs
    return dataclasses.replace(motion, **fields)


def _same_plane(a: walls.PlaneWall, b: walls.PlaneWall) -> bool:
    """Whether two walls are the same plane, at rest: equal normals and offsets ``p . n``."""
    n_a, n_b = np.asarray(a.normal, float), np.asarray(b.normal, float)
    return (np.allclose(n_a, n_b) and np.isclose(np.dot(a.point, n_a), np.dot(b.point, n_b))
            and not np.any(a.velocity) and not np.any(b.velocity))


def _beam_bound(scene) -> dict:
    """``{"beam": (step, why)}``: the step in which the beam's spot moves :data:`BEAM_STEP_FRACTION` of its radius,
    or nothing without a moving beam."""
    beam = typed_scene(scene).beam
    if beam is not None and beam_step(beam) is not None:
        step = beam_step(beam)
        return {"beam": (step, f"{step:.6g} s, in which the beam's spot (beam.speed = {beam.speed:g} m/s) moves "
                               f"{BEAM_STEP_FRACTION:g} of beam.spot_radius = {beam.spot_radius:g} m")}
    return {}


def _smallest_bound(bounds) -> float:
    """The smallest step bound (s) of ``{kind: (step, why)}``; inf for none (an implicit run at its run.dt)."""
    return min((bound for bound, _ in bounds.values()), default=np.inf)


def _explicit_steps(run, bounds) -> int:
    """The steps an explicit run of ``run.duration`` would take: at ``run.dt``, or 0.9 of the smallest bound where
    that is shorter (or ``run.dt`` is ``"auto"``)."""
    limit = _smallest_bound(bounds)
    dt = min(0.9 * limit, np.inf if run.dt == "auto" else run.dt)
    return max(1, int(np.ceil(run.duration / dt * (1 - 1e-12)))) if np.isfinite(dt) else 1


def _time_step(run, bounds, thermal_only) -> tuple[float, int, float]:
    """``(dt, n_steps, limit)``: ``run.dt`` checked against every bound (``{kind: (step, why)}``, s) or 0.9 of the
    smallest, shortened to ``duration / n_steps`` so that the run ends exactly at ``run.duration``."""
    limit = _smallest_bound(bounds)
    if run.dt == "auto":
        dt = 0.9 * limit if np.isfinite(limit) else run.duration
    else:
        dt = run.dt
        for kind, (bound, name) in bounds.items():
            if dt > bound:
                raise SceneError(f"run.dt: dt = {dt:.6g} s exceeds {name}; use dt <= {limit:.6g} s"
                                 + (" or the implicit integrator" if kind == "thermal" and thermal_only else ""))
    n_steps = max(1, int(np.ceil(run.duration / dt * (1 - 1e-12))))
    return run.duration / n_steps, n_steps, limit  # equal steps that end at the duration, none above the stable one


def _fastest_wall(scene) -> tuple[float, int | None]:
    """The largest speed (m/s) at which a scene's wall advances into the packing (:func:`sintercond.scene.advance_speed`),
    and that wall (None if none does)."""
    speeds = [advance_speed(w) for w in _walls(scene)]
    if not speeds or max(speeds) == 0:
        return 0.0, None
    return max(speeds), int(np.argmax(speeds))


def _highest_temperature(scene) -> float:
    """The highest temperature a scene names (initial, walls, environment): where radiation is stiffest."""
    scene = typed_scene(scene)
    temperatures = [scene.initial.temperature] + [w.temperature for w in _walls(scene) if w.temperature is not None]
    temperatures += [env.environment_temperature for env in (scene.convection, scene.radiation) if env is not None]
    temperatures += [scene.preheating.end_temperature] if scene.preheating is not None else []
    temperatures += [float(np.max(file_temperatures(scene.packing)))] if scene.initial.from_file else []
    return float(max(temperatures))


def _walls(scene) -> list:
    """The scene's ``[[walls]]`` (:data:`sintercond.scene.typed.Wall`) and the held floor of
    ``boundary.floor_temperature``."""
    scene = typed_scene(scene)
    walls_ = list(scene.walls)
    if scene.boundary is not None and scene.boundary.floor_temperature is not None:
        walls_.append(Wall(axis=2, side="min", mode="held", temperature=scene.boundary.floor_temperature,
                           penetration=default_penetration(scene), velocity=[0.0, 0.0, 0.0]))
    return walls_


def scene_walls(scene, centres, radii) -> list[walls.PlaneWall]:
    """The scene's walls as :class:`~sintercond.laws.walls.PlaneWall` (insulated ones included).

    A wall plane lies at the packing's extreme along its axis, moved
    ``penetration`` mean radii into it; its normal points into the packing.
    """
    planes = []
    for wall in _walls(scene):
        axis, depth = wall.axis, wall.penetration * float(np.mean(radii))
        normal = np.zeros(3)
        if wall.side == "min":
            normal[axis] = 1.0
            position = float(np.min(centres[:, axis] - radii)) + depth
        else:
            normal[axis] = -1.0
            position = float(np.max(centres[:, axis] + radii)) - depth
        point = np.zeros(3)
        point[axis] = position
        planes.append(walls.PlaneWall(tuple(point), tuple(normal), wall.mode, wall.temperature,
                                      tuple(float(v) for v in wall.velocity)))
    return planes


def _wall_heat_specs(planes, centres, radii):
    """``(column, index of the scene wall, mode, held mask or None)`` of each held or conducting wall of a scene.

    A particle held by several walls counts for the first (as in
    :func:`_apply_walls`, where the last one sets its temperature, they are
    only ever equal on an edge of two held faces).
    """
    specs, claimed = [], np.zeros(len(radii), bool)
    for k, wall in enumerate(planes):
        if wall.mode == "held":
            mask = (np.asarray(wall.penetration(centres, radii)) >= 0) & ~claimed
            claimed |= mask
            specs.append((f"heat_wall{k}_W", k, "held", mask))
        elif wall.mode == "conducting":
            specs.append((f"heat_wall{k}_W", k, "conducting", None))
    return tuple(specs)


FEW_WALL_CONTACTS = 0.5
"""A held or conducting wall touching fewer than this fraction of the particles facing it is reported as a handful."""


def wall_supports(scene, centres, radii, planes=None) -> np.ndarray:
    """``[n, 3]`` bool: the displacement components held in a many-body sintering run: the vertical one of the
    particles resting on a floor (a wall on axis 2, side min); the packing shrinks away from other walls
    (:func:`sintercond.sim.neck_growth.neck_state`)."""
    supports = np.zeros((len(radii), 3), bool)
    planes = scene_walls(scene, centres, radii) if planes is None else planes
    for wall, plane in zip(_walls(scene), planes):
        if wall.axis == 2 and wall.side == "min":
            supports[:, 2] |= np.asarray(plane.penetration(centres, radii)) >= 0
    return supports


def wall_contacts(scene, centres, radii, log=None, *, planes=None) -> dict:
    """``{k: particles touching scene wall k}`` for each held or conducting wall, logged; warns on a handful.

    The particles facing a wall are its face layer, those whose surface comes within half a mean radius of the
    outermost one: on a rough bed the wall plane (the outermost particle moved ``walls[k].penetration`` mean
    radii in) may touch only the few that stick out, and the boundary condition then acts through them alone.
    With mechanics the count is the start's (the particles then settle onto the walls: ``history.csv``'s
    ``wall_contacts``) and no warning is given.
    """
    scene = typed_scene(scene)
    planes = scene_walls(scene, centres, radii) if planes is None else planes
    counts = {}
    for k, (wall, plane) in enumerate(zip(_walls(scene), planes)):
        if plane.mode not in ("held", "conducting"):
            continue
        penetration = np.asarray(plane.penetration(centres, radii))
        touching = int(np.count_nonzero(penetration >= 0 if plane.mode == "held" else penetration > 0))
        facing = int(np.count_nonzero(penetration > float(np.max(penetration)) - 0.5 * float(np.mean(radii))))
        counts[k] = touching
        name = f"walls[{k}]" if k < len(scene.walls) else "boundary.floor_temperature"
        message = (f"{name} ({plane.mode}, axis {wall.axis} {wall.side}) touches {touching} of the {facing} "
                   "particles facing it")
        if touching < FEW_WALL_CONTACTS * facing and not mechanics_on(scene):  # moving particles settle onto it
            depth = f"{wall.penetration:g} mean radii"
            message += (f"; only a handful: raise walls[{k}].penetration (now {depth}) so that its plane reaches "
                        "into the rough face" if k < len(scene.walls) else
                        f"; only a handful: replace boundary.floor_temperature by a held [[walls]] floor (axis = 2, "
                        f"side = \"min\") with a penetration above its {depth}, so that its plane reaches into the "
                        "rough face")
            warnings.warn(message, WallContactWarning, stacklevel=2)
        if log is not None:
            log(message)
    return counts


class WallContactWarning(UserWarning):
    """A held or conducting wall touches only a handful of the particles facing it."""


def _apply_walls(planes, centres, radii):
    """Held walls (of the scene's ``planes``) become fixed particles; returns them and the conducting walls as
    ``(index, wall, penetration)``."""
    held = np.zeros(len(radii), bool)
    held_t = np.zeros(len(radii))
    conducting = []
    for index, wall in enumerate(planes):
        penetration = np.asarray(wall.penetration(centres, radii))
        if wall.mode == "held":
            touching = penetration >= 0
            held |= touching
            held_t = np.where(touching, wall.temperature, held_t)
        elif wall.mode == "conducting":
            conducting.append((index, wall, penetration))
    return held, held_t, conducting


def _merged_wall_conductance(scene, radii, conducting):
    """Per-particle wall conductance at unit conductivity and the conductance-weighted wall temperature."""
    if not conducting:
        return None, None
    c = scene.conduction
    k_wall = np.zeros(len(radii))
    t_wall = np.zeros(len(radii))
    for index, wall, penetration in conducting:
        try:
            k_w = np.asarray(walls.wall_conductance(c.law, radii, penetration, 1.0, params=c.params,
                                                    neck_model=c.neck_model))
        except ValueError as err:
            raise SceneError(f"walls[{index}]: {err}") from None
        if not np.all(np.isfinite(k_w)):
            raise SceneError(f"walls[{index}].penetration: the wall cuts a particle deeper than the neck model "
                             f"allows for a plane (r/3 for the volume-conserving neck)")
        t_wall = np.where(k_w > 0, (k_wall * t_wall + k_w * wall.temperature) / np.maximum(k_wall + k_w, 1e-300),
                          t_wall)
        k_wall = k_wall + k_w
    return k_wall, t_wall
