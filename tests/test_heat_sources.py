"""External heat, convection, radiation: closed forms, limits, and a lone cooling particle."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond.laws import heat_sources as hs
from sintercond.contacts import network
from sintercond.simulate import simulate_table


def test_nozzle_linear_attenuation():
    z = np.array([-1e-4, 0.0, 0.5e-3, 1e-3, 2e-3])
    q = np.asarray(hs.nozzle_power(1e-4, z, 1e6, 1e-3, absorptance=0.8))
    full = 0.8 * 1e6 * np.pi * 1e-8
    np.testing.assert_allclose(q, [0.0, full, full / 2, 0.0, 0.0], rtol=1e-14, atol=1e-18)


def test_laser_lambert_beer():
    z = np.array([0.0, 1e-4, 2e-4])
    q = np.asarray(hs.laser_power(1e-4, z, 1e6, 1e4))
    np.testing.assert_allclose(q[1:] / q[:-1], np.exp(-1.0), rtol=1e-14)
    assert float(hs.laser_power(1e-4, -1.0, 1e6, 1e4)) == 0.0
    # d/dmu ln Q = -z
    g = jax.grad(lambda mu: jnp.log(hs.laser_power(1e-4, 2e-4, 1e6, mu)))(1e4)
    assert float(g) == pytest.approx(-2e-4, rel=1e-12)


def test_beam_geometry():
    centres = np.array([[0.0, 0.0, 0.9e-3], [0.5e-3, 0.0, 0.9e-3], [0.0, 0.0, 0.5e-3]])
    depth = np.asarray(hs.beam_depth(centres, np.full(3, 0.1e-3), (0.0, 0.0), 0.2e-3, 1.0e-3))
    np.testing.assert_allclose(depth, [0.0, -1.0, 0.4e-3], atol=1e-15)
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]])
    np.testing.assert_allclose(hs.beam_position(0.5, path, 2.0), [1.0, 0.0])
    np.testing.assert_allclose(hs.beam_position(1.0, path, 2.0), [1.0, 1.0])
    np.testing.assert_allclose(hs.beam_position(10.0, path, 2.0), [1.0, 2.0])


def test_convection_and_radiation():
    assert float(hs.whitaker_nusselt(0.0, 0.7)) == 2.0
    nu = float(hs.whitaker_nusselt(100.0, 0.7, 1.0))
    assert nu == pytest.approx(2 + (0.4 * 10 + 0.06 * 100 ** (2 / 3)) * 0.7**0.4, rel=1e-14)
    r, k_env = 1e-4, 0.026
    q = float(hs.convection_power(r, 400.0, 300.0, k_env))  # Nu = 2: h = k/r
    assert q == pytest.approx(k_env / r * (-100.0) * 4 * np.pi * r**2, rel=1e-14)
    assert float(hs.radiation_power(r, 500.0, 500.0, 0.6)) == 0.0
    dq = jax.grad(hs.radiation_power, argnums=1)(r, 800.0, 300.0, 0.6)
    assert float(dq) == pytest.approx(-4 * 0.6 * hs.STEFAN_BOLTZMANN * 800.0**3 * 4 * np.pi * r**2, rel=1e-12)


def test_lone_particle_cools_exponentially_by_convection():
    r, k_env, c = 1e-4, 0.026, 1e-6  # radius, air conductivity, capacity (J/K)
    table = network.ContactTable(neighbors=jnp.zeros((1, 1), jnp.int32), conductance=jnp.zeros((1, 1)))

    def source(temperature, time):
        return hs.convection_power(r, temperature, 300.0, k_env)

    rate = k_env / r * 4 * np.pi * r**2 / c  # C dT/dt = -h A (T - T_E)
    t_end = 2.0 / rate
    final, _ = simulate_table(jnp.array([800.0]), table, c, t_end / 4000, n_steps=4000, save_every=4000, source=source)
    assert float(final[0]) == pytest.approx(300 + 500 * np.exp(-2.0), rel=5e-4)


def test_convection_scales_with_the_nusselt_number():
    """Bug caught: a convection law that ignores ``nusselt`` (or uses h = k/r whatever Nu) passed, since
    every test used Nu = 2. Eqs. 37-38: h = Nu k_E / (2 r), so Q = 2 pi Nu k_E r (T_E - T), closed form."""
    r, k_env = 1e-4, 0.026
    for nu in (2.0, 4.0, 7.5):
        q = float(hs.convection_power(r, 400.0, 300.0, k_env, nusselt=nu))
        assert q == pytest.approx(2 * np.pi * nu * k_env * r * (300.0 - 400.0), rel=1e-14)


def test_stefan_boltzmann_constant_is_the_papers():
    """Bug caught: the expectation came from the module's own constant, so any value passed. Quintana-Ruiz
    & Campello (2020) Eq. 41 use 5.670367e-8 W/(m^2 K^4), within 1.3e-6 of CODATA 2018's exact
    5.670374419e-8. A black sphere of radius 1 m at 1000 K against 0 K emits eps B T^4 4 pi r^2."""
    assert hs.STEFAN_BOLTZMANN == pytest.approx(5.670374419e-8, rel=2e-6)
    q = float(hs.radiation_power(1.0, 1000.0, 0.0, 1.0))
    assert q == pytest.approx(-5.670367e-8 * 1e12 * 4 * np.pi, rel=1e-14)
