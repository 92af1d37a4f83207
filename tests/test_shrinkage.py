"""Many-body shrinkage of a sintering packing (``Sintering(shrinkage="many_body")``, second stage).

References: the law tier (:func:`sintercond.laws.sintering.grow_neck`, tested against closed forms) for contacts that
are free to approach; a closed form by symmetry (a weighted harmonic mean) for an over-constrained hexagon; a dense
least-squares minimisation of the dissipation, written here from the equations, for a random cluster; rigid
motions; conservation of heat; central differences.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import simulate
from sintercond.laws import neck, sintering
from sintercond.sim import neck_growth
from sintercond.state import particle_state

DENSITY, HEAT, KAPPA = 4430.0, 560.0, 7.0  # Ti6Al4V
KINETICS = {"A": 1e-16, "activation_energy": 100.0}
PSI = np.deg2rad(sintering.KINETIC_LAWS["grain_boundary"].default_params["dihedral_angle"])


def packing(x, radii, temperature, supports=None, every=1, dt=1e-3, held=False, kinetics=KINETICS, neck_ratio=0.0,
            recent_start=False):
    """A static packing whose contacts touch (or overlap), sintering many-body; ``(sim, state, params)``.

    ``held``: every particle held at its temperature (isothermal pairs, the contacts at known temperatures).
    ``neck_ratio``: start necks, as a fraction of the smaller radius (0: point contacts).
    """
    x, radii = np.asarray(x, np.float64), np.asarray(radii, np.float64)
    temperature = np.broadcast_to(np.asarray(temperature, np.float64), radii.shape)
    physics = simulate.Physics.create(law="rojek", neck_model="volume_conserving", conductance="lifted", held=held,
                                      sintering=neck_growth.Sintering(every=every, shrinkage="many_body",
                                                                                      balance_tol=1e-12,
                                                                                      recent_start=recent_start))
    particles = particle_state(x, radii, temperature, DENSITY, fixed=np.full(len(radii), held) if held else None,
                               fixed_temperature=temperature if held else None)
    contacts = simulate.lifted_contacts(physics, x, radii)
    if neck_ratio:
        pairs = np.asarray(contacts.pairs)
        r_min = np.minimum(radii[pairs[:, 0]], radii[pairs[:, 1]])
        a = neck_ratio * r_min
        contacts = dataclasses.replace(contacts, neck=jnp.asarray(a),
                                       overlap=jnp.asarray(sintering.neck_overlap(a, r_min, r_min)))
    supports = np.zeros((len(radii), 3), bool) if supports is None else supports
    state = simulate.init_state(particles, contacts, dt,
                                sintering=neck_growth.neck_state(contacts, particles.temperature, supports=supports,
                                                                 positions=particles.positions))
    params = simulate.Params(conductivity=[KAPPA], specific_heat=[HEAT], sintering=dict(kinetics))
    return simulate.simulator(physics), state, params


def run(sim, state, params, n_steps):
    return jax.jit(lambda s, p: simulate.rollout(sim, s, p, n_steps)[0])(state, params)


def free_neck(a0, r_i, r_j, temperature, duration, spec, updates=1):
    """The law tier's neck of a free pair held at ``temperature`` for ``duration``, in the simulator's ``updates``
    growth intervals."""
    return float(sintering.grow_neck("grain_boundary", a0, r_i, r_j, [temperature] * updates,
                                     [duration / updates] * updates, KINETICS,
                                     quadrature_nodes=spec.quadrature_nodes,
                                     newton_iterations=spec.newton_iterations)[-1])


def pair_slot(state, i, j):
    return int(np.flatnonzero(np.asarray(state.contacts.neighbors[i]) == j)[0])


def test_a_free_pair_approaches_and_grows_as_the_law_tier_and_keeps_its_centre():
    radii = np.array([40e-6, 30e-6])
    x = np.array([[0.0, 0.0, 0.0], [70e-6, 0.0, 0.0]]) @ np.array([[0.6, 0.8, 0.0], [-0.8, 0.6, 0.0], [0, 0, 1]])
    sim, state, params = packing(x, radii, 1150.0, held=True, every=5)
    end = run(sim, state, params, 50)
    expected = free_neck(0.0, *radii, 1150.0, 50 * float(state.dt), sim.physics.sintering, updates=10)
    assert expected > 0.05 * radii.min()
    np.testing.assert_allclose(float(end.contacts.table_neck[0, pair_slot(end, 0, 1)]), expected, rtol=1e-12)
    distance = np.linalg.norm(np.diff(np.asarray(end.particles.positions), axis=0))
    np.testing.assert_allclose(radii.sum() - distance, float(sintering.neck_overlap(expected, *radii)), rtol=1e-12)
    # no net motion: the two move by equal and opposite amounts along the line of centres
    np.testing.assert_allclose(np.asarray(end.particles.positions).mean(axis=0), x.mean(axis=0), atol=1e-20)
    stats = neck_growth.neck_statistics(end)
    np.testing.assert_allclose(float(stats["shrinkage"]), float(sintering.neck_overlap(expected, *radii)) / radii.sum(),
                               rtol=1e-12)
    assert not bool(end.sintering.unbalanced) and not bool(end.sintering.unstable)


def test_a_chain_on_a_support_closes_up_on_it_contact_by_contact():
    radii = np.array([40e-6, 30e-6, 35e-6, 45e-6])
    x = np.zeros((4, 3))
    x[1:, 2] = np.cumsum(radii[:-1] + radii[1:])
    supports = np.zeros((4, 3), bool)
    supports[0] = True
    sim, state, params = packing(x, radii, 1100.0, supports=supports, held=True, every=4)
    end = run(sim, state, params, 40)
    approach = [float(sintering.neck_overlap(free_neck(0.0, radii[k], radii[k + 1], 1100.0, 40e-3,
                                                       sim.physics.sintering, updates=10), radii[k], radii[k + 1]))
                for k in range(3)]
    expected = x.copy()
    expected[1:, 2] -= np.cumsum(approach)
    np.testing.assert_allclose(np.asarray(end.particles.positions), expected, rtol=0, atol=1e-12 * radii.max())
    assert np.asarray(end.particles.positions)[0].tolist() == x[0].tolist()


def test_a_uniform_simple_cubic_cell_shrinks_uniformly_about_its_centre():
    r, counts = 40e-6, 3
    grid = np.stack(np.meshgrid(*[np.arange(counts)] * 3, indexing="ij"), -1).reshape(-1, 3) * 2 * r
    sim, state, params = packing(grid, np.full(len(grid), r), 1200.0, held=True, every=10)
    end = run(sim, state, params, 30)
    a = free_neck(0.0, r, r, 1200.0, 30e-3, sim.physics.sintering, updates=3)
    h = float(sintering.neck_overlap(a, r, r))
    centre = grid.mean(axis=0)
    np.testing.assert_allclose(np.asarray(end.particles.positions), centre + (grid - centre) * (1 - h / (2 * r)),
                               rtol=0, atol=1e-10 * r)
    nbrs, necks = np.asarray(end.contacts.neighbors), np.asarray(end.contacts.table_neck)
    valid = (nbrs < len(grid)) & (nbrs != np.arange(len(grid))[:, None])
    np.testing.assert_allclose(necks[valid], a, rtol=1e-10)


def hexagon(temperatures_centre_rim=(1250.0, 1000.0), neck_ratio=0.05):
    """Seven equal spheres in a plane: one in the middle, six around it touching it and each other."""
    r = 40e-6
    angles = np.arange(6) * np.pi / 3
    x = np.concatenate([[[0.0, 0.0, 0.0]], 2 * r * np.stack([np.cos(angles), np.sin(angles), 0 * angles], 1)])
    temperature = np.array([temperatures_centre_rim[0]] + [temperatures_centre_rim[1]] * 6)
    return x, np.full(7, r), temperature


def test_an_over_constrained_hexagon_balances_its_contacts_as_the_weighted_harmonic_mean_closed_form():
    """Spokes and rim share one approach ``d`` by symmetry; the balance makes it
    ``(F_s + F_r) / (F_s / dh_s + F_r / dh_r)``, each contact's force over its free approach (module docstring)."""
    x, radii, temperature = hexagon()
    r, ratio, dt, steps = radii[0], 0.05, 1e-3, 20
    sim, state, params = packing(x, radii, temperature, held=True, every=steps, dt=dt, neck_ratio=ratio)
    end = run(sim, state, params, steps)
    a0 = ratio * r
    spoke_t, rim_t = 0.5 * (temperature[0] + temperature[1]), temperature[1]
    free = {}
    force = {}
    for name, t in (("spoke", spoke_t), ("rim", rim_t)):
        a = free_neck(a0, r, r, t, steps * dt, sim.physics.sintering)
        free[name] = float(sintering.neck_overlap(a, r, r) - sintering.neck_overlap(a0, r, r))
        a_mid = 0.5 * (a0 + a)  # Bouvard & McMeeking's force over pi gamma_s at the interval's mean neck
        force[name] = 4 * r * (1 - np.cos(PSI / 2)) + a_mid * np.sin(PSI / 2)
    d = (force["spoke"] + force["rim"]) / (force["spoke"] / free["spoke"] + force["rim"] / free["rim"])
    assert free["spoke"] > 1.5 * free["rim"]  # the spokes would shrink faster: the ring holds them back
    positions = np.asarray(end.particles.positions)
    np.testing.assert_allclose(positions[0], 0.0, atol=1e-12 * r)
    np.testing.assert_allclose(np.linalg.norm(positions[1:], axis=1), 2 * r - d, rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(positions[1:] - np.roll(positions[1:], 1, axis=0), axis=1),
                               2 * r - d, rtol=1e-12)
    expected_neck = float(neck.neck_radius(r, r, float(sintering.neck_overlap(a0, r, r)) + d))
    necks = np.asarray(end.contacts.table_neck)
    np.testing.assert_allclose(necks[0, pair_slot(end, 0, 1)], expected_neck, rtol=1e-11)
    np.testing.assert_allclose(necks[1, pair_slot(end, 1, 2)], expected_neck, rtol=1e-11)


def dense_balance(x, pairs, weights, free, supports):
    """The displacements minimising ``sum w (dh - dh_free)^2`` by a dense least-squares solve: the minimum-norm
    solution (no rigid motion), the supported components removed from the unknowns."""
    n = len(x)
    rows = np.zeros((len(pairs), 3 * n))
    for k, (i, j) in enumerate(pairs):
        normal = (x[j] - x[i]) / np.linalg.norm(x[j] - x[i])
        rows[k, 3 * i:3 * i + 3], rows[k, 3 * j:3 * j + 3] = normal, -normal
    keep = ~supports.reshape(-1)
    root = np.sqrt(weights)[:, None]
    u = np.zeros(3 * n)
    u[keep] = np.linalg.lstsq(root * rows[:, keep], np.sqrt(weights) * free, rcond=None)[0]
    return u.reshape(n, 3)


def test_the_balance_of_a_random_cluster_is_the_least_squares_minimum_of_the_dissipation():
    rng = np.random.default_rng(7)
    n = 40
    x = rng.uniform(0.0, 300e-6, (n, 3))
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if np.linalg.norm(x[i] - x[j]) < 150e-6])
    assert len(pairs) > 3 * n  # over-constrained: the contacts cannot all approach freely
    weights = rng.uniform(0.2, 5.0, len(pairs))
    free = rng.uniform(0.0, 1e-7, len(pairs))
    supports = np.zeros((n, 3), bool)
    supports[rng.choice(n, 3, replace=False), 2] = True
    u, unbalanced, _, _ = jax.jit(neck_growth.balance_displacements, static_argnums=5)(
        jnp.asarray(pairs), jnp.asarray(x), jnp.asarray(weights), jnp.asarray(free), jnp.asarray(supports), 1e-13)
    expected = dense_balance(x, pairs, weights, free, supports)
    scale = np.abs(expected).max()
    # the two agree up to the rigid motions the supports leave free (none with three z supports and enough contacts:
    # checked by the residual of the normal equations instead of the displacements where the system is singular)
    normal = (x[pairs[:, 1]] - x[pairs[:, 0]]) / np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1)[:, None]
    approach = lambda v: np.sum((v[pairs[:, 0]] - v[pairs[:, 1]]) * normal, axis=1)  # noqa: E731
    np.testing.assert_allclose(approach(np.asarray(u)), approach(expected), rtol=0, atol=1e-9 * scale)
    dissipation = lambda v: np.sum(weights * (approach(v) - free) ** 2)  # noqa: E731
    np.testing.assert_allclose(dissipation(np.asarray(u)), dissipation(expected), rtol=1e-9)
    assert np.all(np.asarray(u)[supports] == 0.0)
    assert not bool(unbalanced)


def test_an_insulated_many_body_run_conserves_heat_and_its_necks_grow_monotone():
    x, radii, temperature = hexagon((1300.0, 900.0), neck_ratio=0.0)
    sim, state, params = packing(x, radii, temperature, every=5, dt=2e-4, neck_ratio=0.02)
    capacity = np.asarray(state.particles.mass) * HEAT
    states = [state]
    for _ in range(4):
        states.append(run(sim, states[-1], params, 50))
    heat = [float(np.asarray(s.particles.temperature) @ capacity) for s in states]
    np.testing.assert_allclose(heat, heat[0], rtol=1e-13)
    necks = np.stack([np.asarray(s.contacts.neck) for s in states])
    assert np.all(np.isfinite(necks)) and np.all(np.diff(necks, axis=0) >= 0.0)
    assert necks[-1].max() > 1.5 * necks[0].max()
    assert not bool(states[-1].sintering.unbalanced)


GRADIENT_POINT = (float(np.log(1e-16)), 100.0)  # ln A (A in m^4 K/s), Q (kJ/mol)


def kinetic_params(log_a, q):
    return simulate.Params(conductivity=[KAPPA], specific_heat=[HEAT],
                           sintering={"A": jnp.exp(log_a), "activation_energy": q})


def assert_gradients_equal_central_differences(f, point=GRADIENT_POINT, steps=(1e-3, 1e-2)):
    """``jax.grad`` of ``f(ln A, Q)`` against Richardson-extrapolated central differences (error O(step^4)), 1e-6."""
    grads = jax.jit(jax.grad(f, argnums=(0, 1)))(*point)
    f = jax.jit(f)
    for k, step in enumerate(steps):
        def at(delta, k=k):
            args = list(point)
            args[k] = args[k] + delta
            return float(f(*args))
        d1 = (at(step) - at(-step)) / (2 * step)
        d2 = (at(2 * step) - at(-2 * step)) / (4 * step)
        np.testing.assert_allclose(float(grads[k]), (4 * d1 - d2) / 3, rtol=1e-6)


@pytest.mark.slow
def test_the_gradient_of_the_shrinkage_by_the_kinetic_parameters_equals_central_differences():
    x, radii, temperature = hexagon()
    sim, state, params = packing(x, radii, temperature, held=True, every=5, dt=1e-3, neck_ratio=0.05)

    def shrinkage(log_a, q):
        return neck_growth.neck_statistics(simulate.rollout(sim, state, kinetic_params(log_a, q), 20)[0])["shrinkage"]

    assert_gradients_equal_central_differences(shrinkage)


def test_many_body_shrinkage_refuses_a_state_without_supports_and_a_contact_across_a_boundary():
    x, radii, temperature = hexagon()
    sim, state, params = packing(x, radii, temperature)
    with pytest.raises(ValueError, match="NeckState.supports"):
        simulate.rollout(sim, state.__class__(**{**state.__dict__, "sintering": neck_growth.neck_state(
            state.contacts, state.particles.temperature)}), params, 1)
    far = np.array(x)
    far[1] *= 1.5  # particle 1 listed as touching 0 and 2 though it is not (as across a periodic boundary)
    apart = state.__class__(**{**state.__dict__, "sintering": state.sintering.__class__(
        **{**state.sintering.__dict__, "start_positions": jnp.asarray(far)})})
    with pytest.raises(ValueError, match="particles 0 and 1 are .* apart"):
        simulate.rollout(sim, apart, params, 1)
    # a contact pulled apart by the balance during the run (not at its start) is no reason to refuse a resume
    moved = state.__class__(**{**state.__dict__, "particles": state.particles.__class__(
        **{**state.particles.__dict__, "positions": jnp.asarray(far)})})
    simulate.rollout(sim, moved, params, 1)
    with pytest.raises(ValueError, match="supports and positions together"):
        neck_growth.neck_state(state.contacts, state.particles.temperature, supports=np.zeros((7, 3), bool))
    independent = simulate.simulator(simulate.Physics.create(
        law="rojek", neck_model="volume_conserving", conductance="lifted", sintering=neck_growth.Sintering()))
    with pytest.raises(ValueError, match="supports is for Sintering"):
        simulate.rollout(independent, state, params, 1)
    with pytest.raises(ValueError, match="Sintering.shrinkage must be one of"):
        neck_growth.Sintering(shrinkage="collective")
    with pytest.raises(ValueError, match="Sintering.balance_tol"):
        neck_growth.Sintering(balance_tol=0.0)
    with pytest.raises(ValueError, match=r"supports must be a \[n, 3\]"):
        neck_growth.neck_state(state.contacts, state.particles.temperature, supports=np.zeros((7, 2), bool),
                               positions=x)


def test_a_balance_that_did_not_converge_is_refused_on_the_host():
    x, radii, temperature = hexagon()
    sim, state, params = packing(x, radii, temperature)
    flagged = state.__class__(**{**state.__dict__, "sintering": state.sintering.__class__(
        **{**state.sintering.__dict__, "unbalanced": jnp.asarray(True)})})
    with pytest.raises(FloatingPointError, match="many-body sintering balance did not converge"):
        neck_growth.check_stable(flagged)
    neck_growth.check_stable(state)


def test_a_balance_that_cannot_reach_its_tolerance_is_flagged():
    rng = np.random.default_rng(7)
    n = 30
    x = rng.uniform(0.0, 250e-6, (n, 3))
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if np.linalg.norm(x[i] - x[j]) < 150e-6])
    args = (jnp.asarray(pairs), jnp.asarray(x), jnp.asarray(rng.uniform(0.2, 5.0, len(pairs))),
            jnp.asarray(rng.uniform(0.0, 1e-7, len(pairs))), jnp.zeros((n, 3), bool))
    assert not bool(neck_growth.balance_displacements(*args, 1e-12)[1])
    assert bool(neck_growth.balance_displacements(*args, 1e-300)[1])  # below round-off: never reached


def test_the_shrinkage_of_a_packing_with_start_necks_is_zero_at_the_start():
    x, radii, temperature = hexagon()
    sim, state, params = packing(x, radii, temperature, neck_ratio=0.05)
    assert float(neck_growth.neck_statistics(state)["shrinkage"]) == 0.0


def test_stiff_contacts_that_stopped_growing_still_balance():
    """A tenth of the contacts do not grow (at their cap, or cold): weighted as the update weights them."""
    rng = np.random.default_rng(7)
    n = 60
    x = rng.uniform(0.0, 330e-6, (n, 3)) + 2e-3
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if np.linalg.norm(x[i] - x[j]) < 120e-6])
    free = rng.uniform(0.5e-9, 1e-9, len(pairs))
    free[rng.random(len(pairs)) < 0.1] = 0.0
    weights = rng.uniform(1.0, 3.0, len(pairs)) / np.maximum(free, neck_growth.STIFF_CONTACT_RATIO * free.max())
    supports = np.zeros((n, 3), bool)
    supports[np.argsort(x[:, 2])[:5], 2] = True
    u, unbalanced, _, _ = neck_growth.balance_displacements(jnp.asarray(pairs), jnp.asarray(x),
                                                            jnp.asarray(weights), jnp.asarray(free),
                                                            jnp.asarray(supports), 1e-12)
    assert not bool(unbalanced)
    expected = dense_balance(x, pairs, weights, free, supports)
    normal = (x[pairs[:, 1]] - x[pairs[:, 0]]) / np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1)[:, None]
    approach = lambda v: np.sum((v[pairs[:, 0]] - v[pairs[:, 1]]) * normal, axis=1)  # noqa: E731
    np.testing.assert_allclose(approach(np.asarray(u)), approach(expected), rtol=0, atol=1e-8 * free.max())


def test_a_balance_with_a_non_finite_weight_is_flagged():
    x, _, _ = hexagon()
    pairs = jnp.array([[0, k] for k in range(1, 7)])
    weights = jnp.array([1.0, 1.0, jnp.inf, 1.0, 1.0, 1.0])
    _, unbalanced, _, _ = neck_growth.balance_displacements(pairs, jnp.asarray(x), weights, jnp.full(6, 1e-9),
                                                            jnp.zeros((7, 3), bool), 1e-12)
    assert bool(unbalanced)


@pytest.mark.slow
def test_gradients_of_positions_equal_central_differences_and_are_zero_when_nothing_grows():
    x, radii, temperature = hexagon()
    sim, state, params = packing(x, radii, temperature, held=True, every=5, dt=1e-3, neck_ratio=0.05)

    def positions(log_a, q):
        end = simulate.rollout(sim, state, kinetic_params(log_a, q), 10)[0]
        return end.particles.positions[1, 0] + 0.3 * end.particles.positions[2, 1]

    assert_gradients_equal_central_differences(positions)
    # no contact grows in an update (the Arrhenius factor underflows to 0, every weight 0): zero gradients, no NaN
    cold = jax.jit(jax.grad(positions, argnums=(0, 1)))(jnp.log(1e-16), 20000.0)
    assert all(np.isfinite(float(g)) and float(g) == 0.0 for g in cold)


@pytest.mark.slow
@pytest.mark.parametrize("recent_start", [False, True])
def test_float32_many_body_shrinkage_agrees_with_float64_to_its_stated_accuracy(recent_start):
    """docs/simulator.md: necks to about 1e-6 relative; displacements to a few 1e-5 of themselves (the float32
    positions round each update's small displacement to their own spacing); from rest and from the recent
    balances."""
    x, radii, temperature = hexagon((1300.0, 900.0))
    sim, state, params = packing(x, radii, temperature, every=5, dt=2e-4, neck_ratio=0.05, recent_start=recent_start)
    single = jax.tree_util.tree_map(lambda a: a.astype(jnp.float32) if a.dtype == jnp.float64 else a, state)
    params32 = simulate.Params(conductivity=jnp.array([KAPPA], jnp.float32), specific_heat=jnp.array([HEAT], jnp.float32),
                               sintering={k: jnp.float32(v) for k, v in KINETICS.items()})
    end64, end32 = run(sim, state, params, 500), run(sim, single, params32, 500)
    assert end32.particles.positions.dtype == end32.contacts.neck.dtype == jnp.float32
    assert not bool(end32.sintering.unbalanced)
    necks64, necks32 = np.asarray(end64.contacts.neck), np.asarray(end32.contacts.neck, np.float64)
    np.testing.assert_allclose(necks32, necks64, rtol=0, atol=1e-6 * necks64.max())
    u64 = np.asarray(end64.particles.positions) - x
    u32 = np.asarray(end32.particles.positions, np.float64) - x
    assert np.abs(u64).max() > 1e-7  # the ring did move (m)
    np.testing.assert_allclose(u32, u64, rtol=0, atol=2e-4 * np.abs(u64).max())


def test_conjugate_gradients_solve_a_dense_system_and_count_their_iterations():
    """The counted solve against numpy's dense one, and its iterations against the same recurrence in numpy."""
    rng = np.random.default_rng(3)
    q = np.linalg.qr(rng.normal(size=(30, 30)))[0]
    matrix = q @ np.diag(np.geomspace(1.0, 10.0, 30)) @ q.T
    b = rng.normal(size=30)
    diagonal = np.diag(matrix)
    x, iterations = neck_growth.conjugate_gradients(lambda v: jnp.asarray(matrix) @ v, jnp.asarray(b),
                                                    jnp.zeros(30), lambda r: r / jnp.asarray(diagonal), 1e-10, 1000)
    np.testing.assert_allclose(np.asarray(x), np.linalg.solve(matrix, b), rtol=1e-8)
    y, r = np.zeros(30), b.copy()  # preconditioned CG as in Saad (2003), Algorithm 9.1
    z = r / diagonal
    p, count = z.copy(), 0
    while r @ r > (1e-10 * np.linalg.norm(b)) ** 2:
        ap = matrix @ p
        alpha = (r @ z) / (p @ ap)
        y, r_new = y + alpha * p, r - alpha * ap
        z_new = r_new / diagonal
        p, r, z, count = z_new + (r_new @ z_new) / (r @ z) * p, r_new, z_new, count + 1
    assert int(iterations) == count
    assert 5 < count < 30
    _, none = neck_growth.conjugate_gradients(lambda v: jnp.asarray(matrix) @ v, jnp.asarray(b),
                                              jnp.asarray(np.linalg.solve(matrix, b)), lambda r: r, 1e-10, 1000)
    assert int(none) == 0  # started at the solution


def test_a_balance_started_from_earlier_displacements_reaches_the_same_minimum_in_fewer_iterations():
    """The random over-constrained cluster: from rest, from its own solution (no iteration), and from the solution of
    a balance whose weights differ by 1e-4 (as the next update's do, some 1e-4 to 1e-3), against the dense least squares."""
    rng = np.random.default_rng(11)
    n = 40
    x = rng.uniform(0.0, 300e-6, (n, 3))
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if np.linalg.norm(x[i] - x[j]) < 150e-6])
    weights = rng.uniform(0.2, 5.0, len(pairs))
    free = rng.uniform(0.0, 1e-7, len(pairs))
    supports = np.zeros((n, 3), bool)
    supports[rng.choice(n, 3, replace=False), 2] = True
    solve = jax.jit(neck_growth.balance_displacements, static_argnums=5)
    args = lambda w: (jnp.asarray(pairs), jnp.asarray(x), jnp.asarray(w), jnp.asarray(free), jnp.asarray(supports))  # noqa: E731
    _, _, from_rest, balance = solve(*args(weights), 1e-12)
    recent = jnp.stack([balance, jnp.zeros_like(balance)])
    _, _, from_itself, _ = solve(*args(weights), 1e-12, None, recent)
    assert int(from_itself) <= 1 < int(from_rest)
    changed = weights * rng.uniform(0.9999, 1.0001, len(weights))
    u_rest = solve(*args(changed), 1e-12)[0]
    u_warm, unbalanced, _, _ = solve(*args(changed), 1e-12, None, recent)
    assert not bool(unbalanced)
    rest, warm = solve(*args(changed), 1e-8)[2], solve(*args(changed), 1e-8, None, recent)[2]  # the default tolerance
    assert int(warm) <= int(rest) - 10
    expected = dense_balance(x, pairs, changed, free, supports)
    normal = (x[pairs[:, 1]] - x[pairs[:, 0]]) / np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1)[:, None]
    approach = lambda v: np.sum((v[pairs[:, 0]] - v[pairs[:, 1]]) * normal, axis=1)  # noqa: E731
    for v in (u_rest, u_warm):
        np.testing.assert_allclose(approach(np.asarray(v)), approach(expected), rtol=0, atol=1e-9 * np.abs(expected).max())
        assert np.all(np.asarray(v)[supports] == 0.0)


def test_a_heated_lattice_reports_its_balance_iterations_and_later_updates_take_fewer():
    """A 6 x 6 x 6 simple cubic lattice on a plate, heated along a ramp: the first update starts from rest, the later
    ones from the earlier displacements (the last ones 0.6 of the first's or fewer), and the necks are those of balances solved
    from rest to the same tolerance."""
    side, r = 6, 40e-6
    grid = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1).reshape(-1, 3)
    x = grid * 2 * r + r
    radii = np.full(len(x), r)
    temperature = np.linspace(1000.0, 1300.0, len(x))
    supports = np.zeros((len(x), 3), bool)
    supports[:, 2] = x[:, 2] == x[:, 2].min()
    sim, state, params = packing(x, radii, temperature, supports=supports, every=5, dt=2e-4, neck_ratio=0.05,
                                 recent_start=True)

    def rollout(s, p):
        return simulate.rollout(sim, s, p, 60, simulate.SaveAt(5, lambda s: s.sintering.balance_iterations))

    end, iterations = jax.jit(rollout)(state, params)
    iterations = np.asarray(iterations)
    assert iterations[0] > 20
    assert np.all(iterations[1:] < iterations[0]) and np.all(iterations[-4:] <= 0.6 * iterations[0])
    rest_sim = packing(x, radii, temperature, supports=supports, every=5, dt=2e-4, neck_ratio=0.05)[0]
    from_rest, rest_iterations = jax.jit(lambda s, p: simulate.rollout(
        rest_sim, s, p, 60, simulate.SaveAt(5, lambda s: s.sintering.balance_iterations)))(state, params)
    assert np.all(np.asarray(rest_iterations)[1:] > iterations[1:])
    necks, expected = np.asarray(end.contacts.neck), np.asarray(from_rest.contacts.neck)
    np.testing.assert_allclose(necks, expected, rtol=1e-9)


def test_the_balance_gathered_on_a_table_equals_the_balance_scattered_from_its_pairs():
    """A static table's rows (each contact in both) give the same forces as the pairs: a hexagonal ring with a
    centre, random dashpots and free approaches, one sphere's vertical held."""
    x, radii, temperature = hexagon((1300.0, 900.0))
    sim, state, params = packing(x, radii, temperature)
    contacts = state.contacts
    rng = np.random.default_rng(5)
    c = contacts.pairs.shape[0]
    supports = np.zeros((len(radii), 3), bool)
    supports[0, 2] = True
    args = (contacts.pairs, state.particles.positions, jnp.asarray(rng.uniform(0.5, 2.0, c)),
            jnp.asarray(rng.uniform(0.0, 1e-8, c)), jnp.asarray(supports), 1e-12)
    scattered = neck_growth.balance_displacements(*args)[0]
    gathered, unbalanced, _, _ = neck_growth.balance_displacements(*args, table=(contacts.slot_pair,
                                                                                contacts.neighbors))
    assert not bool(unbalanced)
    assert np.abs(np.asarray(scattered)).max() > 1e-10
    np.testing.assert_allclose(np.asarray(gathered), np.asarray(scattered), rtol=0,
                               atol=1e-9 * np.abs(np.asarray(scattered)).max())


@pytest.mark.slow
def test_the_starts_from_recent_balances_carry_no_free_motions_over_hundreds_of_updates():
    """A 6 x 6 x 6 simple cubic lattice (rows that slide: floppy) at random temperatures, 400 updates: the positions
    against those of balances solved from rest (whose free motions are left out at every update). Kept as
    displacements, the recent updates carried their free motions on and extrapolated them (8 % of the largest
    displacement here); kept as ``B u`` mapped by the new blocks, 0.1 %; kept as contact values, the starts lie in
    the range of the system on its new normals, and the positions are those from rest."""
    side, r = 6, 40e-6
    grid = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1).reshape(-1, 3)
    x = grid * 2 * r + r
    temperature = np.random.default_rng(0).uniform(1000.0, 1300.0, len(x))
    supports = np.zeros((len(x), 3), bool)
    supports[:, 2] = x[:, 2] == x[:, 2].min()
    sim, state, params = packing(x, np.full(len(x), r), temperature, supports=supports, every=5, dt=2e-4,
                                 neck_ratio=0.05, recent_start=True)
    end = jax.jit(lambda s, p: simulate.rollout(sim, s, p, 2000, checkpoint=False)[0])(state, params)
    rest_sim = packing(x, np.full(len(x), r), temperature, supports=supports, every=5, dt=2e-4, neck_ratio=0.05)[0]
    from_rest = jax.jit(lambda s, p: simulate.rollout(rest_sim, s, p, 2000, checkpoint=False)[0])(state, params)
    u, u_rest = (np.asarray(s.particles.positions) - x for s in (end, from_rest))
    assert np.abs(u_rest).max() > 1e-6  # m
    np.testing.assert_allclose(u, u_rest, rtol=0, atol=1e-8 * np.abs(u_rest).max())
    np.testing.assert_allclose(np.asarray(end.contacts.neck), np.asarray(from_rest.contacts.neck), rtol=1e-8)


def test_a_start_from_an_earlier_balance_leaves_no_slide_on_a_sphere_with_one_contact():
    """A sphere resting on one contact of a chain, its normal turned by 1e-3 rad since the recent balance: the
    balance leaves its slide along the contact free, and from rest the solve moves it along the normal only. The start from the
    recent ``B u`` had a part of 1e-3 along the slide, divided by the blocks' floor (1e-3): the sphere slid as far
    as its contact approached, update after update (a poured bed's shrinkage -0.060 against 0.0042 from rest).
    With the start, the slide is nil and the approaches are the dense least squares'."""
    r = 40e-6
    x = np.array([[0.0, 0.0, 0.0], [2 * r, 0.0, 0.0], [4 * r, 0.0, 0.0], [2 * r + r, 0.0, 2 * r * np.sin(np.pi / 3)]])
    pairs = np.array([[0, 1], [1, 2], [1, 3]])
    weights, free = np.array([1.0, 2.0, 0.5]), np.array([3e-8, 1e-8, 2e-8])
    supports = np.zeros((4, 3), bool)
    supports[0] = True
    solve = jax.jit(neck_growth.balance_displacements, static_argnums=5)
    args = lambda y: (jnp.asarray(pairs), jnp.asarray(y), jnp.asarray(weights), jnp.asarray(free),  # noqa: E731
                      jnp.asarray(supports))
    balance = solve(*args(x), 1e-12)[3]
    turn = 1e-3
    c, s = np.cos(turn), np.sin(turn)
    turned = x.copy()
    turned[3] = x[1] + np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]]) @ (x[3] - x[1])
    normal = (turned[3] - turned[1]) / np.linalg.norm(turned[3] - turned[1])
    u_rest = np.asarray(solve(*args(turned), 1e-12)[0])
    u_warm, unbalanced, _, _ = solve(*args(turned), 1e-12, None, jnp.stack([balance, jnp.zeros_like(balance)]))
    u_warm = np.asarray(u_warm)
    assert not bool(unbalanced)

    def slide(u):  # sphere 3's displacement in its contact's tangent plane
        return np.linalg.norm(u[3] - np.dot(u[3], normal) * normal)

    scale = np.abs(u_rest).max()
    assert scale > 1e-9 and slide(u_rest) <= 1e-9 * scale
    assert slide(u_warm) <= 1e-6 * scale
    expected = dense_balance(turned, pairs, weights, free, supports)
    normals = turned[pairs[:, 1]] - turned[pairs[:, 0]]
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    approach = lambda v: np.sum((v[pairs[:, 0]] - v[pairs[:, 1]]) * normals, axis=1)  # noqa: E731
    np.testing.assert_allclose(approach(u_warm), approach(expected), rtol=0, atol=1e-9 * scale)


def test_a_poured_bed_shrinks_as_from_rest_when_its_balances_start_from_the_recent_ones():
    """A rolled bed of polydisperse spheres on a plate (many on one or two contacts), heated from below, 100
    many-body updates: the positions and the shrinkage with the balances started from the recent ones against
    those solved from rest (no free motion carried on)."""
    from sintercond.beds.packing import powder_bed

    bed = powder_bed(0.4e-3, 0.25e-3, (45e-6, 105e-6), seed=3)
    x, radii = np.asarray(bed.centres, np.float64), np.asarray(bed.radii, np.float64)
    temperature = 1250.0 - 2e5 * (x[:, 2] - x[:, 2].min())
    supports = np.zeros((len(x), 3), bool)
    supports[:, 2] = x[:, 2] - radii < 1e-7  # on the floor
    sim, state, params = packing(x, radii, temperature, supports=supports, every=5, dt=2e-4, neck_ratio=0.05,
                                 recent_start=True)

    rest_sim = packing(x, radii, temperature, supports=supports, every=5, dt=2e-4, neck_ratio=0.05)[0]
    warm, from_rest = (jax.jit(lambda s, p, sim=sim: simulate.rollout(sim, s, p, 500, checkpoint=False)[0])(
        state, params) for sim in (sim, rest_sim))
    u, u_rest = (np.asarray(s.particles.positions) - x for s in (warm, from_rest))
    assert np.abs(u_rest).max() > 1e-7  # m
    np.testing.assert_allclose(u, u_rest, rtol=0, atol=1e-9 * np.abs(u_rest).max())  # measured: 2e-12
    shrinkage = [float(neck_growth.neck_statistics(s)["shrinkage"]) for s in (warm, from_rest)]
    assert shrinkage[1] > 0
    np.testing.assert_allclose(shrinkage[0], shrinkage[1], rtol=1e-9)
    assert int(warm.sintering.balance_iterations) < int(from_rest.sintering.balance_iterations)


def test_a_balance_keeps_the_contact_values_of_its_blocks_times_its_displacements_until_their_self_stress_grows():
    """A chain of four spheres held at both ends (a self-stress: equal contact values along it are in balance on
    their own). A balance returns contact values ``y`` with ``sum_j y_ij n_ij = B u`` on every movable component;
    given recent values with a self-stress 1e10 times its forces added (each solve adds some, and the starts carry
    them on), the displacements are those from rest, and its values, whose round-off no longer gives its ``B u``,
    are not kept (zeros: the recent ones are cleared, :func:`neck_growth.pushed`)."""
    r = 40e-6
    x = np.array([[2 * r * k, 0.0, 0.0] for k in range(4)])
    pairs = np.array([[0, 1], [1, 2], [2, 3]])
    weights, free = np.array([1.0, 3.0, 2.0]), np.array([2e-8, 1e-8, 3e-8])
    supports = np.zeros((4, 3), bool)
    supports[[0, 3]] = True
    solve = jax.jit(neck_growth.balance_displacements, static_argnums=5)
    args = (jnp.asarray(pairs), jnp.asarray(x), jnp.asarray(weights), jnp.asarray(free), jnp.asarray(supports))
    u, _, _, balance = solve(*args, 1e-12)
    u, balance = np.asarray(u), np.asarray(balance)
    blocks, _ = neck_growth.balance_blocks(jnp.asarray(pairs), jnp.asarray(np.tile([1.0, 0.0, 0.0], (3, 1))),
                                           jnp.asarray(weights), jnp.asarray(~supports))
    b_u = np.where(~supports, np.einsum("nab,nb->na", np.asarray(blocks), u), 0.0)
    on_particles = np.zeros((4, 3))
    np.add.at(on_particles, pairs[:, 0], balance[:, None] * [1.0, 0.0, 0.0])
    np.add.at(on_particles, pairs[:, 1], -balance[:, None] * [1.0, 0.0, 0.0])
    on_particles[supports] = 0.0
    assert np.abs(b_u).max() > 0
    np.testing.assert_allclose(on_particles, b_u, rtol=0, atol=1e-12 * np.abs(b_u).max())
    stressed = jnp.stack([jnp.asarray(balance + 1e10 * np.abs(balance).max()), jnp.zeros(3)])
    u_stressed, unbalanced, _, kept = solve(*args, 1e-12, None, stressed)
    assert not bool(unbalanced)
    np.testing.assert_allclose(np.asarray(u_stressed), u, rtol=0, atol=1e-10 * np.abs(u).max())
    assert np.all(np.asarray(kept) == 0.0)
    recent = neck_growth.pushed(stressed, kept)
    assert np.all(np.asarray(recent) == 0.0)
    assert np.all(np.asarray(neck_growth.pushed(stressed, jnp.asarray(balance))[0]) == balance)


def test_a_checkpoint_of_balances_kept_per_particle_is_refused_naming_the_leaf(tmp_path):
    """Checkpoints written before the balances were kept as contact values hold them as ``[k, n, 3]``: refused on
    resume with the "another version" message, not broadcast into the start."""
    from sintercond.output.io import load_checkpoint, save_checkpoint

    x, radii, temperature = hexagon((1300.0, 900.0))
    _, state, _ = packing(x, radii, temperature)
    carried = state.sintering
    old = dataclasses.replace(state, sintering=dataclasses.replace(
        carried, recent_balances=jnp.zeros((carried.recent_balances.shape[0], len(radii), 3))))
    save_checkpoint(tmp_path, old)
    with pytest.raises(ValueError, match=r"\.sintering\.recent_balances of shape \(4, 7, 3\).*another version"):
        load_checkpoint(tmp_path / "checkpoint.npz", state)
    save_checkpoint(tmp_path, state)
    loaded = load_checkpoint(tmp_path / "checkpoint.npz", state)
    assert loaded.sintering.recent_balances.shape == carried.recent_balances.shape
