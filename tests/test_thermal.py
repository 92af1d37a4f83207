"""Thermal pipe network: contacts vs brute force, conservation, analytic solutions, limits, steady state."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond.beds import packing
from sintercond.contacts import network
from sintercond.laws import geometry
from sintercond.sim import thermal
from sintercond.simulate import simulate_table
from sintercond.sim import steady
from sintercond.laws.conductance import rojek_pair_conductance
from _helpers import find_contacts

A, R = 1.0e-4, 0.52e-4  # lattice spacing and radius (m): sintered SC lattice, h = 2R - A


def sc_lattice(nx, ny=1, nz=1, a=A, r=R):
    g = [np.arange(k) * a for k in (nx, ny, nz)]
    centres = np.array(np.meshgrid(*g, indexing="ij")).reshape(3, -1).T
    return centres, np.full(len(centres), r)


@pytest.fixture(scope="module")
def bed():
    b = packing.powder_bed(320.0, 260.0, seed=5)
    return b.centres * 1e-6, b.radii * 1e-6


def test_contacts_equal_brute_force(bed):
    centres, radii = bed
    table = find_contacts(centres, radii, tolerance=1e-9)
    rows = np.arange(len(radii))[:, None]
    found = {(i, j) for i, j in zip(*np.nonzero(table != rows)) for j in [table[i, j]] if i < j}
    brute = {tuple(p) for p in geometry.contacts(centres, radii, tolerance=1e-9)}
    assert found == brute and len(brute) > len(radii)


def test_contact_table_conductances(bed):
    centres, radii = bed
    t = network.contact_table(centres, radii, 20.0)
    pairs = t.pairs()
    i, j = pairs[:, 0], pairs[:, 1]
    h = radii[i] + radii[j] - np.linalg.norm(centres[i] - centres[j], axis=1)
    expected = np.asarray(rojek_pair_conductance(radii[i], radii[j], np.maximum(h, 0), 20.0))
    nbr = np.asarray(t.neighbors)
    k = np.array([np.asarray(t.conductance)[a, list(nbr[a]).index(b)] for a, b in pairs])
    np.testing.assert_allclose(k, expected, rtol=1e-14)
    # symmetric network: K_ij stored on both rows
    k_back = np.array([np.asarray(t.conductance)[b, list(nbr[b]).index(a)] for a, b in pairs])
    np.testing.assert_array_equal(k, k_back)


def test_insulated_packing_conserves_heat(bed):
    centres, radii = bed
    t = network.contact_table(centres, radii, 20.0)
    capacity = jnp.asarray(4 / 3 * np.pi * radii**3 * 4430 * 560)  # Ti6Al4V rho c (J/K)
    temperature = jnp.asarray(np.random.default_rng(0).uniform(300, 1000, len(radii)))
    dt = float(thermal.table_time_step(capacity, t))
    final, saved = simulate_table(temperature, t, capacity, dt, n_steps=400, save_every=100)
    energy = jnp.sum(capacity * saved, axis=1)
    np.testing.assert_allclose(energy, float(jnp.sum(capacity * temperature)), rtol=1e-13)
    # discrete maximum principle at the stable step
    assert float(saved.min()) >= float(temperature.min()) - 1e-9 and float(saved.max()) <= float(temperature.max()) + 1e-9
    implicit, _ = simulate_table(temperature, t, capacity, 50 * dt, n_steps=8, save_every=8, method="implicit")
    assert float(jnp.sum(capacity * implicit)) == pytest.approx(float(jnp.sum(capacity * temperature)), rel=1e-11)


def test_two_particle_relaxation_matches_analytic():
    centres, radii = sc_lattice(2)
    t = network.contact_table(centres, radii, 20.0)
    k = float(rojek_pair_conductance(R, R, 2 * R - A, 20.0))
    capacity = jnp.array([2e-3, 5e-3])
    rate = k * (1 / 2e-3 + 1 / 5e-3)  # d(T1 - T2)/dt = -rate (T1 - T2)
    t_end = 3.0 / rate
    temperature = jnp.array([1000.0, 300.0])
    errors = []
    for n_steps in (100, 200, 400):
        final, _ = simulate_table(temperature, t, capacity, t_end / n_steps, n_steps=n_steps, save_every=n_steps)
        errors.append(abs(float(final[0] - final[1]) - 700 * np.exp(-rate * t_end)))
    assert errors[0] / errors[1] == pytest.approx(2.0, rel=0.05) and errors[1] / errors[2] == pytest.approx(2.0, rel=0.05)
    assert errors[-1] < 2e-3 * 700
    final, _ = simulate_table(temperature, t, capacity, t_end / 400, n_steps=400, save_every=400, method="implicit")
    assert abs(float(final[0] - final[1]) - 700 * np.exp(-rate * t_end)) < 2e-3 * 700


@pytest.mark.slow
def test_chain_converges_to_the_heat_equation():
    # A chain of N particles with ends held at 0 relaxes its lowest mode at
    # (2K/C)(1 - cos(pi/(N-1))), the continuum rate pi^2 D / L^2 with D = K a^2 / C
    # up to O(1/N^2).
    ratios = []
    for n in (6, 11, 21, 41):
        centres, radii = sc_lattice(n)
        t = network.contact_table(centres, radii, 20.0)
        k = float(rojek_pair_conductance(R, R, 2 * R - A, 20.0))
        x = np.arange(n) * A
        length = (n - 1) * A
        mode = jnp.asarray(np.sin(np.pi * x / length))
        held = jnp.asarray((x == 0) | (x == length))
        capacity = 1e-3
        dt = 0.05 * float(thermal.table_time_step(capacity, t))
        steps = 2000
        final, _ = simulate_table(mode, t, capacity, dt, n_steps=steps, save_every=steps, fixed_mask=held,
                                    fixed_temperature=0.0)
        rate = -np.log(float(final[n // 2]) / float(mode[n // 2])) / (steps * dt)
        ratios.append(rate / (np.pi**2 * k * A**2 / capacity / length**2))
    errors = np.abs(np.array(ratios) - 1)
    assert np.all(np.diff(errors) < 0) and errors[-1] < 2e-3


@pytest.mark.slow
def test_explicit_implicit_and_steady_agree():
    centres, radii = sc_lattice(6, 2, 2)
    t = network.contact_table(centres, radii, 20.0)
    hot = jnp.asarray(centres[:, 0] == 0)
    cold = jnp.asarray(centres[:, 0] == centres[:, 0].max())
    fixed = hot | cold
    held = jnp.where(hot, 900.0, 300.0)
    field = steady.steady_state(t, fixed, held)
    np.testing.assert_allclose(field, 900 - 600 * centres[:, 0] / centres[:, 0].max(), rtol=1e-11)  # linear
    capacity = 1e-3
    dt = float(thermal.table_time_step(capacity, t))
    start = jnp.where(fixed, held, 300.0)
    explicit, _ = simulate_table(start, t, capacity, dt, n_steps=4000, save_every=4000, fixed_mask=fixed,
                                   fixed_temperature=held)
    implicit, _ = simulate_table(start, t, capacity, 200 * dt, n_steps=100, save_every=100, fixed_mask=fixed,
                                   fixed_temperature=held, method="implicit")
    np.testing.assert_allclose(explicit, field, rtol=1e-8)
    np.testing.assert_allclose(implicit, field, rtol=1e-8)


@pytest.mark.slow
@pytest.mark.parametrize("shape", [(2, 1, 1), (5, 1, 1), (4, 3, 2)])
def test_sc_lattice_conductivity_is_pair_conductance_over_spacing(shape):
    centres, radii = sc_lattice(*shape)
    k_star = steady.steady_state_conductivity(centres, radii, 20.0, axis=0)
    assert k_star == pytest.approx(float(rojek_pair_conductance(R, R, 2 * R - A, 20.0)) / A, rel=1e-12)


def test_bad_packing_input():
    centres, radii = sc_lattice(3)
    with pytest.raises(ValueError, match="h must be <= max_overlap"):
        network.contact_table(centres, np.full(3, 0.9 * A), 20.0)  # overlap beyond the neck model's range
    with pytest.raises(ValueError, match="kappa_i"):
        network.contact_table(centres, radii, -1.0)


def test_unstable_step_is_refused():
    centres, radii = sc_lattice(4)
    t = network.contact_table(centres, radii, 20.0)
    limit = thermal.check_table_time_step(1e-6, 1e-3, t)
    with pytest.raises(ValueError, match=r"dt = .* exceeds the explicit stability limit"):
        thermal.check_table_time_step(1.5 * limit, 1e-3, t)
    with pytest.raises(ValueError, match="dt must be finite and > 0"):
        thermal.check_table_time_step(-1.0, 1e-3, t)
    # and the limit is real: 2.5x above it the explicit step blows up (largest mode |1 - 2.5 * lambda| > 1)
    start = jnp.asarray(np.random.default_rng(0).uniform(300, 1000, len(radii)))
    final, _ = simulate_table(start, t, 1e-3, 2.5 * limit, n_steps=200, save_every=200)
    assert float(jnp.max(jnp.abs(final))) > 1e4


@pytest.mark.slow
def test_quintana_ruiz_5_3_setup_inside_hashin_shtrikman():
    # A settled random bed between a hot and a cold face, k = 100 W/(m K), the
    # conductivity-based law (Quintana-Ruiz Eqs. 32-35, lens radius). Our bed is
    # built geometrically with small settling overlaps (no Hertz mechanics yet),
    # so its contacts are far smaller than their 5.3 example's: k* is small,
    # but it must lie inside the HS bounds [0, 2 k f / (3 - f)].
    from sintercond.laws.effective import hashin_shtrikman_bounds

    bed = packing.powder_bed(320.0, 480.0, diameter_range=(45.0, 150.0), seed=7)
    centres, radii, box = packing.rev_box(bed, 200.0)
    m = geometry.rev_measures(centres, radii, box)
    k_star = steady.steady_state_conductivity(centres * 1e-6, radii * 1e-6, 100.0, axis=2, law="conductivity",
                                               box=(box[0] * 1e-6, box[1] * 1e-6))
    lower, upper = hashin_shtrikman_bounds(0.0, 100.0, m.n)
    assert float(lower) <= k_star <= float(upper)
    assert k_star > 0


def test_conducting_walls_in_series():
    # two particles between walls at 1000 K (x < 0) and 300 K (x > A): a chain of
    # three resistances, wall-1, 1-2, 2-wall, so the steady heat flow and the two
    # temperatures follow from 1/K_total = sum 1/K.
    centres, radii = sc_lattice(2)
    penetration = 0.02 * R
    k_w = network.wall_conductance(centres, radii, 20.0, axis=0, position=-R + penetration)
    k_w2 = network.wall_conductance(centres, radii, 20.0, axis=0, position=A + R - penetration)
    assert k_w[0] > 0 and k_w[1] == 0 and k_w2[1] == pytest.approx(k_w[0], rel=1e-12)
    table = network.contact_table(centres, radii, 20.0).with_walls(k_w + k_w2, np.where(k_w > 0, 1000.0, 300.0))
    k_12 = float(rojek_pair_conductance(R, R, 2 * R - A, 20.0))
    q = 700.0 / (2 / k_w[0] + 1 / k_12)
    field = np.asarray(steady.steady_state(table, jnp.zeros(2, bool), jnp.zeros(2)))
    np.testing.assert_allclose(field, [1000 - q / k_w[0], 300 + q / k_w[0]], rtol=1e-12)
    # the wall counts in the stable step, and explicit and implicit runs reach the same field
    capacity = 1e-3
    dt = float(thermal.table_time_step(capacity, table))
    assert dt == pytest.approx(capacity / (k_w[0] + k_12), rel=1e-12)
    explicit, _ = simulate_table(jnp.full(2, 300.0), table, capacity, dt, n_steps=20000, save_every=20000)
    implicit, _ = simulate_table(jnp.full(2, 300.0), table, capacity, 50 * dt, n_steps=400, save_every=400,
                                   method="implicit")
    np.testing.assert_allclose(explicit, field, rtol=1e-9)
    np.testing.assert_allclose(implicit, field, rtol=1e-9)


def test_periodic_packing_contacts_and_conservation():
    # a ring: 5 particles along x in a periodic box of 5 spacings, so the ends touch across the boundary
    centres, radii = sc_lattice(5)
    box = np.array([5 * A, 10 * A, 10 * A])
    free_table = find_contacts(centres, radii)
    periodic_table = find_contacts(centres, radii, periodic_box=box)
    degree = lambda t: np.sum(t != np.arange(len(radii))[:, None], axis=1)  # noqa: E731
    assert list(degree(free_table)) == [1, 2, 2, 2, 1]
    assert list(degree(periodic_table)) == [2, 2, 2, 2, 2]
    t = network.contact_table(centres, radii, 20.0, periodic_box=box)
    k = float(rojek_pair_conductance(R, R, 2 * R - A, 20.0))
    np.testing.assert_allclose(np.sort(np.asarray(t.conductance), axis=1)[:, -2:], k, rtol=1e-14)
    capacity = 1e-3
    start = jnp.asarray([1000.0, 300, 300, 300, 300])
    final, _ = simulate_table(start, t, capacity, float(thermal.table_time_step(capacity, t)), n_steps=3000,
                                save_every=3000)
    np.testing.assert_allclose(final, 440.0, rtol=1e-9)  # a ring equilibrates to the mean


@pytest.mark.slow
@pytest.mark.parametrize("per_particle_scale", [False, True])
def test_network_step_derivative_equals_plain_autodiff(bed, per_particle_scale):
    """explicit_update with a network (the written derivative, scale and capacity entering through
    conduction_rates, computed inside the step or passed in as a rollout does) against JAX's own
    derivative of the same step written with plain gathers: gradients in the temperature, power, pulse,
    scale and capacity agree to round-off."""
    centres, radii = bed
    table = network.contact_table(centres, radii, 1.0)
    n = len(radii)
    rng = np.random.default_rng(1)
    t0 = jnp.asarray(300.0 + 50.0 * rng.random(n))
    power, pulse = jnp.asarray(1e-3 * rng.random(n)), jnp.asarray(2e-3 * rng.random(n))
    capacity = jnp.asarray(4430.0 * 4 / 3 * np.pi * radii**3 * 560.0)
    scale = jnp.asarray(7.0 * (1.0 + 0.1 * rng.random(n))) if per_particle_scale else jnp.asarray(7.0)
    dt = 0.5 * float(thermal.explicit_stability_limit(capacity, float(jnp.max(scale)) * network.total_conductance(table)))
    weights = jnp.asarray(rng.random(n))

    def plain(t, p, q, s, c):
        lt = network.gather_laplacian(table.conductance, table.neighbors, t)
        return jnp.sum(weights * jnp.sin((t + dt * (p + 0.5 * q - s * lt) / c) / 50.0))

    def written(t, p, q, s, c, hoisted):
        rates = thermal.conduction_rates(s, c) if hoisted else None
        new = thermal.explicit_update(t, p, c, dt, network=(s, table.conductance, table.neighbors),
                                      pulse=(q, jnp.asarray(0.5)), rates=rates)
        return jnp.sum(weights * jnp.sin(new / 50.0))

    args = (t0, power, pulse, scale, capacity)
    reference = jax.jit(jax.grad(plain, argnums=tuple(range(5))))(*args)
    for hoisted in (False, True):
        assert float(written(*args, hoisted)) == pytest.approx(float(plain(*args)), rel=1e-15)
        grads = jax.jit(jax.grad(written, argnums=tuple(range(5))), static_argnums=5)(*args, hoisted)
        for g, r in zip(grads, reference):
            np.testing.assert_allclose(g, r, rtol=1e-12, atol=1e-14 * float(jnp.max(jnp.abs(r))))
