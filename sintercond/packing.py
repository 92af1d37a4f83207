"""Random sphere packings: gravity deposition, then settling under gravity, checked.

A powder bed is built in two steps:

1. :func:`deposit_spheres` drops spheres one by one at random lateral
   positions onto the floor or the pile (ballistic deposition, NumPy): no
   overlaps, every sphere resting on one support. The pile is loose (solid
   fraction ~0.1), several times the asked height.
2. :func:`relax_under_gravity` lets the pile settle: damped dynamics of
   gravity plus stiff harmonic repulsion between overlapping spheres and with
   the floor and side walls (frictionless, so the pile collapses to a dense
   random packing), on a pair list rebuilt on the host whenever a sphere
   has moved half the skin, until the net force on every sphere is below
   ``force_tol`` of its weight. Contacts end up as small overlaps (the weight
   of the pile over the stiffness, ~1e-3 of a radius), which
   :func:`sintercond.geometry.contacts` counts as contacts. A pile that has
   not settled within the step budget raises :class:`PackingError`; it is
   never returned half-fallen.

Everything here runs in float64 (NumPy, and JAX inside ``jax.enable_x64``)
whatever precision the thermal model uses: the packing of a scene does not
depend on ``SINTERCOND_ENABLE_X64``.

:func:`powder_bed` does both and reports the bed (height, packing fraction,
coordination, isolated particles); :func:`rev_box` cuts a cubic
representative volume out of the bed's interior, away from floor and walls,
as Rizza & Galati (2024, Sect. 3.3) did for their 150 um PB cube with
45-150 um particles.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

FILL_FRACTION = 0.62
"""Solid fraction assumed to size a bed: ``n = FILL_FRACTION L^2 H / mean volume`` spheres."""

MAX_PARTICLES = 20_000
"""Largest bed :func:`powder_bed` builds (memory and settling time grow with it; a scene refuses beyond)."""


class PackingError(ValueError):
    """A bed that cannot be built or did not settle; the message says which quantity and its range."""


@dataclasses.dataclass(frozen=True)
class Packing:
    """Spheres in a container, with what characterises the settled bed.

    Attributes:
      centres: ``[n, 3]`` (length); ``z`` up, floor at ``z = 0``.
      radii: ``[n]`` (length).
      container: ``(lo, hi)`` corners of the lateral walls and floor; ``hi[2]``
        is the top of the pile (highest sphere top).
      max_overlap: largest sphere-sphere overlap over the sum of radii.
      height: mean surface height (length): the highest sphere surface above
        each point of a 64 x 64 lateral grid, averaged (what a profilometer reads).
      packing_fraction: solid volume over ``lateral_size^2 * height``.
      coordination: mean number of sphere-sphere contacts per sphere.
      isolated: spheres touching neither another sphere nor the floor or a wall (0 when settled).
      residual_force: largest net force on a sphere over its weight at the end of the settling.
    """

    centres: np.ndarray
    radii: np.ndarray
    container: tuple
    max_overlap: float
    height: float = math.nan
    packing_fraction: float = math.nan
    coordination: float = math.nan
    isolated: int = 0
    residual_force: float = math.nan

    def summary(self) -> dict:
        """The bed's figures as a flat dict (for a run summary)."""
        return {"particles": len(self.radii), "bed_height_m": self.height, "bed_top_m": float(self.container[1][2]),
                "packing_fraction": self.packing_fraction, "coordination": self.coordination,
                "isolated_particles": self.isolated}


def sample_diameters(n, low, high, rng):
    """Diameters with a uniform *volume* distribution on ``[low, high]`` (number density ~ d^-3).

    Mass-weighted uniform sizes are how sieved powder fractions (e.g. 45-150 um
    for PBF-EB) are usually specified; the number distribution is then skewed
    to the small end.
    """
    u = rng.uniform(0.0, 1.0, n)
    # inverse CDF of p(d) ~ d^-3 on [low, high]
    return 1.0 / np.sqrt(1.0 / low**2 - u * (1.0 / low**2 - 1.0 / high**2))


def mean_sphere_volume(low, high):
    """Mean volume of a sphere whose diameter follows :func:`sample_diameters`: ``(pi/6) E[d^3]``.

    ``E[d^3] = 2 (high - low) / (low^-2 - high^-2)`` for ``p(d) ~ d^-3``; ``low^3`` when ``low = high``.
    """
    if high <= low:
        return math.pi / 6 * low**3
    return math.pi / 6 * 2.0 * (high - low) / (low**-2 - high**-2)


def bed_particle_count(lateral_size, height, diameter_range):
    """Number of spheres :func:`powder_bed` uses for a bed of this size (``FILL_FRACTION`` of the volume)."""
    low, high = diameter_range
    return int(math.ceil(FILL_FRACTION * lateral_size**2 * height / mean_sphere_volume(low, high)))


def check_bed(lateral_size, height, diameter_range, max_particles=MAX_PARTICLES, names=None):
    """Raise :class:`PackingError` naming the quantity unless a bed of this size can be built; returns ``n``.

    Rules: all finite and > 0; ``low <= high < lateral_size``; ``height >= high``
    (at least one layer of the largest spheres); at most ``max_particles`` spheres.
    ``names`` maps ``lateral_size``, ``height``, ``diameter_range`` to the
    names the message uses (e.g. scene keys).
    """
    names = {"lateral_size": "lateral_size", "height": "height", "diameter_range": "diameter_range", **(names or {})}
    for key, value in (("lateral_size", lateral_size), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                or not math.isfinite(value) or value <= 0:
            raise PackingError(f"{names[key]} must be a finite number > 0 (length); got {value!r}")
    try:
        low, high = (float(v) for v in diameter_range)
    except (TypeError, ValueError):
        raise PackingError(f"{names['diameter_range']} must be two numbers [low, high]; got {diameter_range!r}") from None
    if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high < lateral_size):
        raise PackingError(f"{names['diameter_range']} must satisfy 0 < low <= high < {names['lateral_size']} "
                           f"({lateral_size:g}); got {list(diameter_range)}")
    if height < high:
        raise PackingError(f"{names['height']} must be >= the largest diameter {high:g} (one layer); got {height:g}")
    n = bed_particle_count(lateral_size, height, (low, high))
    if n > max_particles:
        raise PackingError(f"a bed of {names['lateral_size']} {lateral_size:g}, {names['height']} {height:g} and "
                           f"{names['diameter_range']} {[low, high]} needs {n} particles; the limit is "
                           f"{max_particles} (make the bed smaller or the particles larger)")
    return n


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


def _pair_list(x, r, skin, capacity=0):
    """Pairs ``i < j`` closer than ``r_i + r_j + skin`` (NumPy, blocks of rows), padded to a power of two."""
    n = len(r)
    rows, cols = [], []
    for start in range(0, n, 512):
        block = slice(start, min(start + 512, n))
        d2 = np.sum((x[block, None, :] - x[None, :, :]) ** 2, axis=-1)
        reach = r[block, None] + r[None, :] + skin
        i, j = np.nonzero(d2 < reach**2)
        i = i + start
        keep = i < j
        rows.append(i[keep])
        cols.append(j[keep])
    i, j = np.concatenate(rows), np.concatenate(cols)
    size = max(capacity, 1 << max(int(len(i)) - 1, 1).bit_length())
    pad = size - len(i)
    mask = np.concatenate([np.ones(len(i), bool), np.zeros(pad, bool)])
    return np.concatenate([i, np.zeros(pad, int)]), np.concatenate([j, np.zeros(pad, int)]), mask


def _net_force(x, v, r, mass, i, j, mask, size, stiffness, contact_damping):
    """Gravity (g = 1) plus damped harmonic repulsion of overlapping pairs, floor and side walls, ``[n, 3]``.

    Each contact is a spring ``stiffness * overlap`` and a normal dashpot
    ``2 zeta sqrt(stiffness m*)`` (``zeta = contact_damping``, ``m*`` the reduced
    mass; the walls take the sphere's mass): impacts lose energy, as they must
    for a pile to come to rest with a finite time step.
    """
    d = x[i] - x[j]
    dist2 = jnp.sum(d**2, axis=1)
    safe = jnp.where(dist2 > 0, dist2, 1.0)
    n_ij = d / jnp.sqrt(safe)[:, None]
    in_contact = mask & (dist2 > 0) & (r[i] + r[j] > jnp.sqrt(safe))
    overlap = jnp.where(in_contact, r[i] + r[j] - jnp.sqrt(safe), 0.0)
    m_star = mass[i] * mass[j] / (mass[i] + mass[j])
    closing = jnp.sum((v[i] - v[j]) * n_ij, axis=1)
    dashpot = jnp.where(in_contact, 2.0 * contact_damping * jnp.sqrt(stiffness * m_star) * closing, 0.0)
    f = (stiffness * overlap - dashpot)[:, None] * n_ij
    force = jnp.zeros_like(x).at[i].add(f).at[j].add(-f)
    gamma = (2.0 * contact_damping * jnp.sqrt(stiffness * mass))[:, None]
    lo = r[:, None] - x  # > 0: overlaps the floor (z) or the x = 0, y = 0 walls, pushed +
    hi = (x + r[:, None] - size).at[:, 2].set(-1.0)  # > 0: overlaps a far wall, pushed -; no lid
    force = force + jnp.where(lo > 0, stiffness * lo - gamma * v, 0.0) - jnp.where(hi > 0, stiffness * hi + gamma * v, 0.0)
    return force.at[:, 2].add(-mass)


@jax.jit
def _damped_chunk(x, v, r, mass, i, j, mask, size, stiffness, damping, contact_damping, dt, steps):
    def step(_, carry):
        x, v = carry
        force = _net_force(x, v, r, mass, i, j, mask, size, stiffness, contact_damping)
        v = v + dt * (force / mass[:, None] - damping * v)
        return x + dt * v, v

    x_new, v_new = jax.lax.fori_loop(0, steps, step, (x, v))  # steps traced: one compilation per capacity
    static = _net_force(x_new, jnp.zeros_like(v_new), r, mass, i, j, mask, size, stiffness, contact_damping)
    residual = jnp.max(jnp.linalg.norm(static, axis=1) / mass)
    moved = jnp.max(jnp.linalg.norm(x_new - x, axis=1))
    return x_new, v_new, residual, moved


def relax_under_gravity(centres, radii, lateral_size, max_steps=None, stiffness=None, damping=0.3, contact_damping=0.3,
                        force_tol=2e-3, skin=1.0):
    """Let spheres settle under gravity; returns ``(settled centres, residual force over weight)``.

    Damped dynamics (semi-implicit Euler, viscous damping ``damping`` per unit
    time) of gravity plus damped harmonic contacts (:func:`_net_force`) with
    the other spheres, the floor and the side walls, in float64 whatever the JAX default. Lengths are scaled by
    the mean radius inside, masses by the cube of the radius, gravity is 1;
    ``stiffness`` is the contact stiffness over the weight of a mean sphere per
    radius (default ``1e4`` per ten layers of the pile), so overlaps are about
    (layers above) / stiffness radii. The pair list holds pairs within
    ``skin`` mean radii of contact and is rebuilt whenever a sphere may have
    moved half of it. Stops when the net force on every sphere is below
    ``force_tol`` of its weight.

    Raises:
      PackingError: the pile did not settle within ``max_steps`` (default:
        enough for the pile to fall its own height three times and settle).
    """
    radii = np.asarray(radii, dtype=np.float64)
    scale = float(np.mean(radii))
    r_np = radii / scale
    x_np = np.asarray(centres, dtype=np.float64) / scale
    size = float(lateral_size) / scale
    top = float(np.max(x_np[:, 2] + r_np))
    if stiffness is None:
        stiffness = 1e4 * max(1.0, top / 20.0)
    # stable for the lightest sphere with 12 contacts: springs need dt sqrt(12 k / m) < 2, dashpots
    # dt 12 (2 zeta sqrt(k m / 2)) / m < 2; dt = sqrt(m_min / k) / 4 keeps both below 1.3
    dt = 0.25 * float(np.sqrt(np.min(r_np**3) / stiffness))
    if max_steps is None:  # terminal speed g / damping: fall the pile's height three times, then 200 damping times
        max_steps = int((3 * top / (1.0 / damping) + 200.0 / damping) / dt)
    with jax.enable_x64(True):
        r, mass = jnp.asarray(r_np), jnp.asarray(r_np**3)
        x, v = jnp.asarray(x_np), jnp.zeros((len(r_np), 3), jnp.float64)
        args = tuple(jnp.float64(a) for a in (size, stiffness, damping, contact_damping, dt))
        done, capacity, residual = 0, 0, math.inf
        chunk = 64
        while done < max_steps:
            i, j, mask = _pair_list(np.asarray(x), r_np, skin, capacity)
            capacity = len(i)
            x_new, v_new, residual, moved = _damped_chunk(x, v, r, mass, jnp.asarray(i), jnp.asarray(j),
                                                          jnp.asarray(mask), *args, jnp.int32(chunk))
            if float(moved) > 0.5 * skin and chunk > 1:  # a pair may have been missed: redo it shorter
                chunk //= 2
                continue
            x, v, done = x_new, v_new, done + chunk
            residual = float(residual)
            if residual < force_tol:
                break
            chunk = min(2 * chunk, 4096) if float(moved) < 0.2 * skin else chunk
        settled = np.asarray(x) * scale
    if not residual < force_tol:
        raise PackingError(f"the bed did not settle within {max_steps} steps: the largest net force is "
                           f"{residual:.3g} of a sphere's weight (allowed < {force_tol:g})")
    return settled, residual


def _surface_height(centres, radii, lateral_size, points=64):
    """Mean over a lateral grid of the highest sphere surface above each point (0 where none)."""
    g = (np.arange(points) + 0.5) * lateral_size / points
    gx, gy = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    best = np.zeros(len(gx))
    for start in range(0, len(radii), 1024):
        c, r = centres[start:start + 1024], radii[start:start + 1024]
        rho2 = (gx[:, None] - c[None, :, 0]) ** 2 + (gy[:, None] - c[None, :, 1]) ** 2
        above = np.where(rho2 < r**2, c[None, :, 2] + np.sqrt(np.maximum(r**2 - rho2, 0.0)), 0.0)
        best = np.maximum(best, above.max(axis=1))
    return float(best.mean())


def powder_bed(lateral_size, height, diameter_range=(45.0, 150.0), seed=0, max_particles=MAX_PARTICLES,
               height_tolerance=0.25):
    """A settled random bed of polydisperse spheres filling a square container to about ``height``.

    Args:
      lateral_size: side of the square container (length).
      height: bed height to fill (length), at least the largest diameter; the
        bed gets ``FILL_FRACTION * lateral_size^2 * height`` of solid volume.
      diameter_range: ``(low, high)`` diameters, uniform by volume.
      seed: random seed (the result is reproducible, and the same in float32 and float64 JAX).
      max_particles: refuse beds needing more spheres.
      height_tolerance: refuse a settled bed whose mean surface height is off
        ``height`` by more than this fraction.

    Returns:
      :class:`Packing`, with its height, packing fraction, coordination and isolated spheres.

    Raises:
      PackingError: invalid sizes (:func:`check_bed`), or a bed that did not settle.
    """
    n = check_bed(lateral_size, height, diameter_range, max_particles)
    low, high = (float(v) for v in diameter_range)
    rng = np.random.default_rng(seed)
    radii = sample_diameters(n, low, high, rng) / 2
    centres, residual = relax_under_gravity(deposit_spheres(radii, lateral_size, rng), radii, lateral_size)
    i, j, real = _pair_list(centres, radii, 0.0)
    i, j = i[real], j[real]
    d = np.linalg.norm(centres[i] - centres[j], axis=1)
    overlap = (radii[i] + radii[j] - d) / (radii[i] + radii[j])
    touching = overlap > 0
    degree = np.bincount(i[touching], minlength=n) + np.bincount(j[touching], minlength=n)
    on_wall = ((centres[:, 2] - radii < 0) | np.any(centres[:, :2] - radii[:, None] < 0, axis=1)
               | np.any(centres[:, :2] + radii[:, None] > lateral_size, axis=1))
    isolated = int(np.sum((degree == 0) & ~on_wall))
    surface = _surface_height(centres, radii, lateral_size)
    top = float(np.max(centres[:, 2] + radii))
    fraction = float(np.sum(4.0 / 3.0 * np.pi * radii**3) / (lateral_size**2 * surface))
    if isolated or abs(surface / height - 1.0) > height_tolerance:
        raise PackingError(f"the bed settled to a mean height {surface:.4g} for height {height:.4g} "
                           f"(allowed within {height_tolerance:.0%}) with {isolated} isolated particles")
    container = (np.zeros(3), np.array([lateral_size, lateral_size, top]))
    return Packing(centres, radii, container, float(np.max(overlap, initial=0.0)), surface, fraction,
                   float(2 * np.sum(touching) / n), isolated, residual)


def from_scene(p) -> Packing:
    """The packing of a validated scene's ``[packing]`` table (radii after ``sinter_swelling``).

    ``powder_bed``: :func:`powder_bed`, radii then grown by ``sinter_swelling``
    (settled contacts become necks). ``simple_cubic``: centres
    ``radius + spacing * (i, j, k)``, container ``[0, (counts - 1) spacing + 2 radius]``.
    """
    if p["kind"] == "simple_cubic":
        counts = np.asarray(p["counts"])
        grid = np.array(np.meshgrid(*(np.arange(c) for c in counts), indexing="ij")).reshape(3, -1).T
        centres = grid * p["spacing"] + p["radius"]
        radii = np.full(len(centres), float(p["radius"]))
        hi = (counts - 1) * p["spacing"] + 2 * p["radius"]
        overlap = max(2 * p["radius"] - p["spacing"], 0.0) / (2 * p["radius"])
        return Packing(centres, radii, (np.zeros(3), hi), overlap, float(hi[2]))
    bed = powder_bed(p["lateral_size"], p["height"], tuple(p["diameter_range"]), seed=p.get("seed", 0))
    return dataclasses.replace(bed, radii=bed.radii * (1.0 + p.get("sinter_swelling", 0.0)))


def rev_box(packing: Packing, size, floor_clearance=None):
    """A cube of side ``size`` centred laterally, starting ``floor_clearance`` above the floor.

    Returns ``(centres, radii, box)`` of the spheres that intersect the cube,
    ready for :func:`sintercond.geometry.rev_measures`. The default clearance
    is the largest diameter, to stay clear of the floor's ordering. The cube
    must fit inside the container and below the bed's mean surface height
    (``packing.height``; the highest sphere top if that is unknown), so that
    it holds bulk powder, not the rough surface.
    """
    lo_c, hi_c = packing.container
    clearance = 2 * float(np.max(packing.radii)) if floor_clearance is None else float(floor_clearance)
    centre_xy = 0.5 * (lo_c[:2] + hi_c[:2])
    lo = np.array([centre_xy[0] - size / 2, centre_xy[1] - size / 2, clearance])
    hi = lo + size
    top = packing.height if math.isfinite(packing.height) else hi_c[2]
    if np.any(lo[:2] < lo_c[:2]) or np.any(hi[:2] > hi_c[:2]) or hi[2] > top:
        raise ValueError(f"a cube of size {size} at height {clearance} does not fit in the bed "
                         f"({hi_c[0] - lo_c[0]:g} x {hi_c[1] - lo_c[1]:g}, mean surface height {top:g})")
    nearest = np.clip(packing.centres, lo, hi)
    touching = np.linalg.norm(packing.centres - nearest, axis=1) < packing.radii
    return packing.centres[touching], packing.radii[touching], (lo, hi)
