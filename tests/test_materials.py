"""Temperature-dependent properties of sintercond.laws.materials against their closed forms and central differences."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond.laws import materials
from sintercond.laws.tortuosity import ti6al4v_conductivity, ti6al4v_conductivity_table

E0, THETA_STAR = 1e6, 400.0  # Example 5.1


def central_difference(fn, x, rel_step=1e-6):
    h = rel_step * abs(x)
    return (float(fn(x + h)) - float(fn(x - h))) / (2 * h)


# --------------------------------------------------------------------------
# softening (Eq. 42, erratum 6)


def test_softening_is_flat_below_the_onset_and_exponential_above():
    theta = np.array([250.0, 300.0, 399.9, 400.0])
    np.testing.assert_array_equal(materials.softened_modulus(theta, E0, THETA_STAR), E0)
    for theta in (450.0, 700.0):
        expected = E0 * math.exp(1 - theta / THETA_STAR)  # Eq. 42 as printed
        assert float(materials.softened_modulus(theta, E0, THETA_STAR)) == pytest.approx(expected, rel=1e-15)
    # Example 5.1: the floor at 700 K (no E_min given) is E0 e^(-0.75) = 0.47 MPa
    assert float(materials.softened_modulus(700.0, E0, THETA_STAR)) == pytest.approx(0.4724e6, rel=1e-4)


def test_softening_rate_and_floor():
    theta, rate = 600.0, 2.5
    expected = E0 * math.exp(rate * (1 - theta / THETA_STAR))
    assert float(materials.softened_modulus(theta, E0, THETA_STAR, rate)) == pytest.approx(expected, rel=1e-15)
    assert float(materials.softened_modulus(theta, E0, THETA_STAR, 0.0)) == E0  # rate 0: no softening
    e_min = 0.3 * E0
    assert expected < e_min
    assert float(materials.softened_modulus(theta, E0, THETA_STAR, rate, e_min)) == e_min  # the floor binds
    assert float(materials.softened_modulus(450.0, E0, THETA_STAR, rate, e_min)) == pytest.approx(
        E0 * math.exp(rate * (1 - 450.0 / THETA_STAR)), rel=1e-15)  # not yet
    assert float(materials.softened_modulus(1e6, E0, THETA_STAR, rate, e_min)) == e_min  # no underflow trouble


@pytest.mark.parametrize("theta, e_min", [(300.0, 0.1e6), (520.0, 0.1e6), (900.0, 0.3e6)])
def test_softening_gradients_match_central_differences(theta, e_min):
    args = [theta, E0, THETA_STAR, 1.7, e_min]
    grads = jax.grad(materials.softened_modulus, argnums=(0, 1, 2, 3, 4))(*args)
    for k in range(5):
        def along(x, k=k):
            shifted = list(args)
            shifted[k] = x
            return materials.softened_modulus(*shifted)
        reference = central_difference(along, args[k])
        assert float(grads[k]) == pytest.approx(reference, rel=1e-6, abs=1e-9 * E0 / abs(args[k]))


def test_softening_gradient_at_the_kinks_is_the_colder_sides():
    d_theta = jax.grad(materials.softened_modulus)
    assert float(d_theta(THETA_STAR, E0, THETA_STAR)) == 0.0  # unsoftened side of theta*
    rate, kink = 1.0, 677.0
    e_min = float(materials.softened_modulus(kink, E0, THETA_STAR))  # the floor meets the law at `kink` exactly
    slope = -E0 / THETA_STAR * math.exp(1 - kink / THETA_STAR)  # the softening law's, not the floor's 0
    assert float(d_theta(kink, E0, THETA_STAR, rate, e_min)) == pytest.approx(slope, rel=1e-9)
    for theta in (THETA_STAR, kink):
        grads = jax.grad(materials.softened_modulus, argnums=(0, 1, 2, 3, 4))(theta, E0, THETA_STAR, rate, e_min)
        assert all(bool(jnp.isfinite(g)) for g in grads)


# --------------------------------------------------------------------------
# tables


T_NODES = np.array([300.0, 500.0, 800.0, 1200.0])
VALUES = np.array([7.0, 9.5, 12.0, 17.5])


def test_table_is_exact_at_nodes_and_linear_between():
    table = materials.tabulated(T_NODES, VALUES)
    np.testing.assert_allclose(table(T_NODES), VALUES, rtol=1e-15)
    mid = 0.5 * (T_NODES[:-1] + T_NODES[1:])
    np.testing.assert_allclose(table(mid), 0.5 * (VALUES[:-1] + VALUES[1:]), rtol=1e-15)
    quarter = T_NODES[1] + 0.25 * (T_NODES[2] - T_NODES[1])
    assert float(table(quarter)) == pytest.approx(VALUES[1] + 0.25 * (VALUES[2] - VALUES[1]), rel=1e-15)
    np.testing.assert_allclose(table(np.array([250.0, 300.0 + 1e-9])), np.interp([250.0, 300.0 + 1e-9], T_NODES, VALUES),
                               rtol=1e-15)


def test_table_clamps_or_extrapolates():
    clamped = materials.tabulated(T_NODES, VALUES)
    extrapolated = materials.tabulated(T_NODES, VALUES, extrapolate=True)
    np.testing.assert_allclose(clamped(np.array([100.0, 2000.0])), [VALUES[0], VALUES[-1]], rtol=1e-15)
    low = VALUES[0] + (100.0 - T_NODES[0]) * (VALUES[1] - VALUES[0]) / (T_NODES[1] - T_NODES[0])
    high = VALUES[-1] + (2000.0 - T_NODES[-1]) * (VALUES[-1] - VALUES[-2]) / (T_NODES[-1] - T_NODES[-2])
    np.testing.assert_allclose(extrapolated(np.array([100.0, 2000.0])), [low, high], rtol=1e-14)
    assert float(jax.grad(clamped)(2000.0)) == 0.0
    with pytest.raises(ValueError, match="increasing"):
        materials.tabulated(T_NODES[::-1], VALUES)
    with pytest.raises(ValueError, match="length"):
        materials.tabulated(T_NODES, VALUES[:-1])


@pytest.mark.parametrize("theta", [320.0, 650.0, 1100.0, 1500.0])
def test_table_gradients_match_central_differences(theta):
    table = materials.tabulated(T_NODES, VALUES, extrapolate=True)
    assert float(jax.grad(table)(theta)) == pytest.approx(central_difference(table, theta), rel=1e-6)
    d_values = jax.grad(lambda v: materials.interpolate_table(theta, T_NODES, v, extrapolate=True))(jnp.asarray(VALUES))
    for k in range(len(VALUES)):
        def along(x, k=k):
            values = VALUES.copy()
            values[k] = x
            return materials.interpolate_table(theta, T_NODES, values, extrapolate=True)
        assert float(d_values[k]) == pytest.approx(central_difference(along, VALUES[k]), rel=1e-6, abs=1e-9)
    assert float(jnp.sum(d_values)) == pytest.approx(1.0, rel=1e-14)  # the weights of a linear interpolation


@pytest.mark.slow
def test_ti6al4v_conductivity_is_the_shipped_table():
    _, temperatures, conductivities = ti6al4v_conductivity_table()
    conductivity = materials.ti6al4v_conductivity_property()
    np.testing.assert_allclose(conductivity(temperatures), conductivities, rtol=1e-15)
    inside = np.linspace(temperatures[0], temperatures[-1], 37)
    np.testing.assert_allclose(conductivity(inside), ti6al4v_conductivity(inside), rtol=1e-14)
    assert float(conductivity(300.0)) == conductivities[0]  # clamped (tortuosity's returns NaN there)
    assert float(materials.ti6al4v_conductivity_property(extrapolate=True)(300.0)) < conductivities[0]


# --------------------------------------------------------------------------
# the Property protocol


def test_properties_as_constant_law_or_table():
    theta = jnp.array([300.0, 600.0])
    constant = materials.as_property(60.0)
    assert isinstance(constant, materials.Constant)
    np.testing.assert_array_equal(constant(theta), [60.0, 60.0])
    law = materials.Law(materials.softened_modulus, dict(E0=E0, theta_star=THETA_STAR))
    np.testing.assert_allclose(law(theta), materials.softened_modulus(theta, E0, THETA_STAR), rtol=1e-15)
    table = materials.tabulated(T_NODES, VALUES)
    for prop in (constant, law, table):
        assert isinstance(prop, materials.Property)
        assert materials.as_property(prop) is prop


def test_property_parameters_are_differentiable_leaves():
    def modulus_at(prop, theta):
        return prop(theta)

    law = materials.Law(materials.softened_modulus, dict(E0=E0, theta_star=THETA_STAR, rate=1.3))
    grads = jax.jit(jax.grad(modulus_at))(law, 500.0)
    expected = jax.grad(materials.softened_modulus, argnums=(1, 2, 3))(500.0, E0, THETA_STAR, 1.3)
    for name, g in zip(("E0", "theta_star", "rate"), expected):
        assert float(grads.params[name]) == pytest.approx(float(g), rel=1e-14)
    table_grads = jax.jit(jax.grad(modulus_at))(materials.tabulated(T_NODES, VALUES), 650.0)
    np.testing.assert_allclose(table_grads.values, [0.0, 0.5, 0.5, 0.0], rtol=1e-14)
    assert float(jax.grad(modulus_at)(materials.Constant(2.0), 650.0).value) == 1.0


@pytest.mark.slow
def test_jit_vmap_and_float32():
    theta = np.linspace(250.0, 1300.0, 23)
    law = lambda t: materials.softened_modulus(t, E0, THETA_STAR, 1.5, 0.2e6)  # noqa: E731
    table = materials.ti6al4v_conductivity_property(extrapolate=True)
    for fn in (law, lambda t: table(t)):
        eager = fn(jnp.asarray(theta))
        np.testing.assert_allclose(jax.jit(fn)(jnp.asarray(theta)), eager, rtol=1e-15)
        np.testing.assert_allclose(jax.vmap(fn)(jnp.asarray(theta)), eager, rtol=1e-15)
        np.testing.assert_allclose([float(fn(t)) for t in theta], eager, rtol=1e-15)
        narrow = fn(jnp.asarray(theta, dtype=jnp.float32))
        assert narrow.dtype == jnp.float32
        np.testing.assert_allclose(np.asarray(narrow, dtype=np.float64), eager, rtol=2e-6)
