"""Every heat source inside the coupled (thermo-mechanical) step, against the printed laws (issue 28).

Quintana-Ruiz & Campello (2020): the laser's Lambert-Beer power a I0 pi r^2 exp(-mu z) (Eqs. 29, 31) and the
nozzle's a I0 pi r^2 (1 - z/d_max) (Eq. 30) at the beam's position along its path, Newton cooling with
h = Nu k_E / (2r) (Eqs. 37-38), Stefan-Boltzmann exchange (Eq. 41), a prescribed pulse while t < its duration.
Spheres apart (no conduction) and at rest without gravity: one explicit step changes each temperature by
dt P_i / C_i, C_i = rho c (4/3) pi r^3, with P_i written out here.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import simulate
from sintercond.sim import mechanics
from sintercond.state import particle_state

SIGMA = 5.670367e-8  # W/(m^2 K^4), the paper's value
RHO, C = 4430.0, 560.0
R = np.array([5e-5, 4e-5, 6e-5])
# sphere 0 under the spot at the top, sphere 1 under it deeper, sphere 2 beside the beam's path
X = np.array([[1e-4, 1e-4, 2e-4], [1e-4, 1.3e-4, 0.5e-4], [6e-4, 6e-4, 1e-4]])
T0 = np.array([400.0, 800.0, 1200.0])
I0, MU, D_MAX, SPOT, ABS, SPEED = 2e8, 2e4, 3e-4, 6e-5, 0.7, 0.5
PATH = [[1e-4, 1e-4], [5e-4, 1e-4]]
T_E, K_E, NU_SSELT, EMISSIVITY = 300.0, 0.026, 2.4, 0.4
PULSE, PULSE_END = np.array([1e-3, 2e-3, 3e-3]), 1e-5
DT = 1e-6


def _step(beam, at_step=0):
    physics = simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                      mechanics=True, gravity=(0.0, 0.0, 0.0), beam=beam, convection=True,
                                      radiation=True, pulse=True)
    particles = particle_state(X, R, T0, RHO)
    contacts, fns = simulate.dynamic_contacts(X, particles.radii, 1e-5)
    state = simulate.init_state(particles, contacts, DT, step=at_step,
                                mechanics=mechanics.mechanical_state(physics.mechanics, X, contacts))
    f = lambda x: jnp.asarray(x, jnp.float64)  # noqa: E731
    params = simulate.Params(
        conductivity=f([12.6]), specific_heat=f([C]),
        mechanics=mechanics.MechanicalParams(E0=f(1e8), nu=f(0.3)),
        beam=simulate.BeamParams(f(I0), f(MU if beam == "laser" else D_MAX), f(SPOT), f(ABS), f(SPEED), f(PATH)),
        convection=simulate.ConvectionParams(f(T_E), f(K_E), f(NU_SSELT)),
        radiation=simulate.RadiationParams(f(T_E), f(EMISSIVITY)),
        pulse=simulate.PulseParams(f(PULSE), f(PULSE_END)))
    sim = simulate.simulator(physics, fns)
    new = sim.step_fn(state, params)
    capacity = RHO * C * 4 / 3 * math.pi * R**3
    return (np.asarray(new.particles.temperature) - T0) * capacity / DT, float(state.time)


def _printed_powers(beam_power, t):
    area = 4 * math.pi * R**2
    convection = NU_SSELT * K_E / (2 * R) * (T_E - T0) * area
    radiation = EMISSIVITY * SIGMA * (T_E**4 - T0**4) * area
    pulse = PULSE if t < PULSE_END else 0.0
    return beam_power + convection + radiation + pulse


def _close(power, expected):
    # the power is read back from a temperature change: 4 ulp of T per step is the round-off of that difference
    capacity = RHO * C * 4 / 3 * math.pi * R**3
    assert np.all(np.abs(power - expected) <= 1e-12 * np.abs(expected) + 4 * np.spacing(T0) * capacity / DT)


def _depths():
    surface = np.max(X[:, 2] + R)
    return surface - (X[:, 2] + R)


@pytest.mark.parametrize("beam", ["laser", "nozzle"])
def test_every_source_heats_the_coupled_step_by_its_printed_law(beam):
    power, t = _step(beam)
    z = _depths()
    shape = np.exp(-MU * z) if beam == "laser" else 1 - z / D_MAX
    in_spot = np.array([True, True, False])  # lateral distance 0, 3e-5 < SPOT + r; sphere 2 far away
    beam_power = np.where(in_spot, ABS * I0 * math.pi * R**2 * shape, 0.0)
    _close(power, _printed_powers(beam_power, t))


def test_the_beam_has_moved_on_and_the_pulse_is_over_at_a_later_step():
    """At step 400 (t = 4e-4 s) the spot is 2e-4 m along the path, away from spheres 0 and 1 (more than
    SPOT + r laterally), and the pulse (1e-5 s) has ended: only convection and radiation remain."""
    power, t = _step("laser", at_step=400)
    assert t == pytest.approx(400 * DT, rel=1e-15)
    spot = np.array(PATH[0]) + [SPEED * t, 0.0]
    assert np.all(np.linalg.norm(X[:, :2] - spot, axis=1) > SPOT + R)
    _close(power, _printed_powers(0.0, t))
