"""Contact laws of sintercond.laws.forces against closed forms and small independent integrations.

References: Hertz's static overlap, the restitution relation of the
delta^(1/4)-damped Hertz contact (the one LAMMPS' ``damping coeff_restitution``
inverts), Mindlin's stick spring, Coulomb's slip limit, the rolling limit,
Remark 1's wall limits, the eigenvalues of the symplectic-Euler amplification
matrix, central differences for every gradient.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond.laws import forces

# a 1 mm particle of Example 5.1 (rho = 3000, E = 1 MPa, nu = 0.3)
R = 1e-3
M = 4.0 / 3.0 * math.pi * R**3 * 3000.0
E, NU = 1e6, 0.3
R_STAR, M_STAR = R / 2, M / 2
E_STAR = E / (2 * (1 - NU**2))
G_STAR = E / (2 * (1 + NU)) / 2          # Eq. 9 as printed, one material
J_STAR = 1.4 * M * R**2 / 2              # Eq. 18, I = (2/5) m r^2
Z = np.array([0.0, 0.0, 1.0])


def assert_gradients_match(fn, args, rtol=1e-6, rel_step=1e-6):
    """Forward-mode Jacobian of ``fn`` (array output) against central differences in float64, argument by argument.

    Tolerance ``rtol |fd| + 1e-8 max|f| / |x|``: the second term is the round-off of a central difference
    with step ``rel_step |x|`` (about ``eps max|f| / (rel_step |x|)``), for outputs whose derivative is ~0.
    """
    args = [np.float64(a) for a in args]
    value = np.atleast_1d(np.asarray(fn(*args), dtype=np.float64))
    jacobians = jax.jacfwd(fn, argnums=tuple(range(len(args))))(*args)
    for k, x in enumerate(args):
        h = rel_step * abs(x)
        up, down = list(args), list(args)
        up[k], down[k] = x + h, x - h
        reference = (np.atleast_1d(np.asarray(fn(*up))) - np.atleast_1d(np.asarray(fn(*down)))) / (2 * h)
        got = np.atleast_1d(np.asarray(jacobians[k]))
        atol = 1e-8 * np.max(np.abs(value)) / abs(x)
        np.testing.assert_allclose(got, reference, rtol=rtol, atol=atol, err_msg=f"argument {k}")


def assert_all_finite(tree):
    for leaf in jax.tree_util.tree_leaves(tree):
        assert bool(jnp.all(jnp.isfinite(leaf))), leaf


# --------------------------------------------------------------------------
# effective quantities and walls


def test_effective_quantities_match_the_printed_forms():
    r_i, r_j, m_i, m_j = 1e-3, 3e-3, 2e-5, 5e-4
    E_i, nu_i, E_j, nu_j = 1e6, 0.3, 7e6, 0.22
    np.testing.assert_allclose(forces.effective_radius(r_i, r_j), r_i * r_j / (r_i + r_j), rtol=1e-15)
    np.testing.assert_allclose(forces.effective_mass(m_i, m_j), m_i * m_j / (m_i + m_j), rtol=1e-15)
    printed = E_i * E_j / (E_j * (1 - nu_i**2) + E_i * (1 - nu_j**2))  # Eq. 3
    np.testing.assert_allclose(forces.effective_modulus(E_i, nu_i, E_j, nu_j), printed, rtol=1e-15)
    G_i, G_j = E_i / (2 * (1 + nu_i)), E_j / (2 * (1 + nu_j))
    np.testing.assert_allclose(forces.shear_modulus(E_i, nu_i), G_i, rtol=1e-15)
    np.testing.assert_allclose(forces.effective_shear_modulus(E_i, nu_i, E_j, nu_j), G_i * G_j / (G_i + G_j),
                               rtol=1e-15)
    mindlin = 1 / ((2 - nu_i) / G_i + (2 - nu_j) / G_j)
    np.testing.assert_allclose(forces.effective_shear_modulus(E_i, nu_i, E_j, nu_j, convention="mindlin"),
                               mindlin, rtol=1e-15)
    j_i, j_j = 0.4 * m_i * r_i**2 + m_i * r_i**2, 0.4 * m_j * r_j**2 + m_j * r_j**2
    np.testing.assert_allclose(forces.effective_rolling_inertia(m_i, r_i, m_j, r_j), j_i * j_j / (j_i + j_j),
                               rtol=1e-14)


def test_mindlin_convention_is_the_papers_over_two_minus_nu():
    paper = forces.effective_shear_modulus(E, NU, E, NU)
    mindlin = forces.effective_shear_modulus(E, NU, E, NU, convention="mindlin")
    assert float(paper / mindlin) == pytest.approx(1.7, rel=1e-14)  # 2 - nu at nu = 0.3
    with pytest.raises(ValueError, match="convention"):
        forces.effective_shear_modulus(E, NU, E, NU, convention="lammps")


def test_wall_limits_of_remark_1_with_finite_gradients():
    inf = jnp.inf
    r_i, m_i = 1e-3, 1.2e-5
    assert float(forces.effective_radius(r_i, inf)) == r_i
    assert float(forces.effective_mass(m_i, inf)) == m_i
    np.testing.assert_allclose(forces.effective_rolling_inertia(m_i, r_i, inf, inf), 1.4 * m_i * r_i**2,
                               rtol=1e-15)
    np.testing.assert_allclose(forces.effective_modulus(E, NU, inf, 0.2), E / (1 - NU**2), rtol=1e-15)
    np.testing.assert_allclose(forces.effective_shear_modulus(E, NU, inf, 0.2), E / (2 * (1 + NU)), rtol=1e-15)
    for fn, args in [
        (forces.effective_radius, (r_i, inf)),
        (forces.effective_mass, (m_i, inf)),
        (forces.effective_rolling_inertia, (m_i, r_i, inf, inf)),
        (forces.effective_modulus, (E, NU, inf, 0.2)),
        (forces.effective_shear_modulus, (E, NU, inf, 0.2)),
    ]:
        grads = jax.grad(fn, argnums=tuple(range(len(args))))(*args)
        assert_all_finite(grads)
        assert float(grads[0]) > 0  # the particle's own value still matters
    # d r*/d r_i = 1 at the wall: r* = r_i
    assert float(jax.grad(forces.effective_radius)(r_i, inf)) == pytest.approx(1.0, rel=1e-15)


# --------------------------------------------------------------------------
# normal force


@pytest.mark.parametrize("load", [1e-6, 1.23e-4, 3e-2])
def test_static_hertz_overlap_under_a_load(load):
    # Hertz: delta = (3 F / (4 E* sqrt(r*)))^(2/3)
    for r_star, e_star in [(R_STAR, E_STAR), (R, E / (1 - NU**2))]:  # two spheres; sphere on a wall
        delta = (3 * load / (4 * e_star * math.sqrt(r_star))) ** (2.0 / 3.0)
        force = forces.hertz_normal_force(delta, 0.0, r_star, M_STAR, e_star, 1.0)
        assert float(force) == pytest.approx(load, rel=1e-13)


def test_example_5_1_weight_and_overlap():
    weight = M * 9.81
    assert weight == pytest.approx(1.23e-4, rel=3e-3)  # the paper's constant contact force
    r_star = float(forces.effective_radius(R, jnp.inf))
    e_star = float(forces.effective_modulus(E, NU, jnp.inf, NU))
    delta = (3 * weight / (4 * e_star * math.sqrt(r_star))) ** (2.0 / 3.0)
    assert float(forces.hertz_normal_force(delta, 0.0, r_star, M, e_star, 1.0)) == pytest.approx(weight, rel=1e-13)


def test_normal_force_damping_term_and_clamp():
    delta, delta_dot = 2e-6, -0.3
    d_con = 2 * 0.7 * math.sqrt(2 * E_STAR * M_STAR * math.sqrt(R_STAR)) * delta**0.25  # Eq. 6
    elastic = 4 / 3 * math.sqrt(R_STAR) * E_STAR * delta**1.5
    expected = elastic + d_con * delta_dot
    assert expected < 0  # a pulling contact while it opens fast
    assert float(forces.hertz_normal_force(delta, delta_dot, R_STAR, M_STAR, E_STAR, 0.7)) == pytest.approx(
        expected, rel=1e-13)
    assert float(forces.hertz_normal_force(delta, delta_dot, R_STAR, M_STAR, E_STAR, 0.7, no_tension=True)) == 0.0
    for delta in (0.0, -1e-6):
        assert float(forces.hertz_normal_force(delta, 1.0, R_STAR, M_STAR, E_STAR, 0.7)) == 0.0


def _collision_restitution(xi, v0, n_steps, r_star=1.0, m_star=1.0, e_star=1.0):
    """e of one head-on collision: RK4 on m* delta'' = -f_n(delta, delta'), from delta = 0."""
    duration = 2.87 * (m_star**2 / (r_star * e_star**2 * v0)) ** 0.2
    h = 3.0 * duration / n_steps

    def acceleration(x, v):
        return -forces.hertz_normal_force(x, v, r_star, m_star, e_star, xi) / m_star

    def rk4(state, _):
        x, v = state
        k1x, k1v = v, acceleration(x, v)
        k2x, k2v = v + h / 2 * k1v, acceleration(x + h / 2 * k1x, v + h / 2 * k1v)
        k3x, k3v = v + h / 2 * k2v, acceleration(x + h / 2 * k2x, v + h / 2 * k2v)
        k4x, k4v = v + h * k3v, acceleration(x + h * k3x, v + h * k3v)
        return (x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x), v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)), None

    (_, v), _ = jax.lax.scan(rk4, (jnp.zeros_like(xi), v0 + jnp.zeros_like(xi)), None, length=n_steps)
    return -v / v0


def _restitution_relation(xi):
    """e(xi) of the delta^(1/4)-damped Hertz contact: beta = xi sqrt(6/5), e = exp(-pi beta/sqrt(1-beta^2))."""
    beta = np.asarray(xi) * math.sqrt(6.0 / 5.0)
    return np.exp(-math.pi * beta / np.sqrt(1.0 - beta**2))


def test_restitution_of_one_collision():
    xi = jnp.array([0.0, 0.05, 0.1, 0.2, 0.4, 0.7, 1.0])
    e = {n: np.asarray(jax.jit(lambda x, n=n: _collision_restitution(x, 1.0, n))(xi)) for n in (8000, 16000)}
    # converged to ~2e-5 (the exit through delta = 0, where the damping is singular, is not located)
    np.testing.assert_allclose(e[8000], e[16000], rtol=5e-5, atol=1e-7)
    e = e[16000]
    assert e[0] == pytest.approx(1.0, abs=1e-9)  # xi -> 0: elastic
    assert np.all(np.diff(e) < 0)  # e decreases with xi
    # against the relation LAMMPS' coeff_restitution inverts (xi = sqrt(5/6) beta), where beta < 1
    np.testing.assert_allclose(e[:6], _restitution_relation(xi[:6]), rtol=2e-4)
    assert 0 < e[-1] < 0.02  # xi = 1 ("critical"): e = 0.009, not 0: the contact is nonlinear
    # the delta^(1/4) damping makes e independent of the impact speed
    slow = np.asarray(jax.jit(lambda x: _collision_restitution(x, 0.01, 16000))(xi))
    np.testing.assert_allclose(slow, e, rtol=1e-5, atol=1e-7)


# --------------------------------------------------------------------------
# tangential force


def _k_t(delta, r_star=R_STAR, g_star=G_STAR):
    return 8 * g_star * math.sqrt(r_star * delta)  # Mindlin, Eq. 7


DELTA = 2e-6
F_N = 4 / 3 * math.sqrt(R_STAR) * E_STAR * DELTA**1.5


def _friction(spring, v_t, normal=Z, dt=1e-5, delta=DELTA, f_n=F_N, xi=0.0, mu_s=0.5, mu_d=None, **kw):
    return forces.mindlin_tangential_force(jnp.asarray(spring), jnp.asarray(v_t), jnp.asarray(normal), dt, delta,
                                           f_n, R_STAR, M_STAR, G_STAR, xi, mu_s, mu_d, **kw)


def test_stick_spring_is_force_over_mindlin_stiffness():
    spring = np.array([1e-8, -2e-8, 0.0])
    force, new_spring, slipping = _friction(spring, np.zeros(3))
    assert not bool(slipping)
    np.testing.assert_allclose(new_spring, spring, rtol=1e-15)
    np.testing.assert_allclose(force, -_k_t(DELTA) * spring, rtol=1e-13)
    # the stored spring is the force over k_t
    np.testing.assert_allclose(np.linalg.norm(new_spring), np.linalg.norm(force) / _k_t(DELTA), rtol=1e-13)


def test_stick_integrates_the_tangential_velocity_with_damping():
    v_t, dt, xi = np.array([1e-4, 3e-4, 0.0]), 1e-5, 0.6
    force, new_spring, slipping = _friction(np.zeros(3), v_t, dt=dt, xi=xi)
    d_fric = 2 * xi * math.sqrt(8 * G_STAR * M_STAR * math.sqrt(R_STAR)) * DELTA**0.25  # Eq. 11
    assert not bool(slipping)
    np.testing.assert_allclose(new_spring, v_t * dt, rtol=1e-15)
    np.testing.assert_allclose(force, -_k_t(DELTA) * v_t * dt - d_fric * v_t, rtol=1e-13)


@pytest.mark.parametrize("slip_direction", ["trial", "velocity"])
def test_slip_force_is_coulomb_and_the_reset_spring_reproduces_it(slip_direction):
    mu_s, mu_d, xi = 0.5, 0.4, 0.3
    spring = np.array([3e-6, 1e-6, 0.0])  # far beyond the limit
    v_t = np.array([0.02, 0.0, 0.0])
    force, new_spring, slipping = _friction(spring, v_t, xi=xi, mu_s=mu_s, mu_d=mu_d, slip_direction=slip_direction)
    assert bool(slipping)
    assert float(jnp.linalg.norm(force)) == pytest.approx(mu_d * F_N, rel=1e-13)
    trial = -_k_t(DELTA) * (spring + v_t * 1e-5) - 2 * xi * math.sqrt(
        8 * G_STAR * M_STAR * math.sqrt(R_STAR)) * DELTA**0.25 * v_t
    expected_direction = trial if slip_direction == "trial" else -v_t  # erratum 3; Eq. 8 with erratum 1
    np.testing.assert_allclose(force / np.linalg.norm(force), expected_direction / np.linalg.norm(expected_direction),
                               rtol=1e-12, atol=1e-15)
    # erratum 1: the stored spring gives back the slip force (same velocity, no new increment); it now sticks
    again, _, slipping_again = _friction(new_spring, v_t, dt=0.0, xi=xi, mu_s=mu_s, mu_d=mu_d)
    assert not bool(slipping_again)
    np.testing.assert_allclose(again, force, rtol=1e-12)


def test_velocity_slip_direction_is_zero_without_velocity():
    force, _, slipping = _friction(np.array([3e-6, 0, 0]), np.zeros(3), slip_direction="velocity")
    assert bool(slipping)
    np.testing.assert_array_equal(force, np.zeros(3))
    with pytest.raises(ValueError, match="slip_direction"):
        _friction(np.zeros(3), np.zeros(3), slip_direction="luding")


def test_spring_is_carried_onto_a_tilted_plane_with_its_length():
    spring = np.array([2e-7, -1e-7, 0.0])
    tilt = 0.3
    normal = np.array([math.sin(tilt), 0.0, math.cos(tilt)])
    rotated = np.asarray(forces.rotate_onto_tangent_plane(jnp.asarray(spring), jnp.asarray(normal)))
    assert np.linalg.norm(rotated) == pytest.approx(np.linalg.norm(spring), rel=1e-14)
    assert abs(rotated @ normal) < 1e-14 * np.linalg.norm(spring)
    assert rotated @ spring > 0  # the nearest in-plane direction, not another one
    # a spring already in the plane is left alone
    np.testing.assert_allclose(forces.rotate_onto_tangent_plane(jnp.asarray(spring), jnp.asarray(Z)), spring,
                               rtol=1e-15)
    # the friction law does this before anything else: the force lies in the tilted plane
    force, new_spring, _ = _friction(spring, np.zeros(3), normal=normal)
    assert abs(float(force @ normal)) < 1e-12 * float(jnp.linalg.norm(force))
    assert float(jnp.linalg.norm(new_spring)) == pytest.approx(np.linalg.norm(spring), rel=1e-14)


def test_open_contact_forgets_its_spring():
    for delta in (0.0, -1e-6):
        force, new_spring, slipping = _friction(np.array([1e-7, 0, 0]), np.array([0.1, 0, 0]), delta=delta)
        np.testing.assert_array_equal(force, np.zeros(3))
        np.testing.assert_array_equal(new_spring, np.zeros(3))
        assert not bool(slipping)


def test_contact_velocity_and_friction_torque():
    v_i, v_j = np.array([0.1, 0.2, -0.3]), np.array([0.0, -0.1, 0.05])
    w_i, w_j = np.array([1.0, 2.0, 3.0]), np.array([-2.0, 0.5, 1.0])
    n = np.array([0.0, 0.6, 0.8])
    r_i, r_j = 1e-3, 2e-3
    u = (v_i + np.cross(w_i, r_i * n)) - (v_j + np.cross(w_j, -r_j * n))  # contact points' velocities
    delta_dot, v_t = forces.relative_contact_velocity(*map(jnp.asarray, (v_i, v_j, w_i, w_j, n)), r_i, r_j)
    assert float(delta_dot) == pytest.approx(u @ n, rel=1e-14)
    np.testing.assert_allclose(v_t, u - (u @ n) * n, rtol=1e-13, atol=1e-16)
    f_t = np.array([0.3, -0.4, 0.3])
    torque_i, torque_j = forces.friction_torque(jnp.asarray(f_t), jnp.asarray(n), r_i, r_j)
    np.testing.assert_allclose(torque_i, np.cross(r_i * n, f_t), rtol=1e-14)        # Eq. 14
    np.testing.assert_allclose(torque_j, np.cross(-r_j * n, -f_t), rtol=1e-14)


# --------------------------------------------------------------------------
# rolling resistance


def _rolling(spring, omega_i, omega_j=(0.0, 0.0, 0.0), normal=Z, dt=1e-5, delta=DELTA, f_n=F_N, xi=0.0, mu_r=0.2, **kw):
    return forces.rolling_resistance_torque(jnp.asarray(spring), jnp.asarray(omega_i), jnp.asarray(omega_j),
                                            jnp.asarray(normal), dt, delta, f_n, R_STAR, J_STAR, G_STAR, xi, mu_r, **kw)


def test_rolling_stick_and_limit():
    k_r = _k_t(DELTA) * R_STAR**2  # Eq. 15
    spring = np.array([1e-5, 0.0, 0.0])
    torque, new_spring, slipping = _rolling(spring, np.zeros(3))
    assert not bool(slipping)
    np.testing.assert_allclose(torque, -k_r * spring, rtol=1e-13)
    # a large relative spin reaches the rolling limit mu_r r* |f_n| (Eq. 16)
    omega = np.array([0.0, 400.0, 0.0])
    torque, new_spring, slipping = _rolling(np.zeros(3), omega, xi=0.2)
    assert bool(slipping)
    assert float(jnp.linalg.norm(torque)) == pytest.approx(0.2 * R_STAR * F_N, rel=1e-13)
    assert float(torque @ omega) < 0  # it resists the rolling
    d_rol = 2 * 0.2 * math.sqrt(8 * G_STAR * J_STAR * math.sqrt(R_STAR)) * R_STAR * DELTA**0.25  # Eq. 18
    np.testing.assert_allclose(-k_r * new_spring - d_rol * omega, torque, rtol=1e-12)  # Eq. 20, erratum 1


def test_rolling_projection_drops_twisting():
    twist = 50.0 * Z  # a spin about the normal: no rolling
    literal, _, _ = _rolling(np.zeros(3), twist)
    projected, spring, _ = _rolling(np.zeros(3), twist, projection=True)
    assert float(jnp.linalg.norm(literal)) > 0  # erratum 5: the printed law resists twisting too
    np.testing.assert_array_equal(projected, np.zeros(3))
    np.testing.assert_array_equal(spring, np.zeros(3))
    rolling = np.array([10.0, 0.0, 0.0])
    np.testing.assert_allclose(_rolling(np.zeros(3), rolling, projection=True)[0], _rolling(np.zeros(3), rolling)[0],
                               rtol=1e-14)


# --------------------------------------------------------------------------
# gradients: central differences at interior points, finite at the edges

SPRING = np.array([1e-8, -2e-8, 0.0])
V_T = np.array([1e-4, 2e-4, 0.0])
TILTED = np.array([0.1, 0.0, math.sqrt(1 - 0.01)])


def _friction_scalar(slip):
    mu = 0.01 if slip else 0.5

    def fn(delta, f_n, r_star, m_star, g_star, xi, dt):
        force, spring, _ = forces.mindlin_tangential_force(
            jnp.asarray(SPRING), jnp.asarray(V_T), jnp.asarray(TILTED), dt, delta, f_n, r_star, m_star, g_star, xi, mu)
        return jnp.concatenate([force, spring])
    return fn


def _rolling_scalar(slip, projection):
    mu_r = 0.01 if slip else 0.5

    def fn(delta, f_n, r_star, j_star, g_star, xi, dt):
        torque, spring, _ = forces.rolling_resistance_torque(
            jnp.asarray(1e-3 * SPRING), jnp.asarray([1.0, 2.0, 3.0]), jnp.asarray([0.5, 0.0, -1.0]),
            jnp.asarray(TILTED), dt, delta, f_n, r_star, j_star, g_star, xi, mu_r, projection=projection)
        return jnp.concatenate([torque, spring])
    return fn


LAWS = {
    "effective_radius": (forces.effective_radius, (1e-3, 3e-3)),
    "effective_mass": (forces.effective_mass, (2e-5, 5e-4)),
    "effective_modulus": (forces.effective_modulus, (1e6, 0.3, 3e6, 0.2)),
    "effective_shear_modulus": (forces.effective_shear_modulus, (1e6, 0.3, 3e6, 0.2)),
    "mindlin_shear_modulus": (lambda *a: forces.effective_shear_modulus(*a, convention="mindlin"),
                              (1e6, 0.3, 3e6, 0.2)),
    "effective_rolling_inertia": (forces.effective_rolling_inertia, (2e-5, 1e-3, 5e-4, 3e-3)),
    "hertz_normal_force": (forces.hertz_normal_force, (DELTA, 0.05, R_STAR, M_STAR, E_STAR, 0.7)),
    "friction_stick": (_friction_scalar(False), (DELTA, F_N, R_STAR, M_STAR, G_STAR, 0.4, 1e-5)),
    "friction_slip": (_friction_scalar(True), (DELTA, F_N, R_STAR, M_STAR, G_STAR, 0.4, 1e-5)),
    "rolling_stick": (_rolling_scalar(False, False), (DELTA, F_N, R_STAR, J_STAR, G_STAR, 0.3, 1e-5)),
    "rolling_slip_projected": (_rolling_scalar(True, True), (DELTA, F_N, R_STAR, J_STAR, G_STAR, 0.3, 1e-5)),
    "hertz_collision_duration": (forces.hertz_collision_duration, (R_STAR, M_STAR, E_STAR, 0.5)),
    "hertz_collision_overlap": (forces.hertz_collision_overlap, (R_STAR, M_STAR, E_STAR, 0.5)),
    "stability_limit": (forces.symplectic_euler_stability_limit, (1.3,)),
    "contact_time_step": (lambda r, m, e, g, v: forces.contact_time_step(r, m, e, g, v, xi_rol=2.0),
                          (R_STAR, M_STAR, E_STAR, G_STAR, 0.5)),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(LAWS))
def test_gradients_match_central_differences(name):
    fn, args = LAWS[name]
    assert_gradients_match(fn, args)


def test_which_branch_the_gradient_points_cover():
    # the parametrised checks above must exercise both stick and slip
    _, _, stick = forces.mindlin_tangential_force(jnp.asarray(SPRING), jnp.asarray(V_T), jnp.asarray(TILTED), 1e-5,
                                                  DELTA, F_N, R_STAR, M_STAR, G_STAR, 0.4, 0.5)
    _, _, slip = forces.mindlin_tangential_force(jnp.asarray(SPRING), jnp.asarray(V_T), jnp.asarray(TILTED), 1e-5,
                                                 DELTA, F_N, R_STAR, M_STAR, G_STAR, 0.4, 0.01)
    assert not bool(stick) and bool(slip)


@pytest.mark.slow
@pytest.mark.parametrize("delta", [0.0, -1e-7, 1e-300, 1e-30])
@pytest.mark.parametrize("zero_velocity", [True, False])
def test_gradients_finite_at_the_edges(delta, zero_velocity):
    v = np.zeros(3) if zero_velocity else V_T

    def all_laws(delta, f_n, spring, v_t, omega):
        n = jnp.asarray(Z)
        normal = forces.hertz_normal_force(delta, 0.1, R_STAR, M_STAR, E_STAR, 1.0, no_tension=True)
        force, s_t, _ = forces.mindlin_tangential_force(spring, v_t, n, 1e-5, delta, f_n, R_STAR, M_STAR, G_STAR,
                                                        1.0, 0.5)
        torque, s_r, _ = forces.rolling_resistance_torque(spring, omega, jnp.zeros(3), n, 1e-5, delta, f_n, R_STAR,
                                                          J_STAR, G_STAR, 0.2, 0.1, projection=True)
        return normal + jnp.sum(force) + jnp.sum(s_t) + jnp.sum(torque) + jnp.sum(s_r)

    for spring in (np.zeros(3), SPRING):
        grads = jax.grad(all_laws, argnums=(0, 1, 2, 3, 4))(delta, F_N, jnp.asarray(spring), jnp.asarray(v),
                                                             jnp.asarray(v))
        assert_all_finite(grads)
    if delta <= 0:
        assert float(jax.grad(forces.hertz_normal_force)(delta, 0.1, R_STAR, M_STAR, E_STAR, 1.0)) == 0.0


# --------------------------------------------------------------------------
# time step


@pytest.mark.parametrize("z", [0.0, 0.3, 1.0, math.sqrt(3.5), 4.0])
def test_stability_limit_is_where_the_amplification_matrix_leaves_the_unit_disc(z):
    limit = float(forces.symplectic_euler_stability_limit(z))
    assert limit == pytest.approx(min(2 * (math.sqrt(1 + z * z) - z), 1 / z if z else np.inf), rel=1e-12)

    def spectral_radius(a):
        # v <- v - a (X + 2 z v), X <- X + a v  (X = omega x, a = omega dt)
        m = np.array([[1 - 2 * z * a, -a], [a * (1 - 2 * z * a), 1 - a * a]])
        return max(abs(np.linalg.eigvals(m)))

    assert spectral_radius(0.999 * limit) < 1 if z > 0 else spectral_radius(0.999 * limit) <= 1 + 1e-12
    assert spectral_radius(1.001 * limit) > 1


def test_eq_47_collision_time_step():
    v = 0.3
    dt_con = 2.87 * (M_STAR**2 / (R_STAR * E_STAR**2 * v)) ** 0.2
    assert float(forces.hertz_collision_duration(R_STAR, M_STAR, E_STAR, v)) == pytest.approx(dt_con, rel=1e-14)
    assert float(forces.hertz_collision_time_step(R_STAR, M_STAR, E_STAR, v)) == pytest.approx(dt_con / 10, rel=1e-14)
    assert float(forces.hertz_collision_duration(R_STAR, M_STAR, E_STAR, 0.0)) == np.inf
    # energy balance of the largest overlap: m* v^2/2 = (8/15) sqrt(r*) E* delta^(5/2)
    delta = float(forces.hertz_collision_overlap(R_STAR, M_STAR, E_STAR, v))
    assert 8 / 15 * math.sqrt(R_STAR) * E_STAR * delta**2.5 == pytest.approx(M_STAR * v**2 / 2, rel=1e-13)


def test_tangential_mode_binds_for_the_papers_materials():
    v = 0.3
    eq_47 = float(forces.hertz_collision_time_step(R_STAR, M_STAR, E_STAR, v))
    auto = float(forces.contact_time_step(R_STAR, M_STAR, E_STAR, G_STAR, v))
    assert auto < 0.6 * eq_47  # erratum 8: Eq. 47 alone is too long for the stick mode
    no_friction = float(forces.contact_time_step(R_STAR, M_STAR, E_STAR, 0.0, v))
    assert no_friction == pytest.approx(eq_47, rel=1e-14)


def _stick_oscillation(dt, n_steps, delta=DELTA, f_n=F_N):
    """Two equal spheres pressed together (delta fixed), a tangential kick; symplectic Euler on v and omega.

    Returns the largest |relative tangential contact velocity| of the last tenth of the run over the kick.
    """
    n = jnp.asarray(Z)  # from i (below) to j (above)
    inertia = 0.4 * M * R**2

    def step(state, _):
        v_i, v_j, w_i, w_j, spring = state
        _, v_t = forces.relative_contact_velocity(v_i, v_j, w_i, w_j, n, R, R)
        force, spring, _ = forces.mindlin_tangential_force(spring, v_t, n, dt, delta, f_n, R_STAR, M_STAR, G_STAR,
                                                           1.0, 1e3)
        torque_i, torque_j = forces.friction_torque(force, n, R, R)
        state = (v_i + dt * force / M, v_j - dt * force / M, w_i + dt * torque_i / inertia,
                 w_j + dt * torque_j / inertia, spring)
        return state, jnp.linalg.norm(v_t)

    kick = jnp.array([1e-4, 0.0, 0.0])
    zero = jnp.zeros(3)
    _, speeds = jax.lax.scan(step, (kick, zero, zero, zero, zero), None, length=n_steps)
    return float(jnp.max(speeds[-n_steps // 10:])) / 1e-4


def test_automatic_step_is_stable_and_three_times_it_is_not():
    v = 0.3  # the collision that brought them together
    delta = float(forces.hertz_collision_overlap(R_STAR, M_STAR, E_STAR, v))
    f_n = 4 / 3 * math.sqrt(R_STAR) * E_STAR * delta**1.5
    auto = float(forces.contact_time_step(R_STAR, M_STAR, E_STAR, G_STAR, v))
    period = 2 * math.pi / math.sqrt(3.5 * _k_t(delta) / M_STAR)
    n_steps = int(20 * period / auto)
    assert _stick_oscillation(auto, n_steps, delta, f_n) < 1e-3  # damped out
    assert _stick_oscillation(3 * auto, n_steps // 3, delta, f_n) > 1e3  # blows up
    # and Eq. 47's step alone is already unstable here (erratum 8)
    eq_47 = float(forces.hertz_collision_time_step(R_STAR, M_STAR, E_STAR, v))
    assert _stick_oscillation(eq_47, int(20 * period / eq_47), delta, f_n) > 1


def test_head_on_collision_at_the_automatic_step():
    # symplectic Euler (the simulator's scheme) on a head-on collision, against the converged RK4 value
    v0, xi = 0.3, 0.3
    auto = float(forces.contact_time_step(R_STAR, M_STAR, E_STAR, G_STAR, v0, xi_con=xi))
    reference = float(_collision_restitution(jnp.asarray(xi), v0, 16000, R_STAR, M_STAR, E_STAR))

    def restitution(dt):
        x, v = 0.0, v0
        for _ in range(int(3 * 2.87 * (M_STAR**2 / (R_STAR * E_STAR**2 * v0)) ** 0.2 / dt) + 1):
            delta = max(x, 0.0)
            force = 4 / 3 * math.sqrt(R_STAR) * E_STAR * delta**1.5 + 2 * xi * math.sqrt(
                2 * E_STAR * M_STAR * math.sqrt(R_STAR)) * delta**0.25 * v
            v -= dt * force / M_STAR
            x += dt * v
        return -v / v0

    assert restitution(auto) == pytest.approx(reference, rel=0.03)
    assert abs(restitution(auto) - reference) < abs(restitution(10 * auto) - reference)


# --------------------------------------------------------------------------
# transformations and dtypes


def _vector_args(batch=()):
    rng = np.random.default_rng(0)
    spring = rng.normal(size=batch + (3,)) * 1e-8
    v_t = rng.normal(size=batch + (3,)) * 1e-3
    normal = rng.normal(size=batch + (3,))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    delta = np.abs(rng.normal(size=batch)) * 2e-6
    f_n = 4 / 3 * math.sqrt(R_STAR) * E_STAR * delta**1.5
    return spring, v_t, normal, delta, f_n


def _laws(spring, v_t, normal, delta, f_n):
    normal_force = forces.hertz_normal_force(delta, v_t[..., 0], R_STAR, M_STAR, E_STAR, 0.7)
    friction = forces.mindlin_tangential_force(spring, v_t, normal, 1e-5, delta, f_n, R_STAR, M_STAR, G_STAR, 0.5,
                                               0.3)
    rolling = forces.rolling_resistance_torque(spring, 1e3 * v_t, -1e3 * v_t, normal, 1e-5, delta, f_n, R_STAR,
                                               J_STAR, G_STAR, 0.2, 0.1, projection=True)
    return normal_force, friction, rolling


@pytest.mark.slow
def test_jit_equals_eager_and_vmap_equals_loop():
    args = _vector_args((16,))
    eager = _laws(*map(jnp.asarray, args))
    jitted = jax.jit(_laws)(*map(jnp.asarray, args))
    mapped = jax.vmap(_laws)(*map(jnp.asarray, args))
    looped = [_laws(*(jnp.asarray(a[k]) for a in args)) for k in range(16)]
    for got in (jitted, mapped):
        for a, b in zip(jax.tree_util.tree_leaves(eager), jax.tree_util.tree_leaves(got)):
            np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-30)
    for k, one in enumerate(looped):
        for a, b in zip(jax.tree_util.tree_leaves(mapped), jax.tree_util.tree_leaves(one)):
            np.testing.assert_allclose(a[k], b, rtol=1e-13, atol=1e-30)
    slipping = np.asarray(eager[1][2])
    assert slipping.any() and not slipping.all()  # both branches are in the batch


@pytest.mark.slow
def test_float32_within_tolerance():
    args = _vector_args((64,))
    wide = _laws(*(jnp.asarray(a, dtype=jnp.float64) for a in args))
    narrow = _laws(*(jnp.asarray(a, dtype=jnp.float32) for a in args))
    for a, b in zip(jax.tree_util.tree_leaves(wide), jax.tree_util.tree_leaves(narrow)):
        assert b.dtype == (jnp.bool_ if a.dtype == jnp.bool_ else jnp.float32)
        if a.dtype == jnp.bool_:
            assert (np.asarray(a) == np.asarray(b)).mean() > 0.95  # flips only at the stick-slip threshold
            continue
        scale = np.max(np.abs(np.asarray(a)))
        np.testing.assert_allclose(np.asarray(b, dtype=np.float64), a, rtol=0, atol=2e-5 * scale)
    dt32 = forces.contact_time_step(np.float32(R_STAR), np.float32(M_STAR), np.float32(E_STAR), np.float32(G_STAR),
                                   np.float32(0.3))
    assert dt32.dtype == jnp.float32
    assert float(dt32) == pytest.approx(float(forces.contact_time_step(R_STAR, M_STAR, E_STAR, G_STAR, 0.3)), rel=1e-5)


def test_stable_time_step_refuses_an_approach_speed_that_sizes_nothing():
    """Issue 28: v_rel = 0 gave inf (or NaN), v_rel = -1 a plausible-looking step. Concrete input raises naming
    v_rel; traced input gives NaN; v_rel = 0 is allowed only with a static overlap delta > 0."""
    import jax

    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match=r"v_rel \(m/s"):
            forces.contact_time_step(R_STAR, M_STAR, E_STAR, G_STAR, bad)
    with pytest.raises(ValueError, match=r"delta \(m"):
        forces.contact_time_step(R_STAR, M_STAR, E_STAR, G_STAR, 0.0, delta=0.0)
    traced = jax.jit(lambda v: forces.contact_time_step(R_STAR, M_STAR, E_STAR, G_STAR, v))
    assert np.isnan(float(traced(-1.0))) and np.isnan(float(traced(0.0)))
    assert float(traced(0.3)) == pytest.approx(float(forces.contact_time_step(R_STAR, M_STAR, E_STAR, G_STAR, 0.3)),
                                               rel=1e-14)
    # a static load: v_rel = 0 sizes the step from delta alone, the same as a slow approach to that overlap
    static = float(forces.contact_time_step(R_STAR, M_STAR, E_STAR, G_STAR, 0.0, delta=DELTA))
    assert np.isfinite(static) and static > 0
