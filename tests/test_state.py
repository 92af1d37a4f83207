"""ParticleState: a PyTree that passes through jit and scan, built with validation."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond.contacts import network
from sintercond.sim import thermal
from sintercond.state import ParticleState, heat_capacity, particle_state
from _helpers import explicit_euler_step


def _state():
    positions = np.array([[0.0, 0, 0], [1e-4, 0, 0], [2e-4, 0, 0]])
    return particle_state(positions, 0.52e-4, [300.0, 600.0, 900.0], density=[4430.0, 8960.0],
                          specific_heat=[560.0, 385.0], material=[0, 1, 0], fixed=[True, False, False],
                          fixed_temperature=1000.0)


def test_capacity_per_material_and_held_values():
    s = _state()
    volume = 4 / 3 * np.pi * 0.52e-4**3
    np.testing.assert_allclose(heat_capacity(s, [560.0, 385.0]), volume * np.array([4430 * 560, 8960 * 385, 4430 * 560]),
                               rtol=1e-15)
    np.testing.assert_array_equal(s.temperature, [1000.0, 600.0, 900.0])


def test_is_a_pytree_through_jit_and_scan():
    s = _state()
    leaves, treedef = jax.tree.flatten(s)
    assert len(leaves) == 7 and isinstance(jax.tree.unflatten(treedef, leaves), ParticleState)
    table = network.contact_table(np.asarray(s.positions), np.asarray(s.radii), 20.0)
    capacity = heat_capacity(s, [560.0, 385.0])
    dt = float(thermal.table_time_step(capacity, table))

    @jax.jit
    def advance(state):
        def step(st, _):
            t = explicit_euler_step(st.temperature, table, capacity, dt, st.fixed, st.fixed_temperature)
            return dataclasses.replace(st, temperature=t), None
        return jax.lax.scan(step, state, None, length=50)[0]

    out = advance(s)
    assert isinstance(out, ParticleState) and float(out.temperature[0]) == 1000.0
    assert float(jnp.min(out.temperature)) >= 600.0 - 1e-9


def test_validation_names_the_field():
    with pytest.raises(ValueError, match=r"radii \(m\) must be finite and > 0"):
        particle_state(np.zeros((2, 3)), -1.0, 300.0, 4430.0, 560.0)
    with pytest.raises(ValueError, match=r"material must be in \[0, 0\]; got 2"):
        particle_state(np.zeros((2, 3)), 1e-4, 300.0, 4430.0, 560.0, material=[0, 2])
    with pytest.raises(ValueError, match=r"positions must be \[n, 3\]"):
        particle_state(np.zeros((2, 2)), 1e-4, 300.0, 4430.0, 560.0)
    with pytest.raises(ValueError, match=r"temperature \(K\) must be finite and > 0"):
        particle_state(np.zeros((2, 3)), 1e-4, -5.0, 4430.0, 560.0)
