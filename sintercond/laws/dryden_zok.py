"""Dryden & Zok (2004) conductance sigma(alpha) of a sphere with two polar contact caps.

A sphere of unit radius carries ``T = cos(theta)`` on two polar caps of
half-angle ``alpha`` and is adiabatic between them; ``sigma`` is the mean
squared temperature gradient inside it, and the effective conductivity of a
sintered solid is ``k_e = k f sigma`` (Dryden & Zok 2004, Eq. 26, Eq. 27).
Through the Mehler-Dirichlet representation the mixed boundary-value problem
becomes the Fredholm equation of the second kind (their Eq. 24)::

    j(t) - (1/pi) int_0^alpha [K(t - u) + K(t + u)] j(u) du = cos(3t/2),  0 <= t < alpha,
    K(xi) = 1/4 [2 sec(xi/2) + pi |sin(xi/2)| + cos(xi/2) ln tan^2(xi/2)]     (Eq. 25)

and ``sigma = (6/pi) int_0^alpha j(u) cos(3u/2) du`` (Eq. 28).

Numerical method
----------------
``K`` is even, so the two kernel terms are one convolution over ``[-alpha,
alpha]`` with ``j`` extended evenly; its singularities sit on the diagonal
``u = +-t``: ``ln|xi|`` and a kink ``|xi|``. We split, with smooth ``A, B, C``,

    K(xi) = A(xi) ln|xi| + B(xi) |xi| + C(xi),
    A = cos(xi/2)/2,  B = (pi/4) sin(|xi|/2)/|xi|,  C = sec(xi/2)/2 + cos(xi/2)/2 ln(tan(|xi|/2)/|xi|),

and discretise on ``u = alpha s``, ``s in [0, 1]``, with Gauss-Legendre panels
graded geometrically toward ``s = 1`` (where ``j`` has a ``(1-s) ln(1-s)``
type endpoint behaviour, and where the ``1/(pi - xi)`` pole of ``sec`` lies
when ``alpha = pi/2``). On panels near a singular point (``s = tau`` or its
mirror ``s = -tau``) the products ``A j`` and ``B j`` are interpolated by the
panel polynomial and integrated exactly against ``ln|tau - s|`` and
``|tau - s|`` (product integration); elsewhere plain Gauss weights apply.
Because ``ln|xi| = ln(alpha) + ln|tau - s|``, these modified weights do not
depend on ``alpha``: they are computed once per mesh in NumPy (float64), and
the ``alpha``-dependent assembly and the dense solve run in JAX, so ``sigma``
is differentiable in ``alpha`` and ``vmap``s over it.

Plain Nystrom (the paper used 60 equally spaced collocation points) converges
only algebraically on the log kernel; benchmarks/RESULTS.md compares.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from numpy.polynomial import legendre

PANEL_ORDER = 8
"""Gauss-Legendre nodes per panel."""

DEFAULT_NODES = 96
"""Default number of collocation nodes (12 panels of 8): |error| ~ 3e-14 (benchmarks/RESULTS.md)."""

# Smallest distance of a panel break from s = 1 (panel_breaks); meshes up to
# 352 nodes never reach it, so their weights are unchanged by it.
_CLOSEST_BREAK = 1e-14

# Panels whose distance to a singular point is below this many panel lengths
# get product-integration weights.
_NEAR = 1.0


# --------------------------------------------------------------------------
# kernel


def kernel(xi):
    """Dryden & Zok's kernel ``K(xi)`` in closed form (Eq. 25), for ``0 < |xi| < pi``."""
    xi = jnp.abs(xi)
    return 0.25 * (2.0 / jnp.cos(xi / 2) + jnp.pi * jnp.sin(xi / 2) + jnp.cos(xi / 2) * jnp.log(jnp.tan(xi / 2) ** 2))


def kernel_series_coefficient(n):
    """Coefficient of ``cos((n + 1/2) xi)`` in the series of Eq. 25: ``(-1)^n - H_n [1 - (-1)^n]``.

    ``H_0 = 1`` and ``H_n = 1/(2n)`` (Eq. 8); the ``H_0`` choice does not
    matter because ``1 - (-1)^0 = 0``.
    """
    n = np.asarray(n)
    sign = np.where(n % 2 == 0, 1.0, -1.0)
    h = np.where(n == 0, 1.0, 1.0 / (2.0 * np.maximum(n, 1)))
    return sign - h * (1.0 - sign)


def _kernel_parts(xi):
    """``(A, B, C)`` with ``K = A ln|xi| + B |xi| + C``, smooth and NaN-free at ``xi = 0``."""
    x = jnp.abs(xi)
    nonzero = x > 0
    x_safe = jnp.where(nonzero, x, 1.0)
    a = 0.5 * jnp.cos(x / 2)
    b = jnp.where(nonzero, 0.25 * jnp.pi * jnp.sin(x_safe / 2) / x_safe, 0.125 * jnp.pi)
    log_tan_over_x = jnp.where(nonzero, jnp.log(jnp.tan(x_safe / 2) / x_safe), -jnp.log(2.0))
    c = 0.5 / jnp.cos(x / 2) + 0.5 * jnp.cos(x / 2) * log_tan_over_x
    return a, b, c


# --------------------------------------------------------------------------
# the mesh and its alpha-independent product-integration weights (NumPy)


class _Mesh(NamedTuple):
    nodes: np.ndarray  # [n] s in (0, 1)
    weights: np.ndarray  # [n] Gauss weights on [0, 1]
    near: np.ndarray  # [2, n, n] bool: (direct, mirrored) pairs using product weights
    log_weights: np.ndarray  # [2, n, n] int l_k(s) ln|x0 - s| ds, x0 = +-tau_i
    abs_weights: np.ndarray  # [2, n, n] int l_k(s) |x0 - s| ds


def panel_breaks(n_panels: int) -> np.ndarray:
    """Panel breakpoints on ``[0, 1]``.

    A quarter of the panels (at least 2) split ``[0, 1/2]`` evenly; the rest
    shrink geometrically (ratio 0.35) toward ``s = 1``, where ``j`` is least
    smooth. Chosen by the convergence study in benchmarks/dryden_zok.py.
    The last break stays at least ``_CLOSEST_BREAK`` from 1 (the ratio grows
    where 0.35 would go below it, from 360 nodes on): closer, a panel's
    Gauss nodes are a few ulp apart, its Lagrange basis divides by zero and
    sigma came out NaN.
    """
    n_uniform = max(2, round(n_panels / 4))
    n_graded = n_panels - n_uniform
    ratio = max(0.35, (_CLOSEST_BREAK / 0.5) ** (1.0 / max(n_graded - 1, 1)))
    uniform = np.linspace(0.0, 0.5, n_uniform + 1)
    graded = 1.0 - 0.5 * ratio ** np.arange(1, n_graded)
    return np.concatenate([uniform, graded, [1.0]])


def _lagrange(nodes, x):
    """Lagrange basis of ``nodes`` evaluated at ``x``: ``[len(x), len(nodes)]``."""
    diff = nodes[:, None] - nodes[None, :]
    np.fill_diagonal(diff, 1.0)
    denom = np.prod(diff, axis=1)
    factors = x[:, None, None] - nodes[None, None, :]  # [m, 1, n]
    factors = np.broadcast_to(factors, (len(x), len(nodes), len(nodes))).copy()
    idx = np.arange(len(nodes))
    factors[:, idx, idx] = 1.0
    return np.prod(factors, axis=2) / denom[None, :]


@functools.cache
def _gauss(n):
    x, w = legendre.leggauss(n)
    return (x + 1) / 2, w / 2  # on [0, 1]


def _log_moments(n):
    """``int_0^1 P~_m(v) ln v dv`` for shifted Legendre ``P~_m``: -1, then (-1)^(m+1)/(m(m+1))."""
    m = np.arange(n)
    return np.where(m == 0, -1.0, (-1.0) ** (m + 1) / np.maximum(m * (m + 1), 1))


def _log_integral_from(x0, end, panel_nodes):
    """``int_{x0}^{end} l_k(s) ln|s - x0| ds`` exactly, for ``[x0, end]`` inside the panel."""
    q = len(panel_nodes)
    length = end - x0
    if length == 0.0:
        return np.zeros(q)
    v, wv = _gauss(q + 2)
    basis = _lagrange(panel_nodes, x0 + length * v)  # [q+2, q]: the panel polynomial on [x0, end]
    shifted = legendre.legvander(2 * v - 1, q - 1)  # [q+2, q]
    coefficients = (2 * np.arange(q) + 1)[:, None] * (shifted * wv[:, None]).T @ basis  # [m, k]
    return length * (np.log(abs(length)) * (wv @ basis) + _log_moments(q) @ coefficients)


def _near_weights(x0, a, b, panel_nodes):
    """Product weights of ``ln|x0 - s|`` and ``|x0 - s|`` on panel ``[a, b]`` for its Lagrange basis."""
    q = len(panel_nodes)
    if a <= x0 <= b:
        w_log = _log_integral_from(x0, b, panel_nodes) - _log_integral_from(x0, a, panel_nodes)
        pieces = [(a, x0), (x0, b)]
    else:
        # Singularity outside: composite Gauss, halving toward the near end,
        # keeps evaluations inside the panel (no extrapolation).
        near, far = (a, b) if x0 < a else (b, a)
        fractions = np.concatenate([[0.0], 0.5 ** np.arange(30, -1, -1)])
        cuts = near + (far - near) * fractions
        s_all, w_all = [], []
        v, wv = _gauss(q + 4)
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            s_all.append(lo + (hi - lo) * v)
            w_all.append(abs(hi - lo) * wv)
        s_all, w_all = np.concatenate(s_all), np.concatenate(w_all)
        w_log = (w_all * np.log(np.abs(x0 - s_all))) @ _lagrange(panel_nodes, s_all)
        pieces = [(a, b)]
    v, wv = _gauss(q + 2)
    w_abs = np.zeros(q)
    for lo, hi in pieces:
        s = lo + (hi - lo) * v
        w_abs += ((hi - lo) * wv * np.abs(x0 - s)) @ _lagrange(panel_nodes, s)
    return w_log, w_abs


@functools.lru_cache(maxsize=16)
def _mesh(n_nodes: int) -> _Mesh:
    if n_nodes % PANEL_ORDER or n_nodes < 2 * PANEL_ORDER:
        raise ValueError(f"nodes must be a multiple of {PANEL_ORDER} and >= {2 * PANEL_ORDER}; got {n_nodes}")
    breaks = panel_breaks(n_nodes // PANEL_ORDER)
    v, wv = _gauss(PANEL_ORDER)
    starts, ends = breaks[:-1], breaks[1:]
    nodes = (starts[:, None] + (ends - starts)[:, None] * v[None, :]).ravel()
    weights = ((ends - starts)[:, None] * wv[None, :]).ravel()
    n = len(nodes)
    near = np.zeros((2, n, n), bool)
    log_w = np.zeros((2, n, n))
    abs_w = np.zeros((2, n, n))
    for mirror, sign in enumerate((1.0, -1.0)):
        for i, tau in enumerate(nodes):
            x0 = sign * tau
            for p, (a, b) in enumerate(zip(starts, ends)):
                if max(a - x0, x0 - b, 0.0) > _NEAR * (b - a):
                    continue
                cols = slice(p * PANEL_ORDER, (p + 1) * PANEL_ORDER)
                near[mirror, i, cols] = True
                log_w[mirror, i, cols], abs_w[mirror, i, cols] = _near_weights(x0, a, b, nodes[cols])
    return _Mesh(nodes, weights, near, log_w, abs_w)


# --------------------------------------------------------------------------
# the solve (JAX)


def _operator(alpha, mesh: _Mesh, dtype):
    """Matrix of ``(1/pi) int_0^alpha J(u, t_i) j(u) du`` acting on ``j`` at the nodes."""
    s = jnp.asarray(mesh.nodes, dtype)
    w = jnp.asarray(mesh.weights, dtype)
    log_alpha = jnp.log(alpha)
    total = 0.0
    for mirror, sign in enumerate((1.0, -1.0)):
        xi = alpha * (s[:, None] - sign * s[None, :])  # t_i - u_k, or t_i + u_k
        near = jnp.asarray(mesh.near[mirror])
        a, b, c = _kernel_parts(xi)
        product = (
            a * (log_alpha * w[None, :] + jnp.asarray(mesh.log_weights[mirror], dtype))
            + b * alpha * jnp.asarray(mesh.abs_weights[mirror], dtype)
            + c * w[None, :]
        )
        xi_far = jnp.where(near, 1.0, xi)  # K is never evaluated at its log singularity
        total = total + jnp.where(near, product, kernel(xi_far) * w[None, :])
    return alpha / jnp.pi * total


def _sigma_single(alpha, mesh: _Mesh):
    s = jnp.asarray(mesh.nodes, alpha.dtype)
    w = jnp.asarray(mesh.weights, alpha.dtype)
    matrix = jnp.eye(s.shape[0], dtype=alpha.dtype) - _operator(alpha, mesh, alpha.dtype)
    j = jnp.linalg.solve(matrix, jnp.cos(1.5 * alpha * s))
    return 6.0 / jnp.pi * alpha * jnp.sum(w * j * jnp.cos(1.5 * alpha * s))


def dryden_zok_sigma(alpha, nodes: int = DEFAULT_NODES):
    """Conductance ``sigma(alpha)`` of Dryden & Zok (2004), Eqs. 24-28.

    Args:
      alpha: contact cap half-angle (rad), ``0 < alpha <= pi/2``; any shape
        (broadcast elementwise). Outside that range the result is NaN.
      nodes: collocation nodes (static), a multiple of 8, >= 16. In float64
        the error is about 1e-9 at 48 nodes, 2e-11 at 64, 3e-13 at 80 and 3e-14 from 96
        on, over the whole range (benchmarks/RESULTS.md); float32 reaches
        about 1e-6.

    Returns:
      ``sigma``, dimensionless, 0 < sigma <= 1; differentiable in ``alpha``.
    """
    alpha = jnp.asarray(alpha)
    if not jnp.issubdtype(alpha.dtype, jnp.floating):
        alpha = alpha.astype(jnp.result_type(float))
    mesh = _mesh(int(nodes))
    valid = (alpha > 0) & (alpha <= jnp.pi / 2)
    alpha_safe = jnp.where(valid, alpha, jnp.pi / 4)
    flat = alpha_safe.reshape(-1)
    sigma = jax.vmap(lambda a: _sigma_single(a, mesh))(flat).reshape(alpha.shape)
    return jnp.where(valid, sigma, jnp.nan)


# --------------------------------------------------------------------------
# asymptotes and bounds


def sigma_small_alpha(alpha):
    """Small-``alpha`` estimate, Dryden & Zok Eq. 30: ``(3/pi)(alpha + sin(3 alpha)/3 + alpha^2 ln(alpha^2)/pi)``."""
    alpha = jnp.asarray(alpha)
    return 3.0 / jnp.pi * (alpha + jnp.sin(3 * alpha) / 3 + alpha**2 * jnp.log(alpha**2) / jnp.pi)


def sigma_half_space(alpha):
    """Half-space limit, Dryden & Zok Eq. 31: ``6 alpha / pi`` (Batchelor & O'Brien)."""
    return 6.0 * jnp.asarray(alpha) / jnp.pi


def sigma_large_alpha(alpha):
    """Large-``alpha`` estimate, Dryden & Zok Eq. 36: ``1 - cos^6(alpha)``.

    The first term of the bound Eq. 35 only: it is *not* a lower bound for
    ``alpha >= 0.3 pi`` (it exceeds the true ``sigma`` there); use
    :func:`sigma_lower_bound` for a bound.
    """
    return 1.0 - jnp.cos(jnp.asarray(alpha)) ** 6


def sigma_lower_bound(alpha, terms: int = 200):
    """Variational lower bound of Dryden & Zok Eq. 35, with ``terms`` terms of its series.

    ``sigma >= 6 I_1 - 3 sum_n (4n+3)/(2n+1) I_{2n+1}^2`` with
    ``I_m = int_{cos alpha}^1 P_m(x) x dx`` (Eq. 34), evaluated in closed form
    from ``x P_m = ((m+1) P_{m+1} + m P_{m-1})/(2m+1)`` and
    ``int_c^1 P_k = (P_{k-1}(c) - P_{k+1}(c))/(2k+1)``.
    """
    c = jnp.cos(jnp.asarray(alpha))
    orders = 2 * terms + 2
    legendre_values = [jnp.ones_like(c), c]
    for k in range(1, orders + 1):
        legendre_values.append(((2 * k + 1) * c * legendre_values[k] - k * legendre_values[k - 1]) / (k + 1))
    p = jnp.stack(legendre_values)  # P_0 .. P_{orders+1}

    def integral_p(k):  # int_c^1 P_k(x) dx
        return 1.0 - c if k == 0 else (p[k - 1] - p[k + 1]) / (2 * k + 1)

    def i_m(m):
        return ((m + 1) * integral_p(m + 1) + m * integral_p(m - 1)) / (2 * m + 1)

    total = 6.0 * i_m(1)
    for n in range(terms):
        m = 2 * n + 1
        total = total - 3.0 * (4 * n + 3) / (2 * n + 1) * i_m(m) ** 2
    return total


def cap_angle(mean_cap_angle, coordination):
    """Dryden & Zok's cap angle ``alpha = alpha_bar N / 6`` (Sect. V)."""
    return jnp.asarray(mean_cap_angle) * jnp.asarray(coordination) / 6.0


def dryden_zok_conductivity(k, f, alpha_bar, coordination, nodes: int = DEFAULT_NODES):
    """Effective conductivity ``k_e = k f sigma(alpha_bar N / 6)`` (Dryden & Zok Eqs. 26, 37).

    Args:
      k: solid conductivity (W/(m K)), > 0.
      f: solid volume fraction, in (0, 1].
      alpha_bar: mean contact cap half-angle (rad), > 0.
      coordination: mean number of contacts ``N``; ``alpha_bar N / 6`` must
        lie in ``(0, pi/2]``.
      nodes: see :func:`dryden_zok_sigma`.

    Returns:
      ``k_e`` (W/(m K)); NaN where ``alpha_bar N / 6`` is out of range.

    As ``alpha -> pi/2`` this tends to the law of mixtures ``k f``, which
    exceeds the Hashin-Shtrikman upper bound ``2 k f / (3 - f)`` once
    ``sigma > 2 / (3 - f)``; for nearly dense solids Dryden & Zok (Sect. V)
    point to Maxwell's estimate (:func:`sintercond.laws.effective.maxwell_conductivity`).
    """
    return jnp.asarray(k) * jnp.asarray(f) * dryden_zok_sigma(cap_angle(alpha_bar, coordination), nodes)


def batchelor_obrien_conductivity(k, f, alpha_bar, coordination):
    """Small-contact limit ``k_e = k f N alpha_bar / pi`` (Dryden & Zok Eq. 37; Batchelor & O'Brien 1977)."""
    return jnp.asarray(k) * jnp.asarray(f) * sigma_half_space(cap_angle(alpha_bar, coordination))


__all__ = [
    "DEFAULT_NODES",
    "batchelor_obrien_conductivity",
    "cap_angle",
    "dryden_zok_conductivity",
    "dryden_zok_sigma",
    "kernel",
    "kernel_series_coefficient",
    "sigma_half_space",
    "sigma_large_alpha",
    "sigma_lower_bound",
    "sigma_small_alpha",
]

