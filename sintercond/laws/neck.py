"""Neck geometry of two overlapping (sintered or pressed) spheres.

All functions take the radii ``r_i``, ``r_j`` and the overlap
``h = r_i + r_j - d`` (``d`` the centre distance; Rojek et al. 2022, Eq. 21)
in any one length unit, broadcast against each other, are pure, and can be
``jit``-, ``vmap``- and ``grad``-transformed. ``h <= 0`` means no contact: the
radius is 0 with zero gradient.

Volume-conserving neck
----------------------
Rojek, Kasztelan & Tharmaraj (2022) replace the lens of two overlapping
spheres by a cylinder of radius ``a`` and height ``h_n`` whose volume equals
the two spherical caps it cuts off (their Eqs. 22-29; Eq. 23 there writes
``r`` for both caps, read ``r_i`` for cap i and ``r_j`` for cap j). Their
residual (Eq. 27)::

    Z(a) = 3 a^2 h_n - h_cj^2 (3 r_j - h_cj) - h_ci^2 (3 r_i - h_ci)

has ``dZ/da = 6 a h_n`` exactly, so ``a = 0`` is a spurious root for every
``h`` and Newton started left of the lens radius converges to it. We solve
the same equation with the trivial factor removed: with ``u = a^2`` and
``s_k = sqrt(r_k^2 - u)``, ``h_ck = u / (r_k + s_k)`` and

    F(u) = Z / (3 a^2) = u * sum_k (r_k + 2 s_k) / (3 (r_k + s_k)^2) - h,
    F'(u) = sum_k (2 r_k + s_k) / (3 (r_k + s_k)^2) > 0,
    F''(u) = sum_k (3 r_k + s_k) / (6 s_k (r_k + s_k)^3) > 0.

``F`` is increasing and convex on ``[0, r_min^2]`` with ``F(0) = -h < 0``, so
a physical root exists iff ``F(r_min^2) >= 0`` (that is ``h <= max_overlap``)
and is unique. ``F(u_coble) > 0`` for Coble's ``u_coble = 2 r* h`` (Rojek
Eqs. 11-12), whose small-``h`` limit it is; Newton from a point right of the
root of an increasing convex function decreases monotonically onto the root,
so the start ``min(u_coble, r_min^2)`` (Coble leaves ``[0, r_min]`` for
``h > r_min^2 / (2 r*)``, before ``max_overlap``) always lands on the physical
root. Five iterations reach 4e-16 relative error in ``a`` over the whole
domain in float64 (benchmarks/RESULTS.md). Equal radii use the closed form of
Eqs. 19-20, which solves the same ``F = 0``, so the two branches are
continuous into each other.

Gradients come from the implicit function theorem on ``F(u; r_i, r_j, h) = 0``
(``dF/dh = -1``, ``dF/dr_k = -u / (r_k + s_k)^2``), never from unrolling the
iterations, and so do not depend on the iteration count; higher orders follow
by differentiating that rule.

Beyond ``max_overlap`` no volume-conserving neck with ``a <= min(r_i, r_j)``
exists. Policy: :func:`neck_radius` returns NaN there (and for non-positive
or non-finite radii, or a non-finite ``h``), so that an invalid state is
visible under ``jit``; :func:`neck_status` returns a :class:`NeckStatus` code
per pair for flagging, and :func:`validate_neck_inputs` raises a
``ValueError`` naming the field and the allowed range, for concrete input at
an API boundary. Gradients are zero wherever the value is 0 (no contact) or
NaN, so one invalid pair cannot poison the gradient of a sum; its NaN value
still does, which is the point.

Float32: values agree with the float64 solution of the same (rounded) input
to 2e-7 relative (about 2 ulp), gradients to 1.5e-6 up to 0.99 ``max_overlap``
and 3e-5 right at it (measured over 1e5 random pairs, radius ratios up to
1e3; tests/test_neck.py checks 5e-7 and 1e-5).
"""

from __future__ import annotations

import enum
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from sintercond._numerics import as_float_arrays, safe_sqrt, sqrt_difference_of_squares
from sintercond._validation import concrete_arrays, fail_where, require_finite, require_positive

DEFAULT_NEWTON_ITERATIONS = 5
"""Newton steps of :func:`neck_radius`; 5 reach ~4e-16 relative error in float64."""

_MAX_NEWTON_ITERATIONS = 50  # cap of the run-to-convergence mode (iterations=None)

# Relative slack above max_overlap still accepted as "at" max_overlap (h given as
# the rounded max_overlap itself); the solve clips a to min(r_i, r_j) there.
_MAX_OVERLAP_SLACK_ULPS = 8


class NeckStatus(enum.IntEnum):
    """Per-pair result code of :func:`neck_status`."""

    OK = 0
    """``0 < h <= max_overlap``: a volume-conserving neck exists."""
    NO_CONTACT = 1
    """``h <= 0``: the spheres do not touch; the neck radius is 0."""
    BEYOND_MAX_OVERLAP = 2
    """``h > max_overlap``: no neck with ``a <= min(r_i, r_j)``; value is NaN."""
    INVALID_INPUT = 3
    """A radius is not finite and positive, or ``h`` is not finite; value is NaN."""


def coble_radius(r_i, r_j, h):
    """Coble's neck radius ``a = sqrt(2 r* h)``, ``r* = 2 r_i r_j / (r_i + r_j)``.

    Rojek et al. (2022), Eqs. 11-12 (Coble 1958, extended to unequal sizes).
    It overestimates the volume-conserving neck and exceeds ``min(r_i, r_j)``
    for ``h > min(r_i, r_j)^2 / (2 r*)``; it is returned as the formula gives.

    Args:
      r_i, r_j: sphere radii, > 0 (length).
      h: overlap ``r_i + r_j - d`` (length); ``h <= 0`` gives 0.

    Returns:
      Neck radius (length), broadcast shape of the inputs; NaN for invalid radii.
    """
    r_i, r_j, h = as_float_arrays(r_i, r_j, h)
    r_star = 2.0 * r_i * r_j / (r_i + r_j)
    a = safe_sqrt(2.0 * r_star * h)
    return jnp.where(_valid_radii(r_i, r_j) & jnp.isfinite(h), a, jnp.nan)


def hertz_radius(r_i, r_j, h):
    """Hertz contact radius ``a = sqrt(r* h)`` with ``r* = r_i r_j / (r_i + r_j)``.

    Quintana-Ruiz & Campello (2020), Eq. 3 and the remark after Eq. 34
    (``A = pi r* delta``); valid for small elastic overlaps only. Note the
    different ``r*`` from :func:`coble_radius`.

    Args:
      r_i, r_j: sphere radii, > 0 (length).
      h: overlap (length); ``h <= 0`` gives 0.

    Returns:
      Contact radius (length); NaN for invalid radii.
    """
    r_i, r_j, h = as_float_arrays(r_i, r_j, h)
    r_star = r_i * r_j / (r_i + r_j)
    a = safe_sqrt(r_star * h)
    return jnp.where(_valid_radii(r_i, r_j) & jnp.isfinite(h), a, jnp.nan)


def intersection_radius(r_i, r_j, h):
    """Radius of the intersection circle (lens) of two overlapping spheres.

    Quintana-Ruiz & Campello (2020), Eqs. 33-34 (after Zohdi):
    ``a^2 = r_i^2 - L_i^2`` with ``L_i = (d - (r_j^2 - r_i^2)/d) / 2``. Evaluated
    in the factored, cancellation-free form
    ``a^2 = h (2(r_i + r_j) - h) (2 r_i - h) (2 r_j - h) / (4 d^2)``.

    Args:
      r_i, r_j: sphere radii, > 0 (length).
      h: overlap (length); ``h <= 0`` gives 0. Defined for
        ``h < 2 min(r_i, r_j)`` (``d > |r_i - r_j|``); NaN beyond, where one
        sphere swallows the other.

    Returns:
      Lens radius (length).
    """
    r_i, r_j, h = as_float_arrays(r_i, r_j, h)
    defined = _valid_radii(r_i, r_j) & jnp.isfinite(h) & (h < 2.0 * jnp.minimum(r_i, r_j))
    # in units of the larger radius: the reverse mode of h^4 / d^2 in metres overflows float32 for
    # micrometre spheres (its cotangent carries 1/d^4), in these units every factor is of order one
    scale = jnp.where(defined, jnp.maximum(r_i, r_j), 1.0)
    x_i, x_j, eta = r_i / scale, r_j / scale, jnp.where(defined, h, 0.0) / scale
    d = x_i + x_j - eta
    d_safe = jnp.where(defined, d, jnp.ones_like(d))
    a_squared = eta * (2.0 * (x_i + x_j) - eta) * (2.0 * x_i - eta) * (2.0 * x_j - eta) / (4.0 * d_safe**2)
    return jnp.where(defined, scale * safe_sqrt(jnp.where(h > 0, a_squared, 0.0)), jnp.nan)


def max_overlap(r_i, r_j):
    """Largest overlap ``h`` for which a volume-conserving neck exists.

    At ``h_max`` the neck radius reaches the smaller radius, ``a = r_s``
    (Rojek et al. 2022: ``a <= r_i``). From ``F(r_s^2) = 0`` (module docstring),
    with ``r_s <= r_l`` and ``s_l = sqrt(r_l^2 - r_s^2)``::

        h_max = r_s / 3 + r_s^2 (r_l + 2 s_l) / (3 (r_l + s_l)^2)

    which is ``2 r / 3`` for equal radii (Eqs. 18-19, discriminant 0).

    Args:
      r_i, r_j: sphere radii, > 0 (length).

    Returns:
      ``h_max`` (length); NaN for invalid radii.
    """
    r_i, r_j = as_float_arrays(r_i, r_j)
    r_s = jnp.minimum(r_i, r_j)
    r_l = jnp.maximum(r_i, r_j)
    h_max = _max_overlap_of_sorted(r_s, r_l, sqrt_difference_of_squares(r_l, r_s))
    return jnp.where(_valid_radii(r_i, r_j), h_max, jnp.nan)


def _max_overlap_of_sorted(r_s, r_l, s_l):
    """``h_max`` of :func:`max_overlap` from the smaller and larger radius and ``s_l = sqrt(r_l^2 - r_s^2)``;
    array-library agnostic, so that validation computes it in NumPy before anything compiles."""
    return r_s / 3.0 + r_s**2 * (r_l + 2.0 * s_l) / (3.0 * (r_l + s_l) ** 2)


def neck_residual(a, r_i, r_j, h):
    """Rojek's volume-conservation residual ``Z(a)`` (Eq. 27, caps by Eqs. 28-29).

    ``Z = 3 a^2 h_n - h_cj^2 (3 r_j - h_cj) - h_ci^2 (3 r_i - h_ci)`` with
    ``h_n = h_ci + h_cj - h`` (Eq. 24), i.e. ``3/pi`` times the cylinder volume
    minus the two cap volumes. Cap heights use the cancellation-free
    ``h_c = a^2 / (r + sqrt(r^2 - a^2))``. Its derivative is ``6 a h_n``.

    Args:
      a: neck radius, ``0 <= a <= min(r_i, r_j)`` (length).
      r_i, r_j: sphere radii (length).
      h: overlap (length).

    Returns:
      ``Z`` (length^3).
    """
    a, r_i, r_j, h = as_float_arrays(a, r_i, r_j, h)
    h_ci = _cap_height(a, r_i)
    h_cj = _cap_height(a, r_j)
    h_n = h_ci + h_cj - h
    return 3.0 * a**2 * h_n - h_cj**2 * (3.0 * r_j - h_cj) - h_ci**2 * (3.0 * r_i - h_ci)


def neck_radius(r_i, r_j, h, *, iterations: int | None = DEFAULT_NEWTON_ITERATIONS):
    """Volume-conserving cylindrical neck radius (Rojek et al. 2022, Eqs. 19-20, 27).

    Equal radii: the closed form of Eqs. 19-20. Unequal radii: Newton on
    Eq. 27 with the spurious root divided out, from Coble's start (Eq. 33)
    clipped to ``min(r_i, r_j)``; see the module docstring for why this
    always converges to the physical root. Gradients with respect to
    ``r_i``, ``r_j`` and ``h`` are implicit (independent of ``iterations``).

    Args:
      r_i, r_j: sphere radii, > 0 (length).
      h: overlap ``r_i + r_j - d`` (length).
      iterations: Newton steps (static). The default 5 gives ~4e-16
        relative error in float64 everywhere in the domain. ``None`` iterates
        until no entry moves by more than 4 ulp (``lax.while_loop``, at
        most 50 steps; under ``vmap`` the whole batch runs until its slowest
        entry converges).

    Returns:
      Neck radius ``a`` (length): 0 for ``h <= 0`` (zero gradient), the root
      for ``0 < h <= max_overlap(r_i, r_j)``, NaN beyond it or for invalid
      input (see :class:`NeckStatus`).
    """
    r_i, r_j, h = as_float_arrays(r_i, r_j, h)
    return _neck_radius(r_i, r_j, h, iterations)


def neck_status(r_i, r_j, h):
    """Per-pair :class:`NeckStatus` code (int32 array), usable under ``jit``."""
    r_i, r_j, h = as_float_arrays(r_i, r_j, h)
    return _status(r_i, r_j, h)


def validate_neck_inputs(r_i, r_j, h, *, model="volume_conserving", names=("r_i", "r_j", "h")):
    """Raise ``ValueError`` unless every pair is inside the domain of a neck model.

    For concrete input at an API boundary (scene loading, user calls),
    before anything is compiled. Radii must be finite and > 0, ``h`` finite;
    ``h`` is further bounded by ``max_overlap(r_i, r_j)`` for the
    volume-conserving neck and below ``2 min(r_i, r_j)`` for the intersection
    radius (Coble and Hertz take any ``h``). The message names the field, the
    allowed range and the first offending entry.

    Args:
      r_i, r_j: sphere radii (length).
      h: overlaps (length); ``h <= 0`` (no contact) is always allowed.
      model: key of :data:`NECK_MODELS`.
      names: the field names to use in messages.

    Raises:
      ValueError: on the first invalid field.
      TypeError: if called on traced values (use :func:`neck_status` there).
    """
    if model not in NECK_MODELS:
        raise ValueError(f"model must be one of {sorted(NECK_MODELS)}; got {model!r}")
    r_i, r_j, h = concrete_arrays("validate_neck_inputs", r_i, r_j, h)
    name_i, name_j, name_h = names
    require_positive(name_i, r_i)
    require_positive(name_j, r_j)
    require_finite(name_h, h)
    if model == "volume_conserving":
        r_s, r_l = np.minimum(r_i, r_j), np.maximum(r_i, r_j)
        h_max = _max_overlap_of_sorted(r_s, r_l, np.sqrt((r_l - r_s) * (r_l + r_s)))
        fail_where(
            h > h_max * (1.0 + _MAX_OVERLAP_SLACK_ULPS * np.finfo(np.float64).eps),
            lambda i: (
                f"{name_h} must be <= max_overlap({name_i}, {name_j}) "
                f"(no volume-conserving neck with a <= min(r_i, r_j) exists beyond it); "
                f"got {name_h}={float(h[i])!r} with {name_i}={float(r_i[i])!r}, "
                f"{name_j}={float(r_j[i])!r}, max_overlap={float(h_max[i])!r} at index {i}"
            ),
        )
    elif model == "intersection":
        h_limit = 2.0 * np.minimum(r_i, r_j)
        fail_where(
            h >= h_limit,
            lambda i: (
                f"{name_h} must be < 2 min({name_i}, {name_j}) for the intersection radius "
                f"(one sphere swallows the other beyond it); got {name_h}={float(h[i])!r}, "
                f"limit {float(h_limit[i])!r} at index {i}"
            ),
        )


NECK_MODELS = {
    "volume_conserving": neck_radius,
    "coble": coble_radius,
    "intersection": intersection_radius,
    "hertz": hertz_radius,
}
"""Neck (contact) radius models by name, each ``fn(r_i, r_j, h) -> a``."""


# --------------------------------------------------------------------------
# internals


def _valid_radii(r_i, r_j):
    # normal floats only (> 0 in practice): the solver scales by exponent bits
    tiny = jnp.finfo(r_i.dtype).tiny
    return jnp.isfinite(r_i) & jnp.isfinite(r_j) & (r_i >= tiny) & (r_j >= tiny)


def _beyond_max_overlap(r_i, r_j, h):
    eps = jnp.finfo(h.dtype).eps
    return h > max_overlap(r_i, r_j) * (1.0 + _MAX_OVERLAP_SLACK_ULPS * eps)


def _status(r_i, r_j, h):
    valid = _valid_radii(r_i, r_j) & jnp.isfinite(h)
    beyond = _beyond_max_overlap(r_i, r_j, h)
    return jnp.where(
        ~valid,
        NeckStatus.INVALID_INPUT,
        jnp.where(h <= 0, NeckStatus.NO_CONTACT,
                  jnp.where(beyond, NeckStatus.BEYOND_MAX_OVERLAP, NeckStatus.OK)),
    ).astype(jnp.int32)


def _cap_height(a, r):
    """Height of the spherical cap of base radius ``a`` on a sphere of radius ``r``."""
    return a**2 / (r + sqrt_difference_of_squares(r, a))


# The solve works in lengths scaled by c = 2^-e, the power of two that brings
# the smaller radius into [1, 2): rho_k = c r_k, eta = c h, x = c^2 u,
# sigma_k = sqrt(rho_k^2 - x). Scaling by a power of two is exact and costs no
# division, and keeps float32 clear of underflow for micrometre particles given
# in metres. With
#   A_k = rho_k + 2 sigma_k,  B_k = (rho_k + sigma_k)^2,  C_k = 2 rho_k + sigma_k,
# F = x (A_i/B_i + A_j/B_j)/3 - eta and F' = (C_i/B_i + C_j/B_j)/3, so a Newton
# step and the implicit derivative each need a single division.


def _scaled_sphere_terms(x, rho, sqrt=safe_sqrt):
    """``(A, B, C)`` of one sphere at scaled neck ``x``.

    The Newton iteration passes a plain clamped ``sqrt``: it is never
    differentiated, and the double ``where`` of ``safe_sqrt`` costs time there.
    """
    sigma = sqrt(rho * rho - x)
    return rho + 2.0 * sigma, (rho + sigma) ** 2, 2.0 * rho + sigma


def _equal_radii_scaled_neck(rho, eta):
    """``x = a^2`` from Rojek Eqs. 19-20 for ``r_i = r_j = rho`` and ``h = eta``.

    Eq. 19 is rearranged to avoid cancellation at small ``h``
    (``h_c = 12 r h / (3(2r + h) + sqrt(D))``), and its discriminant factored,
    ``D = 9 (2r + h)^2 - 96 r h = 3 (2r - 3h)(6r - h)``, which is exact at
    ``h_max = 2r/3``.
    """
    discriminant = 3.0 * (2.0 * rho - 3.0 * eta) * (6.0 * rho - eta)
    h_c = 12.0 * rho * eta / (3.0 * (2.0 * rho + eta) + safe_sqrt(discriminant))
    return h_c * (2.0 * rho - h_c)


def _newton_scaled_neck(rho_i, rho_j, eta, iterations):
    x_max = jnp.minimum(rho_i, rho_j) ** 2
    x = jnp.minimum(4.0 * eta * rho_i * rho_j / (rho_i + rho_j), x_max)  # Coble, Eqs. 11-12

    def newton_step(x):
        a_i, b_i, c_i = _scaled_sphere_terms(x, rho_i, _clamped_sqrt)
        a_j, b_j, c_j = _scaled_sphere_terms(x, rho_j, _clamped_sqrt)
        step = (x * (a_i * b_j + a_j * b_i) - 3.0 * eta * b_i * b_j) / (c_i * b_j + c_j * b_i)
        return jnp.clip(x - step, 0.0, x_max)

    if iterations is not None:
        for _ in range(iterations):
            x = newton_step(x)
        return x

    # Iterate to convergence: the iterates decrease monotonically, so stop
    # once no step moves any entry by more than a few ulp.
    tolerance = 4 * jnp.finfo(x.dtype).eps

    def not_converged(carry):
        x, step, count = carry
        return (count < _MAX_NEWTON_ITERATIONS) & jnp.any(step > tolerance * x)

    def body(carry):
        x, _, count = carry
        x_new = newton_step(x)
        return x_new, jnp.abs(x - x_new), count + 1

    x, _, _ = jax.lax.while_loop(not_converged, body, (x, jnp.full_like(x, jnp.inf), 0))
    return x


def _clamped_sqrt(x):
    return jnp.sqrt(jnp.maximum(x, 0.0))


def _power_of_two_scale(r_i, r_j):
    """``(c, 1/c)``: the power of two ``c`` with ``c min(r_i, r_j)`` in ``[1, 2)``, and its inverse.

    Built from the exponent bits (no division, no ``pow``); radii must be
    normal floats (``_valid_radii`` guarantees it).
    """
    r = jnp.minimum(r_i, r_j)
    info = jnp.finfo(r.dtype)
    int_dtype = jnp.int64 if info.bits == 64 else jnp.int32
    exponent_mask = ((1 << info.nexp) - 1) << info.nmant
    exponent_bits = jax.lax.bitcast_convert_type(r, int_dtype) & exponent_mask
    unit = jax.lax.bitcast_convert_type(exponent_bits, r.dtype)  # 2^E <= r < 2^(E+1)
    double_bias = (2 * (info.maxexp - 1)) << info.nmant
    scale = jax.lax.bitcast_convert_type(double_bias - exponent_bits, r.dtype)  # 2^-E
    return scale, unit


def _solve_neck_radius(r_i, r_j, h, iterations):
    """Neck radius for radii > 0 and ``h > 0``; ``h`` beyond ``h_max`` gives ``min(r_i, r_j)``."""
    scale, unit = _power_of_two_scale(r_i, r_j)
    rho_i, rho_j, eta = r_i * scale, r_j * scale, h * scale
    x = jnp.where(
        r_i == r_j,
        _equal_radii_scaled_neck(rho_i, eta),
        _newton_scaled_neck(rho_i, rho_j, eta, iterations),
    )
    return jnp.sqrt(x) * unit


# The whole masked function carries the custom JVP, not just the solve: the
# linearisation then keeps three partials and nothing of the masking, which
# makes value-and-gradient 2-3x cheaper on the CPU than differentiating
# through the where()s around a custom-JVP solve.
@partial(jax.custom_jvp, nondiff_argnums=(3,))
def _neck_radius(r_i, r_j, h, iterations):
    valid = _valid_radii(r_i, r_j) & jnp.isfinite(h)
    contact = valid & (h > 0)
    # Masked entries get a harmless in-domain problem (0.1 r_min < h_max), so
    # the solve never produces NaN there; overlaps beyond h_max need no guard
    # (the clipped solve ends at r_min) and are set to NaN afterwards.
    r_i_safe = jnp.where(valid, r_i, 1.0)
    r_j_safe = jnp.where(valid, r_j, 1.0)
    h_safe = jnp.where(contact, h, 0.1 * jnp.minimum(r_i_safe, r_j_safe))
    a = _solve_neck_radius(r_i_safe, r_j_safe, h_safe, iterations)
    beyond = _beyond_max_overlap(r_i, r_j, h)
    return jnp.where(valid & ~beyond, jnp.where(contact, a, 0.0), jnp.nan)


@_neck_radius.defjvp
def _neck_radius_jvp(iterations, primals, tangents):
    # Implicit function theorem on F(u; r_i, r_j, h) = 0 with u = a^2:
    # dF/dh = -1, dF/dr_k = -u / (r_k + s_k)^2, dF/du = F' (module docstring).
    # In scaled terms (exact powers of two cancel):
    #   da = 3 [B_i B_j dh + x (B_j dr_i + B_i dr_j)] / (2 sqrt(x) (C_i B_j + C_j B_i)).
    # Entries without a neck (no contact, NaN) get zero tangents; a is taken
    # from _neck_radius itself so that higher derivatives are implicit too.
    r_i, r_j, h = primals
    dr_i, dr_j, dh = tangents
    a = _neck_radius(r_i, r_j, h, iterations)
    has_neck = a > 0
    r_i = jnp.where(has_neck, r_i, 1.0)
    r_j = jnp.where(has_neck, r_j, 1.0)
    scale, _ = _power_of_two_scale(r_i, r_j)
    root_x = jnp.where(has_neck, a * scale, 0.5)
    x = root_x * root_x
    _, b_i, c_i = _scaled_sphere_terms(x, r_i * scale)
    _, b_j, c_j = _scaled_sphere_terms(x, r_j * scale)
    factor = jnp.where(has_neck, 3.0 / (2.0 * root_x * (c_i * b_j + c_j * b_i)), 0.0)
    # the three partials first: linearisation then keeps 3 residuals, not 4
    da_dh = factor * b_i * b_j
    da_dr_i = factor * x * b_j
    da_dr_j = factor * x * b_i
    return a, da_dh * dh + da_dr_i * dr_i + da_dr_j * dr_j
