"""Contact laws of the thermo-mechanical DEM, one contact at a time.

Quintana-Ruiz & Campello (2020), Sect. 2 (Eqs. 2-20), with the errata and
readings of ``MECHANICS.md`` (cited as "erratum N"), and the time-step
bounds of Sect. 4 (Eq. 47, erratum 8). Every function here is a pure law of
one contact: scalar arguments broadcast over leading dimensions ``[...]``,
vectors carry a trailing axis of 3 (``[..., 3]``); there are no neighbour
lists and no time stepping (the simulator lifts these laws to pairs).
Everything is ``jit``-, ``vmap``- and ``grad``-able, float64 by default and
float32 when given float32 arrays.

Conventions
-----------
* Pair ``(i, j)``, unit normal ``n`` from the centre of ``i`` towards ``j``
  (Eq. 5), overlap ``delta = r_i + r_j - |x_j - x_i|`` (Eq. 4), overlap rate
  ``delta_dot = (v_i - v_j) . n``. Forces and torques returned are those
  *on particle i*; particle ``j`` gets the opposite force, and the torques
  of :func:`friction_torque`.
* Units: any consistent set; SI below (m, kg, Pa, s, N, N m).
* ``delta <= 0`` (no contact): force, torque and springs are 0 with zero
  gradient. Every square root, fractional power, norm and division that can
  see zero goes through :mod:`sintercond._numerics` (double ``where``), so
  gradients are finite at ``delta = 0``, at ``v_t = 0`` and at a zero spring.
  The damping terms grow like ``delta^(1/4)``, so their derivative in
  ``delta`` grows like ``delta^(-3/4)`` as ``delta -> 0+``: finite at every
  positive float (1e225 at ``delta = 1e-300``), as the law itself dictates.

Rigid walls (Remark 1)
----------------------
A wall is the partner ``j`` with infinite radius, mass and modulus. The
effective quantities are written with reciprocals (``1/(1/r_i + 1/r_j)``)
so that ``jnp.inf`` gives the limits ``r* = r_i``, ``m* = m_i``,
``j* = I_i + m_i r_i^2``, ``E* = E_i/(1 - nu_i^2)``, ``G* = G_i`` exactly, with
finite gradients. (LAMMPS' ``fix wall/gran`` gives the wall the particle's
own material instead, ``E* = E/(2(1 - nu^2))``: to compare, pass ``E_j = E_i``
and ``nu_j = nu_i``.)
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from sintercond._deprecation import old_names
from sintercond._numerics import as_float_arrays, materialized, safe_divide, safe_norm, safe_power, safe_sqrt
from sintercond._validation import all_concrete, concrete_arrays, require_positive

SOLID_SPHERE_INERTIA = 0.4
"""``I = (2/5) m r^2`` of a solid sphere (Sect. 2): the factor ``I / (m r^2)``."""

CONTACT_POINT_MOBILITY = 1.0 + 1.0 / SOLID_SPHERE_INERTIA
"""``1 + m r^2 / I = 3.5``: a tangential force ``F`` at the surface of a solid
sphere accelerates the contact point by ``3.5 F / m`` (translation plus spin)."""

HERTZ_DURATION_FACTOR = 2.87
"""The factor of Eq. 47 (Johnson 1985): the duration of a Hertz collision."""

SHEAR_CONVENTIONS = ("paper", "mindlin")


# --------------------------------------------------------------------------
# effective quantities (Eqs. 3, 6, 9, 18)


def _harmonic(a, b):
    """``1 / (1/a + 1/b)``: ``a`` when ``b = inf``, with finite gradients there."""
    return 1.0 / (1.0 / a + 1.0 / b)


def effective_radius(r_i, r_j):
    """Effective radius ``r* = r_i r_j / (r_i + r_j)`` (Eq. 3), as ``1/(1/r_i + 1/r_j)``.

    Args:
      r_i, r_j: radii > 0 (m); ``jnp.inf`` for a wall (gives ``r* = r_i``).

    Returns:
      ``r*`` (m).
    """
    return _harmonic(*as_float_arrays(r_i, r_j))


def effective_mass(m_i, m_j):
    """Effective mass ``m* = m_i m_j / (m_i + m_j)`` (Eq. 6), as ``1/(1/m_i + 1/m_j)``.

    Args:
      m_i, m_j: masses > 0 (kg); ``jnp.inf`` for a wall (gives ``m* = m_i``).

    Returns:
      ``m*`` (kg).
    """
    return _harmonic(*as_float_arrays(m_i, m_j))


def effective_modulus(E_i, nu_i, E_j, nu_j):
    """Effective Young's modulus of Eq. 3, ``1/E* = (1 - nu_i^2)/E_i + (1 - nu_j^2)/E_j``.

    Equal to the printed ``E_i E_j / (E_j (1 - nu_i^2) + E_i (1 - nu_j^2))``;
    the compliance form gives ``E* = E_i / (1 - nu_i^2)`` for a rigid wall
    (``E_j = jnp.inf``, Remark 1).

    Args:
      E_i, E_j: Young's moduli > 0 (Pa).
      nu_i, nu_j: Poisson ratios in (-1, 0.5].

    Returns:
      ``E*`` (Pa).
    """
    E_i, nu_i, E_j, nu_j = as_float_arrays(E_i, nu_i, E_j, nu_j)
    return 1.0 / ((1.0 - nu_i**2) / E_i + (1.0 - nu_j**2) / E_j)


def shear_modulus(E, nu):
    """Shear modulus ``G = E / (2 (1 + nu))`` of an isotropic solid (Sect. 2, after Eq. 9).

    Args:
      E: Young's modulus (Pa); softened by :func:`sintercond.laws.materials.softened_modulus`
        it softens ``G`` too (erratum 6).
      nu: Poisson ratio.

    Returns:
      ``G`` (Pa).
    """
    E, nu = as_float_arrays(E, nu)
    return E / (2.0 * (1.0 + nu))


def effective_shear_modulus(E_i, nu_i, E_j, nu_j, convention="paper"):
    """Effective shear modulus ``G*`` of the tangential and rolling springs.

    ``convention="paper"``: Eq. 9 as printed, ``1/G* = 1/G_i + 1/G_j``.
    ``convention="mindlin"``: Mindlin's ``1/G* = (2 - nu_i)/G_i + (2 - nu_j)/G_j``
    (the one LAMMPS' ``tangential mindlin`` uses). For one material the
    paper's ``G*`` is ``2 - nu`` times Mindlin's: 1.7x at ``nu = 0.3``
    (MECHANICS.md, contact laws). ``G_k`` from :func:`shear_modulus`.

    Walls (``E_j = jnp.inf``): ``G* = G_i`` with the paper's convention
    (Remark 1), ``G_i / (2 - nu_i)`` with Mindlin's.

    Args:
      E_i, E_j: Young's moduli (Pa).
      nu_i, nu_j: Poisson ratios.
      convention: ``"paper"`` (default) or ``"mindlin"`` (static).

    Returns:
      ``G*`` (Pa).
    """
    if convention not in SHEAR_CONVENTIONS:
        raise ValueError(f"convention must be one of {SHEAR_CONVENTIONS}; got {convention!r}")
    E_i, nu_i, E_j, nu_j = as_float_arrays(E_i, nu_i, E_j, nu_j)
    weight_i, weight_j = (1.0, 1.0) if convention == "paper" else (2.0 - nu_i, 2.0 - nu_j)
    # 1/G = 2 (1 + nu) / E, as a product with 1/E: at E = inf its nu-derivative is 0, not inf * 0
    return 1.0 / (weight_i * 2.0 * (1.0 + nu_i) * (1.0 / E_i) + weight_j * 2.0 * (1.0 + nu_j) * (1.0 / E_j))


def effective_rolling_inertia(m_i, r_i, m_j, r_j):
    """``j* = (1/(I_i + m_i r_i^2) + 1/(I_j + m_j r_j^2))^-1`` of Eq. 18, solid spheres.

    ``I = (2/5) m r^2`` (Sect. 2), so ``I + m r^2 = (7/5) m r^2``; each term is
    evaluated as ``(5/7) (1/m) (1/r)^2`` so that a wall (``m_j = r_j = jnp.inf``)
    gives ``j* = I_i + m_i r_i^2`` (Remark 1) with finite gradients.

    Args:
      m_i, m_j: masses (kg).
      r_i, r_j: radii (m).

    Returns:
      ``j*`` (kg m^2).
    """
    m_i, r_i, m_j, r_j = as_float_arrays(m_i, r_i, m_j, r_j)
    factor = 1.0 / (1.0 + SOLID_SPHERE_INERTIA)

    def compliance(m, r):
        return factor * (1.0 / m) * (1.0 / r) ** 2

    return 1.0 / (compliance(m_i, r_i) + compliance(m_j, r_j))


# --------------------------------------------------------------------------
# stiffness and damping coefficients (Eqs. 2, 6, 7, 11, 15, 18)


def _damping_coefficient(xi, stiffness_modulus, inertia, r_star, delta):
    """``2 xi sqrt(c inertia sqrt(r*)) delta^(1/4)``, the shared form of Eqs. 6, 11 and 18."""
    # delta^(1/4) as two square roots: cheaper than a power, NaN-safe at 0 (both roots are safe_sqrt)
    return 2.0 * xi * safe_sqrt(stiffness_modulus * inertia * safe_sqrt(r_star)) * safe_sqrt(safe_sqrt(delta))


def normal_damping_coefficient(delta, r_star, m_star, e_star, xi_con):
    """``d_con = 2 xi_con sqrt(2 E* m* sqrt(r*)) delta^(1/4)`` (Eq. 6), N s/m.

    It is ``2 xi_con sqrt(k m*)`` with the linearised Hertz stiffness
    ``k = d f/d delta = 2 E* sqrt(r* delta)``: ``xi_con`` is the damping ratio
    of the linearised contact (1: critical). 0 for ``delta <= 0``.
    """
    delta, r_star, m_star, e_star, xi_con = as_float_arrays(delta, r_star, m_star, e_star, xi_con)
    return _damping_coefficient(xi_con, 2.0 * e_star, m_star, r_star, delta)


def hertz_normal_force(delta, delta_dot, r_star, m_star, e_star, xi_con, *, no_tension=False):
    """Hertz normal force with viscous damping, Eqs. 2, 4-6: its magnitude along ``-n``.

    ``f_n = (4/3) sqrt(r*) E* delta^(3/2) + d_con delta_dot``, the force on
    ``i`` being ``-f_n n``; positive is repulsive. ``d_con`` from
    :func:`normal_damping_coefficient`.

    Whether damping may pull while a contact opens is not said in the paper
    (MECHANICS.md, contact laws): by default it may (``f_n < 0``);
    ``no_tension=True`` clamps ``f_n >= 0`` (LAMMPS ``limit_damping``).

    Args:
      delta: overlap (m); ``<= 0`` gives 0 with zero gradient.
      delta_dot: overlap rate ``(v_i - v_j) . n`` (m/s), > 0 while approaching.
      r_star, m_star, e_star: effective radius (m), mass (kg), modulus (Pa).
      xi_con: normal damping ratio (1: critical).
      no_tension: clamp the force at 0 (static).

    Returns:
      ``f_n`` (N), broadcast shape of the inputs.
    """
    delta, delta_dot, r_star, m_star, e_star, xi_con = as_float_arrays(
        delta, delta_dot, r_star, m_star, e_star, xi_con)
    elastic = (4.0 / 3.0) * safe_sqrt(r_star) * e_star * (delta * safe_sqrt(delta))  # delta^(3/2) without a power
    force = elastic + normal_damping_coefficient(delta, r_star, m_star, e_star, xi_con) * delta_dot
    if no_tension:
        force = jnp.where(force > 0, force, 0.0)
    return jnp.where(delta > 0, force, 0.0)


def hertz_elastic_energy(delta, r_star, e_star):
    """Elastic energy stored in a Hertz contact, ``(8/15) sqrt(r*) E* delta^(5/2)`` (J): the integral of Eq. 2's
    elastic part over the overlap; 0 for ``delta <= 0``.

    Args:
      delta: overlap (m); r_star, e_star: effective radius (m) and modulus (Pa).
    """
    delta, r_star, e_star = as_float_arrays(delta, r_star, e_star)
    squeezed = jnp.where(delta > 0, delta, 0.0)
    return (8.0 / 15.0) * safe_sqrt(r_star) * e_star * squeezed * squeezed * safe_sqrt(squeezed)


def tangential_stiffness(delta, r_star, g_star):
    """Mindlin's tangential stiffness ``k_t = 8 G* sqrt(r* delta)`` (Eq. 7), N/m; 0 for ``delta <= 0``."""
    delta, r_star, g_star = as_float_arrays(delta, r_star, g_star)
    return 8.0 * g_star * safe_sqrt(r_star * delta)


def tangential_damping_coefficient(delta, r_star, m_star, g_star, xi_fric):
    """``d_fric = 2 xi_fric sqrt(8 G* m* sqrt(r*)) delta^(1/4)`` (Eq. 11), N s/m.

    That is ``2 xi_fric sqrt(k_t m*)``. The contact point of a solid sphere is
    3.5x more mobile than its centre (:data:`CONTACT_POINT_MOBILITY`), so the
    damping ratio of the tangential mode is ``xi_fric sqrt(3.5)`` (erratum 8).
    """
    delta, r_star, m_star, g_star, xi_fric = as_float_arrays(delta, r_star, m_star, g_star, xi_fric)
    return _damping_coefficient(xi_fric, 8.0 * g_star, m_star, r_star, delta)


def rolling_stiffness(delta, r_star, g_star):
    """Rolling stiffness ``k_r = 8 G* sqrt(r* delta) r*^2`` (Eq. 15), N m/rad."""
    delta, r_star, g_star = as_float_arrays(delta, r_star, g_star)
    return tangential_stiffness(delta, r_star, g_star) * r_star**2


def rolling_damping_coefficient(delta, r_star, j_star, g_star, xi_rol):
    """``d_rol = 2 xi_rol sqrt(8 G* j* sqrt(r*)) r* delta^(1/4)`` (Eq. 18), N m s/rad."""
    delta, r_star, j_star, g_star, xi_rol = as_float_arrays(delta, r_star, j_star, g_star, xi_rol)
    return _damping_coefficient(xi_rol, 8.0 * g_star, j_star, r_star, delta) * r_star


# --------------------------------------------------------------------------
# kinematics of one contact


def _contact_arrays(vectors, scalars):
    """Cast vectors ``[..., 3]`` and scalars ``[...]`` to one float dtype; scalars broadcast together."""
    scalars = as_float_arrays(*scalars)
    vectors = [jnp.asarray(v) for v in vectors]
    dtype = jnp.result_type(*vectors, *scalars)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    return [v.astype(dtype) for v in vectors], [s.astype(dtype) for s in scalars]


def _dot(a, b):
    return jnp.sum(a * b, axis=-1)


def _cross(a, b):
    """``a x b`` over the trailing axis, stacked there (``jnp.cross`` stacks in front, then transposes)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return jnp.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def tangential_part(vectors, normal):
    """``v - (v . n) n``: the part of ``vectors [..., 3]`` in the plane normal to the unit ``n``."""
    return vectors - _dot(vectors, normal)[..., None] * normal


def rotate_onto_tangent_plane(spring, normal):
    """Carry a stored spring onto the current contact plane, keeping its length (erratum 4).

    The paper does not say how the accumulated deformation follows a turning
    contact plane. As LAMMPS' ``rotate_rescale_vec``: drop the component along
    the current normal, then rescale to the stored length. A spring normal to
    the plane (no tangential part left) becomes 0.

    Args:
      spring: ``[..., 3]`` stored spring (m, or rad for rolling).
      normal: ``[..., 3]`` current unit normal.

    Returns:
      ``[..., 3]`` spring in the plane, of the input's length.
    """
    projected = tangential_part(spring, normal)
    return projected * safe_divide(safe_norm(spring, keepdims=True), safe_norm(projected, keepdims=True))


def relative_contact_velocity(v_i, v_j, omega_i, omega_j, normal, r_i, r_j):
    """Overlap rate and tangential slip velocity of a contact (Eqs. 2, 7, 12).

    Contact point of ``i`` at ``x_i + r_i n``, of ``j`` at ``x_j - r_j n``; their
    relative velocity is ``u = v_i - v_j + (r_i omega_i + r_j omega_j) x n``.
    Then ``delta_dot = u . n = (v_i - v_j) . n`` and ``v_t = u - (u . n) n``.
    For a wall pass its surface velocity as ``v_j``, ``omega_j = 0`` and
    ``r_j = 0`` (not ``inf``: ``inf * 0`` is NaN).

    Args:
      v_i, v_j, omega_i, omega_j, normal: ``[..., 3]`` (m/s, rad/s, unit).
      r_i, r_j: ``[...]`` lever arms (m), the radii.

    Returns:
      ``(delta_dot [...], v_t [..., 3])`` (m/s).
    """
    (v_i, v_j, omega_i, omega_j, normal), (r_i, r_j) = _contact_arrays(
        (v_i, v_j, omega_i, omega_j, normal), (r_i, r_j))
    spin = r_i[..., None] * omega_i + r_j[..., None] * omega_j
    u = v_i - v_j + _cross(spin, normal)
    return _dot(u, normal), tangential_part(u, normal)


# --------------------------------------------------------------------------
# stick-slip with an accumulated spring (Eqs. 7-13 and 15-20)

SLIP_DIRECTIONS = ("trial", "velocity")


def _stick_slip(trial_spring, rate, stiffness, damping, static_limit, dynamic_limit, slip_direction):
    """Spring-dashpot-slider return map shared by friction and rolling.

    Trial ``f = -k s - d rate``; stick if ``|f| <= static_limit``, else slip
    with ``|f| = dynamic_limit`` along the trial force (``"trial"``, erratum 3)
    or along ``-rate/|rate|`` (``"velocity"``, the paper's ``-mu |f_n| t``,
    erratum 1; 0 where ``rate = 0``), and the spring reset so that it
    reproduces the slip force, ``s = -(f + d rate)/k`` (Eq. 13 with
    erratum 1's sign). ``k = 0`` gives a zero spring.
    """
    # computed once each, not in every [..., 3] consumer per component (materialized)
    stiffness, damping = materialized(stiffness)[..., None], materialized(damping)[..., None]
    trial = -stiffness * trial_spring - damping * rate
    trial_size = materialized(safe_norm(trial))
    slipping = trial_size > static_limit
    if slip_direction == "trial":
        direction = safe_divide(trial, trial_size[..., None])
    else:
        direction = -safe_divide(rate, safe_norm(rate, keepdims=True))
    slip = dynamic_limit[..., None] * direction
    slip_spring = -safe_divide(slip + damping * rate, stiffness)
    force = jnp.where(slipping[..., None], slip, trial)
    spring = jnp.where(slipping[..., None], slip_spring, trial_spring)
    return force, spring, slipping


def _check_slip_direction(slip_direction):
    if slip_direction not in SLIP_DIRECTIONS:
        raise ValueError(f"slip_direction must be one of {SLIP_DIRECTIONS}; got {slip_direction!r}")


def _release_open(delta, force, spring, slipping):
    """Zero force and spring, not slipping, where the contact is open (``delta <= 0``)."""
    contact = delta > 0
    return (jnp.where(contact[..., None], force, 0.0), jnp.where(contact[..., None], spring, 0.0),
            slipping & contact)


def mindlin_tangential_force(spring, v_t, normal, dt, delta, normal_force, r_star, m_star, g_star,
                             xi_fric, mu_s, mu_d=None, *, slip_direction="trial"):
    """Mindlin stick-slip friction with an accumulated spring (Eqs. 7-13), one step.

    1. The stored spring is carried onto the current tangent plane and keeps
       its length (erratum 4, :func:`rotate_onto_tangent_plane`); the normal
       part of ``v_t`` is dropped.
    2. Trial spring ``dx = dx_acc + v_t dt`` (Eqs. 10, 12, rectangle rule) and
       trial force ``f = -k_t dx - d_fric v_t`` (Eq. 7) with
       ``k_t = 8 G* sqrt(r* delta)`` and ``d_fric`` of Eq. 11.
    3. Stick if ``|f| <= mu_s |f_n|`` (Eq. 8): force ``f``, spring ``dx``.
    4. Else slip: force of magnitude ``mu_d |f_n|`` along the trial force
       (``slip_direction="trial"``, default, erratum 3; LAMMPS / Luding 2008)
       or ``-mu_d |f_n| v_t/|v_t|`` (``"velocity"``, Eq. 8 with erratum 1's
       minus sign; 0 at ``v_t = 0`` where ``t`` is undefined). The two agree
       in steady sliding. The spring is reset to reproduce that force,
       ``dx = -(f + d_fric v_t)/k_t`` (Eq. 13, erratum 1).

    At ``delta <= 0`` force and spring are 0 (the contact forgets its history).
    The force is discontinuous where the state switches from stick to slip
    when ``mu_d != mu_s``; with ``mu_d = mu_s`` it is continuous, and its
    gradient is that of the branch taken.

    Args:
      spring: ``[..., 3]`` accumulated tangential spring ``dx_acc`` (m).
      v_t: ``[..., 3]`` tangential relative velocity of the contact points,
        ``i`` relative to ``j``, spins included
        (:func:`relative_contact_velocity`) (m/s).
      normal: ``[..., 3]`` unit normal from ``i`` to ``j``.
      dt: time step (s).
      delta: overlap (m).
      normal_force: ``f_n`` (N), e.g. :func:`hertz_normal_force`; its
        magnitude sets the limit.
      r_star, m_star, g_star: effective radius (m), mass (kg), shear modulus (Pa).
      xi_fric: tangential damping ratio of Eq. 11.
      mu_s: static friction coefficient.
      mu_d: dynamic friction coefficient; ``None`` uses ``mu_s``.
      slip_direction: ``"trial"`` or ``"velocity"`` (static).

    Returns:
      ``(force [..., 3], new_spring [..., 3], slipping [...] bool)``: the
      friction force on ``i`` (N; ``j`` gets ``-force``), the spring to store
      for the next step, and whether the contact slid.
    """
    _check_slip_direction(slip_direction)
    mu_d = mu_s if mu_d is None else mu_d
    (spring, v_t, normal), (dt, delta, normal_force, r_star, m_star, g_star, xi_fric, mu_s, mu_d) = (
        _contact_arrays((spring, v_t, normal),
                        (dt, delta, normal_force, r_star, m_star, g_star, xi_fric, mu_s, mu_d)))
    v_t = tangential_part(v_t, normal)
    trial_spring = rotate_onto_tangent_plane(spring, normal) + v_t * dt[..., None]
    load = jnp.abs(normal_force)
    force, new_spring, slipping = _stick_slip(
        trial_spring, v_t,
        tangential_stiffness(delta, r_star, g_star),
        tangential_damping_coefficient(delta, r_star, m_star, g_star, xi_fric),
        mu_s * load, mu_d * load, slip_direction)
    return _release_open(delta, force, new_spring, slipping)


def rolling_resistance_torque(spring, omega_i, omega_j, normal, dt, delta, normal_force, r_star, j_star,
                              g_star, xi_rol, mu_r, *, projection=False, slip_direction="trial"):
    """Rolling resistance with an accumulated rotational spring (Eqs. 15-20), one step.

    Literal law (default, erratum 5): the relative rotation rate is the full
    ``omega_ij = omega_i - omega_j`` (twisting included) and the spring is a
    rotation vector in the global frame, not carried with the contact plane.
    ``projection=True``: only the rolling part, ``omega_ij - (omega_ij . n) n``,
    is integrated and the spring is carried onto the current tangent plane
    (erratum 4). This is LAMMPS' ``rolling sds``: its spring on the rolling
    displacement ``R (omega_i - omega_j) x n`` with torque ``R n x f_r`` is
    this one for a tangential rotation ``theta`` (``n x (theta x n) = theta``),
    with ``k_r = k_roll R^2``.

    Trial ``theta = theta_acc + omega_ij dt`` (Eqs. 17, 19) and torque
    ``m = -k_r theta - d_rol omega_ij`` (Eq. 15), ``k_r = 8 G* sqrt(r* delta) r*^2``,
    ``d_rol`` of Eq. 18. Stick if ``|m| <= mu_r r* |f_n|`` (Eq. 16); else slip
    with that magnitude along the trial torque (default, erratum 3 carried
    over) or ``-omega_ij/|omega_ij|`` (``"velocity"``: Eq. 16 with erratum 1's
    sign), and the spring reset to reproduce it (Eq. 20, erratum 1). Zero
    torque and spring at ``delta <= 0``.

    Args:
      spring: ``[..., 3]`` accumulated rolling rotation (rad).
      omega_i, omega_j: ``[..., 3]`` spins (rad/s).
      normal: ``[..., 3]`` unit normal from ``i`` to ``j``.
      dt: time step (s).
      delta: overlap (m).
      normal_force: ``f_n`` (N).
      r_star, j_star, g_star: effective radius (m), rolling inertia of
        Eq. 18 (kg m^2, :func:`effective_rolling_inertia`), shear modulus (Pa).
      xi_rol: rolling damping ratio.
      mu_r: rolling resistance coefficient (dimensionless).
      projection: roll on the tangential part only (static).
      slip_direction: ``"trial"`` or ``"velocity"`` (static).

    Returns:
      ``(torque [..., 3], new_spring [..., 3], slipping [...] bool)``: the
      rolling torque on ``i`` (N m; ``j`` gets ``-torque``), the spring to
      store, and whether the rolling limit was reached.
    """
    _check_slip_direction(slip_direction)
    (spring, omega_i, omega_j, normal), (dt, delta, normal_force, r_star, j_star, g_star, xi_rol, mu_r) = (
        _contact_arrays((spring, omega_i, omega_j, normal),
                        (dt, delta, normal_force, r_star, j_star, g_star, xi_rol, mu_r)))
    rate = omega_i - omega_j
    if projection:
        rate = tangential_part(rate, normal)
        spring = rotate_onto_tangent_plane(spring, normal)
    limit = mu_r * r_star * jnp.abs(normal_force)
    torque, new_spring, slipping = _stick_slip(
        spring + rate * dt[..., None], rate,
        rolling_stiffness(delta, r_star, g_star),
        rolling_damping_coefficient(delta, r_star, j_star, g_star, xi_rol),
        limit, limit, slip_direction)
    return _release_open(delta, torque, new_spring, slipping)


def friction_torque(friction_force, normal, r_i, r_j):
    """Torques of the friction force about both centres (Eq. 14, erratum 2: one sum).

    The force ``f_t`` acts on ``i`` at ``x_i + r_i n`` and ``-f_t`` on ``j`` at
    ``x_j - r_j n``, so ``m_i = r_i n x f_t`` and ``m_j = (-r_j n) x (-f_t) = r_j n x f_t``.
    The lever arm is the radius (the paper's ``r_ij = r_i n_ij``; LAMMPS uses
    ``r - delta/2``: pass that as ``r_i`` to compare). A wall's torque is
    irrelevant: pass ``r_j = 0``.

    Args:
      friction_force: ``[..., 3]`` friction force on ``i`` (N).
      normal: ``[..., 3]`` unit normal from ``i`` to ``j``.
      r_i, r_j: ``[...]`` lever arms (m).

    Returns:
      ``(torque_i [..., 3], torque_j [..., 3])`` (N m).
    """
    (friction_force, normal), (r_i, r_j) = _contact_arrays((friction_force, normal), (r_i, r_j))
    moment = _cross(normal, friction_force)
    return r_i[..., None] * moment, r_j[..., None] * moment


# --------------------------------------------------------------------------
# time step (Eq. 47, erratum 8)


def hertz_collision_duration(r_star, m_star, e_star, v_rel):
    """Duration of a Hertz collision, ``2.87 (m*^2 / (r* E*^2 v_rel))^(1/5)`` (Eq. 47), s.

    Evaluated as ``2.87 (m*/E*)^(2/5) (r* v_rel)^(-1/5)`` (no ``m*^2 / E*^2``
    underflow in float32). ``inf`` for ``v_rel = 0``.

    Args:
      r_star, m_star, e_star: effective radius (m), mass (kg), modulus (Pa).
      v_rel: normal approach speed before contact (m/s); its magnitude is used.
    """
    r_star, m_star, e_star, v_rel = as_float_arrays(r_star, m_star, e_star, v_rel)
    speed = jnp.abs(v_rel)
    moving = speed > 0
    duration = HERTZ_DURATION_FACTOR * (m_star / e_star) ** 0.4 * safe_power(r_star * speed, -0.2)
    return jnp.where(moving, duration, jnp.inf)


def hertz_collision_time_step(r_star, m_star, e_star, v_rel, fraction=0.1):
    """The paper's step, ``dt = dt_con / 10`` (Eq. 47): accuracy of the normal collision only.

    See :func:`contact_time_step` for the bound that also covers the
    tangential and rolling modes (erratum 8).
    """
    return fraction * hertz_collision_duration(r_star, m_star, e_star, v_rel)


def hertz_collision_overlap(r_star, m_star, e_star, v_rel):
    """Largest overlap of an undamped Hertz collision at approach speed ``v_rel``, m.

    Energy balance ``m* v^2 / 2 = (8/15) sqrt(r*) E* delta^(5/2)``:
    ``delta_max = (15/16)^(2/5) (m*/E*)^(2/5) v^(4/5) r*^(-1/5)``.
    """
    r_star, m_star, e_star, v_rel = as_float_arrays(r_star, m_star, e_star, v_rel)
    return (15.0 / 16.0) ** 0.4 * (m_star / e_star) ** 0.4 * safe_power(jnp.abs(v_rel), 0.8) * r_star**-0.2


def symplectic_euler_stability_limit(damping_ratio):
    """Largest ``omega dt`` for which symplectic Euler keeps a damped oscillator bounded.

    For ``x'' + 2 z omega x' + omega^2 x = 0`` and ``a = omega dt``, one step
    ``v <- v - dt (omega^2 x + 2 z omega v)``, ``x <- x + dt v`` maps
    ``(v, omega x)`` by a matrix with ``det = 1 - 2 z a`` and
    ``trace = 2 - 2 z a - a^2``. Both eigenvalues lie inside the unit circle
    (Jury) iff ``|det| < 1`` and ``|trace| < 1 + det``, i.e. ``a < 1/z`` and
    ``a^2 + 4 z a - 4 < 0``: ``a < min(2 (sqrt(1 + z^2) - z), 1/z)`` (erratum 8).
    The first is always the smaller one (``2/(sqrt(1+z^2) + z) < 1/z``); it is
    evaluated in that cancellation-free form. ``z = 0`` gives 2, the
    undamped limit; heavy damping lowers it (``z = sqrt(3.5)``: 0.50).

    Args:
      damping_ratio: ``z >= 0``.

    Returns:
      The limit of ``omega dt`` (dimensionless).
    """
    (z,) = as_float_arrays(damping_ratio)
    return 2.0 / (jnp.sqrt(1.0 + z * z) + z)


def _mode_time_step(omega_squared, damping_ratio):
    """``limit(z) / omega``; ``inf`` for a mode at rest (``omega = 0``)."""
    omega = safe_sqrt(omega_squared)
    return jnp.where(omega > 0, safe_divide(symplectic_euler_stability_limit(damping_ratio), omega), jnp.inf)


def contact_time_step(r_star, m_star, e_star, g_star, v_rel, *, delta=None, xi_con=1.0, xi_fric=1.0,
                     xi_rol=0.0, fraction=0.1, safety=0.5):
    """Time step of one contact: Eq. 47 and the symplectic-Euler bounds of its three modes.

    ``min(fraction * dt_con, safety * min(dt_n, dt_t, dt_r))`` where
    ``dt_con`` is Eq. 47's collision duration (:func:`hertz_collision_duration`)
    and each ``dt_k = limit(z_k) / omega_k`` is the stability limit of one
    linearised mode under the staggered scheme (Eqs. 43-44, symplectic Euler;
    :func:`symplectic_euler_stability_limit`), at the overlap ``delta``:

    * normal: ``omega_n^2 = 2 E* sqrt(r* delta) / m*`` (the Hertz tangent
      stiffness over ``m*``), ``z_n = xi_con`` (Eq. 6 is ``2 xi sqrt(k m*)``).
    * tangential (stick): a force ``F`` at the contact accelerates the
      contact point of a solid sphere by ``(1 + r^2 m / I) F / m = 3.5 F / m``,
      so ``omega_t^2 = 3.5 k_t / m*`` with ``k_t = 8 G* sqrt(r* delta)`` and
      ``z_t = xi_fric sqrt(3.5)`` (Eq. 11 is ``2 xi sqrt(k_t m*)``). With the
      paper's ``G*`` (``G*/E* = (1 - nu)/2`` for one material)
      ``omega_t / omega_n = sqrt(14 G*/E*) = 2.2`` at ``nu = 0.3``, and
      ``xi_fric = 1`` gives ``z_t = 1.87``: ``dt_t = 0.50/omega_t`` (erratum 8).
    * rolling: ``omega_r^2 = k_r (1/I_i + 1/I_j)``; since ``r* <= r_i, r_j``
      this is at most ``(5/7) omega_t^2`` for solid spheres, which is used
      (conservative, no per-particle inertias needed); and
      ``j* (1/I_i + 1/I_j) = 3.5`` exactly, so ``z_r = xi_rol sqrt(3.5)``.

    ``omega`` grows like ``delta^(1/4)`` while every ``z`` is independent of
    ``delta``, so the bound is taken at the largest overlap: by default the
    undamped collision's (:func:`hertz_collision_overlap` at ``v_rel``); pass
    ``delta`` for a static load larger than that. The mode limits are exact
    for the linearised contact; ``safety`` leaves room for the Hertz
    nonlinearity and for modes coupling in a packing. Solid spheres
    (``I = (2/5) m r^2``) are assumed.

    Args:
      r_star, m_star, e_star, g_star: effective radius (m), mass (kg),
        Young's and shear moduli (Pa) (the stiffest pair of a system).
      v_rel: largest normal approach speed (m/s).
      delta: largest overlap (m); ``None``: the collision's.
      xi_con, xi_fric, xi_rol: damping ratios of Eqs. 6, 11, 18.
      fraction: Eq. 47's fraction of the collision duration (1/10).
      safety: factor on the stability limits.

    Returns:
      The time step (s). NaN under ``jit`` for an approach speed that sizes
      nothing (``v_rel <= 0`` or not finite, unless a static ``delta > 0`` is
      given, when ``v_rel = 0`` is allowed).

    Raises:
      ValueError: for a concrete ``v_rel`` or ``delta`` outside that domain, naming it.
    """
    sized_by_load = delta is not None
    if all_concrete(v_rel, delta):
        # a step sized for no collision is inf, for a negative speed a plausible-looking number: refuse both
        (speed,) = concrete_arrays("contact_time_step", v_rel)
        require_positive("v_rel (m/s, the largest normal approach speed)", speed, allow_zero=sized_by_load)
        if sized_by_load:
            (load_overlap,) = concrete_arrays("contact_time_step", delta)
            require_positive("delta (m, the largest overlap)", load_overlap)
    r_star, m_star, e_star, g_star, v_rel, xi_con, xi_fric, xi_rol = as_float_arrays(
        r_star, m_star, e_star, g_star, v_rel, xi_con, xi_fric, xi_rol)
    if delta is None:
        delta = hertz_collision_overlap(r_star, m_star, e_star, v_rel)
    (delta,) = as_float_arrays(delta)
    sized = jnp.isfinite(v_rel) & jnp.isfinite(delta) & (
        (v_rel >= 0) & (delta > 0) if sized_by_load else (v_rel > 0))
    sqrt_mobility = math.sqrt(CONTACT_POINT_MOBILITY)
    omega_n_squared = 2.0 * e_star * safe_sqrt(r_star * delta) / m_star
    omega_t_squared = CONTACT_POINT_MOBILITY * tangential_stiffness(delta, r_star, g_star) / m_star
    omega_r_squared = (1.0 - 1.0 / CONTACT_POINT_MOBILITY) * omega_t_squared
    stability = jnp.minimum(
        _mode_time_step(omega_n_squared, xi_con),
        jnp.minimum(_mode_time_step(omega_t_squared, xi_fric * sqrt_mobility),
                    _mode_time_step(omega_r_squared, xi_rol * sqrt_mobility)))
    dt = jnp.minimum(hertz_collision_time_step(r_star, m_star, e_star, v_rel, fraction), safety * stability)
    return jnp.where(sized, dt, jnp.nan)


# Old names, kept for one release: each time-step function has its own name (issue 24).
__getattr__ = old_names("sintercond.laws.forces", {
    "stable_time_step": ("sintercond.laws.forces", "contact_time_step"),
})
