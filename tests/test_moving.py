"""Moving packings (dynamic contacts): neighbour-list overflow is recovered and no contact is lost."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import simulate
from sintercond.beds import packing
from sintercond.contacts import network
from sintercond.laws import geometry
from sintercond.sim import thermal
from sintercond.simulate import simulate_table
from sintercond.rollout import advance
from sintercond.state import ParticleState


@pytest.fixture(scope="module")
def bed():
    b = packing.powder_bed(320.0, 260.0, seed=11)
    return b.centres * 1e-6, b.radii * 1e-6


def _moving_run(t0, positions_fn, radii, capacity, dt, steps, chunk, capacity_multiplier, skin, law="rojek",
                neck_model=None):
    """Explicit conduction while the particles follow ``positions_fn``; the host driver redoes overflowing chunks."""
    physics = simulate.Physics.create(law=law, neck_model=neck_model, conductance="lifted", contacts="dynamic",
                                      motion=positions_fn)
    start = np.asarray(positions_fn(0.0))
    contacts, fns = simulate.dynamic_contacts(start, radii, skin, capacity_multiplier)
    n = len(radii)
    particles = ParticleState(jnp.asarray(start), jnp.asarray(radii), t0, jnp.asarray(capacity), jnp.zeros(n, jnp.int32),
                              jnp.zeros(n, bool), t0)
    state = simulate.init_state(particles, contacts, dt)
    params = simulate.Params(conductivity=jnp.array([7.0]), specific_heat=jnp.array([1.0]))
    sim = simulate.simulator(physics, fns)
    return advance(sim, state, params, steps, chunk, reallocate=simulate.reallocate_neighbors(fns))


@pytest.mark.slow
def test_shrinking_packing_recovers_overflow_and_matches_a_roomy_run(bed):
    centres, radii = bed
    rate, dt, steps = 40.0, 2e-5, 400  # 1 - rate * t_end = 0.68: necks grow, new contacts appear
    positions = simulate.affine_shrinkage(centres, rate)
    capacity = 4 / 3 * np.pi * radii**3 * 4430 * 560
    t0 = jnp.asarray(np.random.default_rng(0).uniform(300, 1000, len(radii)))
    # a tight list (no spare capacity) must overflow as contacts form, and be redone
    tight, report = _moving_run(t0, positions, radii, capacity, dt, steps, 50, 1.0, 0.0, "batchelor_obrien",
                                "intersection")
    assert report.reallocations >= 1
    roomy, report_roomy = _moving_run(t0, positions, radii, capacity, dt, steps, 50, 4.0, 0.0, "batchelor_obrien",
                                      "intersection")
    assert report_roomy.reallocations == 0
    np.testing.assert_allclose(np.asarray(tight.temperature), np.asarray(roomy.temperature), rtol=1e-12)
    # a skin (rebuilds only after half of it is used up) gives the same temperatures
    skinned, _ = _moving_run(t0, positions, radii, capacity, dt, steps, 50, 1.5, 0.2 * float(radii.min()),
                             "batchelor_obrien", "intersection")
    np.testing.assert_allclose(np.asarray(skinned.temperature), np.asarray(roomy.temperature), rtol=1e-12)
    # no contact lost: every brute-force contact at the end is in the final neighbour table
    end = np.asarray(positions(steps * dt))
    idx = np.asarray(tight.contacts.neighbors)
    listed = {(i, int(j)) for i in range(len(radii)) for j in idx[i] if j < len(radii)}
    for i, j in geometry.contacts(end, radii, tolerance=0.0):
        assert (i, j) in listed and (j, i) in listed
    # heat is conserved while the network changes
    assert float(jnp.sum(capacity * tight.temperature)) == pytest.approx(float(jnp.sum(capacity * t0)), rel=1e-12)


@pytest.mark.slow
def test_static_motion_equals_the_static_solver():
    a, r = 1e-4, 0.52e-4
    g = np.arange(4) * a
    centres = np.array(np.meshgrid(g, g[:2], g[:2], indexing="ij")).reshape(3, -1).T
    radii = np.full(len(centres), r)
    table = network.contact_table(centres, radii, 7.0)
    capacity = jnp.full(len(radii), 1e-3)
    dt = 0.5 * float(thermal.table_time_step(capacity, table))
    t0 = jnp.asarray(np.linspace(300, 1000, len(radii)))
    static, _ = simulate_table(t0, table, capacity, dt, n_steps=200, save_every=200)
    still, _ = _moving_run(t0, simulate.affine_shrinkage(centres, 0.0), radii, capacity, dt, 200, 50, 1.25, 0.0)
    np.testing.assert_allclose(np.asarray(still.temperature), np.asarray(static), rtol=1e-12)


def test_affine_shrinkage_is_a_linear_strain_toward_the_centroid():
    """Bug caught (mutation 'shrinkage rate'): a motion at half the rate passed every test above, which compare
    runs of the same motion. Closed form: c0 + (1 - rate t)(c - c0), c0 the centroid."""
    centres = np.random.default_rng(4).uniform(size=(7, 3))
    c0 = centres.mean(axis=0)
    at = simulate.affine_shrinkage(centres, 40.0)(2.5e-3)
    np.testing.assert_allclose(np.asarray(at), c0 + 0.9 * (centres - c0), rtol=1e-14)


@pytest.mark.slow
def test_either_list_overflowing_alone_is_flagged():
    """Bug caught (mutation 'dynamic skin overflow'): dropping the Dense list's flag survived the runs above, whose
    half list overflowed at the same time. Here each list is the tight one in turn, at the step that squeezes."""
    from sintercond.contacts import neighbors, pair_list

    rng = np.random.default_rng(6)
    centres = rng.uniform(0.0, 8.0, (120, 3))
    radii = 0.5 + 0.2 * rng.uniform(-0.5, 0.5, 120)
    squeezed = jnp.asarray(centres.mean(axis=0) + 0.7 * (centres - centres.mean(axis=0)))
    for tight in ("dense", "half"):
        contacts, fns = simulate.dynamic_contacts(centres, radii, 0.2, 1.0 if tight == "dense" else 4.0)
        pairs = pair_list.allocate_half_pairs(contacts.neighbors, centres, radii, fns.skin,
                                              4.0 if tight == "dense" else 1.0)
        contacts = dataclasses.replace(contacts, pairs=pairs)
        after, _, overflow = jax.jit(simulate.follow_contacts, static_argnums=0)(fns, squeezed, jnp.asarray(radii),
                                                                                 contacts)
        assert bool(overflow), tight
        assert bool(neighbors.did_buffer_overflow(after.neighbor_list)) == (tight == "dense")
        assert bool(pair_list.half_pairs_overflowed(after.pairs)) == (tight == "half")
