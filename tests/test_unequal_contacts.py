"""The coupled step between unequal spheres of two materials, one softened by its temperature (issue 28).

Reference: Hertz's collision of two elastic spheres (Johnson 1985, Sect. 11.4), written out here from the
printed effective quantities: r* = r1 r2 / (r1 + r2), m* = m1 m2 / (m1 + m2),
1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2, E1 softened by Eq. 42 at its own temperature. The largest overlap is
delta_max = (15 m* v^2 / (16 E* sqrt(r*)))^(2/5), the contact lasts 2.9432 delta_max / v, and the spheres leave
with the velocities of an elastic collision of their masses.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import simulate
from sintercond.sim import mechanics
from sintercond.state import particle_state

R1, R2 = 1e-3, 1.5e-3
RHO = np.array([3000.0, 8000.0])
E0 = np.array([1e6, 4e6])
NU = np.array([0.3, 0.2])
THETA_STAR = 400.0
T = np.array([500.0, 350.0])  # sphere 1 above the onset, sphere 2 below
V = 0.05
STEPS_PER_CONTACT = 2000


def _hertz_collision():
    m1, m2 = RHO * 4 / 3 * math.pi * np.array([R1, R2]) ** 3
    e1 = E0[0] * math.exp(1 - T[0] / THETA_STAR)  # Eq. 42, rate 1
    r_star, m_star = R1 * R2 / (R1 + R2), m1 * m2 / (m1 + m2)
    e_star = 1 / ((1 - NU[0] ** 2) / e1 + (1 - NU[1] ** 2) / E0[1])
    delta_max = (15 * m_star * V**2 / (16 * e_star * math.sqrt(r_star))) ** 0.4
    return m1, m2, delta_max, 2.9432 * delta_max / V


@pytest.fixture(scope="module")
def collision():
    m1, m2, delta_max, duration = _hertz_collision()
    gap = 0.01 * R1
    positions = np.array([[0.0, 0.0, 0.0], [R1 + R2 + gap, 0.0, 0.0]])
    particles = particle_state(positions, [R1, R2], T, RHO, material=[0, 1])
    physics = simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                      mechanics=True, softening=True, gravity=(0.0, 0.0, 0.0))
    contacts, fns = simulate.dynamic_contacts(positions, particles.radii, 0.1 * R1, capacity_multiplier=3.0)
    motion = mechanics.mechanical_state(physics.mechanics, positions, contacts, velocity=[[V, 0.0, 0.0], [0.0, 0.0, 0.0]])
    dt = duration / STEPS_PER_CONTACT
    state = simulate.init_state(particles, contacts, dt, mechanics=motion)
    two = lambda a, b: jnp.asarray([a, b], jnp.float64)  # noqa: E731
    params = simulate.Params(
        conductivity=two(1e-12, 1e-12), specific_heat=two(100.0, 100.0),  # no heat: the moduli stay put
        mechanics=mechanics.MechanicalParams(E0=jnp.asarray(E0), nu=jnp.asarray(NU), xi_con=0.0, xi_fric=0.0,
                                             theta_star=two(THETA_STAR, THETA_STAR), rate=two(1.0, 1.0),
                                             E_min=two(0.0, 0.0)))
    sim = simulate.simulator(physics, fns)
    n = int((gap / V + 1.5 * duration) / dt)

    def watch(s):
        x = s.particles.positions
        return jnp.stack([R1 + R2 - jnp.linalg.norm(x[1] - x[0]), s.mechanics.velocity[0, 0],
                          s.mechanics.velocity[1, 0]])

    _, saved = jax.jit(lambda s, p: simulate.rollout(sim, s, p, n, simulate.SaveAt(1, watch), checkpoint=False))(
        state, params)
    return np.asarray(saved), dt, (m1, m2, delta_max, duration)


def test_largest_overlap_is_hertzs_with_the_softened_two_material_modulus(collision):
    saved, _, (_, _, delta_max, _) = collision
    # symplectic Euler's error in the peak is second order in dt / t_c: 6e-8 at 2000 steps per contact
    assert saved[:, 0].max() == pytest.approx(delta_max, rel=1e-6)


def test_contact_lasts_hertzs_duration(collision):
    saved, dt, (_, _, _, duration) = collision
    # one step either way, and the 5 digits of Hertz's constant 2.9432
    assert np.sum(saved[:, 0] > 0) * dt == pytest.approx(duration, rel=1.0 / STEPS_PER_CONTACT + 2e-5)


def test_spheres_leave_with_the_elastic_collision_velocities(collision):
    saved, _, (m1, m2, _, _) = collision
    assert saved[-1, 1] == pytest.approx((m1 - m2) / (m1 + m2) * V, rel=1e-7)
    assert saved[-1, 2] == pytest.approx(2 * m1 / (m1 + m2) * V, rel=1e-7)
