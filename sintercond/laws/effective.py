"""Effective conductivity of porous and sintered solids: bounds and closed-form models.

The Dryden & Zok (2004) self-consistent sphere model lives in
:mod:`sintercond.laws.dryden_zok` and is re-exported here; this module adds the
Hashin-Shtrikman bounds and Maxwell's estimate. Conductivities in W/(m K)
(any consistent unit), volume fractions dimensionless; all functions are
pure, broadcast and are differentiable.
"""

from __future__ import annotations

import jax.numpy as jnp

from sintercond._numerics import as_float_arrays, safe_divide
from sintercond.laws.dryden_zok import (  # noqa: F401  (re-exported)
    batchelor_obrien_conductivity,
    cap_angle,
    dryden_zok_conductivity,
    dryden_zok_sigma,
    sigma_half_space,
    sigma_large_alpha,
    sigma_lower_bound,
    sigma_small_alpha,
)


def _hashin_shtrikman(k_matrix, k_inclusion, inclusion_fraction):
    """HS estimate with the given phase as the matrix (coated-sphere assemblage).

    ``k_m + v_i / (1/(k_i - k_m) + v_m/(3 k_m))``, written as
    ``k_m (3 k_m + (1 + 2 v_i) d) / (3 k_m + (1 - v_i) d)`` with ``d = k_i - k_m``
    so that equal phases, a void matrix and a void inclusion need no special case.
    """
    d = k_inclusion - k_matrix
    return k_matrix * safe_divide(3 * k_matrix + (1 + 2 * inclusion_fraction) * d,
                                  3 * k_matrix + (1 - inclusion_fraction) * d, fill=1.0)


def hashin_shtrikman_bounds(k_1, k_2, v_2):
    """Hashin-Shtrikman bounds on the conductivity of an isotropic two-phase mixture.

    Quintana-Ruiz & Campello (2020), Eq. 48. The phases may be given in either
    order; the lower bound takes the less conducting phase as the matrix, the
    upper bound the more conducting one.

    Args:
      k_1, k_2: phase conductivities, >= 0 (W/(m K)).
      v_2: volume fraction of phase 2, in [0, 1].

    Returns:
      ``(lower, upper)`` (W/(m K)).
    """
    k_1, k_2, v_2 = as_float_arrays(k_1, k_2, v_2)
    v_1 = 1.0 - v_2
    k_lo, k_hi = jnp.minimum(k_1, k_2), jnp.maximum(k_1, k_2)
    v_hi = jnp.where(k_2 >= k_1, v_2, v_1)
    lower = _hashin_shtrikman(k_lo, k_hi, v_hi)
    upper = _hashin_shtrikman(k_hi, k_lo, 1.0 - v_hi)
    return lower, upper


def maxwell_conductivity(k_solid, solid_fraction, k_pore=0.0):
    """Maxwell's estimate for a dense solid with isolated spherical pores.

    ``k_e = k (2k + k_p - 2p(k - k_p)) / (2k + k_p + p(k - k_p))`` with porosity
    ``p = 1 - f``; for empty pores ``2 k f / (3 - f)``. It equals the upper
    Hashin-Shtrikman bound (solid as the matrix), the regime Dryden & Zok
    (2004, Sect. V) point to for almost fully dense solids.

    Args:
      k_solid: solid conductivity (W/(m K)).
      solid_fraction: ``f`` in [0, 1].
      k_pore: conductivity of the pore phase (default 0).
    """
    k_solid, solid_fraction, k_pore = as_float_arrays(k_solid, solid_fraction, k_pore)
    return _hashin_shtrikman(k_solid, k_pore, 1.0 - solid_fraction)


__all__ = [
    "batchelor_obrien_conductivity",
    "cap_angle",
    "dryden_zok_conductivity",
    "dryden_zok_sigma",
    "hashin_shtrikman_bounds",
    "maxwell_conductivity",
    "sigma_half_space",
    "sigma_large_alpha",
    "sigma_lower_bound",
    "sigma_small_alpha",
]
