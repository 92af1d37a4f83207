"""Fit of Rojek's conductance slope ``s`` in ``K_i / K_cyl = s a / r`` (Rojek et al. 2022, Eq. 40)."""

from __future__ import annotations

import numpy as np

from fitting.core import Positive, least_squares


def linear_law(params, a_over_r):
    """``K_i / K_cyl = s a / r`` (Eq. 40)."""
    return params["slope"] * a_over_r


def fit_slope(a_over_r, k_over_kcyl, sigma=None, max_a_over_r=0.7, **options):
    """Least-squares slope of Eq. 40 on the points with ``a/r <= max_a_over_r``; returns a FitResult."""
    a_over_r, k_over_kcyl = np.asarray(a_over_r), np.asarray(k_over_kcyl)
    keep = a_over_r <= max_a_over_r
    weights = None if sigma is None else 1.0 / np.broadcast_to(np.asarray(sigma, float), a_over_r.shape)[keep]
    return least_squares(linear_law, a_over_r[keep], k_over_kcyl[keep], {"slope": 1.0}, {"slope": Positive()},
                         weights=weights, **options)
