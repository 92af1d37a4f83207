"""Neck geometry against the paper, closed forms, independent solves and physics.

References used here are computed in this file from the equations
themselves (Rojek et al. 2022, Eqs. 17-29; Quintana-Ruiz & Campello 2020,
Eqs. 33-34), from the independent FE data set in tests/data, or are values
printed in the papers; never earlier output of the library.
"""

import csv
import pathlib

import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from jax.test_util import check_grads

from sintercond.laws import neck
from sintercond.laws.neck import (
    NeckStatus,
    coble_radius,
    hertz_radius,
    intersection_radius,
    max_overlap,
    neck_radius,
    neck_residual,
    neck_status,
    validate_neck_inputs,
)

DATA = pathlib.Path(__file__).parent / "data"


def _fe_table():
    with open(DATA / "fe_neck_conductance.csv") as f:
        rows = [r for r in csv.DictReader(line for line in f if not line.startswith("#"))]
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


# ---------------------------------------------------------------- independent references


def _cap_height_np(a, r):
    return a**2 / (r + np.sqrt((r - a) * (r + a)))


def _volume_residual_relative(a, r_i, r_j, h):
    """(V_cyl - V_cap_i - V_cap_j) / (V_cap_i + V_cap_j), Rojek Eqs. 22-26 (r_k per cap)."""
    h_ci, h_cj = _cap_height_np(a, r_i), _cap_height_np(a, r_j)
    h_n = h_ci + h_cj - h
    v_cyl = np.pi * a**2 * h_n
    v_caps = np.pi * h_ci**2 * (3 * r_i - h_ci) / 3 + np.pi * h_cj**2 * (3 * r_j - h_cj) / 3
    return (v_cyl - v_caps) / v_caps


def _bisect_reference(r_i, r_j, h, iterations=200):
    """Neck radius by bisection of the raw volume balance in extended precision.

    Brackets the root between the lens radius (where h_n = 0; Z < 0 just
    right of it) and min(r_i, r_j), independent of the library's solver.
    """
    ld = np.longdouble
    r_i, r_j, h = (np.asarray(x, dtype=ld) for x in (r_i, r_j, h))

    def z(a):
        h_ci, h_cj = _cap_height_np(a, r_i), _cap_height_np(a, r_j)
        return 3 * a**2 * (h_ci + h_cj - h) - h_ci**2 * (3 * r_i - h_ci) - h_cj**2 * (3 * r_j - h_cj)

    d = r_i + r_j - h
    lens = np.sqrt(h * (2 * (r_i + r_j) - h) * (2 * r_i - h) * (2 * r_j - h)) / (2 * d)
    lo, hi = lens, np.minimum(r_i, r_j)
    for _ in range(iterations):
        mid = (lo + hi) / 2
        neg = z(mid) < 0
        lo, hi = np.where(neg, mid, lo), np.where(neg, hi, mid)
    return ((lo + hi) / 2).astype(np.float64)


def _equal_closed_form(r, h):
    """Rojek Eqs. 19-20 exactly as printed, in extended precision."""
    r, h = np.longdouble(r), np.longdouble(h)
    h_c = (3 * (2 * r + h) - np.sqrt(9 * (2 * r + h) ** 2 - 96 * r * h)) / 8
    return float(np.sqrt(2 * r * h_c - h_c**2))


def _random_pairs(n, seed, max_ratio=1e3, frac_low=0.0):
    rng = np.random.default_rng(seed)
    r_i = np.exp(rng.uniform(np.log(1e-3), np.log(1e3), n))
    r_j = r_i * np.exp(rng.uniform(-np.log(max_ratio), np.log(max_ratio), n))
    frac = rng.uniform(frac_low, 1.0, n)
    h = frac * np.asarray(max_overlap(r_i, r_j))
    return r_i, r_j, h


radius = st.floats(1e-3, 1e3)
log_ratio = st.floats(-np.log(1e3), np.log(1e3))
fraction = st.floats(1e-9, 1.0)

_neck_jit = jax.jit(neck_radius)


# ---------------------------------------------------------------- paper values


def test_rojek_unequal_reference_values():
    # Rojek et al. 2022, Sect. 4.3 and 6 (6 printed digits).
    assert neck_radius(1.0, 3.0, 0.2) == pytest.approx(0.741466, abs=5e-7)
    assert coble_radius(1.0, 3.0, 0.2) == pytest.approx(0.774597, abs=5e-7)
    assert neck_radius(1.0, 3.0, 0.06) == pytest.approx(0.419186, abs=5e-7)


def test_rojek_first_newton_iterate_from_coble():
    # Eq. 34: one Newton step on the raw Eq. 27 from Coble, Z' = 6 a h_n.
    a0 = float(coble_radius(1.0, 3.0, 0.2))
    h_n = _cap_height_np(a0, 1.0) + _cap_height_np(a0, 3.0) - 0.2
    a1 = a0 - float(neck_residual(a0, 1.0, 3.0, 0.2)) / (6 * a0 * h_n)
    assert a1 == pytest.approx(0.745039, abs=5e-7)


@pytest.mark.slow
def test_newton_starts_from_coble_clipped_to_the_smaller_radius():
    """Iteration 0 is Coble's neck sqrt(2 r* h), r* = 2 r_i r_j / (r_i + r_j) (Eqs. 11-12), clipped to
    min(r_i, r_j) (``iterations=0``). Mutant "coble start" (half of Coble's u) still converged in 5 steps,
    so no accuracy test saw it."""
    r_i = np.array([1.0, 1.0, 1.0, 2.0])
    r_j = np.array([3.0, 1e3, 1.5, 0.5])  # unequal radii: equal ones take the closed form, no Newton
    h = np.array([0.2, 0.3, 0.01, 0.18])  # the last: Coble (0.54) beyond the smaller radius 0.5
    r_star = 2 * r_i * r_j / (r_i + r_j)
    expected = np.minimum(np.sqrt(2 * r_star * h), np.minimum(r_i, r_j))
    np.testing.assert_allclose(np.asarray(neck_radius(r_i, r_j, h, iterations=0)), expected, rtol=1e-15)


def test_closed_form_necks_have_finite_zero_gradients_without_contact():
    """Coble, Hertz and lens radii at h = 0 and h < 0: value 0, gradient 0 (not NaN from d sqrt/dx at 0).
    Mutant "safe_sqrt grad" (the double-where's safe argument 0 instead of 1) gave NaN gradients here."""
    for fn in (coble_radius, hertz_radius, intersection_radius):
        for h in (0.0, -0.1):
            g = jax.grad(fn, argnums=(0, 1, 2))(1.0, 3.0, h)
            assert float(fn(1.0, 3.0, h)) == 0.0 and all(float(x) == 0.0 for x in g), (fn.__name__, h, g)


@pytest.mark.slow
def test_neck_residual_derivative_is_6_a_hn():
    a = jnp.linspace(0.05, 0.99, 50)
    dz = jax.vmap(jax.grad(neck_residual), in_axes=(0, None, None, None))(a, 1.0, 3.0, 0.2)
    h_n = _cap_height_np(np.asarray(a), 1.0) + _cap_height_np(np.asarray(a), 3.0) - 0.2
    np.testing.assert_allclose(dz, 6 * np.asarray(a) * h_n, rtol=1e-11, atol=1e-14)


def test_equal_sizes_against_independent_fe_geometry():
    fe = _fe_table()
    a = neck_radius(1.0, 1.0, fe["h_over_r"])
    np.testing.assert_allclose(a, fe["a_over_r"], rtol=2e-11)
    # h_n / 2 = h_c - h / 2 (Eq. 16)
    h_c = _cap_height_np(np.asarray(a), 1.0)
    np.testing.assert_allclose(h_c - fe["h_over_r"] / 2, fe["hn_half_over_r"], rtol=2e-10)


def test_equal_sizes_against_printed_closed_form():
    for h in (0.02, 0.08, 0.2, 0.4, 0.6, 2 / 3):
        assert neck_radius(1.0, 1.0, h) == pytest.approx(_equal_closed_form(1.0, h), rel=1e-14)
    # SPEC: h/r = 0.08 -> a/r = 0.3946 (the captions' 0.19934 is off by 1.5e-5).
    assert neck_radius(1.0, 1.0, 0.08) == pytest.approx(0.3946, abs=5e-5)


@pytest.mark.slow
def test_equal_sizes_scale_with_radius():
    h_over_r = np.linspace(0.001, 0.66, 40)
    for r in (1e-6, 4e-5, 1.0, 7.5e3):
        np.testing.assert_allclose(neck_radius(r, r, h_over_r * r) / r, neck_radius(1.0, 1.0, h_over_r), rtol=1e-14)


# ---------------------------------------------------------------- max_overlap


def test_max_overlap_values():
    assert max_overlap(1.0, 1.0) == pytest.approx(2 / 3, rel=1e-15)
    assert max_overlap(2.5, 2.5) == pytest.approx(5 / 3, rel=1e-15)
    assert max_overlap(1.0, 3.0) == pytest.approx(0.418278, abs=5e-7)
    assert max_overlap(3.0, 1.0) == max_overlap(1.0, 3.0)


def test_max_overlap_is_where_neck_reaches_smaller_radius():
    r_i, r_j, _ = _random_pairs(500, seed=3)
    h_max = np.asarray(max_overlap(r_i, r_j))
    r_s = np.minimum(r_i, r_j)
    # Z(r_s) = 0 at h_max: the cylinder of radius r_s balances the caps there.
    np.testing.assert_allclose(_volume_residual_relative(r_s, r_i, r_j, h_max), 0.0, atol=1e-12)
    np.testing.assert_allclose(neck_radius(r_i, r_j, h_max), r_s, rtol=1e-12)


# ---------------------------------------------------------------- properties


@given(radius, log_ratio, fraction)
def test_volume_conserved(r_i, log_r, frac):
    r_j = r_i * np.exp(log_r)
    h = frac * float(max_overlap(r_i, r_j))
    a = float(_neck_jit(r_i, r_j, h))
    assert abs(_volume_residual_relative(a, r_i, r_j, h)) < 1e-12


@pytest.mark.slow
def test_volume_conserved_batch_and_matches_bisection():
    r_i, r_j, h = _random_pairs(20000, seed=0)
    a = np.asarray(neck_radius(r_i, r_j, h))
    assert np.max(np.abs(_volume_residual_relative(a, r_i, r_j, h))) < 1e-12
    np.testing.assert_allclose(a, _bisect_reference(r_i, r_j, h), rtol=1e-14)


@pytest.mark.slow
def test_run_to_convergence_matches_bisection_for_every_entry():
    """``iterations=None`` (a while_loop) must run until the slowest entry has converged.

    Bug: a loop that stops as soon as one entry has converged (any instead of all) leaves the others at an
    early Newton iterate, 1e-3 off. The batch mixes overlaps from 1e-9 h_max (Coble's start is already
    right) to h_max, so entries converge after different numbers of steps. Measured error 4.7e-16
    (benchmarks/RESULTS.md); bound 2e-15.
    """
    r_i, r_j, h = _random_pairs(4000, seed=3)
    h = h * np.geomspace(1e-9, 1.0, len(h))
    a = np.asarray(jax.jit(lambda *p: neck_radius(*p, iterations=None))(r_i, r_j, h))
    np.testing.assert_allclose(a, _bisect_reference(r_i, r_j, h), rtol=2e-15)


@given(radius, log_ratio, fraction)
def test_symmetric_in_radii(r_i, log_r, frac):
    r_j = r_i * np.exp(log_r)
    h = frac * float(max_overlap(r_i, r_j))
    assert float(_neck_jit(r_i, r_j, h)) == pytest.approx(float(_neck_jit(r_j, r_i, h)), rel=1e-15)


def test_physical_root_between_lens_and_smaller_radius():
    # The spurious root a = 0 and the falling branch (0, a_lens) are never returned.
    r_i, r_j, h = _random_pairs(20000, seed=1)
    a = np.asarray(neck_radius(r_i, r_j, h))
    lens = np.asarray(intersection_radius(r_i, r_j, h))
    assert np.all(a > lens)
    assert np.all(a <= np.minimum(r_i, r_j))
    assert np.all(a <= np.asarray(coble_radius(r_i, r_j, h)))  # Coble overestimates


@pytest.mark.slow
@pytest.mark.parametrize("ratio", [1.0, 1.5, 3.0, 30.0, 1e3, 1e-3])
def test_monotonic_in_overlap(ratio):
    h = np.linspace(0.0, 1.0, 2001)[1:] * float(max_overlap(1.0, ratio))
    a = np.asarray(neck_radius(1.0, ratio, h))
    assert np.all(np.diff(a) > 0)


def test_continuous_across_equal_radii():
    h = np.linspace(0.001, 0.66, 60)
    a_equal = np.asarray(neck_radius(1.0, 1.0, h))
    for delta in (1e-4, 1e-7, 1e-10, 1e-13):
        for r_j in (1.0 + delta, 1.0 - delta):
            h_j = np.minimum(h, float(max_overlap(1.0, r_j)))
            # |da/dr_j| <= 1 here, so the step across the branch switch is O(delta).
            np.testing.assert_allclose(neck_radius(1.0, r_j, h_j), a_equal, atol=2 * delta + 1e-15)
    g = jax.grad(neck_radius, argnums=(0, 1, 2))
    for hh in (0.01, 0.3, 0.6):
        np.testing.assert_allclose(g(1.0, 1.0, hh), g(1.0, 1.0 + 1e-9, hh), rtol=1e-6)


def test_small_overlap_limits():
    # a -> Coble (its small-h limit), lens -> sqrt(2) Hertz, Coble^2 -> 2 lens^2.
    # a / Coble - 1 is O(h/r): measured -h/6 (r_j = 1), -0.194 h (3), -0.333 h (1e3), from h = 1e-12 to 1e-4.
    # The bound 0.5 h is per entry: the former 3e-3 for all of them passed a 1e-3 error at h = 1e-12.
    h = np.array([1e-12, 1e-9, 1e-6])
    for r_j in (1.0, 3.0, 1e3):
        a = np.asarray(neck_radius(1.0, r_j, h))
        assert np.all(np.abs(a / np.asarray(coble_radius(1.0, r_j, h)) - 1) <= 0.5 * h)
        lens = np.asarray(intersection_radius(1.0, r_j, h))
        np.testing.assert_allclose(lens / np.asarray(hertz_radius(1.0, r_j, h)), np.sqrt(2.0), rtol=1e-5)


# ---------------------------------------------------------------- gradients


@pytest.mark.parametrize(
    "r_i,r_j,h",
    [(1.0, 3.0, 0.2), (1.0, 3.0, 0.06), (1.0, 1.0, 0.2), (1.0, 1.0, 1e-4), (2.0, 0.5, 0.15), (1.0, 1e3, 0.3), (1e3, 1.0, 1e-3),
     (1.0, 3.0, 0.41)],
)
@pytest.mark.slow
def test_gradients_match_finite_differences(r_i, r_j, h):
    # FD step small against h: a ~ sqrt(h) varies on the scale of h itself.
    check_grads(neck_radius, (r_i, r_j, h), order=2, modes=["fwd", "rev"], eps=min(1e-6, 1e-3 * h), rtol=1e-5)


@pytest.mark.parametrize("h_over_r", [1e-6, 0.02, 0.08, 0.3, 0.6])
def test_equal_size_gradient_is_analytic(h_over_r):
    # Differentiate the quadratic Eq. 18 and Eq. 20 by hand.
    r, h = 1.3, h_over_r * 1.3
    h_c = 12 * r * h / (3 * (2 * r + h) + np.sqrt(9 * (2 * r + h) ** 2 - 96 * r * h))
    a = np.sqrt(h_c * (2 * r - h_c))
    dq_dhc = 8 * h_c - 3 * (2 * r + h)
    dhc_dh = -(6 * r - 3 * h_c) / dq_dhc
    dhc_dr = -(6 * h - 6 * h_c) / dq_dhc
    da_dh = (r - h_c) / a * dhc_dh
    da_dr = ((r - h_c) * dhc_dr + h_c) / a
    g_i, g_j, g_h = (float(g) for g in jax.grad(neck_radius, argnums=(0, 1, 2))(r, r, h))
    assert g_h == pytest.approx(da_dh, rel=1e-10)
    assert g_i == pytest.approx(g_j, rel=1e-13)  # symmetry
    assert g_i + g_j == pytest.approx(da_dr, rel=1e-10)


def test_gradient_independent_of_iteration_count_and_equal_to_unrolled_solve():
    def unrolled(r_i, r_j, h, steps=12):
        # Plain Newton on Eq. 27 in a (Eqs. 32-34), differentiated by unrolling.
        a = jnp.sqrt(2 * (2 * r_i * r_j / (r_i + r_j)) * h)
        for _ in range(steps):
            h_ci = r_i - jnp.sqrt(r_i**2 - a**2)
            h_cj = r_j - jnp.sqrt(r_j**2 - a**2)
            h_n = h_ci + h_cj - h
            z = 3 * a**2 * h_n - h_cj**2 * (3 * r_j - h_cj) - h_ci**2 * (3 * r_i - h_ci)
            a = a - z / (6 * a * h_n)
        return a

    args = (1.0, 3.0, 0.2)
    ref = jax.grad(unrolled, argnums=(0, 1, 2))(*args)
    for iterations in (5, 6, 10):
        g = jax.grad(lambda *p: neck_radius(*p, iterations=iterations), argnums=(0, 1, 2))(*args)
        np.testing.assert_allclose(g, ref, rtol=1e-10)
    # Even an unconverged solve gets the implicit gradient *at its own iterate*:
    # the rule never differentiates through the loop.
    g1 = jax.grad(lambda h: neck_radius(1.0, 3.0, h, iterations=1))(0.2)
    assert np.isfinite(g1)


def test_no_contact_is_zero_with_zero_gradients():
    for h in (0.0, -1e-12, -0.5):
        for fn in (neck_radius, coble_radius, hertz_radius, intersection_radius):
            assert fn(1.0, 3.0, h) == 0.0
            g = jax.grad(fn, argnums=(0, 1, 2))(1.0, 3.0, h)
            assert all(float(x) == 0.0 for x in g), (fn.__name__, h, g)


@pytest.mark.parametrize(
    "r_i,r_j,h",
    [
        (1.0, 3.0, 1e-300), (1.0, 3.0, 1e-30), (1.0, 1.0, 1e-300), (1.0, 1e3, 1e-20), (1e3, 1.0, 1e-20),
        (1.0, 1e3, 0.3), (1e-3, 1.0, 1e-4),
    ],
)
def test_no_nan_at_small_overlap_and_extreme_ratio(r_i, r_j, h):
    vals = [neck_radius(r_i, r_j, h), *jax.grad(neck_radius, argnums=(0, 1, 2))(r_i, r_j, h)]
    if h >= 1e-30:  # d2a/dh2 ~ h^(-3/2) overflows float64 itself below ~1e-205
        vals.append(jax.grad(jax.grad(neck_radius, argnums=2), argnums=2)(r_i, r_j, h))
    assert np.all(np.isfinite(vals)), vals
    assert float(vals[0]) > 0


@pytest.mark.parametrize("r_j", [1.0, 3.0, 1e3, 1e-3])
@pytest.mark.parametrize("gap", [0.0, 1e-15, 1e-9, 1e-4])
def test_no_nan_near_max_overlap(r_j, gap):
    h = float(max_overlap(1.0, r_j)) * (1 - gap)
    a = neck_radius(1.0, r_j, h)
    g = jax.grad(neck_radius, argnums=(0, 1, 2))(1.0, r_j, h)
    assert np.isfinite(a) and np.all(np.isfinite(g))
    assert float(a) <= min(1.0, r_j)
    if gap >= 1e-9:  # away from the square-root corner at h_max, match bisection
        assert float(a) == pytest.approx(float(_bisect_reference(1.0, r_j, h)), rel=1e-13)


# ---------------------------------------------------------------- policy beyond h_max


@pytest.mark.slow
def test_beyond_max_overlap_is_nan_and_flagged():
    h = np.array([-0.1, 0.0, 0.3, 2 / 3, 0.67, 5.0])
    a = np.asarray(neck_radius(1.0, 1.0, h))
    assert np.isnan(a[4]) and np.isnan(a[5])
    assert np.all(np.isfinite(a[:4]))
    status = np.asarray(neck_status(1.0, 1.0, h))
    assert list(status) == [NeckStatus.NO_CONTACT, NeckStatus.NO_CONTACT, NeckStatus.OK, NeckStatus.OK,
                            NeckStatus.BEYOND_MAX_OVERLAP, NeckStatus.BEYOND_MAX_OVERLAP]
    assert np.asarray(jax.jit(neck_status)(1.0, 1.0, h)).tolist() == status.tolist()
    # gradients: zero for no contact and beyond h_max, so masking the NaN out
    # of a sum leaves the valid entries' gradients intact
    g = np.asarray(jax.grad(lambda x: jnp.sum(jnp.where(x <= 2 / 3, neck_radius(1.0, 1.0, x), 0.0)))(h))
    assert np.all(np.isfinite(g)) and g[0] == g[1] == g[4] == g[5] == 0.0 and g[2] > 0


def test_invalid_radii_are_nan_and_flagged():
    r = np.array([1.0, 0.0, -1.0, np.inf, np.nan])
    a = np.asarray(neck_radius(r, 1.0, 0.1))
    assert np.isfinite(a[0]) and np.all(np.isnan(a[1:]))
    assert np.all(np.asarray(neck_status(r, 1.0, 0.1))[1:] == NeckStatus.INVALID_INPUT)
    assert np.isnan(neck_radius(1.0, 1.0, np.nan))


def test_validate_names_field_and_range():
    validate_neck_inputs([1.0, 2.0], [3.0, 2.0], [0.2, -1.0])  # fine: no contact allowed
    validate_neck_inputs(1.0, 1.0, float(max_overlap(1.0, 1.0)))
    with pytest.raises(ValueError, match=r"h must be <= max_overlap\(r_i, r_j\).*0\.7.*max_overlap=0\.666"):
        validate_neck_inputs(1.0, 1.0, 0.7)
    with pytest.raises(ValueError, match=r"r_j must be finite and > 0; got -2\.0 at index \(1,\)"):
        validate_neck_inputs([1.0, 1.0], [1.0, -2.0], 0.1)
    with pytest.raises(ValueError, match=r"h must be finite"):
        validate_neck_inputs(1.0, 1.0, np.nan)
    # mutant "finite dropped" (a check for NaN only) let inf through to a misleading max_overlap message
    for bad in (np.inf, -np.inf):
        with pytest.raises(ValueError, match=r"h must be finite; got -?inf"):
            validate_neck_inputs(1.0, 1.0, bad)
    with pytest.raises(TypeError, match="needs concrete values"):
        jax.jit(validate_neck_inputs)(1.0, 1.0, 0.1)
    # other models have other domains
    validate_neck_inputs(1.0, 1.0, 0.7, model="coble")
    validate_neck_inputs(1.0, 1.0, 1.9, model="intersection")
    with pytest.raises(ValueError, match=r"h must be < 2 min\(r_i, r_j\) for the intersection radius"):
        validate_neck_inputs(1.0, 3.0, 2.0, model="intersection")
    with pytest.raises(ValueError, match="model must be one of"):
        validate_neck_inputs(1.0, 1.0, 0.1, model="spline")
    with pytest.raises(ValueError, match=r"r_i must be finite and > 0; got 1e-320"):
        validate_neck_inputs(1e-320, 1.0, 0.0)


# ---------------------------------------------------------------- transformations, dtypes


@pytest.mark.slow
def test_jit_vmap_and_plain_agree():
    r_i, r_j, h = _random_pairs(257, seed=7)
    plain = np.asarray(neck_radius(r_i, r_j, h))
    jitted = np.asarray(jax.jit(neck_radius)(r_i, r_j, h))
    vmapped = np.asarray(jax.vmap(neck_radius)(r_i, r_j, h))
    looped = np.array([float(neck_radius(a, b, c)) for a, b, c in zip(r_i[:20], r_j[:20], h[:20])])
    # equal up to the last bit or two (XLA fuses and contracts differently)
    np.testing.assert_allclose(jitted, plain, rtol=1e-15)
    np.testing.assert_allclose(vmapped, plain, rtol=1e-15)
    np.testing.assert_allclose(looped, plain[:20], rtol=1e-15)
    # broadcasting: one radius against many overlaps
    np.testing.assert_allclose(neck_radius(1.0, 3.0, h[:5] % 0.4), jax.vmap(lambda x: neck_radius(1.0, 3.0, x))(h[:5] % 0.4),
                               rtol=1e-15)


FLOAT32_VALUE_RTOL = 5e-7  # measured 2.0e-7 max over 1e5 pairs (float32 eps 1.2e-7)
FLOAT32_GRAD_RTOL = 1e-5  # measured 1.4e-6 max up to 0.99 h_max (3e-5 right at h_max)


@pytest.mark.slow
def test_float32_accuracy():
    """Float32 neck radii agree with float64 to FLOAT32_VALUE_RTOL, gradients to FLOAT32_GRAD_RTOL
    (h at most 99 % of max_overlap: the gradient has a square-root corner at h_max)."""
    r_i, r_j, h = _random_pairs(20000, seed=11)
    h = h * 0.99
    ref = np.asarray(neck_radius(r_i, r_j, h))
    args32 = [jnp.asarray(x, jnp.float32) for x in (r_i, r_j, h)]
    a32 = neck_radius(*args32)
    assert a32.dtype == jnp.float32
    # compare with the float64 solution of the float32-rounded inputs
    ref = np.asarray(neck_radius(*(np.asarray(x, np.float64) for x in args32)))
    np.testing.assert_allclose(np.asarray(a32), ref, rtol=FLOAT32_VALUE_RTOL)
    grad = jax.vmap(jax.grad(neck_radius, argnums=(0, 1, 2)))
    g32 = grad(*args32)
    g64 = grad(*(jnp.asarray(x, jnp.float64) for x in args32))
    for x32, x64 in zip(g32, g64):
        assert x32.dtype == jnp.float32 and np.all(np.isfinite(x32))
        np.testing.assert_allclose(np.asarray(x32), np.asarray(x64), rtol=FLOAT32_GRAD_RTOL, atol=1e-6 * np.abs(x64).max())


@pytest.mark.slow
def test_float32_keeps_dtype_for_every_model():
    x = jnp.asarray([0.5, 1.0], jnp.float32)
    for fn in neck.NECK_MODELS.values():
        assert fn(x, 1.0, 0.1).dtype == jnp.float32
    assert max_overlap(x, 1.0).dtype == jnp.float32


# ---------------------------------------------------------------- the other radii


def test_intersection_radius_against_quintana_form():
    r_i, r_j, h = _random_pairs(1000, seed=5, max_ratio=10.0, frac_low=0.05)
    d = r_i + r_j - h
    l_i = 0.5 * (d - (r_j**2 - r_i**2) / d)  # Eq. 34
    np.testing.assert_allclose(intersection_radius(r_i, r_j, h), np.sqrt(r_i**2 - l_i**2), rtol=1e-9)
    # equal spheres: a^2 = r^2 - (d/2)^2
    assert intersection_radius(1.0, 1.0, 0.5) == pytest.approx(np.sqrt(1 - 0.75**2), rel=1e-15)
    # engulfed: undefined
    assert np.isnan(intersection_radius(1.0, 3.0, 2.5))


@pytest.mark.slow
def test_hertz_and_coble_closed_forms():
    assert hertz_radius(1.0, 3.0, 0.2) == pytest.approx(np.sqrt(0.75 * 0.2), rel=1e-15)
    assert coble_radius(1.0, 1.0, 0.2) == pytest.approx(np.sqrt(2 * 1.0 * 0.2), rel=1e-15)
    check_grads(hertz_radius, (1.0, 3.0, 0.2), order=2, modes=["fwd", "rev"])
    check_grads(coble_radius, (1.0, 3.0, 0.2), order=2, modes=["fwd", "rev"])
    check_grads(intersection_radius, (1.0, 3.0, 0.2), order=2, modes=["fwd", "rev"])
