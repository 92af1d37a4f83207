"""Run a scene: build the packing and network, step in chunks, write outputs and checkpoints.

Outputs in the run directory: ``scene.json`` (the validated scene),
``packing.npz`` (centres, radii), ``vtp/step_XXXXXXXX.vtp`` (VTK PolyData,
ParaView) and/or ``dump.lammpstrj`` (LAMMPS dump, OVITO) every
``output_every`` steps, ``checkpoint.npz`` every ``checkpoint_every`` steps
(written to a temporary file and renamed, so a killed run leaves the last
complete checkpoint). :func:`resume` continues from it and gives results
identical to an uninterrupted run: the same compiled chunk runs on the same
inputs.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
import warnings
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from sintercond import (forces, guards, heat_sources, materials, mechanics, neck_growth, network, packing, plots,
                        simulate, steady, thermal, walls)
from sintercond.rollout import advance
from sintercond.io import (append_lammps, load_checkpoint, save_checkpoint, truncate_lammps, write_network_vtp, write_pvd,
                           write_vtp)
from sintercond.neck import NECK_MODELS
from sintercond.scene import (BEAM_STEP_FRACTION, WALL_STEP_FRACTION, SceneError, advance_speed, beam_step,
                              default_penetration, file_packing, restitution_damping_ratio, validate_scene)
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
    """``progress(phase, steps, max_steps, figure, target)`` for :mod:`sintercond.packing`: a line through ``log``
    at most every :data:`PROGRESS_EVERY_S` seconds with the steps taken, the settling figure against its target
    and an estimate of the time left from the figure's recent rate of decay (it falls about exponentially)."""

    def __init__(self, log, particles):
        self.log, self.particles = log, particles
        self.start = self.last = time.perf_counter()
        self.points = []  # (seconds, ln figure) at the lines written

    def __call__(self, phase, steps, max_steps, figure, target):
        now = time.perf_counter()
        if now - self.last < PROGRESS_EVERY_S:
            return
        self.last = now
        self.points.append((now - self.start, math.log(max(figure, 1e-300))))
        left = ""
        if len(self.points) >= 2:
            (t0, y0), (t1, y1) = self.points[max(0, len(self.points) - 4)], self.points[-1]
            rate = (y0 - y1) / (t1 - t0)  # decay of ln figure per second
            if rate > 0 and figure > target:
                left = f", about {(y1 - math.log(target)) / rate:.0f} s left at this rate"
        self.log(f"packing: {phase} {self.particles:,} spheres: {steps:,} steps (at most {max_steps:,}), figure "
                 f"{figure:.3g} (settled below {target:g}), {now - self.start:.0f} s{left}")


def build_packing(scene, log=None):
    """``(centres, radii, bed)`` of a validated scene: listed spheres as given, else
    :func:`sintercond.packing.from_scene`; a bed that settles reports its progress through ``log``
    (:class:`SettlingProgress`).

    ``bed``: the bed's figures for the summary (empty for listed spheres).
    """
    p = scene["packing"]
    if p["kind"] == "spheres":
        return np.asarray(p["centres"], np.float64), np.asarray(p["radii"], np.float64), {}
    if p["kind"] == "file":
        centres, radii = file_packing(p)
        return np.array(centres), np.array(radii), {}
    if p["kind"] == "poured":
        rng = np.random.default_rng(p["seed"])
        radii = packing.truncated_normal_radii(p["particles"], p["radius_mean"], p["radius_std"],
                                               p["truncation"], rng)
        packed = packing.pour(radii, p["lateral_size"], dem_material(scene), seed=rng, start=p["start"],
                              temperature=scene["initial"]["temperature"],
                              progress=SettlingProgress(log, len(radii)) if log else None)
    else:
        count = packing.bed_particle_count(p["lateral_size"], p["height"], p["diameter_range"]) \
            if p["kind"] == "powder_bed" else 0
        progress = SettlingProgress(log, count) if log and count else None
        if p.get("method") == "dem":
            packed = packing.powder_bed(p["lateral_size"], p["height"], tuple(p["diameter_range"]), seed=p["seed"],
                                        method="dem", material=dem_material(scene), progress=progress)
            packed = dataclasses.replace(packed, radii=packed.radii * (1.0 + p["sinter_swelling"]))
        else:
            packed = packing.from_scene(p, progress=progress)
    return packed.centres, packed.radii, {k: v for k, v in packed.summary().items() if k != "particles"}


def _nusselt(convection):
    if "reynolds" in convection:
        return float(heat_sources.whitaker_nusselt(convection["reynolds"], convection["prandtl"]))
    return convection["nusselt"]


def scene_physics(scene, walls=0) -> simulate.Physics:
    """The static physics spec of a validated scene."""
    c, s, ramp = scene["conduction"], scene.get("sintering"), scene.get("preheating")
    beam = scene.get("beam")
    held = any(w["mode"] == "held" for w in _walls(scene)) or (ramp is not None and ramp["hold"] == "all")
    # a contact resistance makes the law nonlinear in the conductivity, growing necks and kappa(T) change it: lift it
    table = "conductivity_table" in scene["material"]
    lifted = c.get("params", {}).get("contact_resistance", 0.0) or s is not None or table
    return simulate.Physics(
        conduction=simulate.Conduction(
            law=c["law"], neck_model=c.get("neck_model"), conductance="lifted" if lifted else "table",
            held=held, conducting_walls=walls, held_ramp=ramp is not None, conductivity_table=table),
        sources=simulate.Sources(beam=None if beam is None else beam["kind"], convection="convection" in scene,
                                 radiation="radiation" in scene),
        sintering=None if s is None else neck_growth.Sintering(law=s["law"], every=s["every"]))


def mechanics_on(scene) -> bool:
    """Whether a validated scene runs the coupled thermo-mechanical step."""
    return scene["physics"]["mechanics"]


def contact_material(scene) -> dict:
    """The ``[mechanics]`` section as :class:`~sintercond.mechanics.MechanicalParams` names (floats, SI).

    ``mechanics.restitution`` e becomes ``xi_con``
    (:func:`sintercond.scene.restitution_damping_ratio`); wall coefficients
    default to the particles'.
    """
    m = scene["mechanics"]
    xi_con = restitution_damping_ratio(m["restitution"]) if "restitution" in m else m["damping"]
    return dict(E0=m["young_modulus"], nu=m["poisson_ratio"], xi_con=xi_con, xi_fric=m["tangential_damping"],
                xi_rol=m["rolling_damping"], mu=m["friction"], mu_r=m["rolling_friction"], mu_wall=m["wall_friction"],
                mu_r_wall=m["wall_rolling_friction"])


def mechanical_params(scene) -> mechanics.MechanicalParams | None:
    """The contact material of a validated scene (:func:`contact_material`, ``[softening]``), or None without mechanics."""
    if not mechanics_on(scene):
        return None
    soft = scene.get("softening")
    f = lambda x: jnp.asarray(float(x))  # noqa: E731
    return mechanics.MechanicalParams(
        **{k: f(v) for k, v in contact_material(scene).items()}, theta_star=f(soft["onset_temperature"] if soft else 400.0),
        rate=f(soft["rate"] if soft else 1.0), E_min=f(soft["min_modulus"] if soft else 0.0))


def dem_material(scene) -> packing.DemMaterial:
    """The contact material a poured packing settles with: :func:`contact_material` and ``material.density``."""
    c = contact_material(scene)
    return packing.DemMaterial(density=scene["material"]["density"], **{("E" if k == "E0" else k): float(v)
                                                                        for k, v in c.items()})


def mechanical_physics(scene, thermal_physics, planes) -> simulate.Physics:
    """The coupled spec of a validated scene with mechanics: ``thermal_physics`` made dynamic, the walls pushing.

    Every wall of the scene is a :class:`~sintercond.walls.PlaneWall` of
    ``Mechanics.walls``; a held wall pushes as an insulated one (its
    particles are held by ``Conduction.held``, :func:`_apply_walls`).
    """
    p, c = scene["physics"], contact_material(scene)
    walls_ = tuple(dataclasses.replace(w, mode="insulated", temperature=None) if w.mode == "held" else w
                   for w in planes)
    spec = mechanics.Mechanics.create(
        walls_, gravity=p["gravity"], shear=p["shear"], slip_direction=p["slip_direction"],
        rolling_projection=p["rolling_projection"], damping_clamp=p["damping_clamp"], softening="softening" in scene,
        friction=c["mu"] > 0 or c["mu_wall"] > 0, rolling=c["mu_r"] > 0 or c["mu_r_wall"] > 0,
        wall_friction=c["mu_wall"] > 0, wall_rolling=c["mu_r_wall"] > 0)
    conduction = dataclasses.replace(thermal_physics.conduction, conductance="lifted", conducting_walls=0)
    return dataclasses.replace(thermal_physics, conduction=conduction, contacts="dynamic", mechanics=spec)


def scene_params(scene) -> simulate.Params:
    """The differentiable parameters of a validated scene."""
    m, beam, conv, rad = scene["material"], scene.get("beam"), scene.get("convection"), scene.get("radiation")
    f = jnp.asarray
    return simulate.Params(
        mechanics=mechanical_params(scene),
        conductivity=f([m["conductivity"]]) if "conductivity_table" not in m else materials.tabulated(
            *np.asarray(m["conductivity_table"], np.float64).T), specific_heat=f([m["specific_heat"]]),
        law={k: f(v) for k, v in scene["conduction"].get("params", {}).items()},
        sintering=None if "sintering" not in scene else {k: f(v) for k, v in
                                                         scene["sintering"].get("params", {}).items()},
        held_ramp=None if "preheating" not in scene else simulate.HeldRampParams(
            f(scene["preheating"]["end_temperature"]), f(scene["preheating"]["duration"]),
            f(float(scene["preheating"]["steps"]))),
        beam=None if beam is None else simulate.BeamParams(
            intensity=f(beam["intensity"]), reach=f(beam["attenuation"] if beam["kind"] == "laser" else beam["max_depth"]),
            spot_radius=f(beam["spot_radius"]), absorptance=f(beam["absorptance"]), speed=f(beam["speed"]),
            path=f(beam["path"], dtype=float),
            segments_on=None if "segments_on" not in beam else f(beam["segments_on"], dtype=float),
            after_path=f(1.0 if beam["after_path"] == "stay" else 0.0)),
        convection=None if conv is None else simulate.ConvectionParams(
            f(conv["environment_temperature"]), f(conv["environment_conductivity"]), f(_nusselt(conv))),
        radiation=None if rad is None else simulate.RadiationParams(f(rad["environment_temperature"]),
                                                                    f(rad["emissivity"])))


def build_model(scene, centres=None, radii=None, log=None) -> Model:
    """Packing, network, held particles, sources, time step and simulator of a validated scene.

    The time step: ``run.dt`` or, for ``"auto"``, 0.9 of the stable step
    ``min_i C_i / (sum_j K_ij + sum_w K_iw + G_i)`` where ``G_i`` linearises
    convection and radiation (:func:`sintercond.thermal.source_conductance`);
    with mechanics, of the smaller of that (at the initial contacts) and the
    mechanical step (:func:`sintercond.mechanics.mechanical_time_step`: Eq. 47
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
    log = log or (lambda message: None)
    bed = {}
    if centres is None:
        log("packing: building the scene's packing")
        centres, radii, bed = build_packing(scene, log)
    m, c = scene["material"], scene["conduction"]
    physics = scene_physics(scene)
    log(f"network: contacts and conductances of {len(radii)} particles")
    try:
        unit = physics.conduction.conductance == "table"
        table = network.contact_table(centres, radii, 1.0 if unit else m["conductivity"],
                                      c["law"], c.get("params"), c.get("neck_model"))
    except ValueError as err:
        raise SceneError(f"the packing does not fit the conduction model: {err}") from None
    fixed_mask, fixed_temperature, conducting = _apply_walls(scene, centres, radii)
    if "preheating" in scene and scene["preheating"]["hold"] == "all":  # an isothermal cell on the ramp
        fixed_mask = np.ones(len(radii), bool)
        fixed_temperature = np.full(len(radii), scene["initial"]["temperature"])
    touching_walls = wall_contacts(scene, centres, radii, log)
    lifted = physics.conduction.conductance == "lifted"
    physics = dataclasses.replace(physics, conduction=dataclasses.replace(
        physics.conduction, conducting_walls=len(conducting) if lifted else int(bool(conducting))))
    particles = particle_state(centres, radii, scene["initial"]["temperature"], m["density"], m["specific_heat"],
                               fixed=fixed_mask, fixed_temperature=fixed_temperature)
    if not lifted:
        k_wall, t_wall = _merged_wall_conductance(scene, centres, radii, conducting)
        contacts = simulate.table_contacts(table, k_wall, t_wall)
    else:
        contacts = simulate.lifted_contacts(physics, centres, radii,
                                            [(penetration, wall.temperature) for _, wall, penetration in conducting])
    params = scene_params(scene)
    sim = simulate.simulator(physics)
    necks = None
    if physics.sintering is not None:
        necks = neck_growth.neck_state(contacts, particles.temperature)
    # growing necks only raise the conductances: the step is taken on the necks at the kinetic law's cap
    limiting = contacts if necks is None else neck_growth.necks_at_cap(physics.sintering, params.sintering, contacts,
                                                                      particles.radii)
    state = simulate.init_state(particles, limiting, 1.0, sintering=necks)
    run = scene["run"]
    sources = thermal.source_conductance(physics.sources, particles.radii, params, _highest_temperature(scene))
    # every particle held (an isothermal cell on a ramp): no conduction to keep stable
    thermal_limit = np.inf if fixed_mask.all() else float(simulate.thermal_time_step(sim, state, params, sources))
    at_cap = " on the necks at the kinetic law's cap" if necks is not None else ""
    bounds = {"thermal": (thermal_limit, f"the explicit stability limit min(C_i / (sum_j K_ij + G_i)) = "
                                         f"{thermal_limit:.6g} s{at_cap} (G_i: linearised convection and "
                                         "radiation)")}
    if "preheating" in scene:
        ramp = scene["preheating"]
        step = RAMP_STEP_FRACTION * ramp["duration"] / ramp["steps"]
        bounds["preheating"] = (step, f"{step:.6g} s, {RAMP_STEP_FRACTION:g} of a step of the preheating ramp "
                                      "(preheating.duration / preheating.steps)")
    reallocate = None
    motion = None
    if mechanics_on(scene):
        log("mechanics: contact list and the mechanical time step")
        planes = scene_walls(scene, centres, radii)
        physics = mechanical_physics(scene, physics, planes)
        skin = scene["physics"]["skin"] * float(np.max(radii))
        contacts, fns = simulate.dynamic_contacts(centres, radii, skin)
        sim = simulate.simulator(physics, fns)
        reallocate = simulate.reallocate_neighbors(fns)
        impact = scene["physics"]["impact_velocity"]
        wall_speed, fastest = _fastest_wall(scene)
        v_rel = impact + wall_speed
        mechanical_limit = float(mechanics.mechanical_time_step(physics.mechanics, particles, contacts.neighbors,
                                                            params.mechanics, v_rel))
        speed_source = f"physics.impact_velocity = {impact:g} m/s" + (
            f" plus walls[{fastest}].velocity's normal speed {wall_speed:g} m/s" if wall_speed > 0 else "")
        bounds["mechanical"] = (mechanical_limit, f"the mechanical time step {mechanical_limit:.6g} s (Eq. 47 and "
                                                  f"the symplectic-Euler bounds of the stiffest contact, unsoftened, "
                                                  f"at the approach speed {v_rel:g} m/s: {speed_source})")
        if wall_speed > 0:
            step = WALL_STEP_FRACTION * float(np.min(radii)) / wall_speed
            bounds["wall"] = (step, f"{step:.6g} s, in which walls[{fastest}] (walls[{fastest}].velocity, normal "
                                    f"speed {wall_speed:g} m/s) moves {WALL_STEP_FRACTION:g} of the smallest radius")
        motion = mechanics.mechanical_state(physics.mechanics, centres, contacts)
    beam = scene.get("beam")
    if beam is not None and beam_step(beam) is not None:
        step = beam_step(beam)
        bounds["beam"] = (step, f"{step:.6g} s, in which the beam's spot (beam.speed = {beam['speed']:g} m/s) moves "
                                f"{BEAM_STEP_FRACTION:g} of beam.spot_radius = {beam['spot_radius']:g} m")
    limit = min(bound for bound, _ in bounds.values())
    if run["dt"] == "auto":
        dt = 0.9 * limit if np.isfinite(limit) else run["duration"]
    else:
        dt = run["dt"]
        for kind, (bound, name) in bounds.items():
            if dt > bound:
                raise SceneError(f"run.dt: dt = {dt:.6g} s exceeds {name}; use dt <= {limit:.6g} s"
                                 + (" or the implicit integrator" if kind == "thermal" and motion is None else ""))
    n_steps = max(1, int(np.ceil(run["duration"] / dt * (1 - 1e-12))))
    dt = run["duration"] / n_steps  # equal steps that end at the duration, none above the stable one
    state = simulate.init_state(particles, contacts, dt, mechanics=motion, sintering=necks)
    bed = {**bed, **{f"wall{k}_particles": count for k, count in touching_walls.items()}}
    return Model(sim, params, state, n_steps, len(table.pairs()), limit, bed, reallocate,
                 _wall_heat_specs(scene, centres, radii),
                 {kind: bound for kind, (bound, _) in bounds.items()}, v_rel if motion is not None else None,
                 scene["sintering"].get("k_star_axis") if "sintering" in scene else None,
                 scene["packing"]["kind"] == "simple_cubic")


def _fastest_wall(scene) -> tuple[float, int | None]:
    """The largest speed (m/s) at which a scene's wall advances into the packing (:func:`sintercond.scene.advance_speed`),
    and that wall (None if none does)."""
    speeds = [advance_speed(w) for w in _walls(scene)]
    if not speeds or max(speeds) == 0:
        return 0.0, None
    return max(speeds), int(np.argmax(speeds))


def _highest_temperature(scene) -> float:
    """The highest temperature a scene names (initial, walls, environment): where radiation is stiffest."""
    temperatures = [scene["initial"]["temperature"]] + [w["temperature"] for w in _walls(scene) if "temperature" in w]
    temperatures += [scene[k]["environment_temperature"] for k in ("convection", "radiation") if k in scene]
    temperatures += [scene["preheating"]["end_temperature"]] if "preheating" in scene else []
    return float(max(temperatures))


def _walls(scene):
    walls = list(scene["walls"])
    if "floor_temperature" in scene.get("boundary", {}):
        walls.append({"axis": 2, "side": "min", "mode": "held", "temperature": scene["boundary"]["floor_temperature"],
                      "penetration": default_penetration(scene), "velocity": [0.0, 0.0, 0.0]})
    return walls


def scene_walls(scene, centres, radii) -> list[walls.PlaneWall]:
    """The scene's walls as :class:`~sintercond.walls.PlaneWall` (insulated ones included).

    A wall plane lies at the packing's extreme along its axis, moved
    ``penetration`` mean radii into it; its normal points into the packing.
    """
    planes = []
    for wall in _walls(scene):
        axis, depth = wall["axis"], wall["penetration"] * float(np.mean(radii))
        normal = np.zeros(3)
        if wall["side"] == "min":
            normal[axis] = 1.0
            position = float(np.min(centres[:, axis] - radii)) + depth
        else:
            normal[axis] = -1.0
            position = float(np.max(centres[:, axis] + radii)) - depth
        point = np.zeros(3)
        point[axis] = position
        planes.append(walls.PlaneWall(tuple(point), tuple(normal), wall["mode"], wall.get("temperature"),
                                      tuple(float(v) for v in wall["velocity"])))
    return planes


def _wall_heat_specs(scene, centres, radii):
    """``(column, index of the scene wall, mode, held mask or None)`` of each held or conducting wall of a scene.

    A particle held by several walls counts for the first (as in
    :func:`_apply_walls`, where the last one sets its temperature, they are
    only ever equal on an edge of two held faces).
    """
    specs, claimed = [], np.zeros(len(radii), bool)
    for k, wall in enumerate(scene_walls(scene, centres, radii)):
        if wall.mode == "held":
            mask = (np.asarray(wall.penetration(centres, radii)) >= 0) & ~claimed
            claimed |= mask
            specs.append((f"heat_wall{k}_W", k, "held", mask))
        elif wall.mode == "conducting":
            specs.append((f"heat_wall{k}_W", k, "conducting", None))
    return tuple(specs)


FEW_WALL_CONTACTS = 0.5
"""A held or conducting wall touching fewer than this fraction of the particles facing it is reported as a handful."""

def wall_contacts(scene, centres, radii, log=None) -> dict:
    """``{k: particles touching scene wall k}`` for each held or conducting wall, logged; warns on a handful.

    The particles facing a wall are its face layer, those whose surface comes within half a mean radius of the
    outermost one: on a rough bed the wall plane (the outermost particle moved ``walls[k].penetration`` mean
    radii in) may touch only the few that stick out, and the boundary condition then acts through them alone.
    With mechanics the count is the start's (the particles then settle onto the walls: ``history.csv``'s
    ``wall_contacts``) and no warning is given.
    """
    counts = {}
    for k, (wall, plane) in enumerate(zip(_walls(scene), scene_walls(scene, centres, radii))):
        if plane.mode not in ("held", "conducting"):
            continue
        penetration = np.asarray(plane.penetration(centres, radii))
        touching = int(np.count_nonzero(penetration >= 0 if plane.mode == "held" else penetration > 0))
        facing = int(np.count_nonzero(penetration > float(np.max(penetration)) - 0.5 * float(np.mean(radii))))
        counts[k] = touching
        name = f"walls[{k}]" if k < len(scene["walls"]) else "boundary.floor_temperature"
        message = (f"{name} ({plane.mode}, axis {wall['axis']} {wall['side']}) touches {touching} of the {facing} "
                   "particles facing it")
        if touching < FEW_WALL_CONTACTS * facing and not mechanics_on(scene):  # moving particles settle onto it
            depth = f"{wall['penetration']:g} mean radii"
            message += (f"; only a handful: raise walls[{k}].penetration (now {depth}) so that its plane reaches "
                        "into the rough face" if k < len(scene["walls"]) else
                        f"; only a handful: replace boundary.floor_temperature by a held [[walls]] floor (axis = 2, "
                        f"side = \"min\") with a penetration above its {depth}, so that its plane reaches into the "
                        "rough face")
            warnings.warn(message, WallContactWarning, stacklevel=2)
        if log is not None:
            log(message)
    return counts


class WallContactWarning(UserWarning):
    """A held or conducting wall touches only a handful of the particles facing it."""


def _apply_walls(scene, centres, radii):
    """Held walls become fixed particles; returns them and the conducting walls as ``(index, wall, penetration)``."""
    held = np.zeros(len(radii), bool)
    held_t = np.zeros(len(radii))
    conducting = []
    for index, wall in enumerate(scene_walls(scene, centres, radii)):
        penetration = np.asarray(wall.penetration(centres, radii))
        if wall.mode == "held":
            touching = penetration >= 0
            held |= touching
            held_t = np.where(touching, wall.temperature, held_t)
        elif wall.mode == "conducting":
            conducting.append((index, wall, penetration))
    return held, held_t, conducting


def _merged_wall_conductance(scene, centres, radii, conducting):
    """Per-particle wall conductance at unit conductivity and the conductance-weighted wall temperature."""
    if not conducting:
        return None, None
    c = scene["conduction"]
    k_wall = np.zeros(len(radii))
    t_wall = np.zeros(len(radii))
    for index, wall, penetration in conducting:
        try:
            k_w = np.asarray(walls.wall_conductance(c["law"], radii, penetration, 1.0, params=c.get("params"),
                                                    neck_model=c.get("neck_model")))
        except ValueError as err:
            raise SceneError(f"walls[{index}]: {err}") from None
        if not np.all(np.isfinite(k_w)):
            raise SceneError(f"walls[{index}].penetration: the wall cuts a particle deeper than the neck model "
                             f"allows for a plane (r/3 for the volume-conserving neck)")
        t_wall = np.where(k_w > 0, (k_wall * t_wall + k_w * wall.temperature) / np.maximum(k_wall + k_w, 1e-300),
                          t_wall)
        k_wall = k_wall + k_w
    return k_wall, t_wall


MAX_TEMPERATURE = 1e5
"""K; a run whose temperatures leave (0, MAX_TEMPERATURE] stops: no material of this field gets there."""


def physical_range_check(scene):
    """``check(state)`` for :func:`advance`: temperatures finite, > 0 K and <= :data:`MAX_TEMPERATURE`, and
    growing necks still within the time step's stability (:func:`sintercond.neck_growth.check_stable`).

    The error names the step and the scene keys that can drive a run there.
    """
    causes = [key for key, section in (("beam.intensity", "beam"), ("convection.nusselt", "convection"),
                                       ("radiation.emissivity", "radiation")) if section in scene] + ["run.dt"]

    melting = scene["material"].get("melting_point")
    warned = []

    def check(state):
        neck_growth.check_stable(state)
        t = state.particles.temperature
        bad = ~jnp.isfinite(t) | (t <= 0) | (t > MAX_TEMPERATURE)
        if bool(jnp.any(bad)):
            worst = float(jnp.max(jnp.where(jnp.isfinite(t), jnp.abs(t), jnp.inf)))
            raise FloatingPointError(
                f"temperature left the physical range (0, {MAX_TEMPERATURE:g}] K at step {int(state.step)} "
                f"(|T| up to {worst:.3g} K); likely cause: {', '.join(causes)} too large for the time step")
        if melting is not None and not warned:
            hottest = float(jnp.max(t))
            if hottest > melting:
                message = (f"T = {hottest:.6g} K at step {int(state.step)} (t = {float(state.time):.6g} s) is above "
                           f"material.melting_point = {melting:g} K: the model has no melting (no latent heat, no "
                           "liquid), so what follows is not physical")
                if scene["material"]["on_melting"] == "stop":
                    raise MeltingPointCrossed(message + "; lower the heat input (beam.intensity or beam.power), or "
                                              'set material.on_melting = "warn" to go on')
                warned.append(int(state.step))
                warnings.warn(message, MeltingPointWarning, stacklevel=2)
                _log(f"warning: {message} (said once)")
    return check


class MeltingPointCrossed(FloatingPointError):
    """A run crossed ``material.melting_point`` with ``material.on_melting = "stop"`` (the default)."""


class MeltingPointWarning(UserWarning):
    """A run crossed ``material.melting_point`` with ``material.on_melting = "warn"``."""


def run_check(scene, model, state):
    """The ``check(state)`` of a scene's run from ``state``: :func:`physical_range_check`, and with mechanics
    :func:`sintercond.guards.motion_guard` at the speed the step was sized for (``physics.impact_velocity``)."""
    temperatures = physical_range_check(scene)
    if model.sized_speed is None:
        return temperatures
    motion = guards.motion_guard(model.sim, state, model.params, model.sized_speed, "physics.impact_velocity")

    def check(new):
        temperatures(new)
        motion(new)

    return check


RAMP_STEP_FRACTION = 0.1
"""The largest time step is this fraction of a step of a ``[preheating]`` ramp: each level of the ramp is resolved
in ten steps (necks grow over an interval at the mean of its start and end temperatures, so the interval that
straddles a level's edge takes the mean of two levels)."""

HISTORY_COLUMNS = ("step", "time_s", "T_mean_K", "T_min_K", "T_max_K")
"""The columns of ``history.csv`` every run has, one row per output step (the LAMMPS "thermo" analogue)."""
MECHANICS_COLUMNS = ("kinetic_energy_J", "contacts", "wall_contacts", "max_overlap_m")
"""Columns a run with mechanics adds: translational plus rotational kinetic energy, touching particle pairs,
particles touching a wall, and the largest overlap of a pair or a wall contact."""


SINTERING_COLUMNS = ("mean_neck_ratio", "max_neck_ratio", "shrinkage")
"""Columns a run with ``[sintering]`` adds (:func:`sintercond.neck_growth.neck_statistics`): the mean and largest
neck ratio ``a / min(r_i, r_j)`` over the contacts and the mean linear shrinkage of their approaches."""


def history_columns(model) -> tuple:
    """The columns of ``history.csv`` of ``model``: :data:`HISTORY_COLUMNS`, :data:`MECHANICS_COLUMNS` with
    mechanics, :data:`SINTERING_COLUMNS` with sintering, and ``heat_wall{k}_W`` (the heat power into the packing
    through scene wall ``k``, W) for each held or conducting wall."""
    return (HISTORY_COLUMNS + (MECHANICS_COLUMNS if model.physics.mechanics is not None else ())
            + (SINTERING_COLUMNS if model.physics.sintering is not None else ())
            + (("k_star_W_mK",) if model.k_star_axis is not None else ())
            + tuple(spec[0] for spec in model.wall_heat))


def sintered_conductivity(model, state) -> float:
    """k* (W/(m K)) of a sintering state along ``model.k_star_axis``: one steady solve on its grown necks
    (:func:`sintercond.steady.steady_state_network_conductivity`), 0 while no contact conducts. A lattice's end
    layers are held hot and cold; any other packing's face layers (:func:`sintercond.steady.face_layer_box`)."""
    carried, radii = state.sintering, model.radii
    slot = np.asarray(carried.pair_slot)
    pair_k = np.asarray(simulate.neck_conductance(model.physics, state, model.params)).reshape(-1)[slot]
    if not np.any(pair_k > 0):
        return 0.0
    i, j = np.asarray(carried.pairs, np.int64).T
    pairs = network.ContactPairs(i, j, np.asarray(state.contacts.overlap).reshape(-1)[slot], radii[i], radii[j],
                                 len(radii))
    axis = model.k_star_axis
    box = None if model.lattice else steady.face_layer_box(model.centres, radii, axis)
    return float(steady.steady_state_network_conductivity(model.centres, radii, pairs, pair_k, axis=axis, box=box))


class Observation(NamedTuple):
    """What a run reports of a state besides temperatures (host arrays): see :func:`observe`."""

    wall_heat: tuple  # W per held or conducting wall, in model.wall_heat order
    kinetic_energy: float = float("nan")
    pairs: Any = None  # [p, 2] touching particle pairs
    pair_overlap: Any = None  # [p] (m)
    wall_overlap: Any = None  # [n_walls, n] (m), > 0 touching
    velocity: Any = None  # [n, 3] (m/s)
    force: Any = None  # [n, 3] contact force (N), gravity excluded
    power: Any = None  # [n] net heat power into each particle from its contacts, walls and sources (W)


def _probe_fn(model):
    """A jitted ``(state, params) -> (heat power [n] W, velocity after one step or None)`` for :func:`observe`."""
    sim = model.sim

    def probe(state, params):
        prep = sim.prepare_fn(state, params)
        power = sim.heat_power_fn(state, prep)
        after = sim.advance_fn(state, prep).mechanics.velocity if model.physics.mechanics is not None else None
        return power, after

    return jax.jit(probe)


def _plane_penetration(plane, positions, radii, t):
    """``r - (x - p(t)) . n`` (m) of each particle on a plane wall whose point moves at its velocity."""
    point = np.asarray(plane.point) + t * np.asarray(plane.velocity)
    return radii - (positions - point) @ np.asarray(plane.normal)


def observe(scene, model, state, probe) -> Observation:
    """Heat through each held or conducting wall, and with mechanics the motion and the contacts, of ``state``.

    Heat into the packing through a conducting wall: ``sum_i K_iw (T_w - T_i)``
    with ``K_iw`` the wall conductance of the scene's law at the current
    penetration (:func:`sintercond.walls.wall_conductance`); through a held
    wall: the power its held particles lose to the rest,
    ``-sum_i P_i`` over them (what holds them at their temperature).
    With mechanics: the contact force ``m (v(t + dt) - v(t)) / dt - m g``
    (one symplectic-Euler step of the simulator, Eq. 43), kinetic energy
    ``sum m v^2/2 + I omega^2/2`` (``I = (2/5) m r^2``), touching pairs and
    wall contacts.
    """
    p = state.particles
    positions, radii, temperature = (np.asarray(x) for x in (p.positions, p.radii, p.temperature))
    index, conductivity = simulate.conductivity_lookup(model.physics, model.params, p)
    kappa = np.asarray(conductivity)[np.asarray(index)]
    needs_power = (any(spec[2] == "held" for spec in model.wall_heat) or model.physics.mechanics is not None
                   or "vtp" in scene["run"]["formats"])
    power, after = probe(state, model.params) if needs_power else (None, None)
    planes = scene_walls(scene, np.asarray(model.state.particles.positions), radii)
    if model.physics.mechanics is not None:
        planes = list(model.physics.mechanics.walls)
    t = float(state.time)
    conducting_power = np.zeros(len(radii))
    wall_h = [_plane_penetration(plane, positions, radii, t) for plane in planes]
    flows = {}
    c = scene["conduction"]
    for k, wall in enumerate(_walls(scene)):
        if wall["mode"] == "conducting":
            k_w = np.asarray(walls.wall_conductance(c["law"], radii, wall_h[k], kappa, params=c.get("params"),
                                                    neck_model=c.get("neck_model")))
            q = k_w * (wall["temperature"] - temperature)
            conducting_power += q if model.physics.mechanics is not None else 0.0  # the thermal simulator's P_i holds it
            flows[k] = float(np.sum(q))
    for _, k, mode, mask in model.wall_heat:
        if mode == "held":
            flows[k] = -float(np.sum((np.asarray(power) + conducting_power)[mask]))
    heat = tuple(flows[spec[1]] for spec in model.wall_heat)
    total = None if power is None else np.asarray(power) + conducting_power
    if model.physics.mechanics is None:
        return Observation(heat, power=total)
    m = np.asarray(p.mass)
    v, omega = np.asarray(state.mechanics.velocity), np.asarray(state.mechanics.spin)
    inertia = forces.SOLID_SPHERE_INERTIA * m * radii**2
    kinetic = float(0.5 * np.sum(m * np.sum(v * v, axis=1)) + 0.5 * np.sum(inertia * np.sum(omega * omega, axis=1)))
    force = m[:, None] * ((np.asarray(after) - v) / float(state.dt) - np.asarray(model.physics.mechanics.gravity))
    pairs, overlap = _touching_pairs(positions, radii, np.asarray(state.contacts.neighbors))
    return Observation(heat, kinetic, pairs, overlap, np.stack(wall_h) if wall_h else np.zeros((0, len(radii))),
                       v, force, total)


def _touching_pairs(positions, radii, neighbors):
    """Touching pairs ``[p, 2]`` (each once, ``i < j``) among the listed candidates, and their overlaps (m)."""
    n = len(radii)
    rows = np.broadcast_to(np.arange(n)[:, None], neighbors.shape)
    listed = (neighbors < n) & (neighbors != rows)
    i, j = rows[listed], neighbors[listed]
    lo, hi = np.unique(np.stack([np.minimum(i, j), np.maximum(i, j)], axis=1), axis=0).T if len(i) else (i, j)
    overlap = radii[lo] + radii[hi] - np.linalg.norm(positions[hi] - positions[lo], axis=1)
    touching = overlap > 0
    return np.stack([lo[touching], hi[touching]], axis=1), overlap[touching]


def coordination(n, pairs):
    """Contacts per particle ``[n]`` (particle pairs only, walls not counted)."""
    return np.bincount(np.ravel(pairs), minlength=n)


def _history_row(model, state, obs: Observation) -> str:
    t = np.asarray(state.particles.temperature)
    values = [float(state.time), float(t.mean()), float(t.min()), float(t.max())]  # Python floats: plain repr
    if model.physics.mechanics is not None:
        touching_walls = int(np.sum(np.any(obs.wall_overlap > 0, axis=0))) if len(obs.wall_overlap) else 0
        largest = float(max(np.max(obs.pair_overlap, initial=0.0), np.max(obs.wall_overlap, initial=0.0)))
        values += [obs.kinetic_energy, len(obs.pairs), touching_walls, largest]
    if model.physics.sintering is not None:
        stats = neck_growth.neck_statistics(state)
        values += [float(stats[name]) for name in SINTERING_COLUMNS]
    if model.k_star_axis is not None:
        values.append(sintered_conductivity(model, state))
    values += list(obs.wall_heat)
    return f"{int(state.step)}," + ",".join(repr(v) if isinstance(v, float) else str(v) for v in values) + "\n"


def read_history(out) -> dict:
    """``history.csv`` of a run as a dict of arrays: ``time`` (s) and every other column by its name (for the plot)."""
    data = np.genfromtxt(Path(out) / "history.csv", delimiter=",", names=True, ndmin=1)
    return {"time": data["time_s"], **{name: data[name] for name in data.dtype.names if name not in ("step", "time_s")}}


def _log(message):
    print(f"sintercond: {message}", file=sys.stderr, flush=True)


def _clear_outputs(out):
    """A new run into ``out`` first removes the outputs an earlier run left there."""
    for f in _frames(out, "step") + _frames(out, "network"):
        f.unlink()
    for name in ("dump.lammpstrj", "checkpoint.npz", "history.csv", "summary.json", "frames.pvd", "network.pvd",
                 plots.STATE_PICTURE, plots.HISTORY_PLOT):
        if (out / name).exists():
            (out / name).unlink()


def run_scene(scene, out_dir, progress=True, stop_after_chunks=None, _start=None, pictures=True):
    """Run a validated scene into ``out_dir``; returns ``(final temperatures, summary dict)``.

    Prints each phase (packing, network, compile) and, before stepping, the
    step count and the stable step. ``stop_after_chunks`` stops early as a
    kill would, right after that many chunks (for tests of resume).
    """
    out = Path(out_dir)
    if _start is None:
        out.mkdir(parents=True, exist_ok=True)
        _clear_outputs(out)
        (out / "scene.json").write_text(json.dumps(scene, indent=1))
        model = build_model(scene, log=_log)
        np.savez(out / "packing.npz", centres=model.centres, radii=model.radii)
        (out / "bed.json").write_text(json.dumps(model.bed))
        probe = _probe_fn(model)
        obs = observe(scene, model, model.state, probe)
        header = ",".join(history_columns(model)) + "\n"
        (out / "history.csv").write_text(header + _history_row(model, model.state, obs))
        _write_outputs(scene, out, model, model.state, obs)
        state = model.state
    else:
        model, state = _start
        probe = _probe_fn(model)
    run = scene["run"]
    chunk = run["output_every"]
    chunks_done = 0
    _log(f"{len(model.radii)} particles, {model.contacts} contacts; stable step {model.stable_step:.4g} s, "
         f"dt {model.dt:.4g} s, {model.n_steps} steps to {model.n_steps * model.dt:.6g} s; compiling the step")

    last = [int(state.step)]

    def on_chunk(s):
        nonlocal chunks_done
        step = int(s.step)
        crossed = step // run["checkpoint_every"] > last[0] // run["checkpoint_every"]  # an extension's steps
        last[0] = step  # are off the output grid: checkpoint once a multiple of checkpoint_every is passed
        obs = observe(scene, model, s, probe)
        _write_outputs(scene, out, model, s, obs)
        with open(out / "history.csv", "a") as f:
            f.write(_history_row(model, s, obs))
        if crossed or step >= model.n_steps:
            save_checkpoint(out, s)  # the lists' capacities are the shapes of their leaves
        chunks_done += 1
        return stop_after_chunks is not None and chunks_done >= stop_after_chunks and step < model.n_steps

    wall = time.perf_counter()
    bar = tqdm(total=model.n_steps, initial=int(state.step), unit="step", disable=not progress, desc="sintercond run")
    try:
        state, _ = advance(model.sim, state, model.params, model.n_steps - int(state.step), chunk, on_chunk,
                           reallocate=model.reallocate, progress=bar.update, check=run_check(scene, model, state))
    finally:
        bar.close()
    temperature = state.particles.temperature
    if int(state.step) < model.n_steps:
        return temperature, None
    elapsed = time.perf_counter() - wall
    summary = {
        "particles": len(model.radii), "contacts": model.contacts, **model.bed, "steps": int(state.step),
        "dt_s": model.dt, "stable_step_s": model.stable_step, "simulated_s": int(state.step) * model.dt,
        "wall_s": elapsed, "T_min_K": float(temperature.min()), "T_mean_K": float(temperature.mean()),
        "T_max_K": float(temperature.max()),
    }
    if model.physics.mechanics is not None:
        history = read_history(out)
        summary.update({"thermal_step_s": model.limits["thermal"], "mechanical_step_s": model.limits["mechanical"],
                        "kinetic_energy_J": float(history["kinetic_energy_J"][-1]),
                        "final_contacts": int(history["contacts"][-1]),
                        "max_overlap_m": float(history["max_overlap_m"][-1])})
    if model.physics.sintering is not None:
        summary.update({name: float(value) for name, value in neck_growth.neck_statistics(state).items()})
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    if pictures:
        plots.write_run_pictures(out, np.asarray(state.particles.positions), model.radii, temperature, summary,
                                 history=read_history(out))
    return temperature, summary


def written_outputs(out) -> str:
    """What a finished run left in ``out``, for the closing line of ``sintercond run``."""
    out = Path(out)
    listed = [(plots.STATE_PICTURE, "a picture of the last state"), (plots.HISTORY_PLOT, "the history plotted"),
              ("frames.pvd", "the frames as a time series for ParaView"),
              ("network.pvd", "the contact network's frames for ParaView"), ("vtp", "one VTP frame per output"),
              ("dump.lammpstrj", "for OVITO"), ("history.csv", "one row per output"),
              ("summary.json", "the summary"), ("checkpoint.npz", "for --resume")]
    return "; ".join(f"{name}{'/' if name == 'vtp' else ''}: {what}" for name, what in listed if (out / name).exists())


def contact_network(model, state) -> tuple:
    """The contacts of ``state`` and what each carries: ``(pairs [p, 2], fields)``, pairs ``i < j``.

    ``fields``: ``neck_radius`` (m, the neck the conductance law takes), ``conductance`` (W/K) and ``heat_flow``
    (W, ``K (T_i - T_j)``: from ``i`` to ``j``); the contacts the static table lists (touching within the
    packing's tolerance, point contacts of a sintering lattice included), or the touching pairs of a moving
    packing's list.
    """
    physics, p = model.physics, state.particles
    radii, temperature = np.asarray(p.radii), np.asarray(p.temperature)
    index, kappa = simulate.conductivity_lookup(physics, model.params, p)
    law = simulate.merged_law_params(physics, model.params)
    if physics.contacts == "dynamic":
        geometry = mechanics.pair_geometry(p.positions, p.radii, state.contacts.pairs.pairs)
        keep = np.asarray(geometry.touching & geometry.valid)
        pairs = np.stack([np.asarray(geometry.i), np.asarray(geometry.j)], axis=1)[keep]
        k = np.asarray(simulate.pair_conductance(physics, p.radii, index, geometry, kappa, law))[keep]
        overlap = np.asarray(geometry.overlap)[keep]
        neck = np.asarray(NECK_MODELS[physics.neck](radii[pairs[:, 0]], radii[pairs[:, 1]], overlap))
    else:
        neighbors = np.asarray(state.contacts.neighbors)
        rows = np.broadcast_to(np.arange(len(radii))[:, None], neighbors.shape)
        lower = (rows < neighbors) & (neighbors < len(radii))
        pairs = np.stack([rows[lower], neighbors[lower]], axis=1)
        if physics.conduction.conductance == "table":
            k = np.asarray(state.contacts.conductance)[lower] * float(np.asarray(kappa)[0])
            centres = np.asarray(p.positions)
            overlap = np.maximum(radii[pairs[:, 0]] + radii[pairs[:, 1]]
                                 - np.linalg.norm(centres[pairs[:, 0]] - centres[pairs[:, 1]], axis=1), 0.0)
            neck = np.asarray(NECK_MODELS[physics.neck](radii[pairs[:, 0]], radii[pairs[:, 1]], overlap))
        else:
            k = np.asarray(simulate.neck_conductance(physics, state, model.params))[lower]
            neck = np.asarray(state.contacts.neck)[lower]
    flow = k * (temperature[pairs[:, 0]] - temperature[pairs[:, 1]])
    return pairs, {"neck_radius": neck, "conductance": k, "heat_flow": flow}


def _write_outputs(scene, out, model, state, obs: Observation):
    """The frame of ``state``: positions, radii, temperatures, and with mechanics velocity, contact force and
    coordination (contacts per particle)."""
    formats = scene["run"]["formats"]
    step = int(state.step)
    t = float(state.time)
    temperature = state.particles.temperature
    positions = np.asarray(state.particles.positions)
    fields = {}
    if model.physics.mechanics is not None:
        fields = {"velocity": obs.velocity, "force": obs.force,
                  "coordination": coordination(len(model.radii), obs.pairs)}
    if "lammps" in formats:
        append_lammps(out / "dump.lammpstrj", positions, model.radii, temperature, step, fields)
    if "vtp" in formats:
        p = state.particles
        fields = {**fields, "held": np.asarray(p.fixed, np.int64) if p.fixed is not None else
                  np.zeros(len(model.radii), np.int64), "material": np.asarray(p.material, np.int64)}
        if obs.power is not None:
            fields["heat_power"] = np.asarray(obs.power)
        if model.physics.sintering is not None:
            fields["neck_ratio"] = np.asarray(neck_growth.particle_neck_ratio(state))
        (out / "vtp").mkdir(exist_ok=True)
        write_vtp(out / "vtp" / f"step_{step:08d}.vtp", positions, model.radii, temperature, step, t, fields,
                  encoding=scene["run"]["vtp_encoding"])
        if scene["run"]["contact_network"]:
            pairs, per_contact = contact_network(model, state)
            write_network_vtp(out / "vtp" / f"network_{step:08d}.vtp", positions, pairs, step, t, per_contact,
                              encoding=scene["run"]["vtp_encoding"])
        write_frames_pvd(out, model.dt)


def _frames(out, kind):
    """The VTP frames ``out/vtp/{kind}_*.vtp`` (``step``: particles, ``network``: contacts), in step order."""
    return sorted((out / "vtp").glob(f"{kind}_*.vtp")) if (out / "vtp").exists() else []


def write_frames_pvd(out, dt):
    """``out/frames.pvd`` (and ``out/network.pvd`` with contact-network frames): every frame in ``out/vtp`` at its
    physical time ``step * dt`` (ParaView's time series)."""
    for kind, name in (("step", "frames.pvd"), ("network", "network.pvd")):
        frames = _frames(out, kind)
        if frames or kind == "step":
            write_pvd(out / name, [(float(np.float64(int(f.stem.split("_")[1])) * dt), f"vtp/{f.name}")
                                   for f in frames])


def resume(out_dir, progress=True, stop_after_chunks=None, pictures=True, duration=None):
    """Continue the run in ``out_dir`` from its last checkpoint (the whole state).

    A finished run (its ``summary.json`` at the checkpoint's step) is not
    rebuilt: its final temperatures and summary are returned as they are,
    unless ``duration`` (s) extends it: the run then goes on with its own time
    step to the first step at or after ``duration`` (``scene.json`` records the
    new duration), its outputs appended to the ones it has.
    """
    out = Path(out_dir)
    if not (out / "checkpoint.npz").exists():
        raise SceneError(f"{str(out)!r} has no checkpoint.npz to resume from")
    saved = np.load(out / "checkpoint.npz")
    step = int(saved["step"])
    raw = json.loads((out / "scene.json").read_text())
    if duration is not None:
        done = step * float(saved[".dt"])
        if not duration > done:
            raise SceneError(f"--duration {duration:g} s must exceed the {done:.6g} s the run in {out} has simulated")
        raw["run"]["duration"] = float(duration)
    elif (out / "summary.json").exists():
        summary = json.loads((out / "summary.json").read_text())
        if summary.get("steps") == step:
            _log(f"the run in {out} is finished (step {step}); nothing to resume (--duration S extends it)")
            return jnp.asarray(saved["temperature"]), summary
    scene = validate_scene(raw)
    packed = np.load(out / "packing.npz")
    model = build_model(scene, packed["centres"], packed["radii"], log=_log)
    if (out / "bed.json").exists():
        model = dataclasses.replace(model, bed=json.loads((out / "bed.json").read_text()))
    state = load_checkpoint(out / "checkpoint.npz", model.state)
    if duration is not None or float(state.dt) != model.dt:
        # the run keeps its own step (an extension, or the resume of an interrupted one): the steps taken stay valid
        dt = float(state.dt)
        model = dataclasses.replace(model, n_steps=max(step, int(np.ceil(scene["run"]["duration"] / dt * (1 - 1e-12)))),
                                    state=dataclasses.replace(model.state, dt=state.dt))
    if duration is not None:
        (out / "scene.json").write_text(json.dumps(scene, indent=1))
        for name in ("summary.json", plots.STATE_PICTURE, plots.HISTORY_PLOT):
            if (out / name).exists():
                (out / name).unlink()
    # outputs written after the checkpoint by the interrupted run are redone
    for f in _frames(out, "step") + _frames(out, "network"):
        if int(f.stem.split("_")[1]) > step:
            f.unlink()
    if (out / "vtp").exists():
        write_frames_pvd(out, model.dt)
    if (out / "dump.lammpstrj").exists():
        truncate_lammps(out / "dump.lammpstrj", step)
    if (out / "history.csv").exists():
        lines = (out / "history.csv").read_text().splitlines(keepends=True)
        (out / "history.csv").write_text("".join([lines[0]] + [r for r in lines[1:] if int(r.split(",")[0]) <= step]))
    return run_scene(scene, out, progress, stop_after_chunks, _start=(model, state), pictures=pictures)


def summary_table(summary) -> str:
    width = max(len(k) for k in summary)
    return "\n".join(f"{k:<{width}}  {v:.6g}" if isinstance(v, float) else f"{k:<{width}}  {v}" for k, v in summary.items())
