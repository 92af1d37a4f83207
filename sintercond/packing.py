"""Random sphere packings: gravity deposition, then settling under gravity.

A powder bed is built in two steps:

1. :func:`deposit_spheres` drops spheres one by one at random lateral
   positions onto the floor or the pile (ballistic deposition, NumPy): no
   overlaps, every sphere resting on one support.
2. :func:`relax_under_gravity` lets the pile settle: damped dynamics of
   gravity plus stiff harmonic repulsion between overlapping spheres and with
   the floor and side walls, polished by FIRE (``jax_md.minimize.fire_descent``),
   so spheres roll into stable positions resting on several neighbours. Contacts
   end up as small overlaps (the weight of the pile over the stiffness,
   ~1e-3 of a radius by default), which :func:`sintercond.geometry.contacts`
   counts as contacts.

:func:`powder_bed` does both and :func:`rev_box` cuts a cubic representative
volume out of the bed's interior, away from floor and walls, as Rizza &
Galati (2024, Sect. 3.3) did for their 150 um PB cube with 45-150 um
particles.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from sintercond.neighbors import jax_md_guard, jax_md_modules


@dataclasses.dataclass(frozen=True)
class Packing:
    """Spheres in a container.

    Attributes:
      centres: ``[n, 3]`` (length); ``z`` up, floor at ``z = 0``.
      radii: ``[n]`` (length).
      container: ``(lo, hi)`` corners of the lateral walls and floor; ``hi[2]``
        is the top of the pile.
      max_overlap: largest sphere-sphere overlap over the sum of radii.
    """

    centres: np.ndarray
    radii: np.ndarray
    container: tuple
    max_overlap: float


def sample_diameters(n, low, high, rng):
    """Diameters with a uniform *volume* distribution on ``[low, high]`` (number density ~ d^-3).

    Mass-weighted uniform sizes are how sieved powder fractions (e.g. 45-150 um
    for PBF-EB) are usually specified; the number distribution is then skewed
    to the small end.
    """
    u = rng.uniform(0.0, 1.0, n)
    # inverse CDF of p(d) ~ d^-3 on [low, high]
    return 1.0 / np.sqrt(1.0 / low**2 - u * (1.0 / low**2 - 1.0 / high**2))


def deposit_spheres(radii, lateral_size, rng):
    """Ballistic deposition without rolling; returns centres ``[n, 3]``."""
    radii = np.asarray(radii, dtype=np.float64)
    centres = np.zeros((len(radii), 3))
    for k, r in enumerate(radii):
        x, y = rng.uniform(r, lateral_size - r, 2)
        z = r
        if k:
            lateral = np.hypot(centres[:k, 0] - x, centres[:k, 1] - y)
            reach = radii[:k] + r
            hit = lateral < reach
            if hit.any():
                z = max(z, float(np.max(centres[:k][hit, 2] + np.sqrt(reach[hit] ** 2 - lateral[hit] ** 2))))
        centres[k] = (x, y, z)
    return centres


def relax_under_gravity(centres, radii, lateral_size, steps=30_000, stiffness=1e4, damping=1.0, polish_steps=5_000):
    """Let spheres settle under gravity; returns the settled centres.

    Damped dynamics (semi-implicit Euler, viscous damping ``damping``) of
    gravity plus harmonic repulsion from overlapping spheres, the floor and
    the side walls, then FIRE (``jax_md.minimize.fire_descent``) to remove the
    last kinetic energy. Plain FIRE from a loose start is far slower: its
    global velocity resets stall free fall whenever any pair collides.
    Lengths are scaled by the mean radius inside, masses by the cube of the
    radius; ``stiffness`` is the contact stiffness over the weight of a mean
    sphere per radius, so overlaps are of order (spheres above) / stiffness
    radii.
    """
    scale = float(np.mean(radii))
    r = jnp.asarray(radii / scale)
    size = lateral_size / scale
    mass = r**3
    n = r.shape[0]
    off_diagonal = ~jnp.eye(n, dtype=bool)

    def energy(positions):
        diff = positions[:, None, :] - positions[None, :, :]
        d2 = jnp.sum(diff**2, axis=-1)
        d = jnp.sqrt(jnp.where(off_diagonal, d2, 1.0))
        overlap = jnp.where(off_diagonal, jnp.maximum(r[:, None] + r[None, :] - d, 0.0), 0.0)
        pair = 0.25 * stiffness * jnp.sum(overlap**2)  # each pair counted twice
        x, y, z = positions[:, 0], positions[:, 1], positions[:, 2]
        walls = (jnp.maximum(r - z, 0.0) ** 2 + jnp.maximum(r - x, 0.0) ** 2 + jnp.maximum(x + r - size, 0.0) ** 2
                 + jnp.maximum(r - y, 0.0) ** 2 + jnp.maximum(y + r - size, 0.0) ** 2)
        return pair + 0.5 * stiffness * jnp.sum(walls) + jnp.sum(mass * z)

    force = jax.grad(lambda x: -energy(x))
    # stable for the lightest sphere: dt < 2 sqrt(m_min / k); a quarter of it
    dt = 0.5 * float(np.sqrt(np.min(np.asarray(mass)) / stiffness))

    def damped_step(carry, _):
        x, v = carry
        v = v + dt * (force(x) / mass[:, None] - damping * v)
        return (x + dt * v, v), None

    minimize, space = jax_md_modules("minimize", "space")
    _, shift = space.free()
    init, apply = minimize.fire_descent(energy, shift, dt_start=dt, dt_max=4 * dt)

    @jax.jit
    def run(x):
        (x, _), _ = jax.lax.scan(damped_step, (x, jnp.zeros_like(x)), None, length=steps)
        state = jax.lax.fori_loop(0, polish_steps, lambda _, s: apply(s), init(x))
        return state.position

    with jax_md_guard():  # jax-md's minimizers rely on implicit int/float promotion
        settled = run(jnp.asarray(centres / scale))
    return np.asarray(settled) * scale


def powder_bed(lateral_size, height, diameter_range=(45.0, 150.0), seed=0, steps=30_000):
    """A settled random bed of polydisperse spheres filling a container to about ``height``.

    Args:
      lateral_size: side of the square container (length).
      height: bed height to fill (length); spheres are added until the
        deposited pile reaches it.
      diameter_range: ``(low, high)`` diameters, uniform by volume.
      seed: random seed (the result is reproducible).
      steps: damped-dynamics steps of the settling.

    Returns:
      :class:`Packing`.
    """
    low, high = diameter_range
    if not (0 < low <= high < lateral_size):
        raise ValueError(f"diameter_range must satisfy 0 < low <= high < lateral_size; got {diameter_range}")
    rng = np.random.default_rng(seed)
    mean_volume = np.mean(np.pi / 6 * sample_diameters(4096, low, high, rng) ** 3)
    n = int(np.ceil(0.62 * lateral_size**2 * height / mean_volume))
    radii = sample_diameters(n, low, high, rng) / 2
    centres = relax_under_gravity(deposit_spheres(radii, lateral_size, rng), radii, lateral_size, steps=steps)
    i, j = np.triu_indices(n, 1)
    d = np.linalg.norm(centres[i] - centres[j], axis=1)
    overlap = float(np.max((radii[i] + radii[j] - d) / (radii[i] + radii[j])))
    top = float(np.max(centres[:, 2] + radii))
    container = (np.zeros(3), np.array([lateral_size, lateral_size, top]))
    return Packing(centres, radii, container, overlap)


def rev_box(packing: Packing, size, floor_clearance=None):
    """A cube of side ``size`` centred laterally, starting ``floor_clearance`` above the floor.

    Returns ``(centres, radii, box)`` of the spheres that intersect the cube,
    ready for :func:`sintercond.geometry.rev_measures`. The default clearance
    is the largest diameter, to stay clear of the floor's ordering.
    """
    lo_c, hi_c = packing.container
    clearance = 2 * float(np.max(packing.radii)) if floor_clearance is None else float(floor_clearance)
    centre_xy = 0.5 * (lo_c[:2] + hi_c[:2])
    lo = np.array([centre_xy[0] - size / 2, centre_xy[1] - size / 2, clearance])
    hi = lo + size
    if np.any(lo[:2] < lo_c[:2]) or np.any(hi > hi_c):
        raise ValueError(f"a cube of size {size} at height {clearance} does not fit in the bed {hi_c - lo_c}")
    nearest = np.clip(packing.centres, lo, hi)
    touching = np.linalg.norm(packing.centres - nearest, axis=1) < packing.radii
    return packing.centres[touching], packing.radii[touching], (lo, hi)
