"""The half pair list: each contact candidate once, the pairs the contact laws run on, and sums over it.

:func:`half_pairs` keeps each pair ``i < j`` of a Dense neighbour table
(:func:`sintercond.contacts.neighbors.neighbor_list`) within ``r_i + r_j + skin``
(size-aware), sorted by ``(i, j)``, rebuilt whenever the table is rebuilt,
in a fixed-capacity buffer with its own overflow flag
(:func:`half_pairs_overflowed`). Per-pair values (the springs) follow their
pair through rebuilds and reallocations with :func:`remap_half_pairs`.
:func:`pair_exchange` adds a per-pair value to one end and takes it from
the other, so forces and heat are conserved by construction;
:func:`map_pair_blocks` evaluates a per-pair function block by block on the
CPU, so that long lists keep their intermediates in the cache.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp

from sintercond.contacts.neighbors import CANDIDATE_MARGIN
from sintercond.state import pytree_dataclass


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
    """``[n, m]``: the ``j > i`` of ``idx`` within ``r_i + r_j + skin`` in their slots of the table, ``n`` elsewhere."""
    n = radii.shape[0]
    rows = jnp.arange(n, dtype=idx.dtype)[:, None]
    ahead = (idx < n) & (idx > rows)
    j = jnp.where(ahead, idx, rows)
    delta = positions[j] - positions[:, None, :]
    # between two rebuilds each particle moves at most skin / 2 (jax-md's threshold, rounded in float32):
    # a pair beyond r_i + r_j + skin at the rebuild cannot touch before the next one
    reach = (radii[:, None] + radii[j] + skin) * (1.0 + CANDIDATE_MARGIN)
    keep = ahead & (jnp.sum(delta * delta, axis=-1) < reach * reach)
    return jnp.where(keep, idx, n)


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
    kept = jnp.sort(_kept_neighbors(idx, positions, radii, skin), axis=1)  # each row's pairs by j, then n
    per_row = jnp.sum(kept < n, axis=1, dtype=jnp.int32)
    count = jnp.sum(per_row, dtype=jnp.int32)
    if m == 0:
        return HalfPairs(jnp.full((capacity, 2), n, jnp.int32), jnp.maximum(count, jnp.asarray(demand, jnp.int32)))
    # the rows laid end to end: place q holds row i's (q - first[i])-th pair, i the last row starting at or
    # before q (first: an exclusive cumsum of the rows' counts; an empty row starts where the next one
    # does), i.e. the rows starting at or before q, less one; gathers, no compaction of the [n m] slots
    first = jnp.cumsum(per_row) - per_row
    starts = jnp.zeros(capacity, jnp.int32).at[first].add(1, mode="drop")
    i = jnp.clip(jnp.cumsum(starts) - 1, 0, n - 1)
    place = jnp.arange(capacity, dtype=jnp.int32)
    j = kept[i, jnp.clip(place - first[i], 0, m - 1)]
    inside = place < count
    pairs = jnp.stack([jnp.where(inside, i, n), jnp.where(inside, j, n)], axis=1).astype(jnp.int32)
    return HalfPairs(pairs, jnp.maximum(count, jnp.asarray(demand, jnp.int32)))


def half_pair_count(idx, positions, radii, skin) -> int:
    """Pairs :func:`half_pairs` keeps from ``idx`` at ``positions`` (host)."""
    return int(jnp.sum(_kept_neighbors(jnp.asarray(idx), jnp.asarray(positions), jnp.asarray(radii), skin)
                       < radii.shape[0]))


def allocate_half_pairs(idx, positions, radii, skin, capacity_multiplier=1.25, minimum=1) -> HalfPairs:
    """A :func:`half_pairs` list sized on the host: ``capacity_multiplier`` times the pairs kept now (at least ``minimum``)."""
    capacity = max(int(math.ceil(capacity_multiplier * half_pair_count(idx, positions, radii, skin))), int(minimum), 1)
    capacity = half_pair_capacity(capacity)
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
    found by a binary search in the old list (``O(capacity log capacity)``;
    under x64 on the int64 key ``i 2^32 + j``, one gather a step, else
    lexicographically on ``(i, j)``: no int32 key that could overflow);
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
    if jax.config.jax_enable_x64:  # (i, j) as one int64 key i 2^32 + j (never overflows): one gather a step
        def key(i, j):
            return (i.astype(jnp.int64) << 32) | j.astype(jnp.int64)

        lo = jnp.searchsorted(key(oi, oj), key(ni, nj)).astype(jnp.int32)
    else:
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


PAIR_BLOCK = 16384
"""Pairs per block of the pair pass on the CPU (:func:`map_pair_blocks`): lists of at least
:data:`PAIR_BLOCKS_FROM` blocks are evaluated block by block, so that the pair laws' many intermediates stay in
the cache (shorter lists fit in it whole, and blocks made the 38,115-pair list of 1e4 spheres slower)."""

PAIR_BLOCKS_FROM = 4


def half_pair_capacity(need: int) -> int:
    """The capacity allocated for ``need`` pairs: a whole number of :data:`PAIR_BLOCK` blocks when it is blocked."""
    return need if need < PAIR_BLOCKS_FROM * PAIR_BLOCK else -(-need // PAIR_BLOCK) * PAIR_BLOCK


def map_pair_blocks(fn, pairs, *per_pair):
    """``fn(pairs, *per_pair)`` of a half pair list ``[c, 2]`` and per-pair arrays ``[c, ...]`` (or None), by blocks.

    ``fn`` maps pairs to per-pair outputs (a pytree of ``[c', ...]`` arrays)
    and may gather per-particle arrays it closes over. On the CPU a list of
    :data:`PAIR_BLOCKS_FROM` blocks of :data:`PAIR_BLOCK` pairs is evaluated
    one block at a time (``lax.map``): the same arithmetic per pair, but
    each intermediate of the laws stays in the cache instead of making its
    own pass through memory (docs/devlog/coupled_step.md, branch blocked). A capacity that is not a whole number of blocks
    (:func:`half_pair_capacity` allocates one) is padded, at the cost of a
    copy. Elsewhere, and for shorter lists, one call.
    """
    c = pairs.shape[0]
    if c < PAIR_BLOCKS_FROM * PAIR_BLOCK or jax.default_backend() != "cpu":
        return fn(pairs, *per_pair)
    blocks = -(-c // PAIR_BLOCK)
    pad = blocks * PAIR_BLOCK - c

    def split(x):
        if x is None:
            return None
        if pad:  # padding pairs (0, 0) are not pairs (i < j fails): their outputs are dropped below
            x = jnp.concatenate([x, jnp.zeros((pad,) + x.shape[1:], x.dtype)])
        return x.reshape((blocks, PAIR_BLOCK) + x.shape[1:])

    out = jax.lax.map(lambda args: fn(*args), (split(pairs), *map(split, per_pair)))
    return jax.tree.map(lambda y: y.reshape((blocks * PAIR_BLOCK,) + y.shape[2:])[:c], out)


def pair_sum(on_i, on_j, pairs, n):
    """``[n, ...]``: per-pair values scattered to both ends, ``on_i`` to ``pairs[:, 0]``, ``on_j`` to ``pairs[:, 1]``.

    With ``on_j = -on_i`` (a force, a heat flow) the total is zero to
    round-off by construction. Padding pairs (index ``n``) are dropped.
    The additions run in pair order, so sorted lists give sums independent
    of the capacity.
    """
    out = jnp.zeros((n,) + on_i.shape[1:], jnp.result_type(on_i, on_j))
    return out.at[pairs[:, 0]].add(on_i, mode="drop").at[pairs[:, 1]].add(on_j, mode="drop")


def pair_exchange(on_i, pairs, n):
    """``[n, ...]``: what each pair passes from ``j`` to ``i`` (a force, a heat flow), added to ``i``, taken from ``j``.

    The same numbers as ``pair_sum(on_i, -on_i, pairs, n)``, without a
    negated copy of ``on_i`` (``j``'s scatter subtracts).
    """
    out = jnp.zeros((n,) + on_i.shape[1:], on_i.dtype)
    return out.at[pairs[:, 0]].add(on_i, mode="drop").at[pairs[:, 1]].subtract(on_i, mode="drop")
