"""Plane walls: one type for heat now and contact forces next, entering pair laws as a neighbour of infinite radius.

Quintana-Ruiz & Campello (2020), Remark 1: a rigid wall is a body of infinite
radius and mass. For the conduction laws that means the limit ``r_j -> inf``
of every neck model and of every law's wall half, written out in closed form
here (a sphere of 1000 particle radii, as before, is off by ~1e-3):

============================  ===========================================================
neck model                    sphere ``r`` cutting a plane by ``h`` (the penetration)
============================  ===========================================================
``coble``                     ``a = sqrt(2 r* h)`` with ``r* -> 2 r``: ``a = 2 sqrt(r h)``
``hertz``                     ``r* -> r``: ``a = sqrt(r h)`` (MECHANICS.md: area ``pi r delta``)
``intersection``              the circle the plane cuts: ``a^2 = h (2 r - h)``
``volume_conserving``         Rojek Eq. 27 with one cap (the plane's cap vanishes):
                              ``a^2 = r^2 - s^2``, ``s = ((r - 3h) + sqrt((3r - h)(3r - 9h))) / 4``
                              (evaluated as ``r - s = 12 r h / (3r + 3h + sqrt(..))``),
                              defined for ``h <= r/3`` (where ``a = r``)
============================  ===========================================================

The volume-conserving form: with ``s = sqrt(r^2 - a^2)`` the one-cap residual
``F = a^2 (r + 2s) / (3 (r + s)^2) - h`` (:mod:`sintercond.laws.neck`) vanishes iff
``2 s^2 + (3h - r) s + 3hr - r^2 = 0``, whose larger root is the one above
(``s = r`` at ``h = 0``, ``s = 0`` at ``h = r/3``).

Wall halves of the laws (the wall's conductivity ``kappa_wall``, by default
the particle's): Rojek-type laws ``s kappa_wall pi a`` (the half does not
depend on its radius); the fitted law's half ``kappa pi r f(a/r) -> 4 kappa a``
(an isothermal disc on a half-space); the conductivity law (Eqs. 32-35)
``k pi a^2 / d`` with ``k -> kappa_wall`` and ``d`` the centre-to-wall
distance ``r - h`` (Eq. 35 with ``d -> inf`` would give nothing; MECHANICS.md
reads Example 5.1 this way); Feng's 2-D law: a half-plane's spreading
resistance diverges, so the wall half is taken as isothermal (only the
particle's half conducts).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from sintercond._validation import shown
from sintercond._numerics import as_float_arrays, safe_sqrt
from sintercond.laws.conductance import (_feng_half_conductance, _merge_params, _resolve_law, _resolve_neck_model,
                                         fitted_half_conductance_ratio, series_conductance)

WALL_MODES = ("held", "conducting", "insulated")


@dataclasses.dataclass(frozen=True)
class PlaneWall:
    """A plane wall (SI units).

    Attributes:
      point: a point of the plane ``[3]`` (m).
      normal: unit normal ``[3]`` pointing into the packing.
      mode: ``"held"`` (touching particles held at ``temperature``),
        ``"conducting"`` (they exchange heat with the wall at ``temperature``
        through the conduction law) or ``"insulated"``.
      temperature: the wall's temperature (K), for held and conducting walls.
      velocity: ``[3]`` (m/s), for moving walls (mechanics).
    """

    point: tuple
    normal: tuple
    mode: str = "insulated"
    temperature: float | None = None
    velocity: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        normal = np.asarray(self.normal, np.float64)
        if self.mode not in WALL_MODES:
            raise ValueError(f"PlaneWall.mode must be one of {list(WALL_MODES)}; got {self.mode!r}")
        if normal.shape != (3,) or not np.isclose(np.linalg.norm(normal), 1.0, rtol=1e-12):
            raise ValueError(f"PlaneWall.normal must be a unit [3] vector; got {shown(self.normal)}")
        if self.mode != "insulated" and (self.temperature is None or not self.temperature > 0):
            raise ValueError(f"PlaneWall.temperature must be > 0 K for a {self.mode} wall; got {shown(self.temperature)}")

    def penetration(self, positions, radii):
        """How far each sphere cuts the plane, ``r - (x - p) . n`` (m; <= 0: not touching)."""
        positions = jnp.asarray(positions)
        return radii - (positions - jnp.asarray(self.point, positions.dtype)) @ jnp.asarray(self.normal,
                                                                                             positions.dtype)


def wall_neck_radius(neck_model, r, h):
    """Neck or contact radius ``a`` (m) of a sphere ``r`` cutting a plane by ``h`` (m): the ``r_j -> inf`` limit.

    0 (zero gradient) for ``h <= 0``; NaN beyond the model's domain
    (``h > r/3`` for the volume-conserving neck, ``h >= 2r`` for the
    intersection circle). See the module docstring for the forms.
    """
    r, h = as_float_arrays(r, h)
    contact = h > 0
    h_safe = jnp.where(contact, h, 0.0)
    if neck_model == "coble":
        a = 2.0 * safe_sqrt(r * h_safe)
    elif neck_model == "hertz":
        a = safe_sqrt(r * h_safe)
    elif neck_model == "intersection":
        a = jnp.where(h_safe < 2 * r, safe_sqrt(h_safe * (2.0 * r - h_safe)), jnp.nan)
    elif neck_model == "volume_conserving":
        beyond = h_safe > r / 3.0
        h_in = jnp.where(beyond, 0.0, h_safe)
        root = safe_sqrt((3.0 * r - h_in) * (3.0 * r - 9.0 * h_in))
        # r - s without cancellation: (3r + 3h)^2 - root^2 = 48 r h
        r_minus_s = 12.0 * r * h_in / (3.0 * r + 3.0 * h_in + root)
        a = jnp.where(beyond, jnp.nan, safe_sqrt(r_minus_s * (2.0 * r - r_minus_s)))
    else:
        raise ValueError(f"neck_model must be one of 'coble', 'hertz', 'intersection', 'volume_conserving'; "
                         f"got {neck_model!r}")
    return jnp.where(contact, a, 0.0)


def wall_conductance_from_neck(law, a, r, h, kappa, kappa_wall=None, params=None):
    """Conductance (W/K) between a particle and a plane wall through a neck of radius ``a`` (m).

    The particle's half of the pair law in series with the wall's half in
    the ``r_j -> inf`` limit (module docstring). ``h <= 0`` or ``a <= 0``
    gives 0 with zero gradient.
    """
    law = _resolve_law(law)
    params = _merge_params(law, params)
    kappa_wall = kappa if kappa_wall is None else kappa_wall
    a, r, h, kappa, kappa_wall = as_float_arrays(a, r, h, kappa, kappa_wall)
    contact = (h > 0) & (a > 0)
    a = jnp.where(contact, a, 0.5 * r)
    h = jnp.where(contact, h, 0.0)
    if law.name in ("rojek", "argento_bouvard", "batchelor_obrien"):
        k = law.from_neck(a, r, jnp.inf, h, kappa, kappa_wall, params)
    elif law.name == "fitted":
        c = jnp.stack([params["c1"], params["c2"], params["c3"], params["c4"]])
        particle = kappa * jnp.pi * r * fitted_half_conductance_ratio(a / r, c)
        k = series_conductance(particle, 4.0 * kappa_wall * a, params["contact_resistance"])
    elif law.name == "conductivity":
        k = kappa_wall * jnp.pi * a**2 / (r - h)
    elif law.name == "feng":
        particle = _feng_half_conductance(a, r, kappa, params["thickness"])
        k = particle / (1.0 + particle * params["contact_resistance"])  # an isothermal wall half in series
    else:
        raise ValueError(f"law {law.name!r} has no wall limit; give a plane-wall conductance for it")
    return jnp.where(contact, k, 0.0)


def wall_conductance(law, r, h, kappa, kappa_wall=None, params=None, neck_model=None):
    """Conductance (W/K) of spheres ``r`` cutting a plane wall by ``h`` (m) under ``law`` and its neck model."""
    law = _resolve_law(law)
    a = wall_neck_radius(_resolve_neck_model(law, neck_model), r, h)
    return wall_conductance_from_neck(law, a, r, h, kappa, kappa_wall, params)

