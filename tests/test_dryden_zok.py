"""Dryden & Zok (2004) sigma(alpha): kernel, limits, bounds, convergence, gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy.integrate import quad

from sintercond.laws import dryden_zok as dz

ALPHAS = np.pi * np.array([0.002, 0.01, 0.05, 0.1, 0.2, 0.25, 0.3, 0.4, 0.45, 0.49, 0.4999, 0.5])


@pytest.mark.parametrize("n", range(9))
def test_closed_form_kernel_sums_its_series(n):
    # The cos((n + 1/2) xi) are orthogonal on [0, pi] with norm pi/2, so the
    # closed form Eq. 25 must have the series coefficients of Eq. 25 (H_n = 1/(2n)).
    # The integrand has a log singularity at 0 and a removable 1/(pi - xi) * 0 at pi.
    def integrand(xi):
        return float(dz.kernel(xi)) * np.cos((n + 0.5) * xi)

    value = sum(quad(integrand, lo, hi, limit=200, epsabs=1e-13, epsrel=1e-13)[0]
                for lo, hi in ((0, 0.5), (0.5, np.pi - 0.5), (np.pi - 0.5, np.pi)))
    assert 2 / np.pi * value == pytest.approx(float(dz.kernel_series_coefficient(n)), abs=1e-9)


def test_kernel_pole_at_pi():
    # K(xi) (pi - xi) -> 1: the pole that matters only at alpha = pi/2.
    xi = np.pi - np.array([1e-3, 1e-5, 1e-7])
    np.testing.assert_allclose(np.asarray(dz.kernel(xi)) * (np.pi - xi), 1.0, atol=2e-3)


@pytest.mark.slow
def test_half_space_limit():
    alpha = np.array([1e-6, 1e-4, 1e-3])
    sigma = np.asarray(dz.dryden_zok_sigma(alpha))
    # sigma = 6 alpha / pi (1 + O(alpha ln alpha)), Eq. 30 -> Eq. 31
    # Each alpha gets its own bound (one bound scaled to the worst alpha let a
    # 1e-3 error at alpha = 1e-6 through). Measured: |sigma / (6 alpha / pi) - 1|
    # = 0.33..0.34 alpha |ln alpha| and |sigma / Eq. 30 - 1| = 0.154..0.159 alpha
    # here; bounds 1.5x that.
    assert np.all(np.abs(sigma / (6 * alpha / np.pi) - 1) <= 0.5 * alpha * np.abs(np.log(alpha)))
    assert np.all(np.abs(sigma / np.asarray(dz.sigma_small_alpha(alpha)) - 1) <= 0.25 * alpha)


def test_full_caps_conduct_like_the_bulk():
    # alpha = pi/2: T = cos(theta) on the whole sphere, T = z inside, sigma = 1.
    assert float(dz.dryden_zok_sigma(np.pi / 2)) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.slow
def test_monotonic_and_bounded():
    alpha = np.linspace(1e-3, np.pi / 2, 200)
    sigma = np.asarray(dz.dryden_zok_sigma(alpha))
    assert np.all(np.diff(sigma) > 0)
    assert np.all((sigma > 0) & (sigma <= 1 + 1e-12))


@pytest.mark.slow
def test_asymptotes_to_the_degree_of_fig_2():
    alpha = np.linspace(0.01, np.pi / 2, 120)
    sigma = np.asarray(dz.dryden_zok_sigma(alpha))
    small = alpha < 1.0  # "reasonably accurate for alpha < 1" (Eq. 30): within 3 %
    assert np.all(np.abs(np.asarray(dz.sigma_small_alpha(alpha[small])) / sigma[small] - 1) < 0.03)
    large = alpha > 0.4 * np.pi  # Eq. 36 "in very good agreement" near pi/2
    assert np.all(np.abs(np.asarray(dz.sigma_large_alpha(alpha[large])) - sigma[large]) < 2.5e-3)


@pytest.mark.slow
def test_bounds():
    alpha = np.linspace(0.01, np.pi / 2, 120)
    sigma = np.asarray(dz.dryden_zok_sigma(alpha))
    bound = np.asarray(dz.sigma_lower_bound(alpha))
    assert np.all(bound <= sigma + 1e-12), "the full series Eq. 35 is a lower bound"
    one_term = np.asarray(dz.sigma_large_alpha(alpha))
    past = (alpha > 0.3 * np.pi) & (alpha < 0.49 * np.pi)
    assert np.all(one_term[past] > sigma[past]), "Eq. 36 alone is not a lower bound past 0.3 pi"
    assert np.all(one_term[alpha < 0.28 * np.pi] < sigma[alpha < 0.28 * np.pi])
    # truncations approach the bound from above (each term subtracts) and
    # 200 terms are converged where it matters; all equal 1 at pi/2
    assert float(dz.sigma_lower_bound(np.pi / 2)) == pytest.approx(1.0, abs=1e-14)
    assert np.all(np.asarray(dz.sigma_lower_bound(alpha, terms=10)) >= bound - 1e-15)
    np.testing.assert_allclose(dz.sigma_lower_bound(alpha, terms=400), bound, atol=1e-4)


@pytest.mark.slow
def test_converges_with_nodes():
    reference = np.asarray(dz.dryden_zok_sigma(ALPHAS, nodes=256))
    errors = [np.max(np.abs(np.asarray(dz.dryden_zok_sigma(ALPHAS, nodes=n)) - reference)) for n in (16, 32, 48, 64, 96)]
    assert all(e1 > e2 for e1, e2 in zip(errors[:-2], errors[1:-1])), errors
    assert errors[-1] < 1e-11  # the accuracy target is 1e-10 with at most 128 nodes


@pytest.mark.slow
def test_gradient_matches_finite_differences():
    for alpha in (0.05, 0.4, 1.0, 1.5):
        check_grads(dz.dryden_zok_sigma, (alpha,), order=1, modes=["fwd", "rev"], eps=1e-6, rtol=1e-6)
    # and tends to 6/pi as alpha -> 0 (with the alpha ln alpha correction of Eq. 30)
    g = float(jax.grad(dz.dryden_zok_sigma)(1e-4))
    g30 = float(jax.grad(dz.sigma_small_alpha)(1e-4))
    assert g == pytest.approx(g30, rel=1e-3)


@pytest.mark.slow
def test_vmap_jit_and_loop_agree():
    batched = np.asarray(dz.dryden_zok_sigma(ALPHAS))
    looped = np.array([float(dz.dryden_zok_sigma(a)) for a in ALPHAS])
    jitted = np.asarray(jax.jit(jax.vmap(dz.dryden_zok_sigma))(ALPHAS))
    np.testing.assert_allclose(batched, looped, rtol=1e-14)
    np.testing.assert_allclose(jitted, looped, rtol=1e-13)
    assert dz.dryden_zok_sigma(ALPHAS.reshape(3, 4)).shape == (3, 4)


@pytest.mark.slow
def test_out_of_range_is_nan():
    sigma = np.asarray(dz.dryden_zok_sigma(np.array([-0.1, 0.0, np.pi / 2 + 1e-9, 0.3])))
    assert np.all(np.isnan(sigma[:3])) and np.isfinite(sigma[3])
    with pytest.raises(ValueError, match="nodes must be a multiple of 8"):
        dz.dryden_zok_sigma(0.3, nodes=20)


@pytest.mark.slow
def test_float32():
    alpha = ALPHAS.astype(np.float32)
    s32 = dz.dryden_zok_sigma(jnp.asarray(alpha))
    assert s32.dtype == jnp.float32
    # float32(pi/2) rounds above pi/2; compare at the float64 value inside the range
    alpha64 = np.minimum(alpha.astype(np.float64), np.pi / 2)
    np.testing.assert_allclose(np.asarray(s32), np.asarray(dz.dryden_zok_sigma(alpha64)), atol=2e-6)


def test_effective_conductivity():
    k, f, alpha_bar, n = 20.0, 0.6, 0.1, 6.0
    expected = k * f * float(dz.dryden_zok_sigma(alpha_bar * n / 6))
    assert float(dz.dryden_zok_conductivity(k, f, alpha_bar, n)) == pytest.approx(expected, rel=1e-15)
    # small contacts: Batchelor & O'Brien k f N alpha_bar / pi (Eq. 37)
    tiny = 1e-5
    assert float(dz.dryden_zok_conductivity(k, f, tiny, 8.0)) == pytest.approx(
        float(dz.batchelor_obrien_conductivity(k, f, tiny, 8.0)), rel=1e-3)
    assert float(dz.batchelor_obrien_conductivity(k, f, tiny, 8.0)) == pytest.approx(k * f * 8 * tiny / np.pi, rel=1e-15)
    # a simple-cubic array with touching spheres: k_e ~ k alpha (Sect. V)
    alpha = 1e-4
    assert float(dz.dryden_zok_conductivity(1.0, np.pi / 6, alpha, 6.0)) == pytest.approx(alpha, rel=1e-2)
    assert np.isnan(dz.dryden_zok_conductivity(k, f, 1.0, 12.0))  # alpha = 2 > pi/2


@pytest.mark.slow
@pytest.mark.parametrize("nodes", [360, 480])
def test_fine_meshes_stay_finite(nodes):
    """Bug: from 360 nodes the geometric panels toward s = 1 shrank below the float64 spacing there, the
    Lagrange basis divided by zero and sigma was NaN at every alpha. Now the grading stops 1e-14 short of 1;
    the answer agrees with the default mesh to the solver's round-off (measured 3.4e-13; bound 5e-13)."""
    alpha = np.array([0.02, 0.3, 1.0, np.pi / 2])
    fine = np.asarray(dz.dryden_zok_sigma(alpha, nodes=nodes))
    np.testing.assert_allclose(fine, np.asarray(dz.dryden_zok_sigma(alpha)), rtol=0, atol=5e-13)
