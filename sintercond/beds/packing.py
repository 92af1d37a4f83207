"""Random sphere packings: sampled sizes, gravity deposition, lattices, and the beds built on them, checked.

A powder bed is built in one of three ways (``method``, :data:`METHODS`):

- ``"roll"`` (the default): :func:`sintercond.beds.rolling.roll_deposit` drops the
  spheres one by one and lets each roll down the pile to a stable rest on
  three supports or the floor (sequential deposition with rolling, in closed
  form, O(n): a 1e4-sphere bed in seconds). The bed is a stable frictional
  powder's: solid fraction ~0.6, coordination ~5.4-5.5, its contacts at the
  relative overlap :data:`ROLL_OVERLAP`.
- ``"relax"``: :func:`deposit_spheres` drops spheres one by one at random
  lateral positions onto the floor or the pile (ballistic deposition, NumPy,
  on a lateral bin grid) and keeps the lowest of :data:`DEPOSIT_TRIES` drops
  of each (solid fraction ~0.45, about 1.4 times the asked height); the pile
  then collapses without friction under gravity,
  :func:`sintercond.beds.settle.relax_under_gravity` (damped harmonic contacts),
  into a denser random packing (~0.66). Its damped dynamics take ~1e5 steps
  whatever the bed's width (a 1e4-sphere bed ~15 min on two cores).
- ``"dem"`` (:func:`pour`): the real thermo-mechanical DEM,
  :func:`sintercond.beds.settle.dem_settle`, settles a rolled, relaxed or
  ballistic deposit; the bed keeps its :class:`sintercond.beds.settle.SettleReport`
  (``packing.settle``).

A pile that has not settled raises :class:`PackingError`; it is never
returned half-fallen.

Everything here runs in float64 (NumPy, and JAX inside ``jax.enable_x64``)
whatever precision the thermal model uses: the packing of a scene does not
depend on ``SINTERCOND_ENABLE_X64``.

:func:`powder_bed` does both and reports the bed (height, packing fraction,
coordination, isolated particles); :func:`rev_box` cuts a cubic
representative volume out of the bed's interior, away from floor and walls,
as Rizza & Galati (2024, Sect. 3.3) did for their 150 um PB cube with
45-150 um particles.

The settling moved to :mod:`sintercond.beds.settle` (issue 24); its names still
resolve from here for one release, with a ``DeprecationWarning``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sintercond._validation import shown
from sintercond.beds import rolling as _rolling
from sintercond.beds import settle as _settle
from sintercond._deprecation import old_names
from sintercond.beds.settle import PackingError
from sintercond.sim.steady import face_layer_box

FILL_FRACTION = 0.62
"""Solid fraction assumed to size a bed: ``n = FILL_FRACTION L^2 H / mean volume`` spheres."""

DEPOSIT_TRIES = 16
"""Lateral positions :func:`powder_bed` tries for each sphere of its deposit (:func:`deposit_spheres`): the lowest is
kept (a 3,290-sphere bed: solid fraction 0.44 instead of 0.17, 167k relax steps instead of 437k)."""

MAX_PARTICLES = 20_000
"""Largest bed :func:`powder_bed` settles by ``"relax"`` or ``"dem"`` (their settling time grows with it; a scene
refuses beyond)."""

MAX_ROLLED_PARTICLES = 1_000_000
"""Largest bed :func:`powder_bed` builds by ``"roll"`` (O(n): ~2 ms a sphere on one core)."""

ROLL_OVERLAP = 1e-4
"""Relative overlap ``1 - d / (r_i + r_j)`` at which a rolled sphere rests on its supports (and on the floor and
walls, over its radius): the contacts' small overlaps, as a relaxed bed's (median 8e-5, mean 1.4e-4 of the sum of
radii on the 3,290-sphere bed of ``benchmarks/bed_build.py``), so the pipe network sees them."""

_DEFAULT_MATERIAL = _settle.DemMaterial()
"""The contact material of a pour unless one is given: Example 5.3's (:class:`sintercond.beds.settle.DemMaterial`)."""


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
      residual_force: largest net force on a sphere over its weight at the end of the settling (NaN for a
        rolled bed: each sphere came to rest on its supports when it was placed; nothing is integrated).
      settle: the :class:`sintercond.beds.settle.SettleReport` of a DEM settle (``method="dem"``), else None.
      roll: the :class:`sintercond.beds.rolling.RollReport` of a rolled bed (``method="roll"``), else None.
      settled: the :class:`sintercond.beds.settle.DemSettled` state a DEM settle ended in (velocities, spins and the
        springs of its contacts and walls: what a run with the mechanics continues), else None.
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
    settle: _settle.SettleReport | None = None
    roll: _rolling.RollReport | None = None
    settled: _settle.DemSettled | None = dataclasses.field(default=None, compare=False, repr=False)

    def summary(self) -> dict:
        """The bed's figures as a flat dict (for a run summary); a DEM bed adds its
        :class:`sintercond.beds.settle.SettleReport`'s."""
        figures = {"particles": len(self.radii), "bed_height_m": self.height, "bed_top_m": float(self.container[1][2]),
                   "packing_fraction": self.packing_fraction, "coordination": self.coordination,
                   "isolated_particles": self.isolated}
        return figures if self.settle is None else {**figures, **self.settle.summary()}


def sample_diameters(n, low, high, rng):
    """Diameters with a uniform *volume* distribution on ``[low, high]`` (number density ~ d^-3).

    Mass-weighted uniform sizes are how sieved powder fractions (e.g. 45-150 um
    for PBF-EB) are usually specified; the number distribution is then skewed
    to the small end.
    """
    u = rng.uniform(0.0, 1.0, n)
    # inverse CDF of p(d) ~ d^-3 on [low, high]
    return 1.0 / np.sqrt(1.0 / low**2 - u * (1.0 / low**2 - 1.0 / high**2))


def check_radius_distribution(mean, std, truncation=3.0):
    """Raise :class:`PackingError` unless N(mean, std) truncated at ``truncation`` std gives only positive radii."""
    if not (np.isfinite(mean) and np.isfinite(std) and std >= 0 and np.isfinite(truncation) and truncation > 0):
        raise PackingError(f"radius distribution: need finite mean, std >= 0 and truncation > 0; got mean={mean!r}, "
                           f"std={std!r}, truncation={truncation!r}")
    if mean - truncation * std <= 0:
        raise PackingError(f"radius distribution: mean - truncation * std = {mean - truncation * std:.4g} must be > 0 "
                           "(every radius positive)")


def truncated_normal_radii(n, mean, std, truncation=3.0, seed=0):
    """``[n]`` radii from N(mean, std) truncated at ``truncation`` standard deviations (redrawn outside).

    Quintana-Ruiz & Campello (2020), Example 5.3: N(3 mm, 0.667 mm) truncated
    at 3 sigma. ``seed``: an int or a NumPy ``Generator``. Raises
    :class:`PackingError` unless ``0 <= std``, ``truncation > 0`` and every
    radius the truncation allows is positive (``mean - truncation std > 0``).
    """
    check_radius_distribution(mean, std, truncation)
    rng = np.random.default_rng(seed)
    radii = rng.normal(mean, std, n)
    outside = np.abs(radii - mean) > truncation * std
    while outside.any():
        radii[outside] = rng.normal(mean, std, int(outside.sum()))
        outside = np.abs(radii - mean) > truncation * std
    return radii


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
        if (isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer))
                or not math.isfinite(value) or value <= 0):
            raise PackingError(f"{names[key]} must be a finite number > 0 (length); got {shown(value)}")
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


def deposit_spheres(radii, lateral_size, rng, tries=1):
    """Ballistic deposition without rolling; returns centres ``[n, 3]``.

    Each sphere in turn falls vertically at ``tries`` random lateral positions and stays at the lowest place
    where it first touches the floor or a sphere already down (``tries=1``: plain ballistic deposition, a pile of
    solid fraction ~0.17; more tries fill the pile's hollows: ~0.44 with 16). The spheres it may touch come from
    a lateral bin grid (bins at least a largest diameter wide, so the 3 x 3 bins around a position hold every
    sphere within reach): O(n), and the same centres as the search over all spheres down.
    """
    radii = np.asarray(radii, dtype=np.float64)
    n = len(radii)
    centres = np.zeros((n + 1, 3))
    centres[n, :2] = np.inf  # the padding sphere: never within reach
    r_ext = np.append(radii, 0.0)
    bins = max(1, int(lateral_size // (2.0 * float(np.max(radii, initial=0.0)) * (1.0 + 1e-9))))
    width = lateral_size / bins
    members = np.full((bins * bins, 16), n)
    counts = np.zeros(bins * bins, np.int64)
    around = np.arange(-1, 2)
    for k, r in enumerate(radii):
        xy = rng.uniform(r, lateral_size - r, (tries, 2))
        cell = np.minimum((xy / width).astype(np.int64), bins - 1)
        bx = np.clip(cell[:, 0, None] + around, 0, bins - 1)
        by = np.clip(cell[:, 1, None] + around, 0, bins - 1)
        near = members[(bx[:, :, None] * bins + by[:, None, :]).reshape(tries, 9), :int(counts.max())]
        near = near.reshape(tries, -1)
        lateral = np.hypot(centres[near, 0] - xy[:, 0, None], centres[near, 1] - xy[:, 1, None])
        reach = r_ext[near] + r
        hit = lateral < reach
        rest = np.where(hit, centres[near, 2] + np.sqrt(np.where(hit, reach**2 - lateral**2, 0.0)), -np.inf)
        z = np.maximum(r, rest.max(axis=1, initial=-np.inf))
        best = int(np.argmin(z))
        centres[k] = (xy[best, 0], xy[best, 1], z[best])
        home = cell[best, 0] * bins + cell[best, 1]
        if counts[home] == members.shape[1]:
            members = np.concatenate([members, np.full_like(members, n)], axis=1)
        members[home, counts[home]] = k
        counts[home] += 1
    return centres[:n]


def surface_height(centres, radii, lateral_size, points=64) -> float:
    """Mean surface height (m) of a bed in ``[0, L]^2``: the mean over a ``points x points`` lateral grid (cell
    centres) of the highest sphere surface above each grid point (0 where none), :attr:`Packing.height`.

    Each sphere is visited on the grid points of its own footprint only, O(n (2 r points / L)^2)."""
    centres, radii = np.asarray(centres, np.float64), np.asarray(radii, np.float64)
    spacing = lateral_size / points
    best = np.zeros((points, points))
    if len(radii) == 0:
        return 0.0
    # the first grid point at or right of each footprint's edge, one earlier against round-off at the edge
    first = np.clip(np.ceil((centres[:, :2] - radii[:, None]) / spacing - 0.5) - 1, 0, points - 1).astype(np.int64)
    width = int(np.ceil(2.0 * float(np.max(radii)) / spacing)) + 2
    offsets = np.arange(width)
    grid = (np.arange(points) + 0.5) * lateral_size / points
    chunk = max(1, 2**22 // width**2)  # spheres at a time: temporaries of about 4e6 grid points
    for start in range(0, len(radii), chunk):
        c, r, k = centres[start:start + chunk], radii[start:start + chunk], first[start:start + chunk]
        gx = np.minimum(k[:, 0, None] + offsets, points - 1)  # [m, width]; a repeated edge point is harmless
        gy = np.minimum(k[:, 1, None] + offsets, points - 1)
        rho2 = (grid[gx] - c[:, 0, None])[:, :, None] ** 2 + (grid[gy] - c[:, 1, None])[:, None, :] ** 2
        above = np.where(rho2 < r[:, None, None] ** 2,
                         c[:, 2, None, None] + np.sqrt(np.maximum(r[:, None, None] ** 2 - rho2, 0.0)), 0.0)
        np.maximum.at(best, (np.broadcast_to(gx[:, :, None], above.shape), np.broadcast_to(gy[:, None, :], above.shape)),
                      above)
    return float(best.mean())


def bed_box(centres, radii, lateral_size):
    """``(lo, hi)`` (m): the box a powder bed's ``k*`` is measured in (:func:`sintercond.sim.steady.steady_state_conductivity`'s
    ``box``): its container ``[0, L]^2`` laterally, from the floor to its mean surface height (:func:`surface_height`)
    vertically. The particles touching the floor are held hot, those whose surface reaches above the mean surface
    (about half of the top layer) cold, whatever the roughness of the free surface."""
    return np.zeros(3), np.array([lateral_size, lateral_size, surface_height(centres, radii, lateral_size)])


def measurement_box(centres, radii, axis, *, lattice=False, bed_size=None):
    """The box the k* of a packing at ``centres`` (m) is measured in
    (:func:`sintercond.sim.steady.steady_state_conductivity`'s ``box``):
    None for a simple-cubic lattice (its end layers are held); a powder bed of lateral size ``bed_size`` (m), its
    container ``[0, L]^2`` from the floor to the mean surface height (:func:`bed_box`:
    along z the floor's layer is held hot and the particles reaching above the mean surface, about half the top
    layer, cold; across, the layers on two opposite side walls, ``A`` the wall's width times the mean height);
    any other packing, the box of its face layers (:func:`sintercond.sim.steady.face_layer_box`). ``sintercond effective`` and a
    sintering run's ``k_star_W_mK`` both measure in it."""
    if lattice:
        return None
    if bed_size is not None:
        return bed_box(centres, radii, bed_size)
    return face_layer_box(centres, radii, axis)


METHODS = ("roll", "relax", "dem")
"""How :func:`powder_bed` makes its bed: sequential deposition with rolling (the default, O(n)), the frictionless
harmonic relaxation of a ballistic deposit, or the thermo-mechanical DEM (:func:`pour`)."""

STARTS = ("rolled", "relaxed", "deposit")
"""Where a DEM pour starts: the rolled deposit (each sphere at rest on its supports, point contacts), the
harmonically relaxed pile, or the loose ballistic deposit itself."""


def best_fit_deformation(start, now) -> np.ndarray:
    """The homogeneous deformation ``F`` ``[3, 3]`` that best maps a packing's ``start`` centres ``[n, 3]`` (m) onto
    its centres ``now``: ``now_i - <now> ~ F (start_i - <start>)`` in least squares (the best-fit strain of a
    particle assembly, Cundall & Strack's averaging of particle displacements). An axis along which the start has
    no extent (a chain, a layer) keeps ``F``'s identity row and column there: nothing measures it."""
    x0 = np.asarray(start, np.float64) - np.mean(start, axis=0)
    x = np.asarray(now, np.float64) - np.mean(now, axis=0)
    spread = np.sqrt(np.mean(x0**2, axis=0))
    measured = spread > 1e-9 * max(float(np.max(spread, initial=0.0)), np.finfo(np.float64).tiny)
    f = np.eye(3)
    if measured.any():
        m = np.flatnonzero(measured)
        solution, *_ = np.linalg.lstsq(x0[:, m], x[:, m], rcond=None)  # x[:, m] ~ x0[:, m] @ solution
        f[np.ix_(m, m)] = solution.T
    return f


def packing_shrinkage(start, now, axis=2) -> dict:
    """``{"height_shrinkage", "volume_shrinkage"}`` of a packing whose centres moved from ``start`` to ``now``
    ``[n, 3]`` (m), from their :func:`best_fit_deformation` ``F``: ``1 - F[axis, axis]``, the relative loss of height
    along ``axis`` (the build direction, z), and ``1 - det F``, the relative loss of volume (both > 0 as the packing
    shrinks; a rigid motion gives 0)."""
    f = best_fit_deformation(start, now)
    return {"height_shrinkage": float(1.0 - f[axis, axis]), "volume_shrinkage": float(1.0 - np.linalg.det(f))}


def pour(radii, lateral_size, material=_DEFAULT_MATERIAL, seed=0, start="relaxed", temperature=300.0, walls=None,
         progress=None, **settle) -> Packing:
    """Pour spheres into an open square box ``[0, L]^2`` and settle them with the DEM (:func:`sintercond.beds.settle.dem_settle`).

    The spheres are first dropped one by one (:func:`deposit_spheres`, a loose
    pile several times the bed's height). ``start="deposit"``: the DEM settles
    that pile itself (a real pour: the pile collapses under gravity with
    Hertz, Mindlin friction, rolling resistance and the walls; it takes
    ~0.3 s of simulated time, ~1e4-1e5 steps). ``start="relaxed"`` (cheaper):
    the pile is first collapsed by :func:`sintercond.beds.settle.relax_under_gravity` (frictionless
    harmonic contacts), then the DEM settles it from there under the real
    laws; the result meets the same thresholds, but its structure comes from
    a frictionless collapse (denser than a frictional pour would give).

    Args:
      radii: ``[n]`` (m), ``2 max(radii) < lateral_size``.
      lateral_size: box side (m).
      material: :class:`sintercond.beds.settle.DemMaterial` (default: Example 5.3's).
      seed: random seed of the deposit (reproducible).
      start: one of :data:`STARTS`.
      temperature: K, while settling (no heat moves).
      walls: the box's :class:`~sintercond.laws.walls.PlaneWall` s (default :func:`sintercond.beds.settle.box_walls`).
      progress: ``progress(phase, steps, max_steps, figure, target)`` after every chunk of the relaxed start and
        of the DEM settle (:func:`sintercond.beds.settle.relax_under_gravity`,
        :func:`sintercond.beds.settle.dem_settle`), or None.
      settle: keyword arguments of :func:`sintercond.beds.settle.dem_settle` (``kinetic_tol``, ``force_tol``, ``max_time``, ...).

    Returns:
      :class:`Packing` with its :class:`sintercond.beds.settle.SettleReport` (``packing.settle``).

    Raises:
      PackingError: bad input, or a bed that did not settle (naming what missed its threshold).
    """
    return _pour(radii, lateral_size, material, seed, start, temperature, walls, progress, **settle)[0]


def _pour(radii, lateral_size, material, seed, start, temperature, walls, progress=None, **settle):
    """:func:`pour`, also returning the :class:`sintercond.beds.settle.DemSettled` state."""
    if start not in STARTS:
        raise PackingError(f"start must be one of {list(STARTS)}; got {start!r}")
    radii = np.asarray(radii, np.float64)
    if radii.ndim != 1 or len(radii) == 0 or not np.all(np.isfinite(radii) & (radii > 0)):
        raise PackingError("radii must be a non-empty [n] array of finite values > 0 (m)")
    if not (math.isfinite(lateral_size) and 2 * radii.max() < lateral_size):
        raise PackingError(f"lateral_size must exceed the largest diameter {2 * radii.max():g} m; got {lateral_size!r}")
    rng = np.random.default_rng(seed)
    if start == "rolled":
        centres, _ = _rolling.roll_deposit(radii, lateral_size, rng, overlap=0.0)
    else:
        centres = deposit_spheres(radii, lateral_size, rng)
    if start == "relaxed":
        centres, _ = _settle.relax_under_gravity(centres, radii, lateral_size, progress=progress)
        centres[:, 2] = np.maximum(centres[:, 2], radii)  # start off the floor: no sphere inside a wall
        centres[:, :2] = np.clip(centres[:, :2], radii[:, None], lateral_size - radii[:, None])
    walls = _settle.box_walls(lateral_size) if walls is None else tuple(walls)
    if start != "deposit" and "v_rel" not in settle:  # a sphere may drop into a gap: one mean diameter
        settle = {**settle, "v_rel": math.sqrt(2.0 * _settle.GRAVITY * 2.0 * float(np.mean(radii)))}
    settled = _settle.dem_settle(centres, radii, walls, material, temperature, progress=progress, **settle)
    bed = _bed(settled.centres, radii, lateral_size)
    return dataclasses.replace(bed, residual_force=settled.report.force_ratio, settle=settled.report,
                               settled=settled), settled


def _bed(centres, radii, lateral_size) -> Packing:
    """A :class:`Packing` of settled spheres in ``[0, L]^2`` with its figures (height, fraction, coordination)."""
    n = len(radii)
    i, j, real = _settle._pair_list(centres, radii, 0.0)
    i, j = i[real], j[real]
    d = np.linalg.norm(centres[i] - centres[j], axis=1)
    overlap = (radii[i] + radii[j] - d) / (radii[i] + radii[j])
    touching = overlap > 0
    degree = np.bincount(i[touching], minlength=n) + np.bincount(j[touching], minlength=n)
    on_wall = ((centres[:, 2] - radii < 0) | np.any(centres[:, :2] - radii[:, None] < 0, axis=1)
               | np.any(centres[:, :2] + radii[:, None] > lateral_size, axis=1))
    isolated = int(np.sum((degree == 0) & ~on_wall))
    surface = surface_height(centres, radii, lateral_size)
    top = float(np.max(centres[:, 2] + radii))
    fraction = float(np.sum(4.0 / 3.0 * np.pi * radii**3) / (lateral_size**2 * surface))
    container = (np.zeros(3), np.array([lateral_size, lateral_size, top]))
    return Packing(centres, radii, container, float(np.max(overlap, initial=0.0)), surface, fraction,
                   float(2 * np.sum(touching) / n), isolated)


def powder_bed(lateral_size, height, diameter_range=(45.0, 150.0), *, seed=0, max_particles=None,
               height_tolerance=0.25, method="roll", material=None, progress=None, overlap=ROLL_OVERLAP, **settle):
    """A settled random bed of polydisperse spheres filling a square container to about ``height``.

    Args:
      lateral_size: side of the square container (length).
      height: bed height to fill (length), at least the largest diameter; the
        bed gets ``FILL_FRACTION * lateral_size^2 * height`` of solid volume.
      diameter_range: ``(low, high)`` diameters, uniform by volume.
      seed: random seed (the result is reproducible, and the same in float32 and float64 JAX).
      max_particles: refuse beds needing more spheres (default :data:`MAX_ROLLED_PARTICLES` for ``"roll"``,
        :data:`MAX_PARTICLES` for the others).
      height_tolerance: refuse a settled bed whose mean surface height is off
        ``height`` by more than this fraction.
      method: ``"roll"`` (:func:`sintercond.beds.rolling.roll_deposit`, any unit of length), ``"relax"``
        (:func:`sintercond.beds.settle.relax_under_gravity`, any unit of length) or ``"dem"`` (:func:`pour` with
        ``material``, SI units: metres).
      material: :class:`sintercond.beds.settle.DemMaterial` for ``method="dem"`` (default: Example 5.3's).
      progress: ``progress(phase, steps, max_steps, figure, target)`` as the bed is made (spheres down for
        ``"roll"``, steps for the settling ones), or None.
      overlap: the relative overlap of a rolled bed's contacts (``method="roll"``), in ``[0, 0.01]``.
      settle: keyword arguments of :func:`pour` for ``method="dem"`` (``start``, ``kinetic_tol``, ...).

    Returns:
      :class:`Packing`, with its height, packing fraction, coordination and
      isolated spheres (and the :class:`sintercond.beds.rolling.RollReport` for ``"roll"``, the
      :class:`sintercond.beds.settle.SettleReport` for ``"dem"``).

    Raises:
      PackingError: invalid sizes (:func:`check_bed`) or method, or a bed that did not settle.
    """
    if method not in METHODS:
        raise PackingError(f"method must be one of {list(METHODS)}; got {method!r}")
    if settle and method != "dem":
        raise PackingError(f"{sorted(settle)} apply to method='dem' only")
    if method != "roll" and overlap != ROLL_OVERLAP:
        raise PackingError("overlap applies to method='roll' only")
    if max_particles is None:
        max_particles = MAX_ROLLED_PARTICLES if method == "roll" else MAX_PARTICLES
    n = check_bed(lateral_size, height, diameter_range, max_particles)
    low, high = (float(v) for v in diameter_range)
    rng = np.random.default_rng(seed)
    radii = sample_diameters(n, low, high, rng) / 2
    if method == "roll":  # dropped until the surface reaches the height: a rolled bed is looser than FILL_FRACTION
        radii = np.concatenate([radii, sample_diameters(n, low, high, rng) / 2])
        expected = None if progress is None else (  # the count the bed is sized for, not the spare radii
            lambda phase, down, _, figure, target: progress(phase, down, max(n, down), down, max(n, down)))
        centres, report = _rolling.roll_deposit(radii, lateral_size, rng, overlap, progress=expected,
                                                fill_height=height)
        if len(centres) > max_particles:
            raise PackingError(f"the bed needed {len(centres)} spheres to reach height {height:g}; the limit is "
                               f"{max_particles}")
        radii = radii[:len(centres)]
        bed = dataclasses.replace(_bed(centres, radii, lateral_size), roll=report)
    elif method == "dem":
        bed = pour(radii, lateral_size, _settle.DemMaterial() if material is None else material, seed=rng, progress=progress,
                   **settle)
    else:
        centres, residual = _settle.relax_under_gravity(deposit_spheres(radii, lateral_size, rng, DEPOSIT_TRIES), radii,
                                                lateral_size, progress=progress)
        bed = dataclasses.replace(_bed(centres, radii, lateral_size), residual_force=residual)
    if bed.isolated or abs(bed.height / height - 1.0) > height_tolerance:
        raise PackingError(f"the bed settled to a mean height {bed.height:.4g} for height {height:.4g} "
                           f"(allowed within {height_tolerance:.0%}) with {bed.isolated} isolated particles")
    return bed


def from_scene(p, progress=None) -> Packing:
    """The packing of a validated scene's ``[packing]`` table (radii after ``sinter_swelling``).

    ``powder_bed``: :func:`powder_bed` with ``method`` (``"roll"`` by default,
    or ``"dem"`` with the :class:`sintercond.beds.settle.DemMaterial` keys of an optional ``dem``
    table), radii then grown by ``sinter_swelling`` (settled contacts become necks). ``simple_cubic``: centres
    ``radius + spacing * (i, j, k)``, container ``[0, (counts - 1) spacing + 2 radius]``; its packing fraction
    the infinite lattice's (a sphere less the 6 caps its neighbours cut, over the cell ``spacing^3``), its
    coordination this lattice's (bonds between neighbours, the faces' missing ones excluded).
    """
    if p["kind"] == "simple_cubic":
        counts = np.asarray(p["counts"])
        grid = np.array(np.meshgrid(*(np.arange(c) for c in counts), indexing="ij")).reshape(3, -1).T
        centres = grid * p["spacing"] + p["radius"]
        radii = np.full(len(centres), float(p["radius"]))
        hi = (counts - 1) * p["spacing"] + 2 * p["radius"]
        r, a = float(p["radius"]), float(p["spacing"])
        overlap = max(2 * r - a, 0.0) / (2 * r)
        cap = max(r - a / 2, 0.0)  # each of the 6 neighbours cuts a cap of this height off the sphere
        fraction = (4 / 3 * math.pi * r**3 - 6 * math.pi * cap**2 * (3 * r - cap) / 3) / a**3
        bonds = 3 * counts.prod() - (counts[1] * counts[2] + counts[0] * counts[2] + counts[0] * counts[1])
        coordination = 2 * bonds / counts.prod() if 2 * r >= a else 0.0  # touching: point contacts (sintering)
        return Packing(centres, radii, (np.zeros(3), hi), overlap, float(hi[2]), fraction, float(coordination))
    method = p.get("method", "roll")
    material = _settle.DemMaterial(**p["dem"]) if method == "dem" and "dem" in p else None
    bed = powder_bed(p["lateral_size"], p["height"], tuple(p["diameter_range"]), seed=p.get("seed", 0), method=method,
                     material=material, progress=progress)
    return dataclasses.replace(bed, radii=bed.radii * (1.0 + p.get("sinter_swelling", 0.0)))


def rev_box(packing: Packing, size, floor_clearance=None):
    """A cube of side ``size`` centred laterally, starting ``floor_clearance`` above the floor.

    Returns ``(centres, radii, box)`` of the spheres that intersect the cube,
    ready for :func:`sintercond.laws.geometry.rev_measures`. The default clearance
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


# the settling moved to sintercond.beds.settle (issue 24): relaxation and DEM
__getattr__ = old_names("sintercond.beds.packing", {name: ("sintercond.beds.settle", name) for name in (
    "relax_under_gravity", "DemMaterial", "KINETIC_TOL", "FORCE_TOL", "SettleReport", "DemSettled", "box_walls",
    "dem_physics", "GRAVITY", "dem_settle")})
