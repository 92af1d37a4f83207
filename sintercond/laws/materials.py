"""Temperature-dependent material properties, differentiable in temperature and parameters.

A :class:`Property` maps a temperature ``theta`` (K, any shape) to a value of
the same shape. Three kinds, so that conductivity, specific heat and
Young's modulus can each be given in whichever form is known:

* :class:`Constant` -- one value at every temperature;
* :class:`Law` -- a function ``fn(theta, **params)``, e.g. the softening of
  Eq. 42 (:func:`softened_modulus`);
* :class:`Table` -- piecewise-linear in a table of ``(T, value)``
  (:func:`tabulated`), e.g. Ti6Al4V's conductivity
  (:func:`ti6al4v_conductivity_property`).

All three are registered frozen dataclasses (the package's container style):
their numbers are pytree leaves, so ``jax.grad`` reaches them when a
property is passed through ``jit`` as part of the parameters; ``Law.fn`` and
``Table.extrapolate`` are static. :func:`as_property` turns a plain number
into a :class:`Constant`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import jax
import jax.numpy as jnp

from sintercond._numerics import as_float_arrays
from sintercond.state import pytree_dataclass


def softened_modulus(theta, E0, theta_star, rate=1.0, E_min=0.0):
    """Thermal softening of Young's modulus, Eq. 42 with a rate and a floor (erratum 6).

    ``E(theta) = max(E_min, E0 exp(min(0, rate (1 - theta/theta*))))``.
    Eq. 42 prints ``min(E0, E0 e^(1 - theta/theta*))`` and mentions a rate
    and a floor ``E_min`` without printing them; with ``rate = 1`` and
    ``E_min = 0`` this is the printed law. ``theta*`` stays the onset of
    softening for every rate; ``rate >= 0`` is expected (``rate = 0``: no
    softening). It feeds ``E*`` and, through ``G = E/(2(1 + nu))``, ``G*``.

    Differentiable everywhere in ``theta``, ``E0``, ``theta_star``, ``rate``
    and ``E_min`` except at the two kinks (``theta = theta*`` and where the
    floor is reached), where the gradient returned is the one-sided
    derivative from the colder side (unsoftened at ``theta*``, softening law
    at the floor). The exponent is clipped at 0 before ``exp`` (it never
    overflows, and the branch not taken never produces ``inf * 0``). The
    floor's gradient with respect to ``E_min`` is 1 where it binds, 0 elsewhere.

    Args:
      theta: temperature (K).
      E0: reference modulus below ``theta*`` (Pa).
      theta_star: onset of softening (K), > 0.
      rate: softening rate ``r`` (dimensionless).
      E_min: floor of the modulus (Pa).

    Returns:
      ``E(theta)`` (Pa), broadcast shape of the inputs.
    """
    theta, E0, theta_star, rate, E_min = as_float_arrays(theta, E0, theta_star, rate, E_min)
    exponent = rate * (1.0 - theta / theta_star)
    softened = E0 * jnp.exp(jnp.where(exponent < 0, exponent, 0.0))
    return jnp.where(softened >= E_min, softened, E_min)


def interpolate_table(theta, temperatures, values, extrapolate=False):
    """Piecewise-linear interpolation of ``values`` at ``temperatures`` (strictly increasing).

    Exact at the nodes and linear between them. Outside the table the value
    is clamped to the end values (``extrapolate=False``, zero derivative in
    ``theta`` there) or continued along the end segments
    (``extrapolate=True``). Differentiable in ``theta``, in ``values`` and in
    the node temperatures; at a node the derivative in ``theta`` is the
    slope of the segment to its right (the last segment's at the last node).

    Args:
      theta: temperatures to evaluate at (K), any shape.
      temperatures: ``[k]`` node temperatures, ``k >= 2``, increasing (K).
      values: ``[k]`` values at the nodes.
      extrapolate: continue linearly outside the table (static).

    Returns:
      Values, shape of ``theta``, in the dtype of ``theta`` (the table is cast
      to it) when ``theta`` is floating, else in the table's.
    """
    theta = jnp.asarray(theta)
    temperatures, values = as_float_arrays(temperatures, values)
    # the table follows the precision of theta (a float64 table serves a float32 run)
    dtype = theta.dtype if jnp.issubdtype(theta.dtype, jnp.floating) else values.dtype
    theta, temperatures, values = theta.astype(dtype), temperatures.astype(dtype), values.astype(dtype)
    if not extrapolate:
        theta = jnp.clip(theta, temperatures[0], temperatures[-1])
    segment = jnp.clip(jnp.searchsorted(temperatures, theta, side="right") - 1, 0, temperatures.shape[0] - 2)
    t_left, t_right = temperatures[segment], temperatures[segment + 1]
    v_left, v_right = values[segment], values[segment + 1]
    return v_left + (theta - t_left) * (v_right - v_left) / (t_right - t_left)


def _table_segments(temperatures, values, dtype):
    """Nodes, values, each segment's slope and the integral up to each node of a clamped table, in ``dtype``."""
    temperatures, values = as_float_arrays(temperatures, values)
    temperatures, values = temperatures.astype(dtype), values.astype(dtype)
    width = jnp.diff(temperatures)
    slope = jnp.diff(values) / width
    upto = jnp.concatenate([jnp.zeros(1, dtype), jnp.cumsum(0.5 * (values[1:] + values[:-1]) * width)])
    return temperatures, values, slope, upto


def integrate_table(theta, temperatures, values):
    """``int_{T_0}^{theta} f dT`` of the clamped piecewise-linear ``f`` of :func:`interpolate_table` (``extrapolate``
    False): exact, piecewise quadratic, continued along the end values outside (``f``'s unit times K).

    With ``f`` a specific heat (J/(kg K)) it is the specific enthalpy above the first node (J/kg): what
    :func:`sintercond.sim.thermal.enthalpy_update` keeps. Differentiable in ``theta`` and the table.
    """
    theta = jnp.asarray(theta)
    dtype = theta.dtype if jnp.issubdtype(theta.dtype, jnp.floating) else jnp.result_type(float)
    theta = theta.astype(dtype)
    temperatures, values, slope, upto = _table_segments(temperatures, values, dtype)
    inside = jnp.clip(theta, temperatures[0], temperatures[-1])
    k = jnp.clip(jnp.searchsorted(temperatures, inside, side="right") - 1, 0, temperatures.shape[0] - 2)
    x = inside - temperatures[k]
    return (upto[k] + values[k] * x + 0.5 * slope[k] * x * x + values[0] * jnp.minimum(theta - temperatures[0], 0.0)
            + values[-1] * jnp.maximum(theta - temperatures[-1], 0.0))


def invert_table_integral(integral, temperatures, values):
    """The ``theta`` whose :func:`integrate_table` is ``integral`` (``f > 0``, so it increases): on the node's
    segment the root of ``f_k x + (s_k / 2) x^2 = integral - I_k`` in its stable form
    ``x = 2 d / (f_k + sqrt(f_k^2 + 2 s_k d))`` (the square root is ``f`` at the root, > 0), linear outside."""
    integral = jnp.asarray(integral)
    dtype = integral.dtype if jnp.issubdtype(integral.dtype, jnp.floating) else jnp.result_type(float)
    integral = integral.astype(dtype)
    temperatures, values, slope, upto = _table_segments(temperatures, values, dtype)
    inside = jnp.clip(integral, upto[0], upto[-1])
    k = jnp.clip(jnp.searchsorted(upto, inside, side="right") - 1, 0, temperatures.shape[0] - 2)
    d = inside - upto[k]
    x = 2.0 * d / (values[k] + jnp.sqrt(jnp.maximum(values[k] ** 2 + 2.0 * slope[k] * d, 0.0)))
    return (temperatures[k] + x + jnp.minimum(integral - upto[0], 0.0) / values[0]
            + jnp.maximum(integral - upto[-1], 0.0) / values[-1])


@runtime_checkable
class Property(Protocol):
    """A material property as a function of temperature: ``prop(theta) -> value``."""

    def __call__(self, theta) -> jax.Array: ...


@pytree_dataclass
class Constant:
    """The same value at every temperature.

    Attributes:
      value: the value (any unit), a scalar.
    """

    value: Any

    def __call__(self, theta):
        value, theta = as_float_arrays(self.value, theta)
        return value


@pytree_dataclass
class Law:
    """A closed-form law ``fn(theta, **params)``.

    Attributes:
      fn: the law (static), e.g. :func:`softened_modulus`.
      params: its parameters, a dict of numbers (pytree leaves).
    """

    fn: Callable = dataclasses.field(metadata=dict(static=True))
    params: dict = dataclasses.field(default_factory=dict)

    def __call__(self, theta):
        return self.fn(theta, **self.params)


@pytree_dataclass
class Table:
    """Piecewise-linear in a table (:func:`interpolate_table`).

    Attributes:
      temperatures: ``[k]`` node temperatures, increasing (K).
      values: ``[k]`` values at the nodes.
      extrapolate: continue the end segments outside the table (static);
        ``False`` clamps to the end values.
    """

    temperatures: Any
    values: Any
    extrapolate: bool = dataclasses.field(default=False, metadata=dict(static=True))

    def __call__(self, theta):
        return interpolate_table(theta, self.temperatures, self.values, self.extrapolate)


def tabulated(temperatures, values, extrapolate=False) -> Table:
    """A :class:`Table` property; raises ``ValueError`` for a table that cannot be interpolated.

    Args:
      temperatures: ``[k]`` node temperatures, ``k >= 2``, strictly increasing (K).
      values: ``[k]`` values at the nodes.
      extrapolate: see :class:`Table`.
    """
    temperatures, values = jnp.asarray(temperatures), jnp.asarray(values)
    if temperatures.ndim != 1 or temperatures.shape != values.shape or temperatures.shape[0] < 2:
        raise ValueError(
            f"a table needs 1-D temperatures and values of one length >= 2; "
            f"got shapes {temperatures.shape} and {values.shape}")
    try:
        increasing = bool(jnp.all(jnp.diff(temperatures) > 0))
    except jax.errors.ConcretizationTypeError:  # traced: cannot check here
        increasing = True
    if not increasing:
        raise ValueError("table temperatures must be strictly increasing")
    return Table(temperatures, values, extrapolate)


def as_property(value) -> Property:
    """A :class:`Property` as it is, anything else (a number) as a :class:`Constant`."""
    return value if isinstance(value, Property) else Constant(value)


def ti6al4v_conductivity_property(extrapolate=False) -> Table:
    """Bulk Ti6Al4V thermal conductivity (W/(m K)) as a :class:`Table`.

    The table the package ships is Rizza & Galati (2024), Table 1
    (``sintercond/data/ti6al4v_conductivity_rizza2024.csv``, their source:
    Qi et al. 2007): lambda_0 from 11.52 at 879 K to 16.72 at 1273 K. Outside
    that range it is clamped (default) or extrapolated linearly; unlike
    :func:`sintercond.laws.tortuosity.ti6al4v_conductivity`, which returns NaN
    there. Neither is data below 879 K (room-temperature Ti6Al4V is about
    6.7 W/(m K); extrapolation gives ~3.8 at 293 K, clamping 11.5).
    """
    from sintercond.laws.tortuosity import ti6al4v_conductivity_table

    _, temperatures, conductivities = ti6al4v_conductivity_table()
    return tabulated(temperatures, conductivities, extrapolate)
