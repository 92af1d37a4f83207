"""Thermal conductance of a pair of particles, for the pipe-network DEM.

A conductance law turns the pair geometry (radii ``r_i``, ``r_j``, overlap
``h``, and a neck or contact radius ``a`` from a neck model of
:mod:`sintercond.laws.neck`) and the materials (conductivities ``kappa_i``,
``kappa_j``) into the conductance ``K_ij`` of the pipe joining the two centres,
so that the heat flow into ``i`` is ``K_ij (T_j - T_i)`` (Rojek et al. 2022,
Eq. 4). Units: lengths in m and conductivities in W/(m K) give W/K; any
consistent set works.

Every law is one :class:`ConductanceLaw` with the same signature, so the
thermal DEM can take any of them by name (:data:`CONDUCTANCE_LAWS`) or as an
object, with its fittable parameters passed explicitly (``params``):

========================  ======================================  =================
law                       pair conductance                        default neck
========================  ======================================  =================
``rojek``                 halves ``s kappa pi a`` in series       volume_conserving
``argento_bouvard``       the same with ``s = 1/0.899``           volume_conserving
``batchelor_obrien``      halves ``4 kappa a`` in series          volume_conserving
``conductivity``          ``k_ij pi a^2 / d``                     intersection
``feng``                  2-D pipe halves in series               intersection
========================  ======================================  =================

The neck radius each law uses is stated above and can be swapped with
``neck_model=``. Laws that look alike differ by conventions: Rojek's ``a`` is
the cylindrical-neck radius, Quintana-Ruiz's the lens radius. Pairs with
``h <= 0`` have ``K = 0`` with zero gradient; pairs where the neck model is
undefined give NaN (see :mod:`sintercond.laws.neck`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import NamedTuple

import jax.numpy as jnp

from sintercond._numerics import as_float_arrays, safe_divide
from sintercond._validation import all_concrete, concrete_arrays, law_params_valid, require_law_params, require_positive
from sintercond.laws.neck import NECK_MODELS, validate_neck_inputs

ROJEK_SLOPE = 1.064
"""Slope of Rojek et al. (2022), Eq. 40: ``K_i / K_cyl = 1.064 a / r``."""

ARGENTO_BOUVARD_SLOPE = 1.0 / 0.899
"""Argento & Bouvard (1996) ``R/R_cyl = 0.899 (a/r)^-1``, as a Rojek slope (Eq. 42: 1.112)."""

BATCHELOR_OBRIEN_SLOPE = 4.0 / math.pi
"""``4 kappa a`` per half (isothermal disc on a half-space) as a Rojek slope."""


def series_conductance(k_i, k_j, contact_resistance=0.0):
    """Conductances in series: ``1 / (1/k_i + 1/k_j + R_c)``.

    Rojek et al. (2022), Eqs. 5-9 (Eq. 8 with ``R_c = 1/K_c``, Eq. 9 with
    ``R_c = 0``), evaluated as ``k_i k_j / (k_i + k_j + k_i k_j R_c)`` so that
    zero conductances give 0 (with zero gradient) rather than ``1/0``.

    Args:
      k_i, k_j: conductances >= 0 (W/K).
      contact_resistance: ``R_c >= 0`` (K/W); 0 for a perfect interface.

    Returns:
      The series conductance (W/K).
    """
    k_i, k_j, r_c = as_float_arrays(k_i, k_j, contact_resistance)
    return safe_divide(k_i * k_j, k_i + k_j + k_i * k_j * r_c)


# --------------------------------------------------------------------------
# the laws, as functions of the neck radius


def _linear_neck_law(a, r_i, r_j, h, kappa_i, kappa_j, params):
    """Halves ``K_k = s kappa_k pi a`` (Rojek Eq. 43) in series (Eqs. 8-9)."""
    slope = params["slope"]
    return series_conductance(
        slope * kappa_i * jnp.pi * a, slope * kappa_j * jnp.pi * a, params["contact_resistance"]
    )


def fitted_half_conductance_ratio(x, coefficients):
    """``K_i / K_cyl = (4/pi) x (1 + c1 x ln x + c2 x + c3 x^2 + c4 x^3)`` at ``x = a/r`` (NaN-safe at 0)."""
    c1, c2, c3, c4 = (coefficients[k] for k in range(4))
    positive = x > 0
    x_safe = jnp.where(positive, x, 1.0)
    x_log_x = jnp.where(positive, x_safe * jnp.log(x_safe), 0.0)
    return 4.0 / jnp.pi * x * (1.0 + c1 * x_log_x + c2 * x + c3 * x**2 + c4 * x**3)


def fitted_neck_law_coefficients():
    """Coefficients of the fitted smooth law, from sintercond/data/fitted_neck_law.json (made by fitting.neck_law)."""
    import importlib.resources
    import json

    text = importlib.resources.files("sintercond.data").joinpath("fitted_neck_law.json").read_text()
    return tuple(json.loads(text)["coefficients"])


def _fitted_law(a, r_i, r_j, h, kappa_i, kappa_j, params):
    """Halves ``K_k = kappa_k pi r_k f(a/r_k)`` from the fitted smooth law, in series."""
    c = jnp.stack([params["c1"], params["c2"], params["c3"], params["c4"]])
    k_i = kappa_i * jnp.pi * r_i * fitted_half_conductance_ratio(a / r_i, c)
    k_j = kappa_j * jnp.pi * r_j * fitted_half_conductance_ratio(a / r_j, c)
    return series_conductance(k_i, k_j, params["contact_resistance"])


def _conductivity_law(a, r_i, r_j, h, kappa_i, kappa_j, params):
    """``k_ij A / d``, Quintana-Ruiz & Campello (2020), Eqs. 32, 34, 35."""
    d = r_i + r_j - h
    k_ij = (r_i + r_j) / (r_i / kappa_i + r_j / kappa_j)
    return k_ij * jnp.pi * a**2 / d


def _feng_half_conductance(a, r, kappa, thickness):
    """Feng et al. (2009) 2-D disc conductance, Quintana-Ruiz Eq. 36.

    ``alpha`` is the half-angle of the contact arc seen from the centre,
    ``sin(alpha) = a / r``; the result is per unit out-of-plane thickness
    times ``thickness``.
    """
    # double where: arcsin' is infinite at a/r = 1 and log' at alpha = 0; their cotangents would be
    # inf (or inf * 0 = NaN) in reverse mode although the selected value is finite
    x = a / r
    below = x < 1
    alpha = jnp.where(below, jnp.arcsin(jnp.where(below, jnp.maximum(x, 0.0), 0.5)), jnp.pi / 2)
    tiny = jnp.finfo(alpha.dtype).tiny
    positive = alpha > tiny
    log_alpha = jnp.where(positive, jnp.log(jnp.where(positive, alpha, 1.0)), jnp.log(tiny))
    return thickness * jnp.pi * kappa / (-log_alpha + 1.5 + alpha**2 / 36.0 + alpha**4 / 2700.0)


def _feng_law(a, r_i, r_j, h, kappa_i, kappa_j, params):
    t = params["thickness"]
    return series_conductance(
        _feng_half_conductance(a, r_i, kappa_i, t),
        _feng_half_conductance(a, r_j, kappa_j, t),
        params["contact_resistance"],
    )


class ConductanceLaw(NamedTuple):
    """A pair conductance law.

    Attributes:
      name: registry key.
      from_neck: ``fn(a, r_i, r_j, h, kappa_i, kappa_j, params) -> K_ij`` (W/K),
        called only for pairs in contact (``h > 0``, ``a > 0``).
      default_params: the law's parameters and their defaults; these are
        the differentiable (fittable) inputs.
      neck_model: default key of :data:`sintercond.laws.neck.NECK_MODELS`.
      reference: paper and equations.
      params_allowing_zero: parameters that may be 0; all others must be > 0
        (except ``params_any_sign``).
      params_any_sign: parameters that may take any finite value (fit coefficients).
    """

    name: str
    from_neck: Callable
    default_params: Mapping[str, float]
    neck_model: str
    reference: str
    params_allowing_zero: tuple[str, ...] = ()
    params_any_sign: tuple[str, ...] = ()


CONDUCTANCE_LAWS: dict[str, ConductanceLaw] = {
    law.name: law
    for law in (
        ConductanceLaw(
            "rojek", _linear_neck_law,
            {"slope": ROJEK_SLOPE, "contact_resistance": 0.0},
            "volume_conserving", "Rojek et al. 2022, Eqs. 8-9, 40, 43", ("contact_resistance",),
        ),
        ConductanceLaw(
            "argento_bouvard", _linear_neck_law,
            {"slope": ARGENTO_BOUVARD_SLOPE, "contact_resistance": 0.0},
            "volume_conserving", "Argento & Bouvard 1996, via Rojek et al. 2022, Eqs. 41-42", ("contact_resistance",),
        ),
        ConductanceLaw(
            "batchelor_obrien", _linear_neck_law,
            {"slope": BATCHELOR_OBRIEN_SLOPE, "contact_resistance": 0.0},
            "volume_conserving", "Batchelor & O'Brien 1977 (2 kappa a), Dryden & Zok 2004, Eq. 37",
            ("contact_resistance",),
        ),
        ConductanceLaw(
            "fitted", _fitted_law,
            {**dict(zip(("c1", "c2", "c3", "c4"), fitted_neck_law_coefficients())), "contact_resistance": 0.0},
            "volume_conserving", "smooth law fitted to FE half-geometry data (fitting.neck_law)",
            ("contact_resistance",), ("c1", "c2", "c3", "c4"),
        ),
        ConductanceLaw(
            "conductivity", _conductivity_law, {},
            "intersection", "Quintana-Ruiz & Campello 2020, Eqs. 32-35",
        ),
        ConductanceLaw(
            "feng", _feng_law,
            {"thickness": 1.0, "contact_resistance": 0.0},
            "intersection", "Feng et al. 2009, via Quintana-Ruiz & Campello 2020, Eq. 36", ("contact_resistance",),
        ),
    )
}
"""The conductance laws by name."""


def pair_conductance(law, r_i, r_j, h, kappa_i, kappa_j=None, params=None, neck_model=None):
    """Conductance ``K_ij`` of a particle pair under any law.

    Args:
      law: a :class:`ConductanceLaw` or a key of :data:`CONDUCTANCE_LAWS`.
      r_i, r_j: radii, > 0 (m).
      h: overlap ``r_i + r_j - d`` (m); ``h <= 0`` gives 0.
      kappa_i: conductivity of particle i, > 0 (W/(m K)).
      kappa_j: conductivity of particle j; defaults to ``kappa_i``.
      params: overrides of ``law.default_params`` (arrays allowed: these
        are what a fit differentiates).
      neck_model: key of :data:`sintercond.laws.neck.NECK_MODELS`; defaults to
        the law's.

    Returns:
      ``K_ij`` (W/K), broadcast shape of the geometry and materials.
    """
    law = _resolve_law(law)
    params = _merge_params(law, params)
    neck = NECK_MODELS[_resolve_neck_model(law, neck_model)]
    if all_concrete(kappa_i, kappa_j, *params.values()):
        validate_law_inputs(law, params, kappa_i, kappa_j)
    kappa_j = kappa_i if kappa_j is None else kappa_j
    r_i, r_j, h, kappa_i, kappa_j = as_float_arrays(r_i, r_j, h, kappa_i, kappa_j)
    a = neck(r_i, r_j, h)
    return conductance_from_neck(law, a, r_i, r_j, h, kappa_i, kappa_j, params)


def conductance_from_neck(law, a, r_i, r_j, h, kappa_i, kappa_j, params=None):
    """``K_ij`` (W/K) of a law from a neck radius ``a`` already computed by its neck model.

    The second half of :func:`pair_conductance`: the thermal DEM computes the
    necks of a static packing once (they depend on the geometry only) and
    applies the law to them with the current ``params`` and conductivities,
    so that law parameters stay differentiable through a simulation.
    ``h <= 0`` or ``a <= 0`` gives 0 (zero gradient), NaN necks give NaN.
    """
    law = _resolve_law(law)
    params = _merge_params(law, params)
    # Double where: laws may hold log(a) or 1/a, so out-of-contact pairs are
    # evaluated at a harmless in-contact point and then masked.
    contact = (h > 0) & (a > 0)
    undefined = jnp.isnan(a)
    a_safe = jnp.where(contact, a, 0.5 * jnp.minimum(r_i, r_j))
    h_safe = jnp.where(contact, h, 0.0)
    k = law.from_neck(a_safe, r_i, r_j, h_safe, kappa_i, kappa_j, params)
    # under jit, invalid materials or parameters give NaN, never a negative conductance
    # (jnp.asarray: for Python floats, ~True is the int -2, which would flag every pair)
    undefined = undefined | ~((jnp.asarray(kappa_i) > 0) & (jnp.asarray(kappa_j) > 0)) | ~law_params_valid(law, params)
    return jnp.where(undefined, jnp.nan, jnp.where(contact, k, 0.0))


def validate_law_inputs(law, params, kappa_i, kappa_j=None, names=None):
    """Raise ``ValueError`` naming the argument unless the law's parameters and the conductivities are valid.

    Parameters must be finite and > 0 (those in ``law.params_allowing_zero``
    >= 0, ``law.params_any_sign`` any finite value); conductivities finite and
    > 0 (normal floats). ``names`` maps ``kappa_i``, ``kappa_j`` and parameter
    keys to the names the message uses.
    """
    law = _resolve_law(law)
    params = _merge_params(law, params)
    names = names or {}
    require_law_params("validate_law_inputs", law, params, lambda name: names.get(name, f"params[{name!r}] of law "
                                                                                     f"{law.name!r}"))
    kappas = {"kappa_i": kappa_i} if kappa_j is None else {"kappa_i": kappa_i, "kappa_j": kappa_j}
    for name, value in kappas.items():
        (value,) = concrete_arrays("validate_law_inputs", value)
        require_positive(f"{names.get(name, name)} (W/(m K))", value)


def validate_pair_conductance_inputs(law, r_i, r_j, h, kappa_i, kappa_j=None, params=None, neck_model=None):
    """Raise ``ValueError`` naming the field unless :func:`pair_conductance` input is valid.

    For concrete input at an API boundary, before anything is compiled:
    the law and neck model exist, the parameters are known, finite and
    positive (``contact_resistance`` may be 0), the conductivities finite and
    > 0, and the geometry inside the neck model's domain
    (:func:`sintercond.laws.neck.validate_neck_inputs`).
    """
    law = _resolve_law(law)
    model = _resolve_neck_model(law, neck_model)
    validate_law_inputs(law, params, kappa_i, kappa_j)
    validate_neck_inputs(r_i, r_j, h, model=model)


def rojek_pair_conductance(r_i, r_j, h, kappa, slope=ROJEK_SLOPE, contact_conductance=None, *, kappa_j=None):
    """Rojek et al. (2022) pair conductance of two sintered spheres.

    Each half is ``K_k = slope * kappa_k * pi * a`` (Eq. 43) with ``a`` the
    volume-conserving neck radius (:func:`sintercond.laws.neck.neck_radius`); the
    halves combine in series (Eq. 9), with a finite contact conductance
    ``K_c`` in series as well when given (Eq. 8). For equal materials and no
    contact resistance this is ``slope * kappa * pi * a / 2`` (Eq. 45).

    Args:
      r_i, r_j: radii, > 0 (m).
      h: overlap (m), ``<= max_overlap(r_i, r_j)``; ``h <= 0`` gives 0.
      kappa: conductivity of particle i (and j unless ``kappa_j``), W/(m K).
      slope: ``s`` of ``K_i / K_cyl = s a / r`` (Eq. 40), fittable.
      contact_conductance: ``K_c`` (W/K), or None for a perfect interface.
      kappa_j: conductivity of particle j, if different.

    Returns:
      ``K_ij`` (W/K).
    """
    if contact_conductance is not None and all_concrete(contact_conductance):
        (k_c,) = concrete_arrays("rojek_pair_conductance", contact_conductance)
        require_positive("contact_conductance (W/K)", k_c)
    contact_resistance = 0.0 if contact_conductance is None else 1.0 / jnp.asarray(contact_conductance)
    return pair_conductance(
        "rojek", r_i, r_j, h, kappa, kappa_j,
        params={"slope": slope, "contact_resistance": contact_resistance},
    )


def fitted_pair_conductance(r_i, r_j, h, kappa, *, kappa_j=None):
    """Pair conductance from the smooth law fitted to FE data, each half from its own ``a/r``.

    ``K_k = kappa_k pi r_k f(a / r_k)`` with
    ``f(x) = (4/pi) x (1 + c1 x ln x + c2 x + c3 x^2 + c4 x^3)`` (within 0.25 % of
    the FE half-geometry data for 0.1 <= a/r <= 0.85, and the half-space limit
    ``4 kappa a`` as ``a -> 0``), ``a`` the volume-conserving neck, halves in series.
    Unlike Eq. 43, unequal spheres get unequal halves.
    """
    return pair_conductance("fitted", r_i, r_j, h, kappa, kappa_j)


def argento_bouvard_pair_conductance(r_i, r_j, h, kappa, *, kappa_j=None):
    """Argento & Bouvard (1996) law as Rojek's with slope ``1/0.899 = 1.112`` (Rojek Eq. 42)."""
    return pair_conductance("argento_bouvard", r_i, r_j, h, kappa, kappa_j)


def batchelor_obrien_pair_conductance(r_i, r_j, h, kappa, *, kappa_j=None, neck_model=None):
    """Batchelor & O'Brien (1977) small-contact conductance ``2 kappa a``.

    Each half is an isothermal disc of radius ``a`` on a half-space,
    ``4 kappa_k a``; in series these give ``2 kappa a`` for equal materials
    (Dryden & Zok 2004, Eq. 37). ``a`` is the volume-conserving neck unless
    ``neck_model`` says otherwise.
    """
    return pair_conductance("batchelor_obrien", r_i, r_j, h, kappa, kappa_j, neck_model=neck_model)


def conductivity_pair_conductance(r_i, r_j, h, kappa_i, kappa_j=None, *, neck_model=None):
    """Conductivity-based pair conductance ``k_ij A_ij / d`` (Quintana-Ruiz & Campello 2020).

    ``A_ij = pi a^2`` with ``a`` the lens radius (Eqs. 33-34) unless
    ``neck_model`` says otherwise, ``d = r_i + r_j - h`` the centre distance
    (Eq. 32), and ``(r_i + r_j) / k_ij = r_i / k_i + r_j / k_j`` (Eq. 35).
    """
    return pair_conductance("conductivity", r_i, r_j, h, kappa_i, kappa_j, neck_model=neck_model)


def feng_pair_conductance(r_i, r_j, h, kappa_i, kappa_j=None, *, thickness=1.0, neck_model=None):
    """Feng et al. (2009) 2-D pipe-network conductance (Quintana-Ruiz Eq. 36).

    Per disc ``K_k = pi kappa_k t / (-ln alpha_k + 3/2 + alpha_k^2/36 + alpha_k^4/2700)``
    with ``sin(alpha_k) = a / r_k`` (``a`` the lens radius by default) and
    ``t`` the out-of-plane thickness (m; the default 1 gives the conductance
    per unit thickness, W/(m K)); the two discs in series. A 2-D model: use
    it for disc packings.
    """
    return pair_conductance(
        "feng", r_i, r_j, h, kappa_i, kappa_j,
        params={"thickness": thickness}, neck_model=neck_model,
    )


def _resolve_law(law) -> ConductanceLaw:
    if isinstance(law, ConductanceLaw):
        return law
    try:
        return CONDUCTANCE_LAWS[law]
    except (KeyError, TypeError):
        raise ValueError(f"law must be one of {sorted(CONDUCTANCE_LAWS)} or a ConductanceLaw; got {law!r}") from None


def _resolve_neck_model(law: ConductanceLaw, neck_model) -> str:
    name = law.neck_model if neck_model is None else neck_model
    if name not in NECK_MODELS:
        raise ValueError(f"neck_model must be one of {sorted(NECK_MODELS)}; got {name!r}")
    return name


def _merge_params(law: ConductanceLaw, params) -> dict:
    params = {} if params is None else dict(params)
    unknown = set(params) - set(law.default_params)
    if unknown:
        raise ValueError(
            f"params of law {law.name!r} must be among {sorted(law.default_params)}; got unknown {sorted(unknown)}"
        )
    return {**law.default_params, **params}
