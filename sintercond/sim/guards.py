"""Run-time guards of the coupled step: the host refuses a state the explicit step was not sized for.

The automatic mechanical step (:func:`sintercond.sim.mechanics.mechanical_time_step`)
is sized for a largest normal approach speed ``v_rel``: Eq. 47's collision
duration and the symplectic-Euler bounds at the overlap of a collision at
that speed (Quintana-Ruiz & Campello 2020; MECHANICS.md erratum 8). A run
that meets faster contacts, or whose step is unstable for another reason,
goes on silently wrong: overlaps too deep to resolve, particles blown apart,
kinetic energy from nowhere. :func:`motion_guard` returns a ``check(state)``
for :func:`sintercond.rollout.advance` that, after every compiled chunk,

1. measures the largest normal approach speed of every listed pair (touching
   or within the Verlet skin) and of every particle within one radius of a
   wall, and refuses a state where it exceeds the sizing speed, or where an
   overlap is deeper than :data:`sintercond.simulate.MAX_INITIAL_OVERLAP` of
   the smaller radius (Hertz's small-strain law has left its domain: a wall
   driven through a soft particle);
2. balances the mechanical energy when no wall moves: kinetic plus Hertz
   elastic energy (:func:`sintercond.laws.forces.hertz_elastic_energy`, at the
   current, possibly softened, moduli) minus gravity's work since the start
   may not exceed the energy at the start by more than
   :data:`ENERGY_TOLERANCE` of the energies involved. Damping and friction
   only dissipate, so only an unstable step (or a source the model has not
   got) breaks it.

Both are sampled at chunk ends (the outputs of ``sintercond run``), on the
host: a contact that comes and goes between two samples is not seen, but an
unstable step is, since its energy keeps growing. Tangential and rolling
springs are left out of the balance (they start at zero and store at most the
friction-limited fraction of the normal energy). Moving walls do work, so
with them only the approach speed is checked.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from sintercond import simulate
from sintercond.laws import forces
from sintercond.sim import mechanics

ENERGY_TOLERANCE = 0.25
"""Allowed excess of the mechanical energy over its start, as a fraction of the energies involved (the
symplectic-Euler energy error and the springs left out stay well below it; an unstable step grows past it)."""


class UnstableStep(FloatingPointError):
    """The coupled step met a state its time step was not sized for (see :func:`motion_guard`)."""


class MotionFigures(NamedTuple):
    """What the guards read of a state (SI units)."""

    kinetic: float  # J, translational and rotational
    elastic: float  # J, Hertz energy of the touching pairs and wall contacts
    gravity_potential: float  # J, -sum_i m_i g . x_i
    approach: float  # m/s, the largest normal approach speed of a listed pair or a wall contact
    where: str  # which pair or wall contact approaches fastest
    depth: float = 0.0  # the deepest overlap as a fraction of the smaller radius (of the particle, on a wall)
    deepest: str = "no contact"  # which contact that is


def motion_figures(physics: simulate.Physics, state: simulate.SimState, params: simulate.Params) -> MotionFigures:
    """:class:`MotionFigures` of a coupled state (host arrays; the half pair list's pairs and the walls)."""
    p, motion = state.particles, state.mechanics
    x, r, m = (np.asarray(a, np.float64) for a in (p.positions, p.radii, p.mass))
    v, omega = np.asarray(motion.velocity, np.float64), np.asarray(motion.spin, np.float64)
    n = len(r)
    mp = params.mechanics
    modulus = np.asarray(mechanics.particle_modulus(physics.mechanics, mp, p.temperature, p.material), np.float64)
    nu = np.broadcast_to(np.atleast_1d(np.asarray(mp.nu, np.float64))[np.asarray(p.material)], (n,))
    inertia = forces.SOLID_SPHERE_INERTIA * m * r**2
    kinetic = 0.5 * float(np.sum(m * np.sum(v * v, axis=1)) + np.sum(inertia * np.sum(omega * omega, axis=1)))
    gravity = -float(np.sum(m * (x @ np.asarray(physics.mechanics.gravity, np.float64))))
    pairs = np.asarray(state.contacts.pairs.pairs)
    real = pairs[:, 0] < pairs[:, 1]
    pairs = pairs[real]
    i, j = pairs[:, 0], pairs[:, 1]
    separation = x[j] - x[i]
    distance = np.linalg.norm(separation, axis=1)
    normal = separation / np.where(distance > 0, distance, 1.0)[:, None]
    overlap = r[i] + r[j] - distance
    if motion.neck_overlap is not None:  # a sintered neck's approach is not elastic (simulate.sintered_geometry)
        overlap = overlap - np.asarray(motion.neck_overlap, np.float64)[real]
    e_star = np.asarray(forces.effective_modulus(modulus[i], nu[i], modulus[j], nu[j]))
    elastic = float(np.sum(np.asarray(forces.hertz_elastic_energy(overlap, forces.effective_radius(r[i], r[j]),
                                                                    e_star))))
    closing = np.sum((v[i] - v[j]) * normal, axis=1)
    fastest, where = 0.0, "no contact"
    depth, deepest = 0.0, "no contact"
    if len(overlap):
        relative = overlap / np.minimum(r[i], r[j])
        k = int(np.argmax(relative))
        if relative[k] > 0:
            depth, deepest = float(relative[k]), f"particles {int(i[k])} and {int(j[k])}"
    if len(closing) and closing.max() > 0:
        k = int(np.argmax(closing))
        fastest, where = float(closing[k]), f"particles {int(i[k])} and {int(j[k])}"
    t = float(state.time)
    for w, wall in enumerate(physics.mechanics.walls):
        wall_normal = np.asarray(wall.normal, np.float64)
        wall_velocity = np.asarray(wall.velocity, np.float64)
        h = r - (x - (np.asarray(wall.point, np.float64) + t * wall_velocity)) @ wall_normal
        e_wall = modulus / (1.0 - nu**2)
        elastic += float(np.sum(np.asarray(forces.hertz_elastic_energy(h, r, e_wall))))
        k = int(np.argmax(h / r))
        if h[k] / r[k] > depth:
            depth, deepest = float(h[k] / r[k]), f"particle {k} and wall {w}"
        near = h > -r
        closing = np.where(near, (wall_velocity - v) @ wall_normal, -np.inf)
        if closing.max() > fastest:
            k = int(np.argmax(closing))
            fastest, where = float(closing[k]), f"particle {k} and wall {w}"
    return MotionFigures(kinetic, elastic, gravity, fastest, where, depth, deepest)


def motion_guard(sim: simulate.Simulator, state: simulate.SimState, params: simulate.Params, sized_speed: float,
                 speed_key: str = "v_rel"):
    """A ``check(state)`` for :func:`sintercond.rollout.advance` that refuses what the step was not sized for.

    Args:
      sim, state, params: the coupled simulator, its start state and parameters.
      sized_speed: the approach speed the time step was sized for (m/s).
      speed_key: the name of the setting that sized it, for the message (a scene's
        ``physics.impact_velocity``).

    Returns:
      ``check(state)`` raising :class:`UnstableStep` (after the default finite-temperature check of
      :func:`sintercond.rollout.finite_temperatures`, which the caller composes).
    """
    physics = sim.physics
    if physics.mechanics is None:
        raise ValueError("motion_guard needs a coupled simulator (Physics.mechanics)")
    start = motion_figures(physics, state, params)
    walls_move = any(np.any(np.asarray(w.velocity) != 0) for w in physics.mechanics.walls)

    def check(new: simulate.SimState) -> None:
        now = motion_figures(physics, new, params)
        step = int(new.step)
        if not (np.isfinite(now.kinetic) and np.isfinite(now.approach)):
            raise UnstableStep(f"non-finite velocities at step {step}; the time step is unstable: raise {speed_key} "
                               "or lower the time step")
        if now.depth > simulate.MAX_INITIAL_OVERLAP:
            raise UnstableStep(
                f"at step {step} (t = {float(new.time):.6g} s) the overlap of {now.deepest} reached {now.depth:.3g} "
                f"of the smaller radius, beyond the {simulate.MAX_INITIAL_OVERLAP:g} where Hertz's small-strain law "
                f"holds: the contact is crushed; slow the walls or the particles (a scene's walls[k].velocity, "
                f"{speed_key}) or stiffen the material")
        if now.approach > sized_speed:
            raise UnstableStep(
                f"at step {step} (t = {float(new.time):.6g} s) {now.where} approach at {now.approach:.4g} m/s, above "
                f"the {sized_speed:.4g} m/s the time step was sized for: raise {speed_key} to at least "
                f"{now.approach:.3g} m/s (or lower the time step)")
        if walls_move:
            return
        work = now.gravity_potential - start.gravity_potential
        before = start.kinetic + start.elastic
        after = now.kinetic + now.elastic + work
        scale = before + now.kinetic + now.elastic + abs(work)
        if after > before + ENERGY_TOLERANCE * scale:
            raise UnstableStep(
                f"at step {step} (t = {float(new.time):.6g} s) the kinetic plus elastic energy "
                f"{now.kinetic + now.elastic:.4g} J exceeds what the start ({before:.4g} J) and gravity's work "
                f"({-work:.4g} J) can supply: the time step is unstable; raise {speed_key} (or lower the time step)")

    return check
