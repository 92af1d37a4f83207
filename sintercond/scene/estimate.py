"""The work of a run estimated from the scene alone (:func:`estimate_run`: particles, time step, steps, frames,
output bytes, memory), and the time-step bounds a scene sets (a moving wall, a beam's spot)."""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from sintercond.scene.schema import (
    MAX_FRAMES, MAX_MEMORY_BYTES, MAX_OUTPUT_BYTES, MAX_STEPS, SceneError, file_packing, file_temperatures,
    output_interval, restitution_damping_ratio,
)


class RunEstimate(NamedTuple):
    """What a scene will cost, estimated before anything is built (order of magnitude for steps)."""

    particles: int
    dt: float  # s: run.dt, or 0.9 x an estimate of the stable step
    steps: int
    frames: int
    output_bytes: float
    memory_bytes: float


def estimate_run(scene) -> RunEstimate:
    """Estimate particles, step, steps, frames, output bytes and memory of a validated scene; refuse beyond limits.

    The stable step is estimated as ``C / (z K + G)`` for the smallest
    particle: ``C = rho c (4/3) pi r^3``, ``z`` = 12 neighbours (6 in a
    simple-cubic lattice) plus one wall, ``K = kappa pi a`` with Coble's neck
    ``a = sqrt(r h)`` (an upper bound on the necks of every law's default
    model but Feng's 2-D law, which takes ``thickness`` instead), and ``G``
    the linearised convection ``2 pi Nu k_E r`` and radiation
    ``16 pi eps sigma T^3 r^2`` at the highest temperature the scene names.
    """
    from sintercond.laws.heat_sources import STEFAN_BOLTZMANN
    from sintercond.beds.packing import bed_particle_count

    packing, material, run = scene["packing"], scene["material"], scene["run"]
    if packing["kind"] == "spheres":
        n, r = len(packing["radii"]), min(packing["radii"])
        h, z = 2 * r * 1e-3, 13
    elif packing["kind"] == "file":
        radii = file_packing(packing)[1]
        n, r = len(radii), float(np.min(radii))
        h, z = 2 * r * 1e-3, 13
    elif packing["kind"] == "poured":
        n = packing["particles"]
        r = max(packing["radius_mean"] - packing["truncation"] * packing["radius_std"],
                1e-3 * packing["radius_mean"])
        h, z = 2 * r * 1e-3, 13
    elif packing["kind"] == "powder_bed":
        n = bed_particle_count(packing["lateral_size"], packing["height"], packing["diameter_range"])
        r = packing["diameter_range"][0] / 2
        h, z = 2 * r * max(packing["sinter_swelling"], 1e-3), 13
    else:
        n = math.prod(packing["counts"])
        r = packing["radius"]
        h, z = 2 * r - packing["spacing"], 7
    if "sintering" in scene:
        h = r  # the necks grow up to about the radius, a = sqrt(r h): the step is taken on them
    kappa = max([material["conductivity"]] + [k for _, k in material.get("conductivity_table", [])])
    law = scene["conduction"]["law"]
    k_pair = kappa * scene["conduction"].get("params", {}).get("thickness", 1.0) * math.pi if law == "feng" else (
        kappa * math.pi * math.sqrt(r * h))
    g = 0.0
    temperatures = [scene["initial"]["temperature"]] + [w["temperature"] for w in scene["walls"] if "temperature" in w]
    if scene["initial"].get("from_file"):
        temperatures.append(float(np.max(file_temperatures(packing))))
    if "convection" in scene:
        c = scene["convection"]
        nusselt = c["nusselt"] if "nusselt" in c else (
            2.0 + (0.4 * c["reynolds"] ** 0.5 + 0.06 * c["reynolds"] ** (2 / 3)) * c["prandtl"] ** 0.4)
        g += 2 * math.pi * nusselt * c["environment_conductivity"] * r
        temperatures.append(c["environment_temperature"])
    if "radiation" in scene:
        temperatures.append(scene["radiation"]["environment_temperature"])
        g += 16 * math.pi * scene["radiation"]["emissivity"] * STEFAN_BOLTZMANN * max(temperatures) ** 3 * r**2
    c_min = min([material["specific_heat"]] + [c for _, c in material.get("specific_heat_table", [])])
    capacity = material["density"] * c_min * 4 / 3 * math.pi * r**3
    dt = 0.9 * capacity / (z * k_pair + g)
    if scene["physics"]["mechanics"] and not scene["mechanics"]["quasi_static"]:  # quasi-static: no inertia
        wall_speed = max((advance_speed(w) for w in scene["walls"]), default=0.0)
        dt = min(dt, 0.9 * _mechanical_step_estimate(scene, r, wall_speed))
        if wall_speed > 0:
            dt = min(dt, 0.9 * WALL_STEP_FRACTION * r / wall_speed)
    if "beam" in scene and beam_step(scene["beam"]) is not None:
        dt = min(dt, 0.9 * beam_step(scene["beam"]))
    if ramp_step(scene) is not None:
        dt = min(dt, 0.9 * ramp_step(scene))
    dt = dt if run["dt"] == "auto" else run["dt"]
    steps = max(1, math.ceil(run["duration"] / dt))
    frames = steps // output_interval(run, steps)[0] + 1
    per_frame = n * (("vtp" in run["formats"]) * 230 + ("lammps" in run["formats"]) * 140)
    estimate = RunEstimate(n, dt, steps, frames, frames * per_frame, 4e3 * n)
    if run["dt"] != "auto":  # the step count is exact; with the automatic step the build checks it
        check_sintering_every(scene, steps)
    if estimate.memory_bytes > MAX_MEMORY_BYTES:
        raise SceneError(f"the packing needs about {estimate.memory_bytes / 1e9:.3g} GB ({n} particles); the limit "
                         f"is {MAX_MEMORY_BYTES / 1e9:g} GB: make [packing] smaller")
    if not run["override_limits"]:
        for what, value, limit, advice in (
                ("time steps", steps, MAX_STEPS, "shorten run.duration or raise run.dt"),
                ("output frames", frames, MAX_FRAMES, "raise run.output_every or shorten run.duration"),
                ("bytes of output", estimate.output_bytes, MAX_OUTPUT_BYTES,
                 "raise run.output_every, drop a run.formats entry or shorten run.duration")):
            if value > limit:
                raise SceneError(f"run.duration {run['duration']:g} s with a step of about {dt:.3g} s means about "
                                 f"{value:.3g} {what}; the limit is {limit:g}: {advice}, or set "
                                 f"run.override_limits = true")
    return estimate


def check_sintering_every(scene, steps):
    """Refuse ``sintering.every`` above a run's ``steps`` (its step count, or an upper estimate of it): the necks
    grow only at the end of each interval of ``every`` steps, so such a run grows none."""
    every = scene.get("sintering", {}).get("every", 1)
    if every > steps and "neck_rtol" not in scene.get("sintering", {}):  # paced intervals start at one step
        raise SceneError(f"sintering.every = {every} steps is more than the run's {steps} steps (run.duration "
                         f"{scene['run']['duration']:g} s): no neck would grow; lower sintering.every or lengthen "
                         "run.duration")


RAMP_STEP_FRACTION = 0.1
"""A growth interval (``sintering.every`` time steps; one without ``[sintering]``) spans at most this fraction of a
step of a ``[preheating]`` ramp: each level is resolved in ten intervals (necks grow over an interval at the mean of
its start and end temperatures, so the interval that straddles a level's edge takes the mean of two levels)."""


def ramp_step(scene) -> float | None:
    """The step (s) in which a growth interval spans :data:`RAMP_STEP_FRACTION` of a step of the scene's
    ``[preheating]`` ramp (``preheating.duration / preheating.steps``); None without a ramp."""
    if "preheating" not in scene:
        return None
    ramp = scene["preheating"]
    every = scene["sintering"]["every"] if "sintering" in scene else 1  # a growth interval spans every steps
    return RAMP_STEP_FRACTION * ramp["duration"] / ramp["steps"] / every


WALL_STEP_FRACTION = 0.1
"""A moving wall advances at most this fraction of the smallest radius per automatic step (no tunnelling)."""


BEAM_STEP_FRACTION = 0.2
"""A beam's spot advances at most this fraction of its radius per automatic step (the spot is resolved)."""


def advance_speed(wall) -> float:
    """The speed (m/s) at which a scene wall (``[[walls]]`` table) advances into the packing; 0 if it recedes."""
    inward = 1.0 if wall["side"] == "min" else -1.0
    return max(inward * float(wall["velocity"][wall["axis"]]), 0.0)


def beam_step(beam) -> float | None:
    """The step (s) in which the beam's spot moves :data:`BEAM_STEP_FRACTION` of its radius; None for a spot that
    does not move (no speed, or a path of one point or of coincident points)."""
    path = beam["path"]
    if not beam["speed"] > 0 or all(p == path[0] for p in path):
        return None
    return BEAM_STEP_FRACTION * beam["spot_radius"] / beam["speed"]


def _mechanical_step_estimate(scene, r, wall_speed=0.0):
    """:func:`sintercond.laws.forces.contact_time_step` of two of the smallest spheres meeting at
    ``physics.impact_velocity`` plus ``wall_speed`` (s): Eq. 47 and the symplectic-Euler bounds (erratum 8).

    The estimate :func:`estimate_run` counts steps with; the run's own step
    (:func:`sintercond.sim.mechanics.mechanical_time_step`) takes every listed pair
    and wall (a wall contact is stiffer: about 0.8 of this).
    """
    m, physics = scene["mechanics"], scene["physics"]
    e, nu = m["young_modulus"], m["poisson_ratio"]
    mass = scene["material"]["density"] * 4 / 3 * math.pi * r**3
    friction = m["friction"] > 0 or m["wall_friction"] > 0
    rolling = m["rolling_friction"] > 0 or m["wall_rolling_friction"] > 0
    xi_con = restitution_damping_ratio(m["restitution"]) if "restitution" in m else m["damping"]
    return float(_contact_step(physics["shear"])(
        r, mass, e, nu, physics["impact_velocity"] + wall_speed, xi_con,
        m["tangential_damping"] if friction else 0.0, m["rolling_damping"] if rolling else 0.0))


@functools.cache
def _contact_step(shear):
    """Jitted time step of two equal spheres ``(r, m, E, nu, v, xi_con, xi_fric, xi_rol)`` (one compile, not ~50
    dispatched ops)."""
    import jax

    from sintercond.laws import forces

    def step(r, mass, e, nu, v, xi_con, xi_fric, xi_rol):
        g_star = forces.effective_shear_modulus(e, nu, e, nu, shear)
        return forces.contact_time_step(r / 2, mass / 2, forces.effective_modulus(e, nu, e, nu), g_star, v,
                                       xi_con=xi_con, xi_fric=xi_fric, xi_rol=xi_rol)

    return jax.jit(step)

