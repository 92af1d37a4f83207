"""Tables below and above their nodes (sintercond.laws.materials' clamped specific-heat tables), against independent
references: NumPy's ``np.interp`` (which clamps to the end values) and the integral of that clamped function by
SciPy's adaptive quadrature (split at the nodes), then the inverse checked by going back and forth.

The class of bug: the end segments continued with the wrong value (a neighbour node's, the slope of the first or
last segment instead of a constant), or the inverse's linear continuation divided by the wrong end value.
"""

import numpy as np
import pytest
from scipy import integrate

from sintercond.laws import materials

NODES = np.array([300.0, 700.0, 1300.0])
VALUES = np.array([520.0, 760.0, 690.0])  # a rising then a falling segment: every end differs from its neighbour
BELOW_INSIDE_ABOVE = np.array([50.0, 250.0, 299.0, 300.0, 450.0, 700.0, 1000.0, 1300.0, 1301.0, 1800.0, 2500.0])


def clamped_integral(theta):
    """``int_{T_0}^{theta} np.interp(T, nodes, values) dT`` by quadrature (negative below the first node)."""
    f = lambda t: float(np.interp(t, NODES, VALUES))  # noqa: E731
    lo, hi = sorted((NODES[0], theta))
    breaks = [t for t in NODES if lo < t < hi]
    value = integrate.quad(f, lo, hi, points=breaks or None, epsabs=0, epsrel=1e-13, limit=200)[0]
    return value if theta >= NODES[0] else -value


def test_interpolation_is_clamped_outside_the_nodes():
    got = np.asarray(materials.interpolate_table(BELOW_INSIDE_ABOVE, NODES, VALUES))
    np.testing.assert_allclose(got, np.interp(BELOW_INSIDE_ABOVE, NODES, VALUES), rtol=1e-14)


def test_enthalpy_below_and_above_the_nodes_is_the_integral_of_the_clamped_table():
    got = np.asarray(materials.integrate_table(BELOW_INSIDE_ABOVE, NODES, VALUES))
    expected = np.array([clamped_integral(t) for t in BELOW_INSIDE_ABOVE])
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-9)
    # outside, the enthalpy moves with the end values: c(T_0) below, c(T_n) above
    assert got[1] - got[0] == pytest.approx(VALUES[0] * 200.0, rel=1e-13)
    assert got[-1] - got[-2] == pytest.approx(VALUES[-1] * 700.0, rel=1e-13)


def test_the_inverse_returns_temperatures_below_and_above_the_nodes():
    integral = np.array([clamped_integral(t) for t in BELOW_INSIDE_ABOVE])
    back = np.asarray(materials.invert_table_integral(integral, NODES, VALUES))
    np.testing.assert_allclose(back, BELOW_INSIDE_ABOVE, rtol=1e-12)
