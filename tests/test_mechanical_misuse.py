"""The mechanical Python API refuses what its step would silently get wrong (issue 43, item 4).

References: the Hertz tangent stiffness of a sphere on a plane, ``k = 2 E* sqrt(R delta)`` with ``E* = E/(1-nu^2)``
(Quintana-Ruiz & Campello 2020, Eq. 2 differentiated), whose undamped symplectic-Euler step is stable only for
``omega dt < 2``, ``omega^2 = k/m``; and Hertz's static overlap under the weight, ``delta = (3 m g / (4 E*
sqrt(R)))^(2/3)``.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import simulate
from sintercond.sim import mechanics
from sintercond.state import particle_state
from sintercond.laws.walls import PlaneWall

R, RHO, E0, NU, G = 1e-3, 3000.0, 1e6, 0.3, 9.81
MASS = 4.0 / 3.0 * math.pi * R**3 * RHO
E_STAR = E0 / (1 - NU**2)  # a sphere on a rigid plane
DELTA = (3 * MASS * G / (4 * E_STAR * math.sqrt(R))) ** (2 / 3)  # Hertz's overlap of the weight
OMEGA = math.sqrt(2 * E_STAR * math.sqrt(R * DELTA) / MASS)
FLOOR = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))


def _params(**kw):
    base = dict(E0=E0, nu=NU, xi_con=1.0, xi_fric=1.0, xi_rol=0.0, mu=0.0, mu_r=0.0, theta_star=400.0, rate=1.0,
                E_min=0.0)
    base.update(kw)
    return simulate.Params(conductivity=jnp.asarray([60.0]), specific_heat=jnp.asarray([100.0]),
                           mechanics=mechanics.MechanicalParams(**{k: None if v is None else jnp.asarray(float(v))
                                                                   for k, v in base.items()}))


def _resting(dt, params=None, **physics):
    """A sphere resting on the floor at Hertz's overlap of its weight."""
    x = np.array([[0.0, 0.0, R - DELTA]])
    particles = particle_state(x, R, 300.0, RHO)
    spec = simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                   mechanics=True, walls=[FLOOR], **physics)
    contacts, fns = simulate.dynamic_contacts(x, particles.radii, 0.1 * R)
    state = simulate.init_state(particles, contacts, dt, mechanics=mechanics.mechanical_state(spec.mechanics, x,
                                                                                              contacts))
    return simulate.simulator(spec, fns), state, params or _params()


def test_rollout_refuses_a_step_beyond_the_stability_of_a_resting_contact():
    """At 41 times the undamped limit 2/omega (the issue's case) the sphere would be thrown off its floor; the
    rollout refuses it before anything runs, naming the state's step and the limit."""
    sim, state, params = _resting(41 * 2 / OMEGA)
    with pytest.raises(ValueError, match=r"SimState\.dt = .* exceeds the stability limit .* stiffest contact"):
        simulate.rollout(sim, state, params, 10)
    sim, state, params = _resting(0.1 / OMEGA)  # well inside it: runs, and the sphere stays on Hertz's overlap
    final, _ = simulate.rollout(sim, state, params, 200)
    z = float(final.particles.positions[0, 2])
    assert R - z == pytest.approx(DELTA, rel=1e-2)


def test_the_limit_falls_between_the_damped_and_the_undamped_bounds():
    """Damping only lowers the stable step: a step just above 2/omega is refused, one a tenth of it is not."""
    sim, state, params = _resting(1.05 * 2 / OMEGA)
    with pytest.raises(ValueError, match="exceeds the stability limit"):
        simulate.rollout(sim, state, params, 1)
    sim, state, params = _resting(0.2 / OMEGA)
    simulate.rollout(sim, state, params, 1)


@pytest.mark.parametrize("flag, coefficient", [("friction", "mu"), ("rolling", "mu_r")])
def test_a_coefficient_of_a_law_that_is_off_is_refused(flag, coefficient):
    sim, state, params = _resting(0.1 / OMEGA, _params(**{coefficient: 0.3}))
    with pytest.raises(ValueError, match=rf"Mechanics\.{flag}=False .* MechanicalParams\.{coefficient} is"):
        simulate.rollout(sim, state, params, 1)
    sim, state, params = _resting(0.1 / OMEGA, _params(**{coefficient: 0.3}), **{flag: True})
    simulate.rollout(sim, state, params, 1)  # on: taken


def test_a_wall_coefficient_with_friction_off_everywhere_is_refused():
    sim, state, params = _resting(0.1 / OMEGA, _params(mu_wall=0.3))
    with pytest.raises(ValueError, match=r"Mechanics\.friction=False makes the walls frictionless.*mu_wall"):
        simulate.rollout(sim, state, params, 1)
