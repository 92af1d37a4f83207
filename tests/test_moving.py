"""Moving packings: neighbour-list overflow is recovered and no contact is lost."""

import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import geometry, moving, network, packing, thermal


@pytest.fixture(scope="module")
def bed():
    b = packing.powder_bed(320.0, 260.0, seed=11)
    return b.centres * 1e-6, b.radii * 1e-6


def test_shrinking_packing_recovers_overflow_and_matches_a_roomy_run(bed):
    centres, radii = bed
    rate, dt, steps = 40.0, 2e-5, 400  # 1 - rate * t_end = 0.68: necks grow, new contacts appear
    positions = moving.affine_shrinkage(centres, rate)
    capacity = jnp.asarray(4 / 3 * np.pi * radii**3 * 4430 * 560)
    t0 = jnp.asarray(np.random.default_rng(0).uniform(300, 1000, len(radii)))
    # a tight list (no spare capacity) must overflow as contacts form, and be redone
    tight, report = moving.simulate_moving(t0, positions, radii, 7.0, capacity, dt, steps, chunk=50,
                                           capacity_multiplier=1.0, law="batchelor_obrien", neck_model="intersection")
    assert report["reallocations"] >= 1
    roomy, report_roomy = moving.simulate_moving(t0, positions, radii, 7.0, capacity, dt, steps, chunk=50,
                                                 capacity_multiplier=4.0, law="batchelor_obrien",
                                                 neck_model="intersection")
    assert report_roomy["reallocations"] == 0
    np.testing.assert_allclose(np.asarray(tight), np.asarray(roomy), rtol=1e-12)
    # no contact lost: every brute-force contact at the end is in the final neighbour table
    end = np.asarray(positions(steps * dt))
    idx = report["final_idx"]
    listed = {(i, int(j)) for i in range(len(radii)) for j in idx[i] if j < len(radii)}
    for i, j in geometry.contacts(end, radii, tolerance=0.0):
        assert (i, j) in listed and (j, i) in listed
    # heat is conserved while the network changes
    assert float(jnp.sum(capacity * tight)) == pytest.approx(float(jnp.sum(capacity * t0)), rel=1e-12)


def test_static_motion_equals_the_static_solver():
    a, r = 1e-4, 0.52e-4
    g = np.arange(4) * a
    centres = np.array(np.meshgrid(g, g[:2], g[:2], indexing="ij")).reshape(3, -1).T
    radii = np.full(len(centres), r)
    table = network.contact_table(centres, radii, 7.0)
    capacity = jnp.full(len(radii), 1e-3)
    dt = 0.5 * float(thermal.stable_time_step(capacity, table))
    t0 = jnp.asarray(np.linspace(300, 1000, len(radii)))
    static, _ = thermal.simulate(t0, table, capacity, dt, n_steps=200, save_every=200)
    still, _ = moving.simulate_moving(t0, moving.affine_shrinkage(centres, 0.0), radii, 7.0, capacity, dt, 200, chunk=50)
    np.testing.assert_allclose(np.asarray(still), np.asarray(static), rtol=1e-12)
