"""Sintering kinetics: necks that grow with the temperature history.

The neck radius ``a`` of a contact is the state; the overlap (approach) ``h``
follows from it through Rojek et al. (2022)'s volume-conserving geometry, and a
kinetic law gives the growth rate of ``u = a^n`` at the pair temperature. All
functions are pure and can be ``jit``-, ``vmap``- and ``grad``-transformed
(lengths in m, temperatures in K, times in s unless stated).

Geometry: the inverse of the volume-conserving neck
----------------------------------------------------
Rojek et al. (2022, Eqs. 23-27) equate the cylinder ``pi a^2 h_n`` with the two
caps cut off the spheres, ``h_n = h_ci + h_cj - h``. Solved for ``h`` with
``s_k = sqrt(r_k^2 - a^2)``, ``h_ck = a^2 / (r_k + s_k)``::

    h = H(a) = a^2 sum_k (r_k + 2 s_k) / (3 (r_k + s_k)^2)

(the residual ``F`` of :mod:`sintercond.laws.neck` is ``H(a) - h``), with no
cancellation anywhere in ``0 <= a <= min(r_i, r_j)``. Its limits: Coble's
``H ~ a^2 / (2 r*)``, ``r* = 2 r_i r_j / (r_i + r_j)`` (Rojek Eqs. 11-12), as
``a -> 0``; ``H = 2r/3`` at ``a = r`` for equal spheres (Eqs. 18-19). The slope
``dH/da = 2a sum_k (2 r_k + s_k) / (3 (r_k + s_k)^2)`` stays finite at
``a = min(r)`` (8/3 for equal spheres) although each cap height's does not, so
it is given in closed form (:func:`neck_overlap` carries it as its JVP).

Kinetic laws (densifying, initial stage)
----------------------------------------
Each :class:`KineticLaw` gives ``du/dt`` for ``u = a^n`` (its ``exponent``):

* ``grain_boundary`` (Bouvard & McMeeking 1996; Parhami & McMeeking 1998;
  Nosewicz, Rojek et al. 2013, Rojek 2022's ref. 14): a free pair's approach
  rate ``dh/dt = F_s / eta_N`` with ``eta_N = pi a^4 / (8 Delta_b)``,
  ``Delta_b = Omega delta_b D_0b exp(-Q/(R T)) / (k_B T)`` and the sintering
  force ``F_s = pi gamma_s [4 r* (1 - cos(psi/2)) + a sin(psi/2)]``; with
  ``da/dt = (dh/dt) / H'(a)``::

      d(a^6)/dt = 48 (a / H'(a)) (A / T) exp(-Q / (R T)) [4 r* (1 - cos(psi/2)) + a sin(psi/2)]

  ``A = Omega delta_b D_0b gamma_s / k_B`` (m^4 K/s; :func:`grain_boundary_a`
  builds it from the material's constants) and ``a / H'(a) -> r*`` at the point
  contact, so necks start from touching spheres and small necks follow
  ``a^6 = 192 r*^2 (A/T) exp(-Q/(R T)) (1 - cos(psi/2)) t``. Neck data identify
  only ``A`` and ``Q`` (not Omega, delta_b D_0b, gamma_s apart), and ``psi``
  only weakly. The neck stops at the equilibrium neck ``r_min sin(psi/2)``.
* ``power_law``: ``d(a^n)/dt = K0 exp(-Q / (R T)) (r*/r_ref)^p`` with the
  exponent ``n`` and the size exponent ``p`` chosen (n = 6 grain boundary,
  5 volume, 2 viscous), for phase-field data; ``K0`` in m^n/s. ``n`` and ``Q``
  trade off along a valley in neck data: fix ``n`` by mechanism.
* ``viscous`` (Frenkel 1945, polymers and glass): ``d(a^2)/dt = 3 gamma_s r* /
  (2 eta(T))``, ``eta = eta0 exp(Q / (R T))``; only ``gamma_s / eta0`` and
  ``Q`` are identifiable.

The power law and viscous flow are capped at ``max_neck_ratio * min(r)``.

Integration along a temperature history
---------------------------------------
:func:`grow_neck` takes a piecewise-constant history (durations and pair
temperatures). Every law here separates, ``du/dt = shape(a) speed(T)``, so a
constant-temperature interval is integrated exactly. Where ``shape`` does not
depend on ``a`` (power law, viscous flow), ``u += shape speed(T) dt``. For
grain-boundary growth the reduced time to grow from ``a_0`` to ``a_1``,
``int_{a_0}^{a_1} n s^(n-1) / shape(s) ds``, is smooth in ``s`` (in ``u`` it is
not: the force's ``a sin(psi/2)`` term is ``u^(1/6)``, which costs explicit
schemes in ``u`` their order at the point contact); it is evaluated by
Gauss-Legendre quadrature and set equal to ``speed(T) dt`` by Newton steps in
``u_1``, whose derivative is ``1 / shape``. The error against the node and
iteration counts is measured in ``benchmarks/sintering_kinetics.py``:
along the Eq. 6 ramp the defaults (8 nodes, 4 Newton steps) reach round-off;
one long interval that grows a neck from 0 to near the equilibrium neck is
within about 1e-5 (the shape has a square-root branch point at ``a = min(r)``),
so split long holds. Lengths are scaled by ``min(r_i, r_j)`` inside, so that
``u`` does not underflow float32. ``u`` is clipped at the cap, so a capped neck has
zero rate and zero gradient. The pair temperature of two particles is their
arithmetic mean (MUSEN's choice; :func:`pair_temperature`).

Bad input: :func:`validate_growth_inputs` raises a ``ValueError`` naming the
argument and the allowed range for concrete values (it runs inside
:func:`grow_neck` when nothing is traced); under ``jit`` invalid pairs give
NaN and :func:`growth_status` returns a :class:`GrowthStatus` code per pair.

Float32: :func:`neck_overlap` agrees with float64 to a few ulp; grown necks
agree to about 1e-6 relative (tests/test_sintering.py).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from sintercond._numerics import as_float_arrays, safe_power, sqrt_difference_of_squares
from sintercond._validation import (all_concrete, concrete_arrays, fail_where, law_params_valid, require_law_params,
                                    require_positive)
from sintercond.laws.neck import NeckStatus

GAS_CONSTANT = 8.314462618
"""Molar gas constant R, J/(mol K) (CODATA 2018, exact)."""

BOLTZMANN = 1.380649e-23
"""Boltzmann constant k_B, J/K (SI, exact)."""

_MAX_NECK_SLACK_ULPS = 8  # a given as the rounded min(r_i, r_j) still counts as "at" it


# --------------------------------------------------------------------------
# geometry


def neck_overlap(a, r_i, r_j):
    """Overlap (approach) ``h`` of two spheres joined by a volume-conserving neck of radius ``a``.

    The closed-form inverse of :func:`sintercond.laws.neck.neck_radius` (Rojek et
    al. 2022, Eqs. 23-27; module docstring): ``H(a) = a^2 sum_k (r_k + 2 s_k) /
    (3 (r_k + s_k)^2)``, ``s_k = sqrt(r_k^2 - a^2)``. Gradients are closed-form
    and finite on the whole domain, at ``a = 0`` (Coble's limit, slope 0) and
    at ``a = min(r_i, r_j)``.

    Args:
      a: neck radius, ``0 <= a <= min(r_i, r_j)`` (length).
      r_i, r_j: sphere radii, > 0 (same length unit).

    Returns:
      ``h`` (length): 0 at ``a = 0``; NaN beyond ``min(r_i, r_j)``, for ``a < 0``
      or invalid radii (see :func:`neck_overlap_status`).
    """
    a, r_i, r_j = as_float_arrays(a, r_i, r_j)
    return _neck_overlap(a, r_i, r_j)


def neck_overlap_slope(a, r_i, r_j):
    """``dH/da`` of :func:`neck_overlap`: ``2a sum_k (2 r_k + s_k) / (3 (r_k + s_k)^2)`` (dimensionless).

    0 at ``a = 0`` (Coble: ``a / r*``), finite at ``a = min(r)`` (8/3 for
    equal spheres); NaN where :func:`neck_overlap` is NaN.
    """
    a, r_i, r_j = as_float_arrays(a, r_i, r_j)
    valid = _valid_neck(a, r_i, r_j)
    a_s, r_i_s, r_j_s = _safe_geometry(valid, a, r_i, r_j)
    return jnp.where(valid, a_s / _half_inverse_slope(a_s, r_i_s, r_j_s), jnp.nan)


def neck_overlap_status(a, r_i, r_j):
    """Per-pair :class:`sintercond.laws.neck.NeckStatus` of a neck radius (int32), usable under ``jit``.

    ``OK`` for ``0 < a <= min(r)``; ``NO_CONTACT`` for ``a = 0`` (a point
    contact, ``h = 0``); ``BEYOND_MAX_OVERLAP`` for ``a > min(r)``;
    ``INVALID_INPUT`` for ``a < 0``, non-finite ``a`` or invalid radii.
    """
    a, r_i, r_j = as_float_arrays(a, r_i, r_j)
    radii = _valid_radii(r_i, r_j)
    invalid = ~radii | ~jnp.isfinite(a) | (a < 0)
    beyond = a > _max_neck(r_i, r_j)
    return jnp.where(invalid, NeckStatus.INVALID_INPUT,
                     jnp.where(beyond, NeckStatus.BEYOND_MAX_OVERLAP,
                               jnp.where(a == 0, NeckStatus.NO_CONTACT, NeckStatus.OK))).astype(jnp.int32)


def validate_neck_overlap_inputs(a, r_i, r_j, names=("a", "r_i", "r_j")):
    """Raise ``ValueError`` naming the argument unless ``0 <= a <= min(r_i, r_j)`` and the radii are > 0."""
    a, r_i, r_j = concrete_arrays("validate_neck_overlap_inputs", a, r_i, r_j)
    name_a, name_i, name_j = names
    require_positive(name_i, r_i)
    require_positive(name_j, r_j)
    require_positive(name_a, a, allow_zero=True)
    limit = np.minimum(r_i, r_j) * (1.0 + _MAX_NECK_SLACK_ULPS * np.finfo(np.float64).eps)
    fail_where(a > limit, lambda i: (
        f"{name_a} must be <= min({name_i}, {name_j}) (a neck cannot be wider than the smaller sphere); "
        f"got {name_a}={float(a[i])!r} with {name_i}={float(r_i[i])!r}, {name_j}={float(r_j[i])!r} at index {i}"))


def pair_temperature(temperature_i, temperature_j):
    """Temperature of a sintering contact: the arithmetic mean of its two particles' (K).

    MUSEN's choice. MercuryDPM's harmonic mean differs from it by
    ``(T_i - T_j)^2 / (4 T_mean)``, under 0.03 K for pairs 10 K apart at 1000 K.
    """
    temperature_i, temperature_j = as_float_arrays(temperature_i, temperature_j)
    return 0.5 * (temperature_i + temperature_j)


def _valid_radii(r_i, r_j):
    tiny = jnp.finfo(r_i.dtype).tiny
    return jnp.isfinite(r_i) & jnp.isfinite(r_j) & (r_i >= tiny) & (r_j >= tiny)


def _max_neck(r_i, r_j):
    return jnp.minimum(r_i, r_j) * (1.0 + _MAX_NECK_SLACK_ULPS * jnp.finfo(r_i.dtype).eps)


def _valid_neck(a, r_i, r_j):
    return _valid_radii(r_i, r_j) & jnp.isfinite(a) & (a >= 0) & (a <= _max_neck(r_i, r_j))


def _safe_geometry(valid, a, r_i, r_j):
    """Inputs with invalid entries replaced by a harmless in-domain point; ``a`` clipped to ``min(r)``."""
    r_i = jnp.where(valid, r_i, 1.0)
    r_j = jnp.where(valid, r_j, 1.0)
    a = jnp.where(valid, jnp.minimum(a, jnp.minimum(r_i, r_j)), 0.5)
    return a, r_i, r_j


def _cap_terms(a, r):
    """``(r + s, s)`` with ``s = sqrt(r^2 - a^2)`` (cancellation-free)."""
    s = sqrt_difference_of_squares(r, a)
    return r + s, s


def _overlap_per_area(a, r_i, r_j):
    """``H(a) / a^2 = sum_k (r_k + 2 s_k) / (3 (r_k + s_k)^2)`` (1/length)."""
    b_i, s_i = _cap_terms(a, r_i)
    b_j, s_j = _cap_terms(a, r_j)
    return (r_i + 2.0 * s_i) / (3.0 * b_i * b_i) + (r_j + 2.0 * s_j) / (3.0 * b_j * b_j)


def _half_inverse_slope(a, r_i, r_j):
    """``a / H'(a) = 1 / (2 F'(a^2))``, ``F'(u) = sum_k (2 r_k + s_k) / (3 (r_k + s_k)^2)`` (length).

    Smooth in ``a^2`` and equal to ``r*`` at the point contact.
    """
    b_i, s_i = _cap_terms(a, r_i)
    b_j, s_j = _cap_terms(a, r_j)
    return 1.0 / (2.0 * ((2.0 * r_i + s_i) / (3.0 * b_i * b_i) + (2.0 * r_j + s_j) / (3.0 * b_j * b_j)))


@jax.custom_jvp
def _neck_overlap(a, r_i, r_j):
    valid = _valid_neck(a, r_i, r_j)
    a_s, r_i_s, r_j_s = _safe_geometry(valid, a, r_i, r_j)
    return jnp.where(valid, a_s * a_s * _overlap_per_area(a_s, r_i_s, r_j_s), jnp.nan)


@_neck_overlap.defjvp
def _neck_overlap_jvp(primals, tangents):
    # dH = H'(a) da - a^2 / (r_i + s_i)^2 dr_i - a^2 / (r_j + s_j)^2 dr_j (F of neck.py at fixed u,
    # whose r-derivatives are -u / (r_k + s_k)^2): finite at a = min(r), where ds/da is not.
    a, r_i, r_j = primals
    da, dr_i, dr_j = tangents
    h = _neck_overlap(a, r_i, r_j)
    valid = _valid_neck(a, r_i, r_j)
    a_s, r_i_s, r_j_s = _safe_geometry(valid, a, r_i, r_j)
    b_i, _ = _cap_terms(a_s, r_i_s)
    b_j, _ = _cap_terms(a_s, r_j_s)
    u = a_s * a_s
    dh_da = a_s / _half_inverse_slope(a_s, r_i_s, r_j_s)
    zero = jnp.zeros_like(h)
    dh = jnp.where(valid, dh_da * da - u / (b_i * b_i) * dr_i - u / (b_j * b_j) * dr_j, zero)
    return h, dh


# --------------------------------------------------------------------------
# kinetic laws


def _arrhenius(temperature, activation_energy_kj):
    return jnp.exp(-1e3 * activation_energy_kj / (GAS_CONSTANT * temperature))


def _equivalent_radius(r_i, r_j):
    return 2.0 * r_i * r_j / (r_i + r_j)


def _grain_boundary_shape(a, r_i, r_j, params):
    return 48.0 * _half_inverse_slope(a, r_i, r_j) * _grain_boundary_force(a, r_i, r_j, params)


def _grain_boundary_force(a, r_i, r_j, params):
    psi_half = 0.5 * jnp.deg2rad(params["dihedral_angle"])
    return 4.0 * _equivalent_radius(r_i, r_j) * (1.0 - jnp.cos(psi_half)) + a * jnp.sin(psi_half)


def _grain_boundary_speed(temperature, params):
    return params["A"] / temperature * _arrhenius(temperature, params["activation_energy"])


def _grain_boundary_cap(r_i, r_j, params):
    return jnp.minimum(r_i, r_j) * jnp.sin(0.5 * jnp.deg2rad(params["dihedral_angle"]))


def _power_law_shape(a, r_i, r_j, params):
    size = (_equivalent_radius(r_i, r_j) / params["reference_radius"]) ** params["size_exponent"]
    return size * jnp.ones_like(a)


def _power_law_speed(temperature, params):
    return params["K0"] * _arrhenius(temperature, params["activation_energy"])


def _viscous_shape(a, r_i, r_j, params):
    return 1.5 * _equivalent_radius(r_i, r_j) * jnp.ones_like(a)


def _viscous_speed(temperature, params):
    return params["surface_energy"] / params["viscosity"] * _arrhenius(temperature, params["activation_energy"])


def _size_force(a, r_i, r_j, params):
    return _equivalent_radius(r_i, r_j) * jnp.ones_like(a)


def _ratio_cap(r_i, r_j, params):
    return jnp.minimum(r_i, r_j) * params["max_neck_ratio"]


class KineticLaw(NamedTuple):
    """A neck-growth law ``du/dt = shape(a) speed(T)`` for ``u = a^exponent``.

    The rate separates into a geometric factor and an Arrhenius factor, which
    is what lets :func:`grow_neck` integrate each constant-temperature interval
    exactly.

    Attributes:
      name: registry key of :data:`KINETIC_LAWS`.
      shape: ``fn(a, r_i, r_j, params)``: the geometric factor.
      speed: ``fn(T, params)``: the temperature factor, ``T`` the pair temperature (K);
        ``shape * speed`` is ``du/dt`` in m^n/s.
      cap: ``fn(r_i, r_j, params) -> a_max``: the neck stops there (m).
      default_params: the parameters and their defaults (the differentiable inputs), in the
        units of ``units``.
      units: parameter name -> unit as typed.
      exponent_param: the parameter holding ``n`` (``None``: ``fixed_exponent``).
      fixed_exponent: ``n`` when it is not a parameter.
      shape_depends_on_neck: False where ``shape`` is independent of ``a`` (``u`` grows linearly in time).
      reference: paper and equations.
      params_allowing_zero: parameters that may be 0 (others > 0, except ``params_any_sign``).
      params_any_sign: parameters that may take any finite value.
      force: ``fn(a, r_i, r_j, params)``: the contact's sintering force over ``pi gamma_s`` (m), for the
        many-body balance of :mod:`sintercond.sim.neck_growth` (only its ratios between contacts enter there):
        Bouvard & McMeeking's ``4 r* (1 - cos(psi/2)) + a sin(psi/2)`` for grain-boundary diffusion;
        ``r*`` (a force in proportion to the contact's size) for the power law and viscous flow, which
        give no force of their own.
    """

    name: str
    shape: Callable
    speed: Callable
    cap: Callable
    default_params: Mapping[str, float]
    units: Mapping[str, str]
    exponent_param: str | None
    fixed_exponent: float
    shape_depends_on_neck: bool
    reference: str
    params_allowing_zero: tuple[str, ...] = ()
    params_any_sign: tuple[str, ...] = ()
    force: Callable | None = None

    def exponent(self, params):
        """``n`` of ``u = a^n`` for these parameters."""
        return params[self.exponent_param] if self.exponent_param else self.fixed_exponent


KINETIC_LAWS: dict[str, KineticLaw] = {
    law.name: law
    for law in (
        KineticLaw(
            "grain_boundary", _grain_boundary_shape, _grain_boundary_speed, _grain_boundary_cap,
            {"A": 1e-18, "activation_energy": 200.0, "dihedral_angle": 150.0},
            {"A": "m^4 K/s", "activation_energy": "kJ/mol", "dihedral_angle": "degrees"},
            None, 6.0, True,
            "Bouvard & McMeeking 1996; Parhami & McMeeking 1998; Nosewicz et al. 2013 (Rojek 2022 ref. 14)",
            ("activation_energy",), (), _grain_boundary_force,
        ),
        KineticLaw(
            "power_law", _power_law_shape, _power_law_speed, _ratio_cap,
            {"K0": 1e-30, "activation_energy": 100.0, "exponent": 6.0, "size_exponent": 0.0,
             "reference_radius": 40e-6, "max_neck_ratio": 1.0},
            {"K0": "m^n/s", "activation_energy": "kJ/mol", "exponent": "1", "size_exponent": "1",
             "reference_radius": "m", "max_neck_ratio": "1"},
            "exponent", 0.0, False, "phenomenological d(a^n)/dt = K0 exp(-Q/RT) (r*/r_ref)^p",
            ("activation_energy",), ("size_exponent",), _size_force,
        ),
        KineticLaw(
            "viscous", _viscous_shape, _viscous_speed, _ratio_cap,
            {"surface_energy": 0.03, "viscosity": 1e3, "activation_energy": 0.0, "max_neck_ratio": 1.0},
            {"surface_energy": "N/m", "viscosity": "Pa s", "activation_energy": "kJ/mol", "max_neck_ratio": "1"},
            None, 2.0, False, "Frenkel 1945: a^2 = 3 gamma r t / (2 eta)", ("activation_energy",), (),
            _size_force,
        ),
    )
}
"""The kinetic laws by name."""


def grain_boundary_a(atomic_volume, boundary_diffusivity, surface_energy):
    """``A = Omega delta_b D_0b gamma_s / k_B`` (m^4 K/s) of the grain-boundary law.

    Args:
      atomic_volume: Omega (m^3).
      boundary_diffusivity: ``delta_b D_0b``, boundary width times the diffusivity prefactor (m^3/s).
      surface_energy: gamma_s (J/m^2).
    """
    return atomic_volume * boundary_diffusivity * surface_energy / BOLTZMANN


def kinetic_law(law) -> KineticLaw:
    """The :class:`KineticLaw` for a name of :data:`KINETIC_LAWS` (or a law itself)."""
    if isinstance(law, KineticLaw):
        return law
    if law not in KINETIC_LAWS:
        raise ValueError(f"law must be one of {sorted(KINETIC_LAWS)}; got {law!r}")
    return KINETIC_LAWS[law]


def law_params(law, params=None) -> dict:
    """The law's defaults overridden by ``params``; ``ValueError`` naming an unknown key."""
    law = kinetic_law(law)
    params = dict(params or {})
    unknown = sorted(set(params) - set(law.default_params))
    if unknown:
        raise ValueError(f"unknown parameter {unknown[0]!r} of kinetic law {law.name!r}; "
                         f"its parameters are {sorted(law.default_params)}")
    return {**law.default_params, **params}


def growth_rate(law, a, r_i, r_j, temperature, params=None):
    """``du/dt`` (m^n/s) of ``u = a^n`` at neck ``a`` and pair temperature ``temperature``.

    0 at and beyond the law's cap (up to ``min(r_i, r_j)``); NaN for ``a`` outside ``[0, min(r_i, r_j)]``,
    a temperature <= 0 or parameters out of their domain.
    """
    law = kinetic_law(law)
    params = law_params(law, params)
    a, r_i, r_j, temperature = as_float_arrays(a, r_i, r_j, temperature)
    valid = (_valid_neck(a, r_i, r_j) & jnp.isfinite(temperature) & (temperature > 0)
             & _params_valid(law, params))
    safe = jnp.where(valid, a, 0.0)
    return jnp.where(valid, _rate(law, safe, r_i, r_j, jnp.where(valid, temperature, 1.0), params), jnp.nan)


def _rate(law, a, r_i, r_j, temperature, params):
    below = a < law.cap(r_i, r_j, params)
    shape = law.shape(jnp.where(below, a, 0.0), r_i, r_j, params)
    return jnp.where(below, shape * law.speed(temperature, params), 0.0)


# --------------------------------------------------------------------------
# growth along a temperature history


class GrowthStatus(enum.IntEnum):
    """Per-pair result code of :func:`growth_status`."""

    OK = 0
    """The neck grew (or stayed) below its cap."""
    AT_CAP = 1
    """The neck reached its cap (equilibrium neck or ``max_neck_ratio min(r)``) and stopped there."""
    INVALID_INPUT = 2
    """A radius, temperature, duration or parameter is out of its domain, or ``a0`` is outside
    ``[0, min(r)]``: the neck is NaN."""


def grow_neck(law, a0, r_i, r_j, temperatures, durations, params=None, *, quadrature_nodes: int = 8,
              newton_iterations: int = 4):
    """Neck radius after each interval of a piecewise-constant temperature history.

    Args:
      law: a :class:`KineticLaw` or a key of :data:`KINETIC_LAWS`.
      a0: initial neck radius, ``0 <= a0 <= min(r_i, r_j)`` (m); 0 is a point contact.
      r_i, r_j: sphere radii, > 0 (m).
      temperatures: ``[n_intervals, ...]`` pair temperature during each interval, > 0 (K);
        the trailing shape broadcasts with the pairs.
      durations: ``[n_intervals]`` interval lengths, >= 0 (s).
      params: overrides of ``law.default_params`` (arrays allowed; differentiable).
      quadrature_nodes, newton_iterations: Gauss-Legendre nodes of the elapsed-time integral and
        Newton steps of its inversion, for laws whose shape depends on ``a`` (static; module docstring).

    Returns:
      ``[n_intervals, ...]`` neck radius at the end of each interval (m); NaN for invalid
      input (:func:`growth_status`).

    Raises:
      ValueError: for concrete invalid input, naming the argument.
    """
    law = kinetic_law(law)
    params = law_params(law, params)
    for name, value in (("quadrature_nodes", quadrature_nodes), ("newton_iterations", newton_iterations)):
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1; got {value!r}")
    if all_concrete(a0, r_i, r_j, temperatures, durations, *params.values()):
        validate_growth_inputs(law, a0, r_i, r_j, temperatures, durations, params)
    return _grow_neck_compiled(_ByIdentity(law), a0, r_i, r_j, temperatures, durations, params,
                               quadrature_nodes=quadrature_nodes, newton_iterations=newton_iterations)


class _ByIdentity:
    """A static jit argument hashed by identity (a law holds dicts, which do not hash)."""

    def __init__(self, value):
        self.value = value

    def __hash__(self):
        return id(self.value)

    def __eq__(self, other):
        return isinstance(other, _ByIdentity) and other.value is self.value


@partial(jax.jit, static_argnums=0, static_argnames=("quadrature_nodes", "newton_iterations"))
def _grow_neck_compiled(law, a0, r_i, r_j, temperatures, durations, params, *, quadrature_nodes, newton_iterations):
    return _grow_neck(law.value, a0, r_i, r_j, temperatures, durations, params, quadrature_nodes=quadrature_nodes,
                      newton_iterations=newton_iterations)


def _grow_neck(law, a0, r_i, r_j, temperatures, durations, params, *, quadrature_nodes=8, newton_iterations=4):
    temperatures = jnp.asarray(temperatures)
    durations = jnp.asarray(durations)
    dtype = jnp.result_type(a0, r_i, r_j, temperatures, durations, float)
    a0, r_i, r_j = (jnp.asarray(v, dtype) for v in (a0, r_i, r_j))
    temperatures, durations = temperatures.astype(dtype), durations.astype(dtype)
    params = {k: jnp.asarray(v, dtype) for k, v in params.items()}
    pair_shape = jnp.broadcast_shapes(a0.shape, r_i.shape, r_j.shape, temperatures.shape[1:],
                                      *(v.shape for v in params.values()))
    a0, r_i, r_j = (jnp.broadcast_to(v, pair_shape) for v in (a0, r_i, r_j))
    # one temperature row per interval, one column per pair, before any masking by pair
    temperatures = jnp.broadcast_to(temperatures.reshape(temperatures.shape + (1,) * (len(pair_shape)
                                                                                    - temperatures.ndim + 1)),
                                    (durations.shape[0], *pair_shape))
    params = {k: jnp.broadcast_to(v, pair_shape) for k, v in params.items()}
    valid = _valid_growth(law, a0, r_i, r_j, temperatures, durations, params)
    # invalid pairs run a harmless problem and are NaN afterwards (zero gradient there)
    r_i_s = jnp.where(valid, r_i, 1.0)
    r_j_s = jnp.where(valid, r_j, 1.0)
    a0_s = jnp.where(valid, jnp.minimum(a0, jnp.minimum(r_i_s, r_j_s)), 0.0)
    temperatures_s = jnp.where(valid, temperatures, 1.0)
    params_s = {k: jnp.where(valid, v, law.default_params[k]) for k, v in params.items()}
    n = law.exponent(params_s)
    if isinstance(n, float) and n.is_integer():
        n = int(n)  # s ** (n - 1) by multiplications, not exp(log)
    # lengths in units of the smaller radius: u = (a / L)^n stays in [0, 1], where a^n in m^n would underflow
    # float32 (a^6 < 1e-38 for necks below 0.5 um)
    length = jnp.minimum(r_i_s, r_j_s)
    inverse_power = safe_power(1.0 / length, 0.5 * n)  # (1/L)^n as a square: no overflow for small L
    a_cap = jnp.minimum(law.cap(r_i_s, r_j_s, params_s), length)
    u_cap = safe_power(a_cap / length, n)
    nodes, weights = (jnp.asarray(v, dtype) for v in np.polynomial.legendre.leggauss(quadrature_nodes))
    node_params = {k: v[..., None] for k, v in params_s.items()}  # per-pair parameters against the node axis

    def neck(u):  # the scaled neck a / L
        if isinstance(n, int) and n == 6:  # sqrt and cbrt, several times faster than a general power
            positive = u > 0  # (double where: NaN-free at 0)
            return jnp.where(positive, jnp.cbrt(jnp.sqrt(jnp.where(positive, u, 1.0))), 0.0)
        return safe_power(u, 1.0 / n)

    def shape(x):  # du/dtau in scaled units, tau the reduced time speed(T) t / L^n
        return law.shape(x * length, r_i_s, r_j_s, params_s)

    def elapsed(x_start, x_end):
        # the scaled reduced time to grow from x_start to x_end: int n y^(n-1) / shape(L y) dy (smooth in y)
        half, mid = 0.5 * (x_end - x_start), 0.5 * (x_end + x_start)
        y = mid[..., None] + half[..., None] * nodes
        integrand = n * y ** (n - 1) / law.shape(y * length[..., None], r_i_s[..., None], r_j_s[..., None],
                                                 node_params)
        return half * jnp.sum(weights * integrand, axis=-1)

    def interval(u, step):
        temperature, dt = step
        reduced_time = law.speed(temperature, params_s) * dt * inverse_power * inverse_power
        x_start = neck(u)
        u_end = jnp.minimum(u + shape(x_start) * reduced_time, u_cap)
        if law.shape_depends_on_neck:
            # exact for a constant temperature, up to the quadrature: solve elapsed(x_start, x_end) = reduced
            # time for u_end = x_end^n by Newton in u_end (d elapsed / d u_end = 1 / shape), from explicit
            # Euler; elapsed is convex in u_end while the shape falls, concave while it rises, and the clip
            # keeps the iterates in [u, u_cap]
            for _ in range(newton_iterations):
                x_end = neck(u_end)
                residual = elapsed(x_start, x_end) - reduced_time
                u_end = jnp.clip(u_end - residual * shape(x_end), u, u_cap)
        return u_end, neck(u_end) * length

    u0 = safe_power(a0_s / length, n)
    _, history = jax.lax.scan(interval, u0, (temperatures_s, durations))
    # a neck that starts above its cap stays where it is
    history = jnp.where(a0_s >= a_cap, a0_s, history)
    return jnp.where(valid, history, jnp.nan)


def growth_status(law, a, r_i, r_j, temperatures, durations, params=None):
    """Per-pair :class:`GrowthStatus` (int32) of necks ``a`` returned by :func:`grow_neck`, under ``jit``.

    ``temperatures`` and ``durations`` are the history the necks grew along.
    """
    law = kinetic_law(law)
    params = law_params(law, params)
    a, r_i, r_j = as_float_arrays(a, r_i, r_j)
    temperatures, durations = jnp.asarray(temperatures), jnp.asarray(durations)
    valid = _valid_growth(law, a, r_i, r_j, temperatures, durations, params) & jnp.isfinite(a)
    cap = jnp.minimum(law.cap(r_i, r_j, params), jnp.minimum(r_i, r_j))
    at_cap = a >= cap * (1.0 - 8.0 * jnp.finfo(a.dtype).eps)
    return jnp.where(~valid, GrowthStatus.INVALID_INPUT,
                     jnp.where(at_cap, GrowthStatus.AT_CAP, GrowthStatus.OK)).astype(jnp.int32)


def _valid_growth(law, a0, r_i, r_j, temperatures, durations, params):
    ok = _valid_neck(a0, r_i, r_j)
    ok = ok & jnp.all(jnp.isfinite(temperatures) & (temperatures > 0), axis=0)
    ok = ok & jnp.all(jnp.isfinite(durations) & (durations >= 0))
    return ok & _params_valid(law, params)


def _params_valid(law, params):
    ok = law_params_valid(law, params, per_entry=True)
    if "dihedral_angle" in params:
        ok = ok & (jnp.asarray(params["dihedral_angle"]) <= 180.0)
    return ok


def validate_growth_inputs(law, a0, r_i, r_j, temperatures, durations, params=None):
    """Raise ``ValueError`` naming the argument unless :func:`grow_neck` can grow these necks.

    Radii finite and > 0; ``0 <= a0 <= min(r_i, r_j)``; temperatures finite and
    > 0 K; durations finite and >= 0 s; the law's parameters finite and > 0
    (activation energies >= 0, a size exponent any finite value, a dihedral
    angle in (0, 180] degrees, an exponent > 0).
    """
    law = kinetic_law(law)
    params = law_params(law, params)
    validate_neck_overlap_inputs(a0, r_i, r_j, names=("a0", "r_i", "r_j"))
    (temperatures,) = concrete_arrays("validate_growth_inputs", temperatures)
    require_positive("temperatures (K)", temperatures)
    (durations,) = concrete_arrays("validate_growth_inputs", durations)
    if durations.ndim != 1:
        raise ValueError(f"durations must be one-dimensional (one per interval); got shape {durations.shape}")
    if temperatures.ndim == 0 or temperatures.shape[0] != durations.shape[0]:
        raise ValueError(f"temperatures must have one row per interval ({durations.shape[0]} durations); "
                         f"got shape {temperatures.shape}")
    require_positive("durations (s)", durations, allow_zero=True)
    require_law_params("validate_growth_inputs", law, params,
                       lambda name: f"params[{name!r}] of kinetic law {law.name!r} ({law.units[name]})")
    if "dihedral_angle" in params:
        angle = np.asarray(params["dihedral_angle"], dtype=np.float64)
        fail_where(np.atleast_1d(angle) > 180.0, lambda i: f"params['dihedral_angle'] must be in (0, 180] degrees; "
                                                          f"got {float(np.atleast_1d(angle)[i])!r} at index {i}")


# --------------------------------------------------------------------------
# temperature histories


def piecewise_history(step_ends, step_temperatures, output_times):
    """A piecewise-constant history split at the output times: ``(durations, temperatures, output_index)``.

    Args:
      step_ends: increasing end times of the temperature steps (s); the first starts at t = 0.
      step_temperatures: temperature held during each step (K), ``[steps, ...]``.
      output_times: times at which the neck is wanted (s), within ``(0, step_ends[-1]]``.

    Returns:
      ``durations [n]``, ``temperatures [n, ...]`` and ``output_index [len(output_times)]``: the
      neck of :func:`grow_neck` at ``output_times[k]`` is row ``output_index[k]`` of its result.
    """
    step_ends = np.asarray(step_ends, dtype=np.float64)
    output_times = np.asarray(output_times, dtype=np.float64)
    if np.any(np.diff(step_ends) <= 0) or step_ends[0] <= 0:
        raise ValueError("step_ends must be positive and strictly increasing")
    if np.any(output_times <= 0) or np.any(output_times > step_ends[-1] * (1 + 1e-12)):
        raise ValueError(f"output_times must lie in (0, {step_ends[-1]!r}] s; got {output_times.tolist()}")
    edges = np.unique(np.concatenate([step_ends, output_times]))
    edges = edges[edges <= step_ends[-1] * (1 + 1e-12)]
    durations = np.diff(np.concatenate([[0.0], edges]))
    step_of = np.searchsorted(step_ends, edges - 0.5 * durations)  # the step each interval's middle is in
    temperatures = np.asarray(step_temperatures)[step_of]
    output_index = np.searchsorted(edges, output_times)
    return durations, temperatures, output_index


def preheating_history(output_times, *, t_end=9.5, temperature_start=845.0, temperature_end=1273.0, steps=25):
    """The PBF-EB preheating ramp of Rizza & Galati (2024), Eq. 6, as a history for :func:`grow_neck`.

    ``steps`` equal steps of ``t_end / steps`` (0.38 s) from ``temperature_start``
    to ``temperature_end`` (17.12 K each), with the erratum of Eq. 6 (the step
    count belongs inside its ``int()``). Each step is held at the temperature it
    ends at, ``T = 845 K + ceil(t / 0.38 s) 17.12 K``: the reading that
    reproduces their Table 1 (879 K at 0.5 s; :func:`sintercond.laws.tortuosity.preheating_temperature`
    with ``at_step_end=True``); the other reading holds each step 17.12 K lower.

    Returns:
      ``(durations, temperatures, output_index)`` of :func:`piecewise_history`.
    """
    k = np.arange(1, steps + 1)
    step_ends = k * (t_end / steps)
    step_temperatures = temperature_start + k * (temperature_end - temperature_start) / steps
    return piecewise_history(step_ends, step_temperatures, output_times)


def small_neck_grain_boundary(t, r_i, r_j, temperature, params=None):
    """Closed-form small-neck limit of isothermal grain-boundary growth, ``a(t)`` (m).

    ``a^6 = 192 r*^2 (A/T) exp(-Q/(R T)) (1 - cos(psi/2)) t``: the
    grain-boundary rate at ``a -> 0`` (module docstring), where ``a / H'(a) =
    r*`` and the sintering force is ``4 pi gamma_s r* (1 - cos(psi/2))``.
    """
    params = law_params("grain_boundary", params)
    t, r_i, r_j, temperature = as_float_arrays(t, r_i, r_j, temperature)
    r_star = _equivalent_radius(r_i, r_j)
    psi_half = 0.5 * jnp.deg2rad(params["dihedral_angle"])
    rate = (192.0 * r_star**2 * params["A"] / temperature * _arrhenius(temperature, params["activation_energy"])
            * (1.0 - jnp.cos(psi_half)))
    return safe_power(rate * t, 1.0 / 6.0)


__all__ = [
    "BOLTZMANN", "GAS_CONSTANT", "GrowthStatus", "KINETIC_LAWS", "KineticLaw", "grain_boundary_a", "grow_neck",
    "growth_rate", "growth_status", "kinetic_law", "law_params", "neck_overlap", "neck_overlap_slope",
    "neck_overlap_status", "pair_temperature", "piecewise_history", "preheating_history",
    "small_neck_grain_boundary", "validate_growth_inputs", "validate_neck_overlap_inputs",
]

