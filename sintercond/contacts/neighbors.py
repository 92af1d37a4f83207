"""Who touches whom: skinned Dense neighbour lists, per-pair history, host contact searches.

From the fastest path to the reference:

* :func:`neighbor_list`: a Dense neighbour list (jax-md's format: ``[n, m]``
  rows padded with ``n``) with a skin, for packings whose particles move.
  Candidates are the pairs closer than ``2 r_max + skin`` (``2 r_max`` is
  the largest contact distance); the list is rebuilt under ``jit`` only once
  some particle has moved more than half the skin since the last rebuild
  (jax-md's ``dr_threshold`` test), so most steps pay only a displacement
  check. A rebuild sorts the particles by cell and reads each particle's
  candidates from contiguous runs of that order (:func:`_dense_rows`): the
  same pairs as jax-md's own Dense list (:func:`jax_md_neighbor_list`, kept
  as the reference) at a fraction of its cost, whose build writes, scatters
  and prunes an ``[n, 27 x cell capacity]`` candidate table. A list that
  outgrows its rows or its cell ranges sets a flag
  (:func:`did_buffer_overflow`); the host reallocates and redoes the chunk.
  Per-pair quantities of a Dense table (a neck, a contact age) follow the
  pair through rebuilds and reallocations with :func:`remap_pair_history`.
* The half pair list the contact laws run on (each pair once), built from
  this Dense list, is :mod:`sintercond.contacts.pair_list`.
* :func:`cell_list_pairs`: the contacts of a static packing on the host, in
  vectorised NumPy (a cell list, no per-particle Python loop, no compile).
* :func:`brute_force_pairs`: the O(n^2) reference for tests.

jax-md is imported only here, under :func:`jax_md_guard`: its ``space``
metrics give every distance and skin test of :func:`neighbor_list` (free or
periodic, minimum image), and :func:`jax_md_neighbor_list` wraps its
``partition.neighbor_list``. jax-md 0.2.29 relies on implicit dtype
promotion and scatters int64 into int32 buffers under x64 (a FutureWarning
of JAX); we run float64 with strict promotion in tests and warnings as
errors. Float64 positions stay float64 through every list (jax-md casts its
box to float32, never the positions).

Contact criterion everywhere: spheres ``i, j`` touch when
``|c_i - c_j| <= (r_i + r_j)(1 + tolerance)``, distances minimum-image in a
periodic box.
"""

from __future__ import annotations

import contextlib
import itertools
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
# dynamic neighbour list (Dense format, built from a sorted cell list)


class NeighborListFns(NamedTuple):
    """A skinned Dense neighbour list for contacts (see :func:`neighbor_list`).

    Attributes:
      allocate: ``(positions [n, 3], extra_capacity=0, demand=(0, 0)) ->
        NeighborList`` (host, not jit-able): sizes the buffers from these
        positions (or the ``demand`` of a list that overflowed, if larger)
        times ``capacity_multiplier``, plus ``extra_capacity`` slots per row
        and per cell range.
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


@pytree_dataclass
class NeighborList:
    """A Dense neighbour table and what its rebuilds need (the state of :func:`neighbor_list`).

    Every capacity is the shape of a leaf, so a checkpoint restores it with
    the arrays.

    Attributes:
      idx: ``[n, m]`` int32 neighbours of each particle within ``cutoff +
        skin`` at the last rebuild, each pair on both rows; padding ``n``.
      reference_position: ``[n, 3]`` the positions of the last rebuild, as
        the grid sees them (shifted by ``box_lo`` or wrapped into the
        periodic box; m).
      demand: ``[2]`` int32, the most neighbours of a row and the most
        particles of a cell range any build since the allocation met; above
        the capacities the list overflowed (:func:`did_buffer_overflow`), and
        the host reallocates from them.
      range_slots: ``[s]`` int32 ``0 .. s - 1``: ``s`` particles at most in one
        cell range (a row of five half-reach cells, or one cell in a periodic
        box).
    """

    idx: Any
    reference_position: Any
    demand: Any
    range_slots: Any

    @property
    def did_buffer_overflow(self):
        return (self.demand[0] > self.idx.shape[1]) | (self.demand[1] > self.range_slots.shape[0])

    @property
    def max_occupancy(self) -> int:
        return self.idx.shape[1]


class _Grid(NamedTuple):
    """The static cell grid of a list: ``dims`` cells per axis of side ``cell_size`` (m); the last axis is the
    fastest of the cell key, so a row of cells along it is a contiguous run of the particles sorted by key.
    ``ranges``: offsets ``(d0, d1, d2_lo, d2_hi)`` of the neighbour cell ranges of a cell; ``box``: the
    periodic box's sides (m), or None for free boundaries. Hashable: a static argument of the build."""

    dims: tuple
    cell_size: tuple
    box: tuple | None
    ranges: tuple

    @property
    def periodic(self) -> bool:
        return self.box is not None


def _grid(region, reach, periodic) -> _Grid:
    """The cells of a list with candidates within ``reach`` (m) over ``region`` ``[3]`` (m).

    Free boundaries: cells of side >= ``reach / 2``, and the neighbours of a
    cell are 25 rows of five cells along the last axis (offsets -2..2),
    clamped at the faces: with half-reach cells a row holds few particles
    more than its mean (a lattice packing at most three in a row of five),
    so the fixed slots per row waste little. Periodic: cells of side >=
    ``reach``, each distinct neighbour cell its own range (a box of one or
    two cells along an axis counts each cell once).
    """
    per_reach = 1 if periodic else 2
    dims = np.maximum(np.floor(region / (reach / per_reach * (1.0 + 1e-4))).astype(np.int64), 1)
    cell_size = tuple(float(v) for v in region / dims)
    if periodic:
        offsets, _ = _cell_offsets(dims, periodic=True) if np.any(dims < 3) else (
            np.array(list(itertools.product((-1, 0, 1), repeat=3))), True)
        ranges = np.concatenate([offsets, offsets[:, 2:]], axis=1)
    else:
        rows = np.array(list(itertools.product(range(-per_reach, per_reach + 1), repeat=2)))
        ranges = np.concatenate([rows, np.tile([[-per_reach, per_reach]], (len(rows), 1))], axis=1)
    return _Grid(tuple(int(d) for d in dims), cell_size, tuple(float(v) for v in region) if periodic else None,
                 tuple(tuple(int(v) for v in r) for r in ranges))


def _cell_order(key):
    """The permutation sorting ``key`` ``[n]`` (int32, ascending, ties by index): one sort of ``key n + index``
    in int64 under x64 (XLA sorts one int64 operand faster than a key and its index), else an argsort."""
    n = key.shape[0]
    if not jax.config.jax_enable_x64:
        return jnp.argsort(key).astype(jnp.int32)
    packed = jax.lax.sort(key.astype(jnp.int64) * n + jnp.arange(n, dtype=jnp.int64))
    return (packed % n).astype(jnp.int32)


def _cell_ranges(grid: _Grid, pos_box):
    """Particles sorted by cell, and the neighbour cell ranges of each, in that order (jit-able).

    Returns ``(order [n], start [n, R], size [n, R])``: the particles of range
    ``r`` of the ``a``-th particle in cell order are
    ``order[start[a, r] : start[a, r] + size[a, r]]``.
    """
    d0, d1, d2 = grid.dims
    dims = jnp.asarray(grid.dims, jnp.int32)
    cell = jnp.floor(pos_box / jnp.asarray(grid.cell_size, pos_box.dtype)).astype(jnp.int32)
    cell = jnp.clip(cell, 0, dims - 1)  # free: outside the region, into the face cells (still adjacent)
    key = (cell[:, 0] * d1 + cell[:, 1]) * d2 + cell[:, 2]
    order = _cell_order(key)
    count = jnp.zeros(d0 * d1 * d2, jnp.int32).at[key].add(1)
    upto = jnp.cumsum(count)  # particles in cells <= c
    before = upto - count  # particles in cells < c
    cell = cell[order]
    offsets = jnp.asarray(grid.ranges, jnp.int32)
    o0 = cell[:, None, 0] + offsets[None, :, 0]
    o1 = cell[:, None, 1] + offsets[None, :, 1]
    lo2 = cell[:, None, 2] + offsets[None, :, 2]
    hi2 = cell[:, None, 2] + offsets[None, :, 3]
    if grid.periodic:
        o0, o1, lo2, hi2 = o0 % d0, o1 % d1, lo2 % d2, hi2 % d2
        real = jnp.ones(o0.shape, bool)
    else:
        real = (o0 >= 0) & (o0 < d0) & (o1 >= 0) & (o1 < d1)
        o0, o1 = jnp.clip(o0, 0, d0 - 1), jnp.clip(o1, 0, d1 - 1)
        lo2, hi2 = jnp.maximum(lo2, 0), jnp.minimum(hi2, d2 - 1)
    row = (o0 * d1 + o1) * d2
    start = before[row + lo2]
    size = jnp.where(real, upto[row + hi2] - start, 0)
    return order, start, size


def _metric_sq(grid: _Grid, a, b):
    """Squared distances (m^2) of broadcast ``[..., 3]`` positions of the grid's space: jax-md's own metric
    (``space.free`` / ``space.periodic``, minimum image), one pair at a time."""
    (space,) = jax_md_modules("space")
    a, b = jnp.broadcast_arrays(a, b)
    with jax_md_guard():
        displacement, _ = space.free() if grid.box is None else space.periodic(jnp.asarray(grid.box, a.dtype))
        d2 = jax.vmap(lambda x, y: space.square_distance(displacement(x, y)))(a.reshape(-1, 3), b.reshape(-1, 3))
    return d2.reshape(a.shape[:-1])


def _dense_rows(grid: _Grid, reach_sq, pos_box, slots, width):
    """The Dense table of the pairs closer than ``sqrt(reach_sq)`` from a sorted cell list (jit-able).

    In cell order, every particle tests the ``slots`` first particles of
    each of its cell ranges (contiguous in that order, so neighbouring rows
    read the same memory), keeps those within reach as bit masks (a 32-bit
    word per range and 32 slots), and reads the set bits in order into
    ``width`` slots; the rows then go back to the particles' own order. No ``[n, candidates]`` table is
    written, sorted or scattered (jax-md's Dense build does all three).

    Returns:
      ``(idx [n, width] or None, most neighbours of a row, most particles of a range)``; ``width=None``: counts only.
    """
    n = pos_box.shape[0]
    order, start, size = _cell_ranges(grid, pos_box)  # rows in cell order
    n_ranges = start.shape[1]
    offset = jnp.arange(slots, dtype=jnp.int32)
    inside = offset[None, None, :] < size[:, :, None]
    at = jnp.where(inside, start[:, :, None] + offset[None, None, :], 0)  # [n, R, slots] in cell order
    sorted_pos = pos_box[order]
    d2 = _metric_sq(grid, sorted_pos[:, None, None, :], sorted_pos[at])
    me = jnp.arange(n, dtype=jnp.int32)
    keep = inside & (at != me[:, None, None]) & (d2 < reach_sq)
    per_range = -(-slots // 32)  # 32-bit words per range
    if per_range > 1:
        keep = jnp.pad(keep, ((0, 0), (0, 0), (0, 32 * per_range - slots)))
    keep = keep.reshape(n, n_ranges * per_range, min(slots, 32))
    shift = jnp.arange(keep.shape[-1], dtype=jnp.uint32)
    bits = jnp.sum(keep.astype(jnp.uint32) << shift, axis=-1, dtype=jnp.uint32)  # [n, words]
    per_word = jax.lax.population_count(bits).astype(jnp.int32)
    count = jnp.sum(per_word, axis=1, dtype=jnp.int32)
    most, crowded = jnp.max(count, initial=0), jnp.max(size, initial=0)
    if width is None:
        return None, most, crowded
    # the k-th set bit of a row (k < width): in the word whose running popcount first exceeds k, the bit
    # below which that word holds k - (the popcount of the words before) set bits; all by comparisons, no loop
    upto = jnp.cumsum(per_word, axis=1)
    k = jnp.arange(width, dtype=jnp.int32)[None, :, None]
    word = jnp.sum(upto[:, None, :] <= k, axis=2, dtype=jnp.int32)  # [n, width]
    found = word < bits.shape[1]
    word = jnp.minimum(word, bits.shape[1] - 1)
    below = jnp.take_along_axis(upto - per_word, word, axis=1)
    value = jnp.take_along_axis(bits, word, axis=1)[:, :, None]
    low = jnp.uint32(0xFFFFFFFF) >> (31 - shift)  # bits 0 .. b of a word
    rank = (k[:, :, 0] - below)[:, :, None]
    bit = jnp.sum(jax.lax.population_count(value & low).astype(jnp.int32) <= rank, axis=2, dtype=jnp.int32)
    at = jnp.take_along_axis(start, word // per_range, axis=1) + 32 * (word % per_range) + bit
    idx = jnp.where(found, order[jnp.where(found, at, 0)], n)
    row_of = jnp.zeros(n, jnp.int32).at[order].set(me)  # each particle's row in cell order
    return idx[row_of].astype(jnp.int32), most, crowded


_compiled_rows = jax.jit(_dense_rows, static_argnums=(0, 1, 3, 4))
""":func:`_dense_rows` compiled once per grid, reach and capacities (the allocations on the host)."""
_compiled_ranges = jax.jit(_cell_ranges, static_argnums=0)


def neighbor_list(radii, skin, box_lo=None, box_hi=None, periodic_box=None, capacity_multiplier=1.25):
    """A Dense neighbour list of contact candidates, rebuilt only when the skin is used up.

    ``nbrs.idx`` is ``[n, m]`` int32, padded with ``n`` (jax-md's
    convention), holding the pairs closer than ``cutoff + skin`` at the last
    rebuild (each on both rows, in no particular order within a row: the
    same pairs as jax-md's Dense list, :func:`jax_md_neighbor_list`). A
    rebuild sorts the particles by cell (:func:`_grid`) and tests each
    particle against the contiguous runs of particles in its neighbour cell
    ranges (:func:`_dense_rows`); jax-md's Dense build, which writes,
    scatters and prunes an ``[n, 27 x cell capacity]`` candidate table,
    costs several times more (benchmarks/RESULTS.md, ``dynamic_step``). Distances and the skin test are jax-md's own
    (``space.free`` / ``space.periodic``, threshold ``(skin / 2)^2`` in
    float32), so the rebuilds happen at the same steps as with jax-md's list.
    Positions are passed as they are (m); the list shifts them by ``box_lo``
    or wraps them into the periodic box, so ``nbrs.reference_position``
    holds those shifted positions.

    Args:
      radii: ``[n]`` particle radii (m); the contact range is ``2 max(radii)``.
      skin: Verlet skin (m), >= 0. The list holds the pairs closer than
        ``2 r_max + skin`` at its last rebuild and is rebuilt once any
        particle moved ``skin / 2``; 0 rebuilds at every update.
      box_lo, box_hi: ``[3]`` corners (m) of the region of the cell grid, for
        free boundaries. Particles that leave it are still found (they fall
        into the face cells, distances are free-space), at the price of
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
    cutoff = 2.0 * float(radii.max()) * (1.0 + CANDIDATE_MARGIN)
    reach = cutoff + float(skin)
    if periodic_box is None:
        lo, hi = np.asarray(box_lo, dtype=np.float64), np.asarray(box_hi, dtype=np.float64)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(hi > lo):
            raise ValueError("box_lo and box_hi must be [3] with box_hi > box_lo")
        grid = _grid(hi - lo, reach, periodic=False)
        shift_lo = jnp.asarray(lo)

        def to_box(positions):
            return positions - shift_lo.astype(positions.dtype)
    else:
        box = np.asarray(periodic_box, dtype=np.float64)
        if box.shape != (3,) or not np.all(box > 0):
            raise ValueError("periodic_box must be [3] positive side lengths")
        grid = _grid(box, reach, periodic=True)
        box_j = jnp.asarray(box)

        def to_box(positions):
            return jnp.mod(positions, box_j.astype(positions.dtype))

    reach_sq = reach**2  # jax-md's (r_cutoff + dr_threshold)**2
    half_skin = np.float32(skin) / np.float32(2)
    threshold_sq = float(half_skin * half_skin)  # jax-md's (dr_threshold / f32(2))**2, a float32

    def build(pos_box, nbrs):
        slots, width = nbrs.range_slots.shape[0], nbrs.idx.shape[1]
        idx, most, crowded = _dense_rows(grid, reach_sq, pos_box, slots, width)
        return NeighborList(idx, pos_box, jnp.maximum(nbrs.demand, jnp.stack([most, crowded])), nbrs.range_slots)

    def allocate(positions, extra_capacity=0, demand=(0, 0)):
        positions = jnp.asarray(positions)
        pos_box = to_box(positions)
        n = positions.shape[0]
        _, start, size = _compiled_ranges(grid, pos_box)
        slots = max(int(max(int(jnp.max(size)), int(demand[1])) * capacity_multiplier) + int(extra_capacity), 1)
        _, most, _ = _compiled_rows(grid, reach_sq, pos_box, slots, None)
        most = max(int(most), int(demand[0]))
        width = max(min(int(most * capacity_multiplier + int(extra_capacity)), start.shape[1] * slots, n - 1), 0)
        idx, most, crowded = _compiled_rows(grid, reach_sq, pos_box, slots, width)
        nbrs = NeighborList(idx, pos_box, jnp.stack([most, crowded]), jnp.arange(slots, dtype=jnp.int32))
        return _kept_dtype(nbrs, positions)

    def update(positions, nbrs):
        pos_box = to_box(positions)
        if skin == 0:
            return _kept_dtype(build(pos_box, nbrs), positions)
        moved = _metric_sq(grid, pos_box, nbrs.reference_position)
        stale = jnp.any(~(moved <= jnp.asarray(threshold_sq, moved.dtype)))  # NaN or inf (forced) rebuild too
        return _kept_dtype(jax.lax.cond(stale, build, lambda p, nb: nb, pos_box, nbrs), positions)

    return NeighborListFns(allocate, update, cutoff, float(skin), float(capacity_multiplier))


def jax_md_neighbor_list(radii, skin, box_lo=None, box_hi=None, periodic_box=None, capacity_multiplier=1.25):
    """jax-md's own skinned Dense list (``partition.neighbor_list``), with the arguments of :func:`neighbor_list`.

    The reference the sorted cell list is tested and timed against: the same
    pairs (in another order within a row) and the same rebuild steps.
    ``nbrs`` is jax-md's ``NeighborList``; :func:`did_buffer_overflow` and
    :func:`did_rebuild` take it too.
    """
    radii = np.asarray(radii, dtype=np.float64)
    partition, space = jax_md_modules("partition", "space")
    cutoff = 2.0 * float(radii.max()) * (1.0 + CANDIDATE_MARGIN)
    if periodic_box is None:
        lo, hi = np.asarray(box_lo, dtype=np.float64), np.asarray(box_hi, dtype=np.float64)
        box = hi - lo
        displacement, _ = space.free()
        shift_lo = jnp.asarray(lo)

        def to_box(positions):
            return positions - shift_lo.astype(positions.dtype)
    else:
        box = np.asarray(periodic_box, dtype=np.float64)
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
    """``nbrs``, after checking (at trace time) that the list kept the positions' float dtype."""
    if nbrs.reference_position.dtype != positions.dtype:
        raise TypeError(f"the neighbour list turned {positions.dtype} positions into {nbrs.reference_position.dtype}")
    return nbrs


def did_buffer_overflow(nbrs):
    """Scalar bool (jit-able): the list or its cell list ran out of capacity; reallocate and redo."""
    flag = jnp.asarray(nbrs.did_buffer_overflow)
    return flag if flag.dtype == bool else flag != 0


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
    (jax-md) or the row's own index (:class:`sintercond.contacts.network.ContactTable`).
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
