"""Who touches whom: jax-md neighbour lists wrapped once, per-pair history, host contact searches.

Three tools, from the fastest path to the reference:

* :func:`neighbor_list`: a jax-md Dense neighbour list with a skin, for
  packings whose particles move. Candidates are the pairs closer than
  ``2 r_max + skin`` (``2 r_max`` is the largest contact distance); the list
  is rebuilt under ``jit`` only once some particle has moved more than half
  the skin since the last rebuild (jax-md's ``dr_threshold``), so most steps
  pay only a displacement check. A list that outgrows its capacity sets a
  flag (:func:`did_buffer_overflow`); the host reallocates and redoes the
  chunk. Per-pair quantities of a Dense table (a neck, a contact age)
  follow the pair through rebuilds and reallocations with
  :func:`remap_pair_history`.
* :func:`half_pairs`: the pairs the contact laws run on, each ``i < j``
  once, kept within ``r_i + r_j + skin`` (size-aware) and sorted by
  ``(i, j)``, rebuilt from the Dense list whenever it is rebuilt, in a
  fixed-capacity buffer with its own overflow flag
  (:func:`half_pairs_overflowed`). Per-pair values (the springs) follow
  with :func:`remap_half_pairs`; :func:`pair_sum` adds a per-pair value to
  one end and its opposite to the other, so forces and heat are conserved
  by construction.
* :func:`cell_list_pairs`: the contacts of a static packing on the host, in
  vectorised NumPy (a cell list, no per-particle Python loop, no compile).
* :func:`brute_force_pairs`: the O(n^2) reference for tests.

jax-md is imported only here, under :func:`jax_md_guard`: jax-md 0.2.29
relies on implicit dtype promotion and scatters int64 into int32 buffers
under x64 (a FutureWarning of JAX); we run float64 with strict promotion in
tests and warnings as errors. Float64 positions stay float64 through every
jax-md call (jax-md casts its box to float32, never the positions).

Contact criterion everywhere: spheres ``i, j`` touch when
``|c_i - c_j| <= (r_i + r_j)(1 + tolerance)``, distances minimum-image in a
periodic box.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import warnings
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from sintercond.state import pytree_dataclass

CANDIDATE_MARGIN = 1e-6
"""Relative margin on the contact range ``2 r_max`` of :func:`neighbor_list`:
pairs touching within this relative gap are always candidates."""


@contextlib.contextmanager
def jax_md_guard():
    """Context for every jax-md call (trace time is enough): standard promotion, its own warning muted."""
    with jax.numpy_dtype_promotion("standard"), warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="scatter inputs have incompatible types", category=FutureWarning)
        yield


def jax_md_modules(*names):
    """jax-md submodules by name (e.g. ``"partition", "space"``), imported under :func:`jax_md_guard`.

    Its import-time code (``rigid_body``) relies on implicit int/float promotion.
    """
    import importlib

    with jax_md_guard():
        return tuple(importlib.import_module(f"jax_md.{name}") for name in names)


def minimum_image(delta, periodic_box=None):
    """Minimum-image separations ``[..., 3]`` (m) in a periodic box of sides ``[3]`` (m); unchanged if None."""
    if periodic_box is None:
        return delta
    return delta - periodic_box * np.round(delta / periodic_box)


# --------------------------------------------------------------------------
# dynamic neighbour list (jax-md, Dense format)


class NeighborListFns(NamedTuple):
    """A skinned Dense neighbour list for contacts (see :func:`neighbor_list`).

    Attributes:
      allocate: ``(positions [n, 3], extra_capacity=0) -> NeighborList``
        (host, not jit-able): sizes the buffer from these positions times
        ``capacity_multiplier``, plus ``extra_capacity`` slots per row.
      update: ``(positions [n, 3], nbrs) -> nbrs`` (jit-able): rebuilds only
        once a particle moved more than ``skin / 2`` since the last rebuild.
      cutoff: the contact range ``2 r_max (1 + CANDIDATE_MARGIN)`` (m).
      skin: the Verlet skin (m); candidates lie within ``cutoff + skin``.
      capacity_multiplier: spare capacity of each allocation (also of the
        half pair list, :func:`allocate_half_pairs`).
    """

    allocate: Callable
    update: Callable
    cutoff: float
    skin: float
    capacity_multiplier: float = 1.25


def neighbor_list(radii, skin, box_lo=None, box_hi=None, periodic_box=None, capacity_multiplier=1.25):
    """A jax-md Dense neighbour list of contact candidates, rebuilt only when the skin is used up.

    ``nbrs.idx`` is ``[n, m]`` int32, padded with ``n`` (jax-md's convention).
    Positions are passed as they are (m); the list shifts them by ``box_lo``
    or wraps them into the periodic box before handing them to jax-md, so
    ``nbrs.reference_position`` holds those shifted positions.

    Args:
      radii: ``[n]`` particle radii (m); the contact range is ``2 max(radii)``.
      skin: Verlet skin (m), >= 0. The list holds the pairs closer than
        ``2 r_max + skin`` at its last rebuild and is rebuilt once any
        particle moved ``skin / 2``; 0 rebuilds at every update.
      box_lo, box_hi: ``[3]`` corners (m) of the region of the cell list, for
        free boundaries. Particles that leave it are still found (jax-md's
        cells wrap around and the distances are free-space), at the price of
        crowded cells and, eventually, an overflow flag.
      periodic_box: ``[3]`` side lengths (m) of a periodic box (instead of
        ``box_lo``/``box_hi``); distances are minimum-image.
      capacity_multiplier: spare capacity of each allocation, >= 1.

    Returns:
      :class:`NeighborListFns`.
    """
    radii = np.asarray(radii, dtype=np.float64)
    if not (np.isfinite(skin) and skin >= 0):
        raise ValueError(f"skin must be finite and >= 0, got {skin!r}")
    if not capacity_multiplier >= 1.0:
        raise ValueError(f"capacity_multiplier must be >= 1, got {capacity_multiplier!r}")
    if radii.ndim != 1 or len(radii) == 0 or not np.all(radii > 0):
        raise ValueError("radii must be a non-empty [n] array of positive values")
    if (periodic_box is None) == (box_lo is None or box_hi is None):
        raise ValueError("give either box_lo and box_hi (free boundaries) or periodic_box")
    partition, space = jax_md_modules("partition", "space")
    cutoff = 2.0 * float(radii.max()) * (1.0 + CANDIDATE_MARGIN)
    if periodic_box is None:
        lo, hi = np.asarray(box_lo, dtype=np.float64), np.asarray(box_hi, dtype=np.float64)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(hi > lo):
            raise ValueError("box_lo and box_hi must be [3] with box_hi > box_lo")
        box = hi - lo
        displacement, _ = space.free()
        shift_lo = jnp.asarray(lo)

        def to_box(positions):
            return positions - shift_lo.astype(positions.dtype)
    else:
        box = np.asarray(periodic_box, dtype=np.float64)
        if box.shape != (3,) or not np.all(box > 0):
            raise ValueError("periodic_box must be [3] positive side lengths")
        displacement, _ = space.periodic(jnp.asarray(box))
        box_j = jnp.asarray(box)

        def to_box(positions):
            return jnp.mod(positions, box_j.astype(positions.dtype))

    with jax_md_guard():
        fns = partition.neighbor_list(displacement, jnp.asarray(box), cutoff, dr_threshold=float(skin),
                                      capacity_multiplier=float(capacity_multiplier),
                                      format=partition.NeighborListFormat.Dense)

    def allocate(positions, extra_capacity=0):
        positions = jnp.asarray(positions)
        with jax_md_guard():
            return _kept_dtype(fns.allocate(to_box(positions), extra_capacity=int(extra_capacity)), positions)

    def update(positions, nbrs):
        with jax_md_guard():
            return _kept_dtype(fns.update(to_box(positions), nbrs), positions)

    return NeighborListFns(allocate, update, cutoff, float(skin), float(capacity_multiplier))


def _kept_dtype(nbrs, positions):
    """``nbrs``, after checking (at trace time) that jax-md kept the positions' float dtype."""
    if nbrs.reference_position.dtype != positions.dtype:
        raise TypeError(f"jax-md turned {positions.dtype} positions into {nbrs.reference_position.dtype}")
    return nbrs


def did_buffer_overflow(nbrs):
    """Scalar bool (jit-able): the list or its cell list ran out of capacity; reallocate and redo."""
    return nbrs.did_buffer_overflow != 0


def did_rebuild(before, after):
    """Scalar bool (jit-able): ``update`` rebuilt the list between ``before`` and ``after``.

    A rebuild stores the new positions as the reference; a skipped one keeps
    the old. (With ``skin = 0`` a rebuild at unchanged positions reads as
    False; it changed nothing.)
    """
    return jnp.any(after.reference_position != before.reference_position)


def remap_pair_history(old_idx, new_idx, values, fill=0):
    """Carry per-pair values from one neighbour table to another, pair by pair (jit-able).

    For each row ``i`` and slot ``k`` of ``new_idx``, the old slot of row ``i``
    holding the same neighbour gives the value; a pair absent from the old
    table, and every padding slot, gets ``fill``. Padding is either ``n``
    (jax-md) or the row's own index (:class:`sintercond.network.ContactTable`).
    The tables may differ in width (a reallocation). As JaxDEM's
    ``_remap_history_array`` and LAMMPS' ``fix neigh/history`` do.

    Args:
      old_idx: ``[n, m_old]`` int neighbour table the values belong to.
      new_idx: ``[n, m_new]`` int neighbour table to carry them to.
      values: ``[n, m_old, ...]`` per-pair values (any trailing shape, e.g. a
        ``[3]`` tangential spring).
      fill: value of new pairs and padding.

    Returns:
      ``[n, m_new, ...]`` values, dtype of ``values``.
    """
    old_idx, new_idx, values = jnp.asarray(old_idx), jnp.asarray(new_idx), jnp.asarray(values)
    n, m_old = old_idx.shape
    rows = jnp.arange(n, dtype=new_idx.dtype)[:, None]
    # search each new neighbour in its sorted old row: O(n m log m), no [n, m, m] array
    order = jnp.argsort(old_idx, axis=1)
    sorted_old = jnp.take_along_axis(old_idx, order, axis=1)
    at = jax.vmap(jnp.searchsorted)(sorted_old, new_idx.astype(old_idx.dtype))
    at = jnp.minimum(at, m_old - 1)
    real = (new_idx != n) & (new_idx != rows)
    found = real & (jnp.take_along_axis(sorted_old, at, axis=1) == new_idx.astype(old_idx.dtype))
    carried = values[rows, jnp.take_along_axis(order, at, axis=1)]
    found = found.reshape(found.shape + (1,) * (values.ndim - 2))
    return jnp.where(found, carried, jnp.asarray(fill, dtype=values.dtype))


# --------------------------------------------------------------------------
# half pair list (each pair once), fed by the Dense list


@pytree_dataclass
class HalfPairs:
    """Each contact candidate once: the pairs a contact law is evaluated on.

    Attributes:
      pairs: ``[capacity, 2]`` int32 ``(i, j)`` with ``i < j``, sorted by
        ``(i, j)``; the unused tail is padding ``(n, n)``.
      demand: int32 scalar, the most pairs any build since the allocation
        kept; above ``capacity`` the list overflowed (pairs were dropped):
        :func:`half_pairs_overflowed`, and the host reallocates from it.
    """

    pairs: Any
    demand: Any

    @property
    def capacity(self) -> int:
        return self.pairs.shape[0]


def _kept_neighbors(idx, positions, radii, skin):
    """``[n, m]`` rows of ``idx`` keeping ``j > i`` within ``r_i + r_j + skin`` (ascending; ``n`` after them)."""
    n = radii.shape[0]
    rows = jnp.arange(n, dtype=idx.dtype)[:, None]
    ahead = (idx < n) & (idx > rows)
    j = jnp.where(ahead, idx, rows)
    delta = positions[j] - positions[:, None, :]
    # between two rebuilds each particle moves at most skin / 2 (jax-md's threshold, rounded in float32):
    # a pair beyond r_i + r_j + skin at the rebuild cannot touch before the next one
    reach = (radii[:, None] + radii[j] + skin) * (1.0 + CANDIDATE_MARGIN)
    keep = ahead & (jnp.sum(delta * delta, axis=-1) < reach * reach)
    return jnp.sort(jnp.where(keep, idx, n), axis=1)


def half_pairs(idx, positions, radii, skin, capacity, demand=0) -> HalfPairs:
    """The half pair list of a Dense table at ``positions`` (jit-able; build it when the table is rebuilt).

    Keeps each pair ``i < j`` of ``idx`` whose centres are closer than
    ``(r_i + r_j + skin)(1 + CANDIDATE_MARGIN)`` (size-aware, as LAMMPS'
    granular lists: with a polydisperse packing far fewer pairs than the
    Dense list's ``2 r_max + skin``), sorted by ``(i, j)`` so that the
    order of the pairs, and of every sum over them, does not depend on the
    Dense table's layout or on the capacity.

    Args:
      idx: ``[n, m]`` int32 Dense table (padding ``n``), e.g. ``nbrs.idx``.
      positions: ``[n, 3]`` (m), the positions ``idx`` was built at.
      radii: ``[n]`` (m).
      skin: the list's Verlet skin (m).
      capacity: static int, the rows of the result.
      demand: the previous list's ``demand`` (kept if larger).

    Returns:
      :class:`HalfPairs`; ``demand > capacity`` flags an overflow.
    """
    n, m = idx.shape
    kept = _kept_neighbors(idx, positions, radii, skin)
    real = kept < n
    count = jnp.sum(real, dtype=jnp.int32)
    flat = jnp.nonzero(real.ravel(), size=capacity, fill_value=n * m)[0].astype(idx.dtype)
    inside = flat < n * m
    i = jnp.where(inside, flat // max(m, 1), n)
    j = jnp.where(inside, jnp.append(kept.ravel(), n)[flat], n)  # flat == n m: the appended padding
    return HalfPairs(jnp.stack([i, j], axis=1).astype(jnp.int32), jnp.maximum(count, jnp.asarray(demand, jnp.int32)))


def half_pair_count(idx, positions, radii, skin) -> int:
    """Pairs :func:`half_pairs` keeps from ``idx`` at ``positions`` (host)."""
    return int(jnp.sum(_kept_neighbors(jnp.asarray(idx), jnp.asarray(positions), jnp.asarray(radii), skin)
                       < radii.shape[0]))


def allocate_half_pairs(idx, positions, radii, skin, capacity_multiplier=1.25, minimum=1) -> HalfPairs:
    """A :func:`half_pairs` list sized on the host: ``capacity_multiplier`` times the pairs kept now (at least ``minimum``)."""
    capacity = max(int(math.ceil(capacity_multiplier * half_pair_count(idx, positions, radii, skin))), int(minimum), 1)
    return half_pairs(jnp.asarray(idx), jnp.asarray(positions), jnp.asarray(radii), skin, capacity)


def half_pairs_overflowed(half: HalfPairs):
    """Scalar bool (jit-able): a build kept more pairs than the list holds; reallocate and redo."""
    return half.demand > half.capacity


def padded_half_pairs(half: HalfPairs, capacity: int, n: int) -> HalfPairs:
    """``half`` with room for ``capacity`` pairs (>= its own): padding ``(n, n)`` appended (host)."""
    extra = capacity - half.capacity
    if extra < 0:
        raise ValueError(f"capacity {capacity} is below the list's {half.capacity}")
    pad = jnp.full((extra, 2), n, half.pairs.dtype)
    return HalfPairs(jnp.concatenate([half.pairs, pad]), half.demand)


def remap_half_pairs(old_pairs, new_pairs, values, fill=0):
    """Carry per-pair values from one half pair list to another by ``(i, j)`` identity (jit-able).

    Both lists sorted by ``(i, j)`` (:func:`half_pairs`): each new pair is
    found by a lexicographic binary search in the old list
    (``O(capacity log capacity)``, no integer key that could overflow);
    a pair absent from the old list, and padding (``i == j``), gets
    ``fill``. The lists may differ in capacity (a reallocation).

    Args:
      old_pairs: ``[c_old, 2]`` pairs the values belong to.
      new_pairs: ``[c_new, 2]`` pairs to carry them to.
      values: ``[c_old, ...]`` (e.g. ``[c_old, 3]`` tangential springs).

    Returns:
      ``[c_new, ...]`` values, dtype of ``values``.
    """
    old_pairs, new_pairs, values = jnp.asarray(old_pairs), jnp.asarray(new_pairs), jnp.asarray(values)
    c_old = old_pairs.shape[0]
    oi, oj, ni, nj = old_pairs[:, 0], old_pairs[:, 1], new_pairs[:, 0], new_pairs[:, 1]

    def bisect(_, bounds):
        lo, hi = bounds
        mid = (lo + hi) // 2
        at = jnp.minimum(mid, c_old - 1)
        before = (oi[at] < ni) | ((oi[at] == ni) & (oj[at] < nj))
        active = lo < hi
        return jnp.where(active & before, mid + 1, lo), jnp.where(active & ~before, mid, hi)

    lo = jnp.zeros(ni.shape, jnp.int32)
    lo, _ = jax.lax.fori_loop(0, max(c_old, 1).bit_length() + 1, bisect, (lo, jnp.full_like(lo, c_old)))
    at = jnp.minimum(lo, max(c_old - 1, 0))
    found = (ni < nj) & (lo < c_old) & (oi[at] == ni) & (oj[at] == nj)
    found = found.reshape(found.shape + (1,) * (values.ndim - 1))
    return jnp.where(found, values[at], jnp.asarray(fill, values.dtype))


def pair_sum(on_i, on_j, pairs, n):
    """``[n, ...]``: per-pair values scattered to both ends, ``on_i`` to ``pairs[:, 0]``, ``on_j`` to ``pairs[:, 1]``.

    With ``on_j = -on_i`` (a force, a heat flow) the total is zero to
    round-off by construction. Padding pairs (index ``n``) are dropped.
    The additions run in pair order, so sorted lists give sums independent
    of the capacity.
    """
    out = jnp.zeros((n,) + on_i.shape[1:], jnp.result_type(on_i, on_j))
    return out.at[pairs[:, 0]].add(on_i, mode="drop").at[pairs[:, 1]].add(on_j, mode="drop")


# --------------------------------------------------------------------------
# host contact searches (NumPy, float64)


def _empty_pairs():
    return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)


def _touching(positions, radii, i, j, tolerance, periodic_box):
    """Mask of the candidate pairs ``(i, j)`` that touch (the contact criterion of this module)."""
    delta = minimum_image(positions[i] - positions[j], periodic_box)
    distance = np.linalg.norm(delta, axis=1)
    return distance <= (radii[i] + radii[j]) * (1.0 + tolerance)


def brute_force_pairs(positions, radii, tolerance=1e-9, periodic_box=None, chunk=2048):
    """Every touching pair by testing all ``n (n - 1) / 2`` pairs: the reference for tests.

    Args:
      positions: ``[n, 3]`` centres (m). radii: ``[n]`` (m).
      tolerance: relative gap still counted as contact.
      periodic_box: ``[3]`` side lengths (m), or None for free boundaries.
      chunk: rows tested at a time (memory ``chunk * n``).

    Returns:
      ``(i, j)``: ``[n_pairs]`` int64 arrays, ``i < j``, sorted by ``(i, j)``.
    """
    positions = np.asarray(positions, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    box = None if periodic_box is None else np.asarray(periodic_box, dtype=np.float64)
    n = len(radii)
    found_i, found_j = [], []
    for start in range(0, n, chunk):
        rows = np.arange(start, min(start + chunk, n))
        delta = minimum_image(positions[rows, None, :] - positions[None, :, :], box)
        distance = np.linalg.norm(delta, axis=-1)
        touch = distance <= (radii[rows, None] + radii[None, :]) * (1.0 + tolerance)
        touch &= np.arange(n)[None, :] > rows[:, None]
        a, b = np.nonzero(touch)
        found_i.append(rows[a])
        found_j.append(b)
    if not found_i:
        return _empty_pairs()
    return np.concatenate(found_i).astype(np.int64), np.concatenate(found_j).astype(np.int64)


def _cell_offsets(dims, periodic):
    """Neighbour-cell offsets ``[k, 3]`` and whether they are a half shell (each cell pair met once).

    A half shell (self + 13) needs three distinct neighbours per axis; a
    periodic box of one or two cells along an axis gets the distinct offsets
    modulo its cells, each cell pair met from both sides.
    """
    if not periodic or np.all(dims >= 3):
        full = np.array(list(itertools.product((-1, 0, 1), repeat=3)))
        return full[[tuple(o) >= (0, 0, 0) for o in full]], True  # lexicographically forward, self first
    per_axis = [sorted({o % int(d) for o in (-1, 0, 1)}) for d in dims]
    return np.array(list(itertools.product(*per_axis))), False


def cell_list_pairs(positions, radii, tolerance=1e-9, periodic_box=None, budget=1 << 22):
    """Every touching pair, from a NumPy cell list: vectorised, no compile.

    Cells have sides of at least the largest contact distance
    ``2 r_max (1 + tolerance)``; particles are sorted by cell, and for each
    neighbour-cell offset the candidates of every particle are the contiguous
    range of its neighbour cell in that order (``searchsorted`` and
    ``np.repeat``), confirmed with the float64 contact criterion. Candidates
    are generated in chunks of about ``budget`` pairs (memory ~100 B each).

    Args:
      positions: ``[n, 3]`` centres (m). radii: ``[n]`` (m).
      tolerance: relative gap still counted as contact.
      periodic_box: ``[3]`` side lengths (m), or None for free boundaries.
      budget: candidate pairs per chunk.

    Returns:
      ``(i, j)``: ``[n_pairs]`` int64 arrays, ``i < j``, sorted by ``(i, j)``;
      the same pairs as :func:`brute_force_pairs`.
    """
    positions = np.asarray(positions, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    box = None if periodic_box is None else np.asarray(periodic_box, dtype=np.float64)
    n = len(radii)
    if n < 2:
        return _empty_pairs()
    # the largest contact distance, widened so that rounding never pushes a
    # touching pair two cells apart
    side = 2.0 * float(radii.max()) * (1.0 + tolerance) * (1.0 + 1e-9)
    if box is None:
        lo = positions.min(axis=0)
        dims = np.floor((positions.max(axis=0) - lo) / side).astype(np.int64) + 1
        cell = np.minimum(np.floor((positions - lo) / side).astype(np.int64), dims - 1) + 1
        dims = dims + 2  # an empty layer around: neighbour cells never wrap into another row
    else:
        dims = np.maximum(np.floor(box / side).astype(np.int64), 1)
        wrapped = np.mod(positions, box)
        cell = np.minimum(np.floor(wrapped / (box / dims)).astype(np.int64), dims - 1)
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    cells, first, count = np.unique(sorted_key, return_index=True, return_counts=True)
    offsets, half_shell = _cell_offsets(dims, box is not None)
    # work in cell order: neighbours are close in memory
    pos_s, radii_s, cell_s = positions[order], radii[order], cell[order]
    found_i, found_j = [], []
    for offset in offsets:
        other = cell_s + offset
        if box is not None:
            other %= dims
        other_key = (other[:, 0] * dims[1] + other[:, 1]) * dims[2] + other[:, 2]
        at = np.minimum(np.searchsorted(cells, other_key), len(cells) - 1)
        hit = cells[at] == other_key
        start = np.where(hit, first[at], 0)
        size = np.where(hit, count[at], 0)
        same_cell = not np.any(offset) if half_shell else True  # pairs met twice: keep a < b
        ends = np.cumsum(size)
        # split the particles where the running candidate count crosses the budget
        cuts = np.searchsorted(ends, np.arange(budget, int(ends[-1]) + budget, budget), side="right")
        for a0, a1 in zip(np.concatenate([[0], cuts]), np.concatenate([cuts, [n]])):
            if a1 <= a0:
                continue
            sizes = size[a0:a1]
            total = int(sizes.sum())
            if total == 0:
                continue
            a = np.repeat(np.arange(a0, a1), sizes)
            b = np.repeat(start[a0:a1] - (np.cumsum(sizes) - sizes), sizes) + np.arange(total)
            if same_cell:
                keep = a < b
                a, b = a[keep], b[keep]
            touch = _touching(pos_s, radii_s, a, b, tolerance, box)
            found_i.append(order[a[touch]])
            found_j.append(order[b[touch]])
    if not found_i:
        return _empty_pairs()
    i, j = np.concatenate(found_i), np.concatenate(found_j)
    i, j = np.minimum(i, j), np.maximum(i, j)
    pair_order = np.argsort(i * n + j)
    return i[pair_order], j[pair_order]
