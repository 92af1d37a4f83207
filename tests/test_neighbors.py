"""Contact searches against brute force; the skinned jax-md list; per-pair history through rebuilds."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sintercond import geometry, network, neighbors


def random_packing(n, seed, spread=1.0, polydispersity=0.5):
    """``n`` spheres in a cube of side ``spread * n^(1/3)``, radii in ``[0.5 - p/2, 0.5 + p/2]`` (~ a few contacts each)."""
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
    table = network.find_contacts(centres, radii)
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
    assert network.find_contacts(np.zeros((0, 3)), np.zeros(0)).shape == (0, 1)
    table = network.find_contacts(np.array([[0.0, 0, 0], [5.0, 0, 0]]), np.ones(2))
    np.testing.assert_array_equal(table, [[0], [1]])
