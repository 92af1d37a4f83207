"""Conductivity against temperature in the simulator (``Conduction.conductivity_table``; issues 26 and 27).

References: the conductance law at each particle's own conductivity (halves in series, Rojek et al. 2022 Eq. 3),
a constant table against the constant conductivity, conservation of heat, and the table's bound on the step.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import rollout, simulate
from sintercond.laws import materials
from sintercond.sim import neck_growth
from sintercond.laws.conductance import conductance_from_neck
from sintercond.state import particle_state

TI64 = materials.tabulated([879.0, 1273.0], [11.52, 16.72])  # Rizza & Galati (2024) Table 1's ends, linear


def pair(table=True, temperatures=(900.0, 1200.0), sintering=None, conductivity=TI64):
    radii = np.array([40e-6, 30e-6])
    x = np.array([[0.0, 0.0, 0.0], [69.0e-6, 0.0, 0.0]])  # 1 um of overlap: a neck
    physics = simulate.Physics.create(law="rojek", conductance="lifted", conductivity_table=table,
                                      sintering=sintering)
    particles = particle_state(x, radii, np.array(temperatures), 4430.0)
    contacts = simulate.lifted_contacts(physics, x, radii)
    necks = None if sintering is None else neck_growth.neck_state(contacts, particles.temperature)
    state = simulate.init_state(particles, contacts, 1e-4, sintering=necks)
    params = simulate.Params(conductivity=conductivity, specific_heat=[560.0],
                             sintering=None if sintering is None else {"A": 1e-16, "activation_energy": 100.0})
    return simulate.simulator(physics), state, params


def test_each_particle_conducts_at_its_own_temperature():
    sim, state, params = pair()
    prep = sim.prepare_fn(state, params)
    power = sim.heat_power_fn(state, prep)
    a, h = float(state.contacts.table_neck[0, 0]), float(state.contacts.table_overlap[0, 0])
    k = conductance_from_neck("rojek", a, 40e-6, 30e-6, h, float(TI64(900.0)), float(TI64(1200.0)))
    np.testing.assert_allclose(np.asarray(power), [float(k) * 300.0, -float(k) * 300.0], rtol=1e-14)
    assert float(TI64(900.0)) != float(TI64(1200.0))


def test_a_constant_table_runs_as_the_constant_conductivity_and_heat_is_conserved():
    flat = materials.tabulated([500.0, 1500.0], [13.0, 13.0])
    sim_t, state, params_t = pair(conductivity=flat)
    sim_c, _, params_c = pair(table=False, conductivity=[13.0])
    run = lambda sim, p: simulate.rollout(sim, state, p, 200)[1]  # noqa: E731
    np.testing.assert_allclose(np.asarray(run(sim_t, params_t)), np.asarray(run(sim_c, params_c)), rtol=1e-14)
    sim, state, params = pair()
    saved = np.asarray(simulate.rollout(sim, state, params, 400)[1])
    capacity = np.asarray(state.particles.mass) * 560.0
    np.testing.assert_allclose(saved @ capacity, float(state.particles.temperature @ capacity), rtol=1e-14)


def test_growing_necks_at_temperature_dependent_conductivity_and_the_gradient_by_the_table():
    sim, state, params = pair(sintering=neck_growth.Sintering(every=2))

    def hot_end(values):
        p = dataclasses.replace(params, conductivity=materials.Table(TI64.temperatures, values))
        return simulate.rollout(sim, state, p, 100)[0].particles.temperature[1]

    values = jnp.asarray(TI64.values)
    grad = jax.grad(hot_end)(values)
    for k in range(2):
        step = jnp.zeros(2).at[k].set(1e-3)
        central = (hot_end(values + step) - hot_end(values - step)) / 2e-3
        np.testing.assert_allclose(float(grad[k]), float(central), rtol=1e-6)
    assert float(grad[0]) < 0 and float(grad[1]) < 0  # the hot particle cools faster as either end conducts more


def test_the_stable_step_is_bounded_by_the_tables_largest_conductivity():
    sim, state, params = pair()
    constant_sim, _, constant = pair(table=False, conductivity=[16.72])
    assert float(simulate.thermal_time_step(sim, state, params)) == pytest.approx(
        float(simulate.thermal_time_step(constant_sim, state, constant)), rel=1e-14)


def test_a_table_without_its_spec_or_a_bad_table_is_refused_naming_it():
    sim, state, params = pair(table=False, conductivity=TI64)
    with pytest.raises(ValueError, match="Conduction.conductivity_table=True"):
        simulate.rollout(sim, state, params, 2)
    sim, state, params = pair(conductivity=[13.0])
    with pytest.raises(ValueError, match="needs Params.conductivity as a sintercond.laws.materials.Table"):
        simulate.rollout(sim, state, params, 2)
    sim, state, params = pair(conductivity=materials.Table(jnp.array([900.0, 800.0]), jnp.array([1.0, 2.0])))
    with pytest.raises(ValueError, match="strictly increasing"):
        rollout.advance(sim, state, params, 2, 2)
    with pytest.raises(ValueError, match="conductance='lifted'"):
        simulate.Physics.create(conductivity_table=True)


def test_a_scenes_table_reaches_the_run_and_a_bad_table_is_named():
    import copy

    from sintercond import run as runner
    from sintercond.scene import SceneError, validate_scene

    scene = {
        "packing": {"kind": "simple_cubic", "counts": [3, 2, 2], "spacing": 1e-4, "radius": 0.52e-4},
        "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.0,
                     "conductivity_table": [[300, 7.0], [1000, 14.0]]},
        "conduction": {"law": "rojek"},
        "initial": {"temperature": 650.0},
        "run": {"duration": 1e-3, "output_every": 10, "checkpoint_every": 10},
    }
    model = runner.build_model(validate_scene(copy.deepcopy(scene)))
    assert model.physics.conduction.conductivity_table and model.physics.conduction.conductance == "lifted"
    np.testing.assert_array_equal(np.asarray(model.params.conductivity.values), [7.0, 14.0])
    # the automatic step on the table's largest conductivity: 14 / 12 of the constant one's limit apart
    constant = runner.build_model(validate_scene({**copy.deepcopy(scene), "material": {
        "density": 4430.0, "specific_heat": 560.0, "conductivity": 14.0}}))
    assert model.stable_step == pytest.approx(constant.stable_step, rel=1e-12)
    for table, message in (([[300, 7.0]], "at least 2"), ([[300, 7.0], [200, 8.0]], "strictly increasing"),
                           ([[300, 7.0], [1000, -1.0]], r"conductivity_table\[1\]")):
        bad = copy.deepcopy(scene)
        bad["material"]["conductivity_table"] = table
        with pytest.raises(SceneError, match=message):
            validate_scene(bad)
