"""Necks that grow in the simulator (first stage: the packing does not move, contacts sinter independently).

References: the law tier (:func:`sintercond.laws.sintering.grow_neck`, itself tested against closed forms), conservation of
heat, the kinetic law's cap, and central differences.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import rollout, simulate
from sintercond.laws import sintering
from sintercond.sim import neck_growth
from sintercond.state import particle_state

DENSITY, HEAT, KAPPA = 4430.0, 560.0, 7.0  # Ti6Al4V
KINETICS = {"A": 1e-16, "activation_energy": 100.0}  # necks of a few um in a second at 1000-1200 K


def chain(radii, temperatures, every=1, dt=1e-3, pulse=None, kinetics=KINETICS, law="grain_boundary", neck_rtol=None):
    """Spheres in a row along x, each touching the next at a point; ``(sim, state, params)``."""
    radii = np.asarray(radii, np.float64)
    x = np.zeros((len(radii), 3))
    x[1:, 0] = np.cumsum(radii[:-1] + radii[1:])
    physics = simulate.Physics.create(law="rojek", neck_model="volume_conserving", conductance="lifted",
                                      pulse=pulse is not None,
                                      sintering=neck_growth.Sintering(law, every=every, neck_rtol=neck_rtol))
    particles = particle_state(x, radii, np.asarray(temperatures, np.float64), DENSITY)
    contacts = simulate.lifted_contacts(physics, x, radii)
    state = simulate.init_state(particles, contacts, dt, sintering=neck_growth.neck_state(contacts,
                                                                                          particles.temperature))
    params = simulate.Params(conductivity=[KAPPA], specific_heat=[HEAT], sintering=dict(kinetics), pulse=pulse)
    return simulate.simulator(physics), state, params


def pulsed_chain(every=1, neck_rtol=None):
    pulse = simulate.PulseParams(power=jnp.array([2e-3, 0.0, 0.0]), duration=0.15)
    return chain([40e-6, 30e-6, 35e-6], [1000.0, 1100.0, 1050.0], every=every, pulse=pulse, neck_rtol=neck_rtol)


def saved_states(sim, state, params, n_steps):
    """Temperatures ``[n_steps + 1, n]`` and the table's necks ``[n_steps + 1, n, m]`` after every step, the start included."""
    observe = lambda s: (s.particles.temperature, s.contacts.table_neck)  # noqa: E731
    end, (temperature, neck) = jax.jit(lambda s, p: simulate.rollout(sim, s, p, n_steps, simulate.SaveAt(1, observe))
                                       )(state, params)
    return end, (jnp.concatenate([state.particles.temperature[None], temperature]),
                 jnp.concatenate([state.contacts.table_neck[None], neck]))


@pytest.mark.parametrize("every", [1, 4])
def test_each_contact_grows_as_the_law_tier_does_along_its_own_temperature_history(every):
    sim, state, params = pulsed_chain(every)
    n_steps = 240
    end, (temperature, _) = saved_states(sim, state, params, n_steps)
    radii = np.asarray(state.particles.radii)
    for i, j, slot in ((0, 1, 0), (1, 2, 1)):
        pair = 0.5 * (temperature[:, i] + temperature[:, j])
        ends = pair[every::every]
        starts = pair[0:-every:every]
        history = 0.5 * (starts + ends)  # the trapezoid of each growth interval (neck_growth's docstring)
        durations = np.full(len(history), every * float(state.dt))
        spec = sim.physics.sintering  # the same integration as the law tier's, with the spec's nodes and steps
        expected = sintering.grow_neck("grain_boundary", 0.0, radii[i], radii[j], history, durations, KINETICS,
                                       quadrature_nodes=spec.quadrature_nodes,
                                       newton_iterations=spec.newton_iterations)[-1]
        got = float(end.contacts.table_neck[i, slot])
        assert float(expected) > 0.1 * min(radii[i], radii[j])  # the necks did grow
        np.testing.assert_allclose(got, float(expected), rtol=1e-12)
        np.testing.assert_allclose(float(end.contacts.table_overlap[i, slot]),
                                   float(sintering.neck_overlap(expected, radii[i], radii[j])), rtol=1e-12)
    assert np.ptp(np.asarray(temperature[:, 0])) > 50.0  # the history is not isothermal


def test_necks_at_their_own_pace_grow_as_the_law_tier_does_over_the_intervals_their_growth_sets():
    """Sintering(neck_rtol=0.02, every=16) on the pulsed chain: the updates (read from the necks saved at every step)
    come at intervals that follow the rule, recomputed here from the saved necks (the first one step, then the last
    scaled by neck_rtol over the largest relative growth in it, floored, at least 1, at most doubled and at most
    every); each contact's neck equals the law tier's integration over those intervals (the trapezoid of each) to
    1e-12; there are fewer updates than steps; and at its last update each neck is within neck_rtol of the necks
    updated at every step."""
    rtol, every, n_steps = 0.02, 16, 240
    sim, state, params = pulsed_chain(every, rtol)
    end, (temperature, neck) = saved_states(sim, state, params, n_steps)
    radii = np.asarray(state.particles.radii)
    first = np.asarray(neck[:, 0, 0])
    updates = np.flatnonzero(np.diff(first) != 0) + 1  # the steps whose end grew the necks
    lengths = np.diff(np.concatenate([[0], updates]))
    assert lengths[0] == 1 and len(updates) < n_steps / 3 and lengths.max() > 4
    slots = ((0, 1, 0), (1, 2, 1))
    necks = np.stack([np.asarray(neck[:, i, slot]) for i, _, slot in slots])
    for k in range(len(lengths) - 1):
        before = necks[:, updates[k] - lengths[k]]
        after = necks[:, updates[k]]
        growth = np.max((after - before) / after)
        expected = min(max(np.floor(lengths[k] * rtol / growth), 1), 2 * lengths[k], every)
        assert lengths[k + 1] == expected, k
    spec = sim.physics.sintering
    for (i, j, _), row in zip(slots, necks):
        pair = 0.5 * (np.asarray(temperature[:, i]) + np.asarray(temperature[:, j]))
        starts = np.concatenate([[0], updates[:-1]])
        history = 0.5 * (pair[starts] + pair[updates])
        durations = lengths * float(state.dt)
        expected = sintering.grow_neck("grain_boundary", 0.0, radii[i], radii[j], history, durations, KINETICS,
                                       quadrature_nodes=spec.quadrature_nodes,
                                       newton_iterations=spec.newton_iterations)[-1]
        np.testing.assert_allclose(row[updates[-1]], float(expected), rtol=1e-12)
    every_step = saved_states(*pulsed_chain(1), n_steps)[1][1]
    reference = np.stack([np.asarray(every_step[updates[-1], i, slot]) for i, _, slot in slots])
    assert np.max(np.abs(necks[:, updates[-1]] / reference - 1)) < rtol


def test_an_insulated_sintering_cluster_conserves_heat_and_its_necks_grow_monotone_symmetric_and_capped():
    rng = np.random.default_rng(3)
    radii = rng.uniform(30e-6, 45e-6, 5)
    sim, state, params = chain(radii, rng.uniform(900.0, 1300.0, 5), dt=1e-4,
                               kinetics={"A": 1e-10, "activation_energy": 100.0})
    capacity = state.particles.mass * HEAT
    end, (temperature, neck) = saved_states(sim, state, params, 600)
    heat = np.asarray(temperature) @ np.asarray(capacity)
    np.testing.assert_allclose(heat, heat[0], rtol=1e-13)
    neck = np.asarray(neck)
    assert not bool(end.sintering.unstable)
    assert np.all(np.isfinite(neck)) and np.all(np.isfinite(np.asarray(temperature)))
    assert np.all(np.diff(neck, axis=0) >= 0.0)
    nbrs = np.asarray(state.contacts.neighbors)
    lo = np.arange(len(radii) - 1)
    # both rows of a contact hold bitwise the same neck
    np.testing.assert_array_equal(neck[:, lo, np.where(nbrs[lo, 0] == lo + 1, 0, 1)],
                                  neck[:, lo + 1, np.where(nbrs[lo + 1, 0] == lo, 0, 1)])
    # stopped at the equilibrium neck r_min sin(psi / 2), psi the default dihedral angle
    psi = sintering.KINETIC_LAWS["grain_boundary"].default_params["dihedral_angle"]
    cap = np.minimum(radii[:-1], radii[1:]) * np.sin(np.deg2rad(psi) / 2)
    final = neck[-1, lo, np.where(nbrs[lo, 0] == lo + 1, 0, 1)]
    assert np.all(final <= cap * (1 + 1e-12))
    np.testing.assert_allclose(final, cap, rtol=1e-9)
    stats = neck_growth.neck_statistics(end)
    np.testing.assert_allclose(float(stats["max_neck_ratio"]), np.max(final / np.minimum(radii[:-1], radii[1:])),
                               rtol=1e-12)
    expected_shrinkage = np.mean(sintering.neck_overlap(final, radii[:-1], radii[1:]) / (radii[:-1] + radii[1:]))
    np.testing.assert_allclose(float(stats["shrinkage"]), expected_shrinkage, rtol=1e-9)


def test_the_conductance_follows_the_necks():
    sim, state, params = pulsed_chain()
    end, _ = saved_states(sim, state, params, 100)
    start_k = simulate.neck_conductance(sim.physics, state, params)
    end_k = simulate.neck_conductance(sim.physics, end, params)
    assert float(jnp.max(start_k)) < 1e-9  # point contacts
    from sintercond.laws.conductance import conductance_from_neck
    a, h = end.contacts.table_neck[0, 0], end.contacts.table_overlap[0, 0]
    expected = conductance_from_neck("rojek", a, 40e-6, 30e-6, h, KAPPA, KAPPA)
    np.testing.assert_allclose(float(end_k[0, 0]), float(expected), rtol=1e-14)


@pytest.mark.slow
def test_gradients_of_a_neck_and_a_probe_temperature_by_the_kinetic_parameters_equal_central_differences():
    sim, state, params = pulsed_chain(every=2)
    n_steps = 60

    def observe(log_a, q):
        p = simulate.Params(params.conductivity, params.specific_heat, sintering={"A": jnp.exp(log_a),
                                                                                   "activation_energy": q},
                            pulse=params.pulse)
        end, _ = simulate.rollout(sim, state, p, n_steps)
        return jnp.stack([end.contacts.table_neck[0, 0] / 1e-6, end.particles.temperature[2]])

    log_a, q = jnp.log(KINETICS["A"]), KINETICS["activation_energy"]
    jac = jax.jit(jax.jacrev(observe, argnums=(0, 1)))(log_a, q)
    value = jax.jit(observe)
    for k, (x0, h) in enumerate(((log_a, 1e-4), (q, 1e-3))):
        args = [log_a, q]
        args[k] = x0 + h
        up = value(*args)
        args[k] = x0 - h
        down = value(*args)
        central = (up - down) / (2 * h)
        assert np.all(np.abs(np.asarray(central)) > 0)
        np.testing.assert_allclose(np.asarray(jac[k]), np.asarray(central), rtol=1e-6)


def test_a_step_that_grown_necks_make_unstable_is_refused_on_the_host():
    sim, state, params = chain([40e-6, 40e-6], [1000.0, 1200.0], dt=2e-2,
                               kinetics={"A": 1e-13, "activation_energy": 100.0})
    with pytest.raises(FloatingPointError, match="explicit stability limit"):
        rollout.advance(sim, state, params, 200, 20)


def test_the_stable_time_step_is_taken_on_the_current_necks():
    sim, state, params = pulsed_chain()
    end, _ = saved_states(sim, state, params, 100)
    capacity = np.asarray(state.particles.mass) * HEAT
    total = np.asarray(jnp.sum(simulate.neck_conductance(sim.physics, end, params), axis=1))
    np.testing.assert_allclose(float(simulate.thermal_time_step(sim, end, params)), np.min(capacity / total),
                               rtol=1e-14)


@pytest.mark.parametrize("sintering_params, match", [
    ({"Q": 100.0}, "unknown parameter 'Q'"),
    ({"A": -1.0}, r"Params.sintering\['A'\]"),
    ({"dihedral_angle": 200.0}, "dihedral_angle"),
    (None, "needs Params.sintering"),
])
def test_bad_kinetic_parameters_are_refused_naming_them_before_anything_compiles(sintering_params, match):
    sim, state, params = chain([40e-6, 40e-6], [1000.0, 1200.0])
    params = simulate.Params(params.conductivity, params.specific_heat, sintering=sintering_params)
    with pytest.raises(ValueError, match=match):
        simulate.rollout(sim, state, params, 4)


@pytest.mark.parametrize("keywords, match", [
    ({"contacts": "dynamic"}, "contacts='static'"),
    ({"conductance": "table"}, "conductance='lifted'"),
    ({"neck_model": "coble"}, "neck_model='volume_conserving'"),
])
def test_a_sintering_spec_on_what_the_first_stage_cannot_grow_is_refused(keywords, match):
    base = dict(law="rojek", neck_model="volume_conserving", conductance="lifted", sintering=neck_growth.Sintering())
    with pytest.raises(ValueError, match=match):
        simulate.Physics.create(**{**base, **keywords})


@pytest.mark.parametrize("field, value", [("every", 0), ("law", "surface_diffusion"), ("newton_iterations", 1.5),
                                          ("neck_rtol", 0.0), ("neck_rtol", 0.6), ("neck_rtol", "0.01"),
                                          ("neck_rtol", 0.01)])
def test_a_bad_sintering_spec_is_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"Sintering.{field}"):
        neck_growth.Sintering(**{field: value})


def test_a_state_without_its_neck_state_is_refused():
    sim, state, params = chain([40e-6, 40e-6], [1000.0, 1200.0])
    import dataclasses
    with pytest.raises(ValueError, match="SimState.sintering"):
        simulate.rollout(sim, dataclasses.replace(state, sintering=None), params, 4)


def test_held_particles_on_a_ramp_take_each_level_at_its_end_and_bad_ramps_are_refused():
    import dataclasses
    radii = np.array([40e-6, 40e-6])
    x = np.array([[0.0, 0.0, 0.0], [80e-6, 0.0, 0.0]])
    physics = simulate.Physics.create(law="rojek", conductance="lifted", held=True, held_ramp=True)
    particles = particle_state(x, radii, np.array([845.0, 900.0]), DENSITY, fixed=[True, False])
    state = simulate.init_state(particles, simulate.lifted_contacts(physics, x, radii), 0.1)
    ramp = simulate.HeldRampParams(1273.0, 9.5, 25.0)
    params = simulate.Params(conductivity=[KAPPA], specific_heat=[HEAT], held_ramp=ramp)
    sim = simulate.simulator(physics)
    _, held = simulate.rollout(sim, state, params, 95, simulate.SaveAt(1, lambda s: s.particles.temperature[0]))
    times = 0.1 * np.arange(1, 96)
    # Rizza & Galati's Table 1 (879 K at 0.5 s ... 1273 K at 9.5 s): T = 845 + ceil(t / 0.38) 17.12 K
    np.testing.assert_allclose(np.asarray(held), 845.0 + np.ceil(times / 0.38 - 1e-9) * 17.12, rtol=1e-13)
    for bad, match in ((None, "needs Params.held_ramp"), (dataclasses.replace(ramp, steps=2.5), "whole number"),
                       (dataclasses.replace(ramp, duration=0.0), "duration")):
        with pytest.raises(ValueError, match=match):
            simulate.rollout(sim, state, dataclasses.replace(params, held_ramp=bad), 2)
    with pytest.raises(ValueError, match="held_ramp.*needs held=True"):
        simulate.Physics.create(held_ramp=True)


@pytest.mark.slow
def test_the_gradient_of_k_star_at_the_end_by_the_kinetic_parameters_equals_central_differences():
    """k* of the 2 x 2 x 2 cell on the coupled network (three necks at right angles on each sphere, necks traced
    through the run) after 100 steps of the ramp: its gradient in (ln A, Q) equals central differences."""
    from sintercond.contacts.network import contact_pairs
    from sintercond.sim.steady import steady_state_network_conductivity

    r = 40e-6
    grid = np.stack(np.meshgrid(*(np.arange(2),) * 3, indexing="ij"), -1).reshape(-1, 3)
    x = r + 2 * r * grid  # a touching 2 x 2 x 2 cell, held on the ramp
    physics = simulate.Physics.create(law="rojek", conductance="lifted", held=True, held_ramp=True,
                                      sintering=neck_growth.Sintering(every=5))
    particles = particle_state(x, np.full(8, r), np.full(8, 845.0), DENSITY, fixed=True)
    contacts = simulate.lifted_contacts(physics, x, np.full(8, r))
    necks = neck_growth.neck_state(contacts, particles.temperature)
    state = simulate.init_state(particles, contacts, 1e-2, sintering=necks)
    sim = simulate.simulator(physics)
    pairs = contact_pairs(x, np.full(8, r))
    np.testing.assert_array_equal(np.stack([pairs.i, pairs.j], 1), np.asarray(contacts.pairs))

    def k_star(log_a, q):
        params = simulate.Params(conductivity=[KAPPA], specific_heat=[HEAT],
                                 sintering={"A": jnp.exp(log_a), "activation_energy": q},
                                 held_ramp=simulate.HeldRampParams(1273.0, 9.5, 25.0))
        end, _ = simulate.rollout(sim, state, params, 100)
        k = simulate.pair_neck_conductance(physics, end, params)
        return steady_state_network_conductivity(x, np.full(8, r), pairs, k, axis=2, kappa=KAPPA,
                                                 neck_radii=end.contacts.neck, beyond_domain="isolated")

    log_a, q = jnp.log(1.2e-20), 37.0
    grad = jax.jit(jax.grad(k_star, argnums=(0, 1)))(log_a, q)
    value = jax.jit(k_star)
    for k, h in enumerate((1e-4, 1e-3)):
        up, down = [log_a, q], [log_a, q]
        up[k], down[k] = up[k] + h, down[k] - h
        central = (value(*up) - value(*down)) / (2 * h)
        np.testing.assert_allclose(float(grad[k]), float(central), rtol=1e-6)
    assert float(grad[0]) > 0 > float(grad[1])  # faster kinetics, a better conductor at 1 s


def test_the_ramp_takes_each_level_at_its_edge_whatever_the_round_off_of_the_steps():
    """Review: ``25 t / 9.5`` at a step's edge reached by adding time steps is a whole number plus round-off, which a
    bare ``ceil`` took one level early (steps 6460, 6840 and 7220 of 9,500 steps of 1 ms)."""
    ramp = simulate.HeldRampParams(1273.0, 9.5, 25.0)
    k = np.arange(1, 9501)
    dt = jnp.asarray(1e-3)
    t = (jnp.asarray(k - 1).astype(dt.dtype) * dt) + dt  # as the step computes state.time + dt
    held = np.asarray(simulate.held_ramp_temperature(ramp, jnp.full(k.shape, 845.0), t))
    level = -(-25 * k // 9500)  # ceil(25 k / 9500) in integers
    np.testing.assert_allclose(held, 845.0 + level * (1273.0 - 845.0) / 25, rtol=1e-14)


def test_held_particles_do_not_count_in_the_stability_of_growing_necks():
    """Review: the flag took the minimum over every particle before leaving the held ones out."""
    radii = np.array([10e-6, 40e-6])
    x = np.array([[0.0, 0.0, 0.0], [50e-6, 0.0, 0.0]])
    physics = simulate.Physics.create(law="rojek", conductance="lifted", held=True,
                                      sintering=neck_growth.Sintering())
    particles = particle_state(x, radii, np.array([1200.0, 1000.0]), DENSITY, fixed=[True, False])
    contacts = simulate.lifted_contacts(physics, x, radii)
    params = simulate.Params(conductivity=[KAPPA], specific_heat=[HEAT], sintering={"A": 1e-10,
                                                                                      "activation_energy": 100.0})
    sim = simulate.simulator(physics)
    capped = neck_growth.necks_at_cap(physics.sintering, params.sintering, contacts, radii)
    k = float(simulate.neck_conductance(physics, simulate.init_state(particles, capped, 1.0), params)[0, 0])
    c = np.asarray(particles.mass) * HEAT
    dt = 0.5 * (c[0] / k + c[1] / k)  # above the small held sphere's limit, below the free one's
    assert c[0] / k < dt < c[1] / k
    state = simulate.init_state(particles, contacts, dt, sintering=neck_growth.neck_state(contacts,
                                                                                          particles.temperature))
    end, _ = simulate.rollout(sim, state, params, 200)
    assert float(end.contacts.table_neck[0, 0]) == pytest.approx(float(capped.table_neck[0, 0]), rel=1e-9)  # at the cap
    assert not bool(end.sintering.unstable)


def test_a_state_started_between_updates_grows_its_first_interval_from_its_own_start():
    sim, state, params = pulsed_chain(every=4)
    import dataclasses
    start = dataclasses.replace(state, step=state.step + 3,
                                sintering=dataclasses.replace(state.sintering,
                                                              interval_start=state.sintering.interval_start + 3))
    end, _ = simulate.rollout(sim, start, params, 1)  # step 4: one step of growth, not four
    r = np.asarray(state.particles.radii)
    pair = 0.5 * (np.asarray(state.particles.temperature)[:2].mean() + np.asarray(end.particles.temperature)[:2].mean())
    spec = sim.physics.sintering
    expected = sintering.grow_neck("grain_boundary", float(state.contacts.table_neck[0, 0]), r[0], r[1], [pair],
                                   [float(state.dt)], KINETICS, quadrature_nodes=spec.quadrature_nodes,
                                   newton_iterations=spec.newton_iterations)[-1]
    np.testing.assert_allclose(float(end.contacts.table_neck[0, 0]), float(expected), rtol=1e-12)


def test_a_one_sided_table_and_an_extrapolating_conductivity_table_are_refused():
    sim, state, params = chain([40e-6, 40e-6], [1000.0, 1200.0])
    import dataclasses
    one_sided = dataclasses.replace(state.contacts, neighbors=state.contacts.neighbors.at[1, 0].set(1))
    with pytest.raises(ValueError, match="in one of its rows only"):
        neck_growth.neck_state(one_sided, state.particles.temperature)
    from sintercond.laws import materials
    physics = simulate.Physics.create(law="rojek", conductance="lifted", conductivity_table=True)
    table = materials.tabulated([500.0, 1500.0], [7.0, 14.0], extrapolate=True)
    with pytest.raises(ValueError, match="must clamp at its ends"):
        simulate.rollout(simulate.simulator(physics), dataclasses.replace(state, sintering=None),
                         dataclasses.replace(params, conductivity=table, sintering=None), 2)


@pytest.mark.parametrize("physics", [
    simulate.Physics.create(law="rojek"),
    simulate.Physics.create(law="rojek", conductance="lifted"),
    simulate.Physics.create(law="rojek", neck_model="volume_conserving", conductance="lifted",
                            sintering=neck_growth.Sintering(every=2)),
], ids=["table", "lifted", "sintering"])
def test_a_float32_state_runs_with_parameters_written_as_python_floats(physics):
    """A float32 state with ``Params(conductivity=[7.0], ...)`` was promoted to float64 in the step and refused by
    the scan (a TypeError naming lax.dynamic_update_slice or cond branches): the parameters now take the state's
    precision, and the run agrees with float64 to float32's accuracy."""
    radii = np.array([40e-6, 30e-6, 35e-6])
    x = np.zeros((3, 3))
    x[1:, 0] = np.cumsum(radii[:-1] + radii[1:]) * (1 - 1e-3)
    particles = particle_state(x, radii, np.array([1000.0, 1100.0, 1050.0]), DENSITY)
    if physics.conduction.conductance == "table":
        from sintercond.contacts.network import contact_table
        contacts = simulate.table_contacts(contact_table(x, radii, KAPPA, "rojek"))
    else:
        contacts = simulate.lifted_contacts(physics, x, radii)
    necks = neck_growth.neck_state(contacts, particles.temperature) if physics.sintering else None
    state = simulate.init_state(particles, contacts, 1e-4, sintering=necks)
    params = simulate.Params(conductivity=[KAPPA], specific_heat=[HEAT],
                             sintering=dict(KINETICS) if physics.sintering else None)
    single = jax.tree_util.tree_map(lambda a: a.astype(jnp.float32) if a.dtype == jnp.float64 else a, state)
    sim = simulate.simulator(physics)
    end32 = simulate.rollout(sim, single, params, 20)[0]
    end64 = simulate.rollout(sim, state, params, 20)[0]
    assert end32.particles.temperature.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(end32.particles.temperature, np.float64),
                               np.asarray(end64.particles.temperature), rtol=1e-6)
