"""Hashin-Shtrikman bounds and Maxwell's estimate against their closed-form limits."""

import jax
import numpy as np
import pytest

from sintercond.laws.effective import dryden_zok_conductivity, hashin_shtrikman_bounds, maxwell_conductivity


def test_hashin_shtrikman_printed_form():
    # Quintana-Ruiz & Campello Eq. 48 as printed, k_1 < k_2
    k_1, k_2, v_2 = 1.5, 100.0, 0.55
    lower = k_1 + v_2 / (1 / (k_2 - k_1) + (1 - v_2) / (3 * k_1))
    upper = k_2 + (1 - v_2) / (1 / (k_1 - k_2) + v_2 / (3 * k_2))
    lo, hi = hashin_shtrikman_bounds(k_1, k_2, v_2)
    assert float(lo) == pytest.approx(lower, rel=1e-14) and float(hi) == pytest.approx(upper, rel=1e-14)
    lo2, hi2 = hashin_shtrikman_bounds(k_2, k_1, 1 - v_2)  # either order
    assert float(lo2) == pytest.approx(lower, rel=1e-14) and float(hi2) == pytest.approx(upper, rel=1e-14)


def test_hashin_shtrikman_limits():
    v = np.linspace(0, 1, 11)
    lo, hi = hashin_shtrikman_bounds(2.0, 7.0, v)
    assert np.all(np.asarray(lo) <= np.asarray(hi) + 1e-14)
    # pure phases
    assert float(lo[0]) == pytest.approx(2.0) and float(hi[0]) == pytest.approx(2.0)
    assert float(lo[-1]) == pytest.approx(7.0) and float(hi[-1]) == pytest.approx(7.0)
    # inside the Wiener bounds (series <= HS <= parallel)
    series = 1 / ((1 - v) / 2.0 + v / 7.0)
    parallel = (1 - v) * 2.0 + v * 7.0
    assert np.all(series <= np.asarray(lo) + 1e-14) and np.all(np.asarray(hi) <= parallel + 1e-14)
    # equal phases: no spread
    lo, hi = hashin_shtrikman_bounds(3.0, 3.0, v)
    np.testing.assert_allclose(lo, 3.0) and np.testing.assert_allclose(hi, 3.0)
    # a void phase: lower bound 0, upper 2 k v / (3 - v)
    lo, hi = hashin_shtrikman_bounds(0.0, 100.0, v)
    np.testing.assert_allclose(lo, 0.0, atol=1e-14)
    np.testing.assert_allclose(hi, 2 * 100.0 * v / (3 - v), rtol=1e-14)
    g = jax.grad(lambda x: hashin_shtrikman_bounds(0.0, 100.0, x)[1])(0.5)
    assert float(g) == pytest.approx(2 * 100.0 * 3 / (3 - 0.5) ** 2, rel=1e-12)


def test_maxwell():
    f = np.linspace(0, 1, 11)
    np.testing.assert_allclose(maxwell_conductivity(10.0, f), 2 * 10.0 * f / (3 - f), rtol=1e-14, atol=1e-15)
    p, k, kp = 0.2, 10.0, 1.0
    expected = k * (2 * k + kp - 2 * p * (k - kp)) / (2 * k + kp + p * (k - kp))
    assert float(maxwell_conductivity(k, 1 - p, kp)) == pytest.approx(expected, rel=1e-14)


def test_dryden_zok_between_the_bounds():
    # a sintered solid with a void pore phase cannot beat HS upper
    f = 0.6
    _, hi = hashin_shtrikman_bounds(0.0, 1.0, f)
    for alpha_bar in (0.05, 0.2, 0.26):
        assert 0 < float(dryden_zok_conductivity(1.0, f, alpha_bar, 6.0)) <= float(hi)
    # ... until sigma > 2/(3 - f): near full caps the model is the law of mixtures k f
    assert float(dryden_zok_conductivity(1.0, f, np.pi / 2, 6.0)) == pytest.approx(f, rel=1e-12)
    assert float(dryden_zok_conductivity(1.0, f, np.pi / 2, 6.0)) > float(hi)
