"""Rizza & Galati (2024) tortuosity model of a sintered powder's conductivity.

``lambda_pow = n / tau^2 * lambda_0`` (Eq. 1) with the tortuosity factor
``tau^2 = (S_ss / S_0) gamma n^(1 - phi)`` (Eq. 5) built from the geometry of
a representative volume: the relative density ``n = U_0s / U_0``, the fraction
``S_ss / S_0`` of the volume's faces occupied by solid, the neck constriction
``gamma = (D - 2x) / D`` of a pair (Eq. 4, ``x`` the neck radius, ``D`` the
larger diameter of the pair) and ``phi``, the largest coordination number in
the volume. :mod:`sintercond.laws.geometry` computes these inputs from a packing.
All functions are pure and differentiable (``phi`` is a real exponent, so it
can be fitted).
"""

from __future__ import annotations

import csv
import functools
import importlib.resources

import jax.numpy as jnp
import numpy as np

from sintercond._numerics import as_float_arrays


def gamma_factor(x, diameter):
    """Neck constriction ``gamma = (D - 2x) / D`` (Rizza & Galati 2024, Eq. 4).

    Args:
      x: neck radius (length), ``0 <= x < D/2``.
      diameter: the larger diameter ``D`` of the two particles (same length unit).
    """
    x, diameter = as_float_arrays(x, diameter)
    return (diameter - 2.0 * x) / diameter


def tortuosity_squared(sss_over_s0, gamma, n, phi):
    """Tortuosity factor ``tau^2 = (S_ss/S_0) gamma n^(1 - phi)`` (Rizza & Galati 2024, Eq. 5).

    Args:
      sss_over_s0: solid fraction of the volume's face area, in (0, 1].
      gamma: neck constriction (Eq. 4), in (0, 1].
      n: relative density ``U_0s / U_0``, in (0, 1].
      phi: coordination descriptor (the largest coordination number), >= 1.
    """
    sss_over_s0, gamma, n, phi = as_float_arrays(sss_over_s0, gamma, n, phi)
    return sss_over_s0 * gamma * n ** (1.0 - phi)


def powder_conductivity(n, tau2, lambda0):
    """Powder conductivity ``lambda_pow = n lambda_0 / tau^2`` (Rizza & Galati 2024, Eq. 1)."""
    n, tau2, lambda0 = as_float_arrays(n, tau2, lambda0)
    return n * lambda0 / tau2


STEP_EDGE = 1e-9
"""How close (in steps of the ramp) a time must come to an edge between two steps to count as on it."""


def preheating_temperature(t, t_start=0.0, t_end=9.5, temperature_start=845.0, temperature_end=1273.0, steps=25,
                           *, at_step_end=False):
    """Stepped preheating ramp of Rizza & Galati (2024), Eq. 6.

    ``T(t) = T_bp + int((t - t_bp) / (t_p - t_bp) * s) (T_p - T_bp) / s``: the
    temperature rises from ``T_bp`` to ``T_p`` in ``s`` equal steps. The paper
    prints the step count outside the ``int()``; as printed the bracket is
    below 1 until ``t_p`` and the ramp would be flat, so the ``s`` is read
    inside. Defaults: their values (845 K to 1273 K in 9.5 s, 25 steps).
    Time in s, temperature in K.

    With ``at_step_end=True`` the temperature reached at the end of the step
    containing ``t`` is returned: that is what their Table 1 lists (e.g. 879 K
    at 0.5 s, within 1 K). A time within ``STEP_EDGE`` of a step of an edge
    between steps counts as on it (``25 t / 9.5`` at ``t = 6.46`` s is
    ``17.000000000000004`` in floating point), so an edge reached by adding
    time steps takes the level it ends, not the next one.
    """
    t = jnp.asarray(t)
    fraction = jnp.clip((t - t_start) / (t_end - t_start), 0.0, 1.0)
    step = (jnp.ceil(fraction * steps - STEP_EDGE) if at_step_end
            else jnp.floor(fraction * steps + STEP_EDGE))
    return temperature_start + step * (temperature_end - temperature_start) / steps


@functools.cache
def ti6al4v_conductivity_table():
    """Rizza & Galati (2024) Table 1: ``(time s, temperature K, lambda_0 W/(m K))`` arrays."""
    with importlib.resources.files("sintercond.data").joinpath("ti6al4v_conductivity_rizza2024.csv").open() as f:
        rows = [row for row in csv.DictReader(line for line in f if not line.startswith("#"))]
    columns = ("time_s", "temperature_K", "lambda0_W_per_mK")
    return tuple(np.array([float(r[c]) for r in rows]) for c in columns)


def ti6al4v_conductivity(temperature):
    """Bulk Ti6Al4V conductivity (W/(m K)) at ``temperature`` (K), linear in Table 1 of Rizza & Galati.

    Defined on the table's range, 879-1273 K; NaN outside it (no extrapolation).
    """
    _, temps, values = ti6al4v_conductivity_table()
    temperature = jnp.asarray(temperature)
    inside = (temperature >= temps[0]) & (temperature <= temps[-1])
    return jnp.where(inside, jnp.interp(temperature, temps, values), jnp.nan)
