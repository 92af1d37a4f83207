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
an API boundary.

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

DEFAULT_NEWTON_ITERATIONS = 5
"""Newton steps of :func:`neck_radius`; 5 reach ~4e-16 relative error in float64."""

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
    d = r_i + r_j - h
    defined = _valid_radii(r_i, r_j) & jnp.isfinite(h) & (h < 2.0 * jnp.minimum(r_i, r_j))
    d_safe = jnp.where(defined, d, jnp.ones_like(d))
    a_squared = h * (2.0 * (r_i + r_j) - h) * (2.0 * r_i - h) * (2.0 * r_j - h) / (4.0 * d_safe**2)
    return jnp.where(defined, safe_sqrt(jnp.where(h > 0, a_squared, 0.0)), jnp.nan)


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
    s_l = sqrt_difference_of_squares(r_l, r_s)
    h_max = r_s / 3.0 + r_s**2 * (r_l + 2.0 * s_l) / (3.0 * (r_l + s_l) ** 2)
    return jnp.where(_valid_radii(r_i, r_j), h_max, jnp.nan)


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


def neck_radius(r_i, r_j, h, *, iterations: int = DEFAULT_NEWTON_ITERATIONS):
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
        relative error in float64 everywhere in the domain.

    Returns:
      Neck radius ``a`` (length): 0 for ``h <= 0`` (zero gradient), the root
      for ``0 < h <= max_overlap(r_i, r_j)``, NaN beyond it or for invalid
      input (see :class:`NeckStatus`).
    """
    r_i, r_j, h = as_float_arrays(r_i, r_j, h)
    status = _status(r_i, r_j, h)
    solvable = status == NeckStatus.OK
    # Double where: feed the solver a harmless in-domain point wherever the
    # pair is not solvable, so neither value nor gradient turns NaN there.
    r_i_safe = jnp.where(solvable, r_i, 1.0)
    r_j_safe = jnp.where(solvable, r_j, 1.0)
    h_safe = jnp.where(solvable, h, 0.5)
    u = _neck_radius_squared(r_i_safe, r_j_safe, h_safe, iterations)
    a = jnp.where(solvable, jnp.sqrt(u), 0.0)
    return jnp.where(status == NeckStatus.BEYOND_MAX_OVERLAP, jnp.nan,
                     jnp.where(status == NeckStatus.INVALID_INPUT, jnp.nan, a))


def neck_status(r_i, r_j, h):
    """Per-pair :class:`NeckStatus` code (int32 array), usable under ``jit``."""
    r_i, r_j, h = as_float_arrays(r_i, r_j, h)
    return _status(r_i, r_j, h)


def validate_neck_inputs(r_i, r_j, h, *, names=("r_i", "r_j", "h")):
    """Raise ``ValueError`` unless every pair has a volume-conserving neck or no contact.

    For concrete input at an API boundary (scene loading, user calls),
    before anything is compiled. The message names the field, the allowed
    range and the first offending entry.

    Args:
      r_i, r_j: sphere radii (length); must be finite and > 0.
      h: overlaps (length); must be finite and ``<= max_overlap(r_i, r_j)``.
      names: the field names to use in messages.

    Raises:
      ValueError: on the first invalid field.
      TypeError: if called on traced values (use :func:`neck_status` there).
    """
    try:
        r_i, r_j, h = (np.asarray(x, dtype=np.float64) for x in (r_i, r_j, h))
    except jax.errors.TracerArrayConversionError as err:
        raise TypeError("validate_neck_inputs needs concrete values; under jit use neck_status") from err
    r_i, r_j, h = np.broadcast_arrays(r_i, r_j, h)
    for name, r in zip(names[:2], (r_i, r_j)):
        bad = ~(np.isfinite(r) & (r > 0))
        if bad.any():
            idx = _first_index(bad)
            raise ValueError(f"{name} must be finite and > 0; got {float(r[idx])!r} at index {idx}")
    bad = ~np.isfinite(h)
    if bad.any():
        idx = _first_index(bad)
        raise ValueError(f"{names[2]} must be finite; got {float(h[idx])!r} at index {idx}")
    h_max = np.asarray(max_overlap(r_i, r_j), dtype=np.float64)
    bad = h > h_max * (1.0 + _MAX_OVERLAP_SLACK_ULPS * np.finfo(np.float64).eps)
    if bad.any():
        idx = _first_index(bad)
        raise ValueError(
            f"{names[2]} must be <= max_overlap({names[0]}, {names[1]}) "
            f"(no volume-conserving neck with a <= min(r_i, r_j) exists beyond it); "
            f"got {names[2]}={float(h[idx])!r} with {names[0]}={float(r_i[idx])!r}, "
            f"{names[1]}={float(r_j[idx])!r}, max_overlap={float(h_max[idx])!r} at index {idx}"
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
    return jnp.isfinite(r_i) & jnp.isfinite(r_j) & (r_i > 0) & (r_j > 0)


def _status(r_i, r_j, h):
    valid = _valid_radii(r_i, r_j) & jnp.isfinite(h)
    eps = jnp.finfo(h.dtype).eps
    beyond = h > max_overlap(r_i, r_j) * (1.0 + _MAX_OVERLAP_SLACK_ULPS * eps)
    return jnp.where(
        ~valid,
        NeckStatus.INVALID_INPUT,
        jnp.where(h <= 0, NeckStatus.NO_CONTACT,
                  jnp.where(beyond, NeckStatus.BEYOND_MAX_OVERLAP, NeckStatus.OK)),
    ).astype(jnp.int32)


def _first_index(mask):
    return tuple(int(i) for i in np.argwhere(mask)[0])


def _cap_height(a, r):
    """Height of the spherical cap of base radius ``a`` on a sphere of radius ``r``."""
    return a**2 / (r + sqrt_difference_of_squares(r, a))


def _reduced_residual_terms(u, r_i, r_j):
    """``(G(u), F'(u), w_i, w_j)`` of the module docstring, ``F = u G - h``.

    ``w_k = 1 / (3 (r_k + s_k)^2)``, so that ``-dF/dr_k = 3 u w_k``.
    """
    s_i = safe_sqrt(r_i * r_i - u)
    s_j = safe_sqrt(r_j * r_j - u)
    inv_i = 1.0 / (3.0 * (r_i + s_i) ** 2)
    inv_j = 1.0 / (3.0 * (r_j + s_j) ** 2)
    g = (r_i + 2.0 * s_i) * inv_i + (r_j + 2.0 * s_j) * inv_j
    dF_du = (2.0 * r_i + s_i) * inv_i + (2.0 * r_j + s_j) * inv_j
    return g, dF_du, inv_i, inv_j


def _equal_radii_neck_squared(r, h):
    """``a^2`` from Rojek Eqs. 19-20 for ``r_i = r_j = r``.

    Eq. 19 is rearranged to avoid cancellation at small ``h``
    (``h_c = 12 r h / (3(2r + h) + sqrt(D))``), and its discriminant factored,
    ``D = 9 (2r + h)^2 - 96 r h = 3 (2r - 3h)(6r - h)``, which is exact at
    ``h_max = 2r/3``.
    """
    discriminant = 3.0 * (2.0 * r - 3.0 * h) * (6.0 * r - h)
    h_c = 12.0 * r * h / (3.0 * (2.0 * r + h) + safe_sqrt(discriminant))
    return h_c * (2.0 * r - h_c)


def _newton_neck_squared(r_i, r_j, h, iterations):
    u_max = jnp.minimum(r_i, r_j) ** 2
    u = jnp.minimum(4.0 * h * r_i * r_j / (r_i + r_j), u_max)  # Coble, Eqs. 11-12
    for _ in range(iterations):
        g, dF_du, _, _ = _reduced_residual_terms(u, r_i, r_j)
        u = jnp.clip(u - (u * g - h) / dF_du, 0.0, u_max)
    return u


@partial(jax.custom_jvp, nondiff_argnums=(3,))
def _neck_radius_squared(r_i, r_j, h, iterations):
    """``a^2`` for in-domain input (``0 < h <= h_max``, radii > 0)."""
    r_i, r_j, h = jax.lax.stop_gradient((r_i, r_j, h))
    return jnp.where(
        r_i == r_j,
        _equal_radii_neck_squared(r_i, h),
        _newton_neck_squared(r_i, r_j, h, iterations),
    )


@_neck_radius_squared.defjvp
def _neck_radius_squared_jvp(iterations, primals, tangents):
    # Implicit function theorem on F(u; r_i, r_j, h) = u G(u) - h = 0.
    r_i, r_j, h = primals
    dr_i, dr_j, dh = tangents
    u = _neck_radius_squared(r_i, r_j, h, iterations)
    _, dF_du, w_i, w_j = _reduced_residual_terms(u, r_i, r_j)
    # -dF/dr_k = u / (r_k + s_k)^2 = 3 u w_k ; -dF/dh = 1
    du = (dh + 3.0 * u * (w_i * dr_i + w_j * dr_j)) / dF_du
    return u, du
