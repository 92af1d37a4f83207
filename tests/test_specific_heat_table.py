"""Specific heat against temperature in the simulator (``Conduction.specific_heat_table``; issue 27's c(T)).

References: the enthalpy balance ``sum_i m_i int c dT = 0`` of an insulated pair (its equilibrium temperature in
closed form for a linear c), a particle heated at constant power (``m h(T(t)) = m h(T_0) + P t``, a quadratic for
a linear c), a constant table against the constant specific heat, the enthalpy of a lattice conserved to
round-off, central differences of the gradient by the table, and the table's bound on the stable step.
"""

import copy
import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import simulate
from sintercond.contacts import network
from sintercond.laws import materials
from sintercond.state import particle_state

C0, C1 = 500.0, 0.4  # c(T) = C0 + C1 (T - 300) J/(kg K) on [300, 1300] K
LINEAR = materials.tabulated([300.0, 1300.0], [C0, C0 + C1 * 1000.0])


def _enthalpy(t):
    """int_300^T c dT of LINEAR (J/kg)."""
    return C0 * (t - 300.0) + 0.5 * C1 * (t - 300.0) ** 2


def _temperature(h):
    """The inverse of :func:`_enthalpy` (the root of the quadratic)."""
    return 300.0 + (-C0 + math.sqrt(C0**2 + 2.0 * C1 * h)) / C1


def pair(conductance="lifted", specific_heat=LINEAR, table=True, temperatures=(400.0, 1200.0), dt=1e-4,
         integrator="explicit"):
    radii = np.array([40e-6, 40e-6])
    x = np.array([[0.0, 0.0, 0.0], [79e-6, 0.0, 0.0]])
    physics = simulate.Physics.create(law="rojek", conductance=conductance, specific_heat_table=table,
                                      integrator=integrator, rtol=1e-7, atol=1e-6)
    particles = particle_state(x, radii, np.array(temperatures), 4430.0)
    contacts = (simulate.lifted_contacts(physics, x, radii) if conductance == "lifted"
                else simulate.table_contacts(network.contact_table(x, radii, 1.0)))
    state = simulate.init_state(particles, contacts, dt)
    return simulate.simulator(physics), state, simulate.Params(conductivity=[10.0], specific_heat=specific_heat)


@pytest.mark.parametrize("conductance", ["lifted", "table"])
def test_an_insulated_pair_settles_at_the_enthalpy_balance(conductance):
    """Equal spheres at 400 K and 1200 K: 2 h(T_eq) = h(400) + h(1200), T_eq = 845.1323... K; with the table's c at the
    start temperature instead, an explicit step would drift by about a kelvin."""
    sim, state, params = pair(conductance)
    end, _ = simulate.rollout(sim, state, params, 3000)
    expected = _temperature(0.5 * (_enthalpy(400.0) + _enthalpy(1200.0)))
    np.testing.assert_allclose(np.asarray(end.particles.temperature), expected, rtol=1e-13)
    assert abs(expected - 0.5 * (400.0 + 1200.0)) > 40.0  # far from the constant-c answer


def test_the_implicit_integrator_keeps_the_enthalpy_and_matches_a_fine_explicit_run():
    """c(T) under the adaptive implicit step (the enthalpy form of TR-BDF2): the insulated pair reaches the enthalpy
    balance's T_eq = 845.13 K in closed form, and on the way (3 ms, mid-exchange) agrees with explicit runs at
    1e-5 s and 5e-6 s (some 1/400 of the explicit limit) extrapolated to dt -> 0 (Richardson; Euler is first order:
    the two runs differ by 0.14 K, the extrapolation from the implicit run by 2e-3 K)."""
    from sintercond.sim import adaptive

    sim, state, params = pair(integrator="implicit", dt=1e-3)
    integrate = jax.jit(lambda s, p, n: adaptive.integrate(sim, s, p, n), static_argnums=2)
    early, stats = integrate(state, params, 3)
    late, _ = integrate(dataclasses.replace(state, dt=jnp.asarray(0.1)), params, 3)
    assert not bool(stats.failed)
    expected = _temperature(0.5 * (_enthalpy(400.0) + _enthalpy(1200.0)))
    np.testing.assert_allclose(np.asarray(late.particles.temperature), expected, rtol=1e-9)
    runs = [np.asarray(simulate.rollout(*pair(dt=dt)[:2], params, n)[0].particles.temperature)
            for dt, n in ((1e-5, 300), (5e-6, 600))]
    reference = 2.0 * runs[1] - runs[0]
    assert abs(reference[0] - 400.0) > 100.0  # mid-exchange
    np.testing.assert_allclose(np.asarray(early.particles.temperature), reference, atol=0.01)


def test_a_particle_heated_at_constant_power_follows_its_enthalpy():
    """One sphere, no contacts, P = 2 mW for 0.5 s: h(T(t)) = h(T_0) + P t / m at every step, in closed form."""
    x, radii = np.zeros((1, 3)), np.array([40e-6])
    physics = simulate.Physics.create(law="rojek", conductance="lifted", specific_heat_table=True, pulse=True)
    particles = particle_state(x, radii, 350.0, 4430.0)
    state = simulate.init_state(particles, simulate.lifted_contacts(physics, x, radii), 1e-3)
    params = simulate.Params(conductivity=[10.0], specific_heat=LINEAR,
                             pulse=simulate.PulseParams(power=jnp.array([2e-3]), duration=0.5))
    saved = simulate.rollout(simulate.simulator(physics), state, params, 400,
                             simulate.SaveAt(every=100, fn=simulate.probe_temperatures([0])))[1]
    mass = float(particles.mass[0])
    times = np.array([0.1, 0.2, 0.3, 0.4])
    expected = [_temperature(_enthalpy(350.0) + 2e-3 * t / mass) for t in times]
    np.testing.assert_allclose(np.asarray(saved).ravel(), expected, rtol=1e-13)


def test_a_constant_table_runs_as_the_constant_specific_heat():
    flat = materials.tabulated([300.0, 1300.0], [560.0, 560.0])
    sim_t, state, params_t = pair(specific_heat=flat)
    sim_c, _, params_c = pair(specific_heat=[560.0], table=False)
    np.testing.assert_allclose(np.asarray(simulate.rollout(sim_t, state, params_t, 500)[1]),
                               np.asarray(simulate.rollout(sim_c, state, params_c, 500)[1]), rtol=1e-12)


def test_a_lattice_keeps_its_enthalpy_to_round_off():
    """27 sintered spheres, a hot corner, a three-node table with a falling segment: sum m h(T) stays put."""
    table = materials.tabulated([300.0, 700.0, 1300.0], [520.0, 760.0, 690.0])
    g = np.arange(3) * 1e-4
    x = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    radii = np.full(27, 0.53e-4)
    temperature = np.where(np.arange(27) == 0, 1250.0, 320.0)
    physics = simulate.Physics.create(law="rojek", conductance="table", specific_heat_table=True)
    particles = particle_state(x, radii, temperature, 4430.0)
    state = simulate.init_state(particles, simulate.table_contacts(network.contact_table(x, radii, 1.0)), 1.0)
    params = simulate.Params(conductivity=[7.0], specific_heat=table)
    sim = simulate.simulator(physics)
    state = dataclasses.replace(state, dt=0.5 * simulate.thermal_time_step(sim, state, params))
    end = simulate.rollout(sim, state, params, 500)[0]
    mass = np.asarray(particles.mass)

    def enthalpy(t):
        return float(mass @ np.asarray(materials.integrate_table(t, table.temperatures, table.values)))

    start = enthalpy(state.particles.temperature)
    assert enthalpy(end.particles.temperature) == pytest.approx(start, rel=1e-13)
    assert float(jnp.max(end.particles.temperature)) < 900.0  # the heat spread


def test_the_gradient_by_the_table_equals_central_differences():
    sim, state, params = pair()

    def hot_end(values):
        p = dataclasses.replace(params, specific_heat=materials.Table(LINEAR.temperatures, values))
        return simulate.rollout(sim, state, p, 300)[0].particles.temperature[1]

    values = jnp.asarray(LINEAR.values)
    grad = jax.grad(hot_end)(values)
    for k in range(2):
        step = jnp.zeros(2).at[k].set(1e-2)
        central = (hot_end(values + step) - hot_end(values - step)) / 2e-2
        np.testing.assert_allclose(float(grad[k]), float(central), rtol=1e-6)


def test_the_stable_step_is_bounded_by_the_tables_smallest_specific_heat():
    sim, state, params = pair()
    constant_sim, _, constant = pair(specific_heat=[C0], table=False)
    assert float(simulate.thermal_time_step(sim, state, params)) == pytest.approx(
        float(simulate.thermal_time_step(constant_sim, state, constant)), rel=1e-14)


def test_a_table_without_its_spec_or_a_bad_table_is_refused_naming_it():
    sim, state, params = pair(table=False)
    with pytest.raises(ValueError, match="Conduction.specific_heat_table=True"):
        simulate.rollout(sim, state, params, 2)
    sim, state, params = pair(specific_heat=[560.0])
    with pytest.raises(ValueError, match="needs Params.specific_heat as a sintercond.laws.materials.Table"):
        simulate.rollout(sim, state, params, 2)


def test_a_scenes_table_reaches_the_run_and_a_bad_table_is_named():
    from sintercond import run as runner
    from sintercond.scene import SceneError, validate_scene

    scene = {
        "packing": {"kind": "simple_cubic", "counts": [3, 2, 2], "spacing": 1e-4, "radius": 0.52e-4},
        "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.0,
                     "specific_heat_table": [[300, 520.0], [1300, 720.0]]},
        "conduction": {"law": "rojek"},
        "initial": {"temperature": 650.0},
        "run": {"duration": 1e-3, "output_every": 10, "checkpoint_every": 10},
    }
    model = runner.build_model(validate_scene(copy.deepcopy(scene)))
    assert model.physics.conduction.specific_heat_table
    np.testing.assert_array_equal(np.asarray(model.params.specific_heat.values), [520.0, 720.0])
    constant = runner.build_model(validate_scene({**copy.deepcopy(scene), "material": {
        "density": 4430.0, "specific_heat": 520.0, "conductivity": 12.0}}))
    assert model.stable_step == pytest.approx(constant.stable_step, rel=1e-12)  # on the smallest c
    for table, message in (([[300, 520.0]], "at least 2"), ([[300, 520.0], [200, 600.0]], "strictly increasing"),
                           ([[300, 520.0], [1000, -1.0]], r"specific_heat_table\[1\]")):
        bad = copy.deepcopy(scene)
        bad["material"]["specific_heat_table"] = table
        with pytest.raises(SceneError, match=message):
            validate_scene(bad)
