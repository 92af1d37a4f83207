"""External heat, convection and radiation of particles (Quintana-Ruiz & Campello 2020, Sect. 3).

Pure functions of the particle state returning heat powers in W (positive
into the particle), to be summed into ``C_i dT_i/dt`` next to conduction
(their Eq. 28). SI units: m, K, W.
"""

from __future__ import annotations

import jax.numpy as jnp

from sintercond._numerics import as_float_arrays

STEFAN_BOLTZMANN = 5.670367e-8
"""W/(m^2 K^4), the value Quintana-Ruiz & Campello use (Eq. 41)."""


def nozzle_power(radius, depth, intensity, max_depth, absorptance=1.0):
    """Nozzle heating with linear attenuation, ``a I0 pi r^2 (1 - z/d_max)`` (Eqs. 29-30).

    Args:
      radius: particle radius (m).
      depth: depth ``z`` below the striking position along the nozzle's path (m);
        particles outside ``0 <= z <= d_max`` receive nothing.
      intensity: ``I0``, power per unit area of the nozzle's cross-section (W/m^2).
      max_depth: ``d_max``, the heating reach (m).
      absorptance: ``a`` in [0, 1].
    """
    radius, depth, intensity, max_depth, absorptance = as_float_arrays(radius, depth, intensity, max_depth, absorptance)
    reached = (depth >= 0) & (depth <= max_depth)
    return jnp.where(reached, absorptance * intensity * jnp.pi * radius**2 * (1.0 - depth / max_depth), 0.0)


def laser_power(radius, depth, intensity, attenuation, absorptance=1.0):
    """Laser heating with Lambert-Beer attenuation, ``a I0 pi r^2 exp(-mu z)`` (Eqs. 29, 31).

    Args:
      radius: particle radius (m).
      depth: depth ``z >= 0`` along the beam below its striking position (m); ``z < 0`` receives nothing.
      intensity: ``I0`` (W/m^2).
      attenuation: ``mu`` (1/m).
      absorptance: ``a`` in [0, 1].
    """
    radius, depth, intensity, attenuation, absorptance = as_float_arrays(radius, depth, intensity, attenuation,
                                                                          absorptance)
    return jnp.where(depth >= 0, absorptance * intensity * jnp.pi * radius**2 * jnp.exp(-attenuation * depth), 0.0)


def beam_depth(centres, radii, spot_xy, spot_radius, surface_z):
    """Depth of each particle below a vertical beam's striking position, or -1 outside the beam.

    A particle is in the beam when its centre lies within ``spot_radius + r``
    of the beam axis (laterally); its depth is ``surface_z - (z + r)``, the
    distance from the surface to the particle's top, clipped at 0.
    """
    centres = jnp.asarray(centres)
    lateral = jnp.linalg.norm(centres[:, :2] - jnp.asarray(spot_xy), axis=1)
    inside = lateral <= spot_radius + radii
    return jnp.where(inside, jnp.maximum(surface_z - (centres[:, 2] + radii), 0.0), -1.0)


def beam_position(t, waypoints, speed):
    """Position (x, y) at time ``t`` of a beam moving at ``speed`` along a polyline of ``waypoints`` ``[k, 2]``.

    The position stops at the last waypoint (whether the beam still heats there: :func:`beam_switch`).
    """
    waypoints = jnp.asarray(waypoints)
    segments = jnp.linalg.norm(jnp.diff(waypoints, axis=0), axis=1)
    arc = jnp.concatenate([jnp.zeros(1, segments.dtype), jnp.cumsum(segments)])
    s = jnp.clip(speed * t, 0.0, arc[-1])
    return jnp.stack([jnp.interp(s, arc, waypoints[:, 0]), jnp.interp(s, arc, waypoints[:, 1])])


def beam_switch(t, waypoints, speed, segments_on=None, after_path=0.0):
    """Whether a beam moving along ``waypoints`` ``[k, 2]`` at ``speed`` heats at time ``t``: 1 or 0.

    On along the segments whose entry of ``segments_on`` ``[k - 1]`` is 1 (None: every segment; 0 marks a
    jump between hatch lines), off before ``t = 0``; once the path is done, ``after_path`` (0: off, 1: the
    beam stays on at the last waypoint). A path of one waypoint (or of coincident ones) is a stationary spot, on
    from ``t = 0`` whatever ``after_path``.
    """
    waypoints = jnp.asarray(waypoints)
    s = speed * t
    if waypoints.shape[0] == 1:  # a stationary spot: on from t = 0
        return jnp.where(s < 0, 0.0, 1.0).astype(waypoints.dtype)
    segments = jnp.linalg.norm(jnp.diff(waypoints, axis=0), axis=1)
    arc = jnp.concatenate([jnp.zeros(1, segments.dtype), jnp.cumsum(segments)])
    on = jnp.ones((), segments.dtype)
    if segments_on is not None:
        index = jnp.clip(jnp.searchsorted(arc, s, side="right") - 1, 0, segments.shape[0] - 1)
        on = jnp.asarray(segments_on, segments.dtype)[index]
    # a path of coincident waypoints is a stationary spot too: on from t = 0
    done = (s > arc[-1]) & (arc[-1] > 0)
    return jnp.where(s < 0, 0.0, jnp.where(done, jnp.asarray(after_path, segments.dtype), on))


def whitaker_nusselt(reynolds, prandtl, viscosity_ratio=1.0):
    """Whitaker's correlation for a sphere, Eq. 39: ``2 + (0.4 Re^1/2 + 0.06 Re^2/3) Pr^0.4 (mu/mu_s)^0.25``."""
    reynolds, prandtl, viscosity_ratio = as_float_arrays(reynolds, prandtl, viscosity_ratio)
    return 2.0 + (0.4 * jnp.sqrt(reynolds) + 0.06 * reynolds ** (2.0 / 3.0)) * prandtl**0.4 * viscosity_ratio**0.25


def convection_power(radius, temperature, environment_temperature, environment_conductivity, nusselt=2.0):
    """Newton cooling ``h (T_E - T) 4 pi r^2`` with ``h = Nu k_E / (2r)`` (Eqs. 37-38; ``Nu = 2``: ``h = k_E/r``)."""
    radius, temperature, environment_temperature, environment_conductivity, nusselt = as_float_arrays(
        radius, temperature, environment_temperature, environment_conductivity, nusselt)
    h = nusselt * environment_conductivity / (2.0 * radius)
    return h * (environment_temperature - temperature) * 4.0 * jnp.pi * radius**2


def radiation_power(radius, temperature, environment_temperature, emissivity):
    """Stefan-Boltzmann exchange ``eps B (T_E^4 - T^4) 4 pi r^2`` (Eq. 41)."""
    radius, temperature, environment_temperature, emissivity = as_float_arrays(
        radius, temperature, environment_temperature, emissivity)
    return emissivity * STEFAN_BOLTZMANN * (environment_temperature**4 - temperature**4) * 4.0 * jnp.pi * radius**2
