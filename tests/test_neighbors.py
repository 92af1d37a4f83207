"""Contact searches against brute force; the skinned Dense list; per-pair history through rebuilds."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sintercond.contacts import network, neighbors, pair_list
from sintercond.laws import geometry
from _helpers import find_contacts


def random_packing(n, seed, spread=1.0, polydispersity=0.5):
    """``n`` spheres in a cube of side ``spread * n^(1/3)``, radii ``0.5 +- p/2`` (a few contacts each)."""
    rng = np.random.default_rng(seed)
    side = spread * max(n, 1) ** (1 / 3)
    centres = rng.uniform(-0.3 * side, 0.7 * side, (n, 3))
    radii = 0.5 + polydispersity * rng.uniform(-0.5, 0.5, n)
    return centres, radii


def as_set(i, j):
    return set(zip(i.tolist(), j.tolist()))


# --------------------------------------------------------------------------
# host searches


def test_brute_force_equals_the_triangle_search():
    centres, radii = random_packing(300, seed=0)
    i, j = neighbors.brute_force_pairs(centres, radii, chunk=37)
    np.testing.assert_array_equal(np.stack([i, j], axis=1), geometry.contacts(centres, radii))
    assert len(i) > 300


@given(n=st.integers(0, 120), seed=st.integers(0, 2**31), spread=st.sampled_from([0.3, 1.0, 3.0]),
       polydispersity=st.sampled_from([0.0, 0.5, 0.9]))
def test_cell_list_equals_brute_force_free(n, seed, spread, polydispersity):
    centres, radii = random_packing(n, seed, spread, polydispersity)
    i, j = neighbors.cell_list_pairs(centres, radii, budget=64)  # many chunks
    bi, bj = neighbors.brute_force_pairs(centres, radii)
    np.testing.assert_array_equal(i, bi)
    np.testing.assert_array_equal(j, bj)


@given(n=st.integers(0, 120), seed=st.integers(0, 2**31),
       cells=st.tuples(*[st.sampled_from([0.6, 1.5, 2.5, 3.5, 6.0])] * 3))
def test_cell_list_equals_brute_force_periodic(n, seed, cells):
    # boxes of 1, 2, 3 or more cells per axis (the half shell needs 3); centres
    # partly outside the box and negative: the search wraps them
    centres, radii = random_packing(n, seed)
    box = np.array(cells) * 2.0 * (float(radii.max()) if n else 1.0) * 1.0001
    i, j = neighbors.cell_list_pairs(centres, radii, periodic_box=box, budget=64)
    bi, bj = neighbors.brute_force_pairs(centres, radii, periodic_box=box)
    np.testing.assert_array_equal(i, bi)
    np.testing.assert_array_equal(j, bj)


def test_touching_lattice_within_tolerance():
    # a touching simple-cubic lattice: every gap is a few ulp either way of 0
    g = np.arange(5) * 0.3
    centres = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T + 1e3  # far from 0: rounding
    radii = np.full(len(centres), 0.15)
    i, j = neighbors.cell_list_pairs(centres, radii, tolerance=1e-9)
    assert as_set(i, j) == as_set(*neighbors.brute_force_pairs(centres, radii, tolerance=1e-9))
    assert len(i) == 3 * 4 * 25  # every lattice bond


def test_contact_table_layout():
    centres, radii = random_packing(400, seed=3)
    pairs = network.contact_pairs(centres, radii)
    bi, bj = neighbors.brute_force_pairs(centres, radii)
    np.testing.assert_array_equal(pairs.i, bi)
    np.testing.assert_array_equal(pairs.j, bj)
    d = np.linalg.norm(centres[bi] - centres[bj], axis=1)
    np.testing.assert_array_equal(pairs.overlap, np.maximum(radii[bi] + radii[bj] - d, 0.0))
    np.testing.assert_array_equal(pairs.r_i, radii[bi])
    table = find_contacts(centres, radii)
    own = np.arange(len(radii))[:, None]
    real = table != own
    # padding at the end of each row, neighbours ascending
    assert np.all(np.diff(real.astype(int), axis=1) <= 0)
    assert np.all(np.where(real[:, 1:] & real[:, :-1], np.diff(table, axis=1) > 0, True))
    directed = {(a, int(b)) for a, row in enumerate(table) for b in row[row != a]}
    assert directed == as_set(bi, bj) | as_set(bj, bi)
    # one value per pair, on both rows
    value = np.arange(len(bi), dtype=np.float64) + 1.0
    nbr, v = network.ell_table(len(radii), bi, bj, value)
    np.testing.assert_array_equal(nbr, table)
    lookup = {(a, b): x for a, b, x in zip(bi.tolist(), bj.tolist(), value.tolist())}
    for a in range(len(radii)):
        for slot in range(nbr.shape[1]):
            b = int(nbr[a, slot])
            assert v[a, slot] == (0.0 if b == a else lookup[(min(a, b), max(a, b))])


def test_isolated_particles_and_empty_packings():
    assert find_contacts(np.zeros((0, 3)), np.zeros(0)).shape == (0, 1)
    table = find_contacts(np.array([[0.0, 0, 0], [5.0, 0, 0]]), np.ones(2))
    np.testing.assert_array_equal(table, [[0], [1]])


# --------------------------------------------------------------------------
# the skinned jax-md list


def listed_pairs(idx):
    """Directed pairs ``(i, j)`` of a jax-md Dense table (padding ``n``)."""
    idx = np.asarray(idx)
    n = len(idx)
    return {(a, int(b)) for a, row in enumerate(idx) for b in row if b < n}


def within(positions, reach, periodic_box=None):
    """Directed pairs closer than ``reach``, by brute force."""
    n = len(positions)
    i, j = neighbors.brute_force_pairs(np.asarray(positions), np.full(n, reach / 2), tolerance=0.0,
                                       periodic_box=periodic_box)
    return as_set(i, j) | as_set(j, i)


def free_list(radii, centres, skin, capacity_multiplier=1.25):
    return neighbors.neighbor_list(radii, skin, box_lo=centres.min(axis=0) - 2.0, box_hi=centres.max(axis=0) + 2.0,
                                   capacity_multiplier=capacity_multiplier)


@pytest.mark.slow
def test_allocated_list_is_the_pairs_within_cutoff_plus_skin_in_float64():
    centres, radii = random_packing(250, seed=4)
    fns = free_list(radii, centres, skin=0.3)
    assert fns.cutoff == pytest.approx(2 * radii.max(), rel=1e-5)
    nbrs = fns.allocate(centres)
    assert nbrs.reference_position.dtype == jnp.float64 and nbrs.idx.dtype == jnp.int32
    assert not bool(neighbors.did_buffer_overflow(nbrs))
    assert listed_pairs(nbrs.idx) == within(centres, fns.cutoff + fns.skin)
    # an update under jit keeps float64 and, with no motion, rebuilds nothing
    after = jax.jit(fns.update)(jnp.asarray(centres), nbrs)
    assert after.reference_position.dtype == jnp.float64
    assert not bool(neighbors.did_rebuild(nbrs, after))


@pytest.mark.slow
def test_periodic_list_wraps():
    centres, radii = random_packing(200, seed=5)
    box = np.ptp(centres, axis=0) * 0.9  # centres outside the box too
    fns = neighbors.neighbor_list(radii, 0.2, periodic_box=box)
    nbrs = fns.allocate(centres)
    assert nbrs.reference_position.dtype == jnp.float64
    assert listed_pairs(nbrs.idx) == within(centres, fns.cutoff + fns.skin, periodic_box=box)


@pytest.mark.slow
def test_overflow_is_flagged_and_reallocation_recovers():
    centres, radii = random_packing(250, seed=6, spread=1.3)
    fns = free_list(radii, centres, skin=0.2, capacity_multiplier=1.0)
    nbrs = fns.allocate(centres)
    squeezed = centres.mean(axis=0) + 0.7 * (centres - centres.mean(axis=0))  # more neighbours each
    nbrs = jax.jit(fns.update)(jnp.asarray(squeezed), nbrs)
    assert bool(neighbors.did_buffer_overflow(nbrs))
    nbrs = fns.allocate(squeezed)
    assert not bool(neighbors.did_buffer_overflow(nbrs))
    assert listed_pairs(nbrs.idx) == within(squeezed, fns.cutoff + fns.skin)


@pytest.mark.slow
def test_sorted_cell_list_is_the_brute_force_pairs_free_periodic_and_thin():
    """The sorted cell list's table against brute force within cutoff + skin (minimum image when periodic):
    a polydisperse packing with particles on and beyond the region's faces (free: they fall into the face
    cells), wrapped into a periodic box, and a periodic box only two cells thick (each cell met once)."""
    centres, radii = random_packing(400, seed=21, polydispersity=0.8)
    skin = 0.15
    lo, hi = centres.min(axis=0) + 0.5, centres.max(axis=0) - 0.5  # some particles outside the region
    centres[:4] = [lo, hi, [lo[0], hi[1], lo[2]], [hi[0], lo[1], hi[2]]]  # and some exactly on its corners
    fns = neighbors.neighbor_list(radii, skin, box_lo=lo, box_hi=hi)
    nbrs = fns.allocate(centres)
    assert not bool(neighbors.did_buffer_overflow(nbrs))
    assert listed_pairs(nbrs.idx) == within(centres, fns.cutoff + fns.skin)
    wide = fns.allocate(centres, extra_capacity=40)  # over 32 slots per cell range: several bit words each
    assert wide.range_slots.shape[0] > 32 and listed_pairs(wide.idx) == listed_pairs(nbrs.idx)
    reach = fns.cutoff + fns.skin
    for box in (np.ptp(centres, axis=0) * 0.9, np.array([9.0, 8.0, 2.2 * reach])):  # the last: two cells in z
        fns = neighbors.neighbor_list(radii, skin, periodic_box=box)
        nbrs = fns.allocate(centres)
        assert listed_pairs(nbrs.idx) == within(centres, reach, periodic_box=box)


@pytest.mark.slow
def test_sorted_cell_list_rebuilds_when_jax_md_does_and_recovers_either_overflow():
    """Rebuild steps against jax-md's own list (same skin test); a table whose rows, or whose cell ranges, are
    too small flags the overflow alone, and the reallocated list holds the brute-force pairs."""
    centres, radii = random_packing(200, seed=22, spread=1.2)
    velocity = np.random.default_rng(23).normal(0.0, 0.01, centres.shape)
    box = dict(box_lo=centres.min(axis=0) - 2.0, box_hi=centres.max(axis=0) + 2.0)
    ours, theirs = neighbors.neighbor_list(radii, 0.3, **box), neighbors.jax_md_neighbor_list(radii, 0.3, **box)
    a, b = ours.allocate(centres), theirs.allocate(centres)
    update_a, update_b = jax.jit(ours.update), jax.jit(theirs.update)
    rebuilt = []
    for t in range(1, 25):
        positions = jnp.asarray(centres + t * velocity)
        a2, b2 = update_a(positions, a), update_b(positions, b)
        assert bool(neighbors.did_rebuild(a, a2)) == bool(neighbors.did_rebuild(b, b2)), t
        assert listed_pairs(a2.idx) == listed_pairs(b2.idx), t
        rebuilt.append(bool(neighbors.did_rebuild(a, a2)))
        a, b = a2, b2
    assert 2 <= sum(rebuilt) < 20
    squeezed = jnp.asarray(centres.mean(axis=0) + 0.8 * (centres - centres.mean(axis=0)))
    roomy = within(squeezed, ours.cutoff + ours.skin)
    for name, tight in (("rows", dataclasses.replace(a, idx=a.idx[:, :2])),
                        ("cell ranges", dataclasses.replace(a, range_slots=jnp.arange(1, dtype=jnp.int32)))):
        forced = dataclasses.replace(tight, reference_position=jnp.full_like(tight.reference_position, jnp.inf))
        assert bool(neighbors.did_buffer_overflow(update_a(squeezed, forced))), name
        again = ours.allocate(squeezed)
        assert not bool(neighbors.did_buffer_overflow(again)) and listed_pairs(again.idx) == roomy, name


def in_contact(positions, radii, idx):
    n = len(radii)
    valid = idx < n
    j = jnp.where(valid, idx, 0)
    d = jnp.linalg.norm(positions[:, None, :] - positions[j], axis=-1)
    return valid & (d <= radii[:, None] + radii[j])


@pytest.mark.slow
def test_contact_age_survives_rebuilds_and_a_reallocation():
    # Each pair's contact age (steps in contact without a break) and the
    # neighbour it was first seen with ride along in [n, m, 2] history,
    # remapped at every update. Reference: a dict keyed by (i, j) from the
    # brute-force contacts of every step.
    centres, radii = random_packing(150, seed=7, spread=1.05)
    velocity = np.random.default_rng(8).normal(0.0, 0.005, centres.shape)
    fns = free_list(radii, centres, skin=0.25, capacity_multiplier=1.5)
    wide = free_list(radii, centres, skin=0.25, capacity_multiplier=3.0)
    radii_j = jnp.asarray(radii)

    def step(fns, positions, nbrs, history):
        new = fns.update(positions, nbrs)
        carried = neighbors.remap_pair_history(nbrs.idx, new.idx, history)
        contact = in_contact(positions, radii_j, new.idx)
        age = jnp.where(contact, carried[..., 0] + 1.0, 0.0)
        first_seen = jnp.where(contact & (carried[..., 0] == 0.0), new.idx.astype(jnp.float64), carried[..., 1])
        return new, jnp.stack([age, first_seen], axis=-1), neighbors.did_rebuild(nbrs, new)

    step = jax.jit(step, static_argnums=0)
    nbrs = fns.allocate(centres)
    history = jnp.zeros(nbrs.idx.shape + (2,))
    reference = {}
    rebuilds, steps = 0, 80
    for t in range(1, steps + 1):
        positions = centres + t * velocity
        if t == steps // 2:  # forced reallocation to a wider table, history carried over
            wider = wide.allocate(positions)
            assert wider.idx.shape[1] > nbrs.idx.shape[1]
            history = neighbors.remap_pair_history(nbrs.idx, wider.idx, history)
            nbrs, fns = wider, wide
        nbrs, history, rebuilt = step(fns, jnp.asarray(positions), nbrs, history)
        assert not bool(neighbors.did_buffer_overflow(nbrs))
        rebuilds += int(rebuilt)
        reference = {p: reference.get(p, 0) + 1 for p in as_set(*neighbors.brute_force_pairs(positions, radii, 0.0))}
        idx, hist = np.asarray(nbrs.idx), np.asarray(history)
        for a, k in zip(*np.nonzero(idx < len(radii))):
            b = int(idx[a, k])
            age = reference.get((min(a, b), max(a, b)), 0)
            assert hist[a, k, 0] == age, (t, a, b)
            if age:
                assert hist[a, k, 1] == b  # carried from the same pair, not the same slot
        assert set(reference) <= listed_pairs(idx)  # no contact lost between rebuilds
    assert hist.dtype == np.float64
    assert max(reference.values()) > 40  # long-lived contacts crossed rebuilds
    assert 2 <= rebuilds < steps // 4  # the skin saves rebuilds


def test_remap_pair_history_padding_and_own_index():
    # rows of 3 particles; padding as jax-md (n = 3) and as ContactTable (own index)
    old = jnp.array([[1, 2, 3], [0, 3, 3], [0, 1, 2]])
    new = jnp.array([[2, 1], [2, 0], [1, 2]])
    values = jnp.array([[10.0, 20.0, 30.0], [40.0, 50.0, 60.0], [70.0, 80.0, 90.0]])
    out = neighbors.remap_pair_history(old, new, values, fill=-1.0)
    np.testing.assert_array_equal(out, [[20.0, 10.0], [-1.0, 40.0], [80.0, -1.0]])
    springs = jnp.stack([values, 2 * values, 3 * values], axis=-1)  # [n, m, 3]
    out3 = neighbors.remap_pair_history(old, new, springs)
    np.testing.assert_array_equal(out3[..., 2], 3 * np.where(out == -1.0, 0.0, out))


@pytest.mark.slow
def test_pair_conductances_compiled_equal_the_eager_law():
    from sintercond.laws.conductance import CONDUCTANCE_LAWS, pair_conductance

    # a jittered sintered simple-cubic lattice: overlaps of a few % of the radius
    rng = np.random.default_rng(9)
    g = np.arange(7.0)
    centres = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T + rng.uniform(-0.02, 0.02, (343, 3))
    radii = 0.53 * (1 + rng.uniform(-0.02, 0.02, 343))
    pairs = network.contact_pairs(centres, radii)
    kappa = np.linspace(5.0, 9.0, len(radii))
    k_i, k_j = kappa[pairs.i], kappa[pairs.j]
    eager = np.asarray(pair_conductance("rojek", pairs.r_i, pairs.r_j, pairs.overlap, k_i, k_j))
    assert len(eager) > 100 and np.all(eager[pairs.overlap > 0] > 0)
    np.testing.assert_allclose(network.pair_conductances("rojek", pairs, k_i, k_j), eager, rtol=1e-14)
    # a law object (compiled afresh) and per-pair parameters (unpadded length) take the same path
    law = CONDUCTANCE_LAWS["rojek"]
    np.testing.assert_allclose(network.pair_conductances(law, pairs, k_i, k_j), eager, rtol=1e-14)
    slope = np.full(len(eager), law.default_params["slope"])
    np.testing.assert_allclose(network.pair_conductances("rojek", pairs, k_i, k_j, params={"slope": slope}), eager,
                               rtol=1e-14)
    with pytest.raises(ValueError, match="kappa_i"):
        network.pair_conductances("rojek", pairs, -k_i, k_j)


# --------------------------------------------------------------------------
# half pair list


def size_aware_pairs(positions, radii, skin):
    """Pairs i < j closer than ``(r_i + r_j + skin)(1 + CANDIDATE_MARGIN)``, by brute force in NumPy."""
    scale = 1.0 + neighbors.CANDIDATE_MARGIN
    d = np.linalg.norm(positions[:, None, :] - positions[None, :, :], axis=-1)
    i, j = np.nonzero((d < (radii[:, None] + radii[None, :] + skin) * scale) & np.triu(np.ones_like(d, bool), 1))
    return list(zip(i.tolist(), j.tolist()))


@pytest.mark.slow
def test_half_pairs_are_the_size_aware_brute_force_pairs_sorted():
    centres, radii = random_packing(300, seed=9, polydispersity=0.8)  # polydisperse: far fewer than 2 r_max + skin
    skin = 0.15
    fns = free_list(radii, centres, skin)
    nbrs = fns.allocate(centres)
    half = pair_list.allocate_half_pairs(nbrs.idx, centres, radii, skin, 1.3)
    expected = size_aware_pairs(centres, radii, skin)  # sorted by (i, j)
    pairs = np.asarray(half.pairs)
    assert half.pairs.dtype == jnp.int32 and int(half.demand) == len(expected)
    assert half.capacity == int(np.ceil(1.3 * len(expected)))
    assert [tuple(p) for p in pairs[:len(expected)].tolist()] == expected  # the pairs, in (i, j) order
    assert np.all(pairs[len(expected):] == len(radii))  # then padding (n, n)
    assert not bool(pair_list.half_pairs_overflowed(half))
    assert len(expected) < 0.75 * len(listed_pairs(nbrs.idx)) / 2  # the size-aware prune keeps fewer
    # too small: flagged, with the demand the host needs; the kept ones are the first in order
    tight = jax.jit(pair_list.half_pairs, static_argnums=(3, 4))(nbrs.idx, centres, radii, skin, 50)
    assert bool(pair_list.half_pairs_overflowed(tight)) and int(tight.demand) == len(expected)
    assert [tuple(p) for p in np.asarray(tight.pairs).tolist()] == expected[:50]


@pytest.mark.slow
def test_remap_half_pairs_follows_pairs_by_identity():
    rng = np.random.default_rng(3)
    n = 40
    universe = [(i, j) for i in range(n) for j in range(i + 1, n)]

    def random_list(k, capacity):
        chosen = sorted(universe[p] for p in rng.choice(len(universe), k, replace=False))
        return np.array(chosen + [(n, n)] * (capacity - k), np.int32)

    old, new = random_list(120, 130), random_list(150, 171)  # overlapping sets, different capacities
    values = rng.normal(size=(130, 3))
    reference = {tuple(p): values[k] for k, p in enumerate(old.tolist()) if p[0] < p[1]}
    out = np.asarray(jax.jit(pair_list.remap_half_pairs)(old, new, values))
    assert out.shape == (171, 3)
    carried = 0
    for k, p in enumerate(new.tolist()):
        np.testing.assert_array_equal(out[k], reference.get(tuple(p), np.zeros(3)))
        carried += tuple(p) in reference
    assert 0 < carried < 150  # some pairs carried, some new
    empty = pair_list.remap_half_pairs(np.full((1, 2), n, np.int32), new, np.ones((1, 3)))
    assert not np.any(np.asarray(empty))


def test_pair_sum_conserves_to_round_off():
    rng = np.random.default_rng(5)
    n = 50
    pairs = np.array(sorted({tuple(sorted(rng.choice(n, 2, replace=False))) for _ in range(300)}), np.int32)
    pairs = np.concatenate([pairs, np.full((7, 2), n, np.int32)])  # padding is dropped
    f = rng.normal(size=(len(pairs), 3)) * 10.0 ** rng.uniform(-3, 3, (len(pairs), 1))
    total = np.asarray(pair_list.pair_sum(jnp.asarray(f), -jnp.asarray(f), pairs, n))
    assert total.shape == (n, 3)
    assert np.max(np.abs(total.sum(axis=0))) < 1e-13 * np.max(np.abs(f))
    expected = np.zeros((n, 3))
    for (a, b), v in zip(pairs.tolist(), f):
        if a < n:
            expected[a] += v
            expected[b] -= v
    np.testing.assert_allclose(total, expected, rtol=1e-12, atol=1e-12 * np.max(np.abs(f)))
    # adding -f and subtracting f are the same IEEE operation: bit for bit
    exchanged = np.asarray(pair_list.pair_exchange(jnp.asarray(f), pairs, n))
    np.testing.assert_array_equal(exchanged, total)


@pytest.mark.slow
def test_pair_blocks_equal_one_pass_padded_or_not(monkeypatch):
    monkeypatch.setattr(pair_list, "PAIR_BLOCK", 16)
    monkeypatch.setattr(pair_list, "PAIR_BLOCKS_FROM", 2)
    assert pair_list.half_pair_capacity(31) == 31  # under two blocks: as asked
    assert pair_list.half_pair_capacity(32) == 32 and pair_list.half_pair_capacity(33) == 48
    rng = np.random.default_rng(8)
    n = 40
    x = jnp.asarray(rng.normal(size=(n, 3)))

    def per_pair(pairs, spring, unused):  # gathers of a closed-over array, a per-pair input, None kept None
        i, j = pairs[:, 0], jnp.minimum(pairs[:, 1], n - 1)
        return jnp.sqrt(jnp.sum((x[j] - x[i]) ** 2, axis=-1)), spring * 2.0 + x[i], unused

    for c in (37, 48):  # padded to 48, and whole blocks
        pairs = np.sort(rng.integers(0, n, (c, 2)), axis=1).astype(np.int32)
        spring = jnp.asarray(rng.normal(size=(c, 3)))
        one = per_pair(jnp.asarray(pairs), spring, None)
        blocked = jax.jit(lambda p, s: pair_list.map_pair_blocks(per_pair, p, s, None))(pairs, spring)
        assert blocked[2] is None and blocked[0].shape == (c,) and blocked[1].shape == (c, 3)
        for a, b in zip(blocked[:2], one[:2]):
            np.testing.assert_allclose(a, b, rtol=1e-15)
