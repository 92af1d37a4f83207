"""The thermo-mechanical lift: contact forces and torques of a packing, the translation + rotation update, the step.

Quintana-Ruiz & Campello (2020), Sects. 2 and 4, with the readings of
``MECHANICS.md`` (cited as "erratum N"). The contact laws of one contact are
:mod:`sintercond.laws.forces`; this module lifts them to a jax-md Dense neighbour
table (``[n, m]``, padding ``n``) and to plane walls, and integrates the
motion. :mod:`sintercond.simulate` builds the coupled step from it
(``Physics(mechanics=Mechanics(...))``, the sub-spec :class:`Mechanics`).

Pairs
-----
The laws run on a half pair list (:class:`sintercond.contacts.pair_list.HalfPairs`,
``[capacity, 2]``, each pair ``i < j`` once, kept within
``r_i + r_j + skin``), built from the jax-md Dense list whenever that list
is rebuilt (MECHANICS.md, "Contacts and history"). The force on ``i`` is
added to ``i`` and subtracted from ``j`` (:func:`sintercond.contacts.pair_list.pair_exchange`),
so momentum is conserved by construction; the springs belong to the pair
(``[capacity, 3]``, the spring of ``i`` relative to ``j``) and follow it
through rebuilds and reallocations (:func:`remap_history`). The list is
sorted by ``(i, j)``, so the sums over it do not depend on when the list was
last rebuilt or on its capacity. The per-pair part (:func:`pair_loads`) is
separate from the sums so that the coupled step can evaluate long lists
block by block (:func:`sintercond.contacts.pair_list.map_pair_blocks`, on the CPU)
and sum once.

Walls (Remark 1)
----------------
A :class:`sintercond.laws.walls.PlaneWall` is the partner ``j`` of every particle
with infinite radius, mass and modulus: ``r* = r_i``, ``m* = m_i``,
``E* = E_i/(1 - nu_i^2)``, ``G* = G_i``, ``j* = I_i + m_i r_i^2``; its surface
velocity enters the relative velocity and its point moves with it
(``point + velocity t``). (LAMMPS' ``fix wall/gran`` gives the wall the
particle's material, ``E* = E/(2(1 - nu^2))``.) Wall springs are stored per
(wall, particle).

Integration (Eqs. 43-46)
------------------------
Forces, torques and heat powers at ``t`` from the same state, then
symplectic Euler: ``v(t+dt) = v + dt F/m``, ``x(t+dt) = x + dt v(t+dt)``,
``omega(t+dt) = omega + dt T/I`` with ``I = (2/5) m r^2`` (solid spheres).
Orientations are not tracked (no law here needs them).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from sintercond._validation import all_concrete, shown
from sintercond.laws import forces
from sintercond._deprecation import old_names
from sintercond._numerics import materialized
from sintercond.laws.materials import softened_modulus
from sintercond.contacts.pair_list import HalfPairs, remap_half_pairs
from sintercond.state import pytree_dataclass


@dataclasses.dataclass(frozen=True)
class Mechanics:
    """The thermo-mechanical sub-spec of :class:`sintercond.simulate.Physics` (static, hashable; no arrays).

    Which contact laws and loads the coupled step (Quintana-Ruiz & Campello
    2020, Eqs. 43-46) evaluates; its differentiable parameters are
    :class:`MechanicalParams` (``Params.mechanics``). ``Physics(mechanics=None)``
    is the thermal step alone: nothing of this is traced.

    Attributes:
      walls: :class:`sintercond.laws.walls.PlaneWall` s that push, rub and (mode
        ``"conducting"``) exchange heat at their fixed temperature: a tuple,
        each wall's ``point``, ``normal`` and ``velocity`` tuples of floats
        (:meth:`create` converts sequences). Static: the number of walls
        decides what is traced; wall temperatures and positions are not
        differentiable.
      gravity: ``(gx, gy, gz)`` acceleration (m/s^2), floats.
      friction: Mindlin stick-slip friction with a spring (Eqs. 7-14).
      rolling: rolling resistance (Eqs. 15-20).
      wall_friction, wall_rolling: with ``friction`` (``rolling``), whether
        the walls rub (resist rolling) too. False: frictionless walls
        (``mu_wall = 0``; without rolling resistance, ``mu_r_wall = 0``):
        their tangential (rolling) law, whose force would be exactly zero,
        is not evaluated and its springs are not stored. Without the
        pairs' law the flag says nothing (:meth:`create` sets it True, so
        that specs that mean the same compare equal).
      softening: Young's modulus from the temperature, Eq. 42 (erratum 6).
      damping_clamp: no tensile normal force (LAMMPS ``limit_damping``).
      shear: ``"paper"`` (Eq. 9) or ``"mindlin"`` effective shear modulus.
      slip_direction: ``"trial"`` or ``"velocity"`` (erratum 3).
      rolling_projection: roll on the tangential part of the relative spin only (erratum 5).
      force_dtype: ``None`` (the contact laws in the positions' dtype) or
        ``"float32"``: forces, torques and springs in float32 while
        positions, velocities and temperatures stay float64 (relative
        separations are formed in float64 first, so the overlap keeps its
        digits); tests/test_mechanics.py states the accuracy.
      quasi_static: no inertia, for sintering at the material's real modulus (needs
        ``Sintering(shrinkage="many_body")``): the particles move only at the neck updates, by the many-body
        balance of the sintering necks, whose step moves each pair by its neck's approach and so leaves the elastic
        overlaps, and the loads they carry, as they were (to first order: not where the balance pulls a pair
        apart, or a neck stops at its cap); the step is the thermal one, not the elastic one
        (:func:`sintercond.sim.terms.mechanics.quasi_static_advance`; docs/simulator.md). False: Newton's law,
        symplectic Euler at the elastic step (Eqs. 43-47).
    """

    walls: tuple = ()
    gravity: tuple = (0.0, 0.0, -9.81)
    friction: bool = False
    rolling: bool = False
    wall_friction: bool = True
    wall_rolling: bool = True
    softening: bool = False
    damping_clamp: bool = False
    shear: str = "paper"
    slip_direction: str = "trial"
    rolling_projection: bool = False
    force_dtype: str | None = None
    quasi_static: bool = False

    def __post_init__(self):
        from sintercond.laws.walls import PlaneWall

        if self.shear not in forces.SHEAR_CONVENTIONS:
            raise ValueError(f"Mechanics.shear must be one of {list(forces.SHEAR_CONVENTIONS)}; got {self.shear!r}")
        if self.slip_direction not in forces.SLIP_DIRECTIONS:
            raise ValueError(f"Mechanics.slip_direction must be one of {list(forces.SLIP_DIRECTIONS)}; "
                             f"got {self.slip_direction!r}")
        if self.force_dtype not in (None, "float32", "float64"):
            raise ValueError(f"Mechanics.force_dtype must be None, 'float32' or 'float64'; got {self.force_dtype!r}")
        for name in ("friction", "rolling", "wall_friction", "wall_rolling", "softening", "damping_clamp",
                     "rolling_projection", "quasi_static"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"Mechanics.{name} must be True or False; got {getattr(self, name)!r}")
        if not (isinstance(self.gravity, tuple) and len(self.gravity) == 3
                and all(isinstance(g, float) and math.isfinite(g) for g in self.gravity)):
            raise ValueError(f"Mechanics.gravity must be a tuple of 3 finite floats (m/s^2); got {self.gravity!r} "
                             "(Mechanics.create converts sequences)")
        if not isinstance(self.walls, tuple):
            raise ValueError(f"Mechanics.walls must be a tuple of PlaneWall; got {type(self.walls).__name__} "
                             "(Mechanics.create converts sequences)")
        for k, w in enumerate(self.walls):
            if not isinstance(w, PlaneWall):
                raise ValueError(f"Mechanics.walls[{k}] must be a PlaneWall; got {type(w).__name__}")
            if w.mode == "held":
                raise ValueError(f"Mechanics.walls[{k}]: mode 'held' is not supported with mechanics; use 'conducting'")
            if not all(isinstance(getattr(w, f), tuple) for f in ("point", "normal", "velocity")):
                raise ValueError(f"Mechanics.walls[{k}]: point, normal and velocity must be tuples of floats (the spec "
                                 "is hashed); Mechanics.create converts them")

    @classmethod
    def create(cls, walls=(), gravity=(0.0, 0.0, -9.81), *, friction=False, rolling=False, wall_friction=True,
               wall_rolling=True, **flags) -> Mechanics:
        """A normalised :class:`Mechanics`: walls and gravity as tuples of floats, NumPy booleans as bools, and
        ``wall_friction`` (``wall_rolling``) True where ``friction`` (``rolling``) is off, so that two specs that
        mean the same step compare equal and compile once. ``flags``: the other fields."""
        from sintercond.laws.walls import PlaneWall

        for name, value in (("friction", friction), ("rolling", rolling), ("wall_friction", wall_friction),
                            ("wall_rolling", wall_rolling)):  # bool("no") is True: friction="no" turned it on
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"Mechanics.{name} must be True or False; got {shown(value)}")
        try:
            gravity = tuple(float(g) for g in gravity)
        except (TypeError, ValueError):
            raise ValueError(f"Mechanics.gravity must be 3 numbers (m/s^2); got {gravity!r}") from None
        if len(gravity) != 3:
            raise ValueError(f"Mechanics.gravity must be 3 numbers (m/s^2); got {gravity!r}")
        walls = tuple(dataclasses.replace(w, point=tuple(map(float, w.point)), normal=tuple(map(float, w.normal)),
                                          velocity=tuple(map(float, w.velocity))) if isinstance(w, PlaneWall) else w
                      for w in walls)
        flags = {k: bool(v) if isinstance(v, np.bool_) else v for k, v in flags.items()}
        friction, rolling = bool(friction), bool(rolling)
        return cls(walls=walls, gravity=gravity, friction=friction, rolling=rolling,
                   wall_friction=bool(wall_friction) or not friction, wall_rolling=bool(wall_rolling) or not rolling,
                   **flags)


@pytree_dataclass
class MechanicalParams:
    """Differentiable parameters of the contact laws (SI units).

    Per-material entries (``E0``, ``nu``, ``theta_star``, ``rate``, ``E_min``)
    are scalars or ``[n_materials]`` indexed by the particles' material.

    Attributes:
      E0: Young's modulus below the softening onset (Pa).
      nu: Poisson ratio.
      xi_con: normal damping ratio (Eq. 6; 1: critical).
      xi_fric: tangential damping ratio (Eq. 11).
      xi_rol: rolling damping ratio (Eq. 18).
      mu: friction coefficient between particles (static = dynamic, Eq. 8).
      mu_r: rolling resistance coefficient between particles (Eq. 16).
      mu_wall, mu_r_wall: the same against walls (None: ``mu``, ``mu_r``).
      theta_star: onset of thermal softening (K), Eq. 42.
      rate: softening rate (erratum 6; 1 is the printed law).
      E_min: floor of the softened modulus (Pa).
    """

    E0: Any
    nu: Any
    xi_con: Any = 1.0
    xi_fric: Any = 1.0
    xi_rol: Any = 0.0
    mu: Any = 0.0
    mu_r: Any = 0.0
    mu_wall: Any = None
    mu_r_wall: Any = None
    theta_star: Any = 400.0
    rate: Any = 1.0
    E_min: Any = 0.0


PARAMETER_RANGES = {
    "E0": (1.0, 1e13, "Pa"),
    "nu": (0.0, 0.5, ""),
    "xi_con": (0.0, 10.0, ""),
    "xi_fric": (0.0, 10.0, ""),
    "xi_rol": (0.0, 10.0, ""),
    "mu": (0.0, 10.0, ""),
    "mu_r": (0.0, 10.0, ""),
    "mu_wall": (0.0, 10.0, ""),
    "mu_r_wall": (0.0, 10.0, ""),
    "theta_star": (1.0, 1e4, "K"),
    "rate": (0.0, 1e3, ""),
    "E_min": (0.0, 1e13, "Pa"),
}
"""``field -> (low, high, unit)``: the closed range of each :class:`MechanicalParams` field. One set of rules: the
Python API checks it (:func:`validate_mechanical_params`, called by :func:`sintercond.simulate.rollout` and
:func:`sintercond.rollout.advance`) and the scene keys that set these fields use the same ranges
(:mod:`sintercond.scene`)."""

PER_MATERIAL = ("E0", "nu", "theta_star", "rate", "E_min")
"""Fields that may be given per material (``[n_materials]``); the others are scalars."""


def validate_mechanical_params(params, n_materials=None, names=None) -> None:
    """Raise ``ValueError`` naming the field and its allowed range unless ``params`` can run.

    Every given field finite and within :data:`PARAMETER_RANGES`; per-material
    fields (:data:`PER_MATERIAL`) scalars or ``[n_materials]``, the rest
    scalars; and ``E_min <= E0`` per material (a floor above the unsoftened
    modulus makes every contact stiffer than the time step was sized for).

    Args:
      params: :class:`MechanicalParams`, or a mapping of its field names (e.g. a scene's values).
      n_materials: the number of materials (None: not checked).
      names: ``field -> name`` the messages use (default ``MechanicalParams.<field>``).
    """
    values = params if isinstance(params, dict) else {f.name: getattr(params, f.name)
                                                       for f in dataclasses.fields(MechanicalParams)}
    names = names or {}
    label = lambda field: names.get(field, f"MechanicalParams.{field}")  # noqa: E731
    arrays = {}
    for field, value in values.items():
        if value is None:
            continue
        low, high, unit = PARAMETER_RANGES[field]
        what = f"{label(field)} must be finite and in [{low:g}, {high:g}]" + (f" {unit}" if unit else "")
        try:
            v = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{what}; got {shown(value)}") from None
        allowed_shapes = [()] + ([(n_materials,)] if field in PER_MATERIAL and n_materials else [])
        if field in PER_MATERIAL and n_materials is None and v.ndim <= 1:
            allowed_shapes.append(v.shape)
        if v.shape not in allowed_shapes:
            per = f" or one per material ({n_materials},)" if field in PER_MATERIAL and n_materials else ""
            raise ValueError(f"{label(field)} must be a scalar{per}; got shape {v.shape}")
        bad = ~(np.isfinite(v) & (v >= low) & (v <= high))
        if bad.any():
            raise ValueError(f"{what}; got {shown(v[bad].ravel()[0])}" + ("" if v.ndim == 0 else
                                                                     f" at material {int(np.argwhere(bad)[0][0])}"))
        arrays[field] = v
    if "E0" in arrays and "E_min" in arrays:
        e0, e_min = np.broadcast_arrays(arrays["E0"], arrays["E_min"])
        above = e_min > e0
        if above.any():
            k = tuple(np.argwhere(above)[0])
            raise ValueError(f"{label('E_min')} ({float(e_min[k]):g} Pa) must not exceed {label('E0')} "
                             f"({float(e0[k]):g} Pa): the softened modulus would rise above the unsoftened one")


@pytree_dataclass
class MechanicalState:
    """Motion and contact history (SI units); fields of laws that are off are None (nothing traced).

    Attributes:
      velocity: ``[n, 3]`` (m/s).
      spin: ``[n, 3]`` angular velocities (rad/s).
      spring: ``[capacity, 3]`` tangential springs of the half pair list's
        pairs (m), the spring of ``i`` relative to ``j`` (``i < j``); None
        without friction. Springs are in the force dtype
        (``Mechanics.force_dtype``).
      rolling: ``[capacity, 3]`` rolling springs per pair (rad); None without rolling.
      wall_spring, wall_rolling: ``[n_walls, n, 3]`` the same against each wall.
      neck: ``[capacity]`` the sintered neck radius of each pair (m), with
        ``Physics.sintering`` (:mod:`sintercond.sim.neck_growth`); None without.
      neck_overlap: ``[capacity]`` its approach ``H(a)`` (m, Rojek et al.
        2022, Eqs. 23-27): the part of the pair's overlap the neck accounts
        for, which the elastic laws do not see; None without sintering.
    """

    velocity: Any
    spin: Any
    spring: Any = None
    rolling: Any = None
    wall_spring: Any = None
    wall_rolling: Any = None
    neck: Any = None
    neck_overlap: Any = None


def mechanical_state(spec, positions, contacts, velocity=None, spin=None) -> MechanicalState:
    """A :class:`MechanicalState` at rest (or with ``velocity``/``spin`` ``[n, 3]``), springs zero.

    Args:
      spec: the :class:`Mechanics` sub-spec (which springs exist).
      positions: ``[n, 3]`` (m), for shapes and dtype.
      contacts: the :class:`sintercond.state.DynamicContacts` of
        :func:`sintercond.simulate.dynamic_contacts` (or its
        :class:`sintercond.contacts.pair_list.HalfPairs`): the springs are laid on
        its half pair list.
    """
    for name, value in (("velocity", velocity), ("spin", spin)):
        if value is not None and np.shape(value) != np.shape(positions):  # [n, 2] or [3] broadcast in the step
            raise ValueError(f"mechanical_state: {name} must be [n, 3] like the positions {np.shape(positions)}; "
                             f"got shape {np.shape(value)}")
    half = getattr(contacts, "pairs", None) if not isinstance(contacts, HalfPairs) else contacts
    if not isinstance(half, HalfPairs):
        raise TypeError("mechanical_state needs the DynamicContacts of simulate.dynamic_contacts (the springs live on "
                        f"its half pair list, DynamicContacts.pairs); got {type(contacts).__name__}")
    positions = jnp.asarray(positions)
    n, w = positions.shape[0], len(spec.walls)
    zeros = jnp.zeros_like(positions)
    velocity = zeros if velocity is None else jnp.asarray(velocity, positions.dtype)
    spin = zeros if spin is None else jnp.asarray(spin, positions.dtype)
    fd = force_dtype(spec, positions.dtype)
    pair = jnp.zeros((half.capacity, 3), fd)
    wall = jnp.zeros((w, n, 3), fd)
    walls = wall_spec(spec)
    return MechanicalState(velocity, spin, pair if spec.friction else None, pair if spec.rolling else None,
                           wall if walls.friction else None, wall if walls.rolling else None)


def wall_spec(spec):
    """The laws the walls see: ``spec`` with friction (rolling) off where ``wall_friction`` (``wall_rolling``) is."""
    return dataclasses.replace(spec, friction=spec.friction and spec.wall_friction,
                               rolling=spec.rolling and spec.wall_rolling)


def wall_coefficients(params: MechanicalParams):
    """``(mu, mu_r)`` against the walls: ``mu_wall``/``mu_r_wall``, or the pairs' ``mu``/``mu_r`` where those are None."""
    return (params.mu if params.mu_wall is None else params.mu_wall,
            params.mu_r if params.mu_r_wall is None else params.mu_r_wall)


def check_wall_coefficients(spec, params: MechanicalParams):
    """Raise ``ValueError`` if a law that is off gets a concrete nonzero coefficient: friction (rolling) off between
    the particles with ``mu`` (``mu_r``) given, or frictionless walls (``wall_friction``/``wall_rolling`` False)
    with nonzero :func:`wall_coefficients`; traced values are not checked. A coefficient the step would ignore is
    a mistake in the call, not a choice."""
    for flag, name, value in (("friction", "mu", params.mu), ("rolling", "mu_r", params.mu_r)):
        if (not getattr(spec, flag) and not isinstance(value, jax.core.Tracer)
                and bool(np.any(np.asarray(value) != 0))):
            raise ValueError(f"Mechanics.{flag}=False leaves the law out of the step, but MechanicalParams.{name} is "
                             f"{value!r}; give {name} = 0 or turn the law on ({flag}=True)")
    mu_w, mu_r_w = wall_coefficients(params)
    for flag, on, name, value in (("wall_friction", spec.friction, "mu_wall", mu_w),
                                  ("wall_rolling", spec.rolling, "mu_r_wall", mu_r_w)):
        if (not (on and getattr(spec, flag)) and not isinstance(value, jax.core.Tracer)
                and bool(np.any(np.asarray(value) != 0))):
            law = flag if on else flag.removeprefix("wall_")
            raise ValueError(f"Mechanics.{law}=False makes the walls frictionless, but MechanicalParams.{name} "
                             f"(or its fallback) is {value!r}; it must be 0 there (or set {law}=True)")


COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False, "xla_cpu_prefer_vector_width": 512}
"""XLA options for compiling a mechanical step (``jax.jit(f, compiler_options=...)``, per executable).

On the CPU, XLA's newer fusion emitters turn the contact laws' many
elementwise fusions over the pairs into slower code than the classic
emitters, and LLVM's 512-bit vectors (a preference: CPUs without AVX-512
keep their widest) run the step a little faster than XLA's default of 256
(measured by benchmarks/coupled_step.py; docs/devlog/coupled_step.md, branch lawfuse). The fields belong to XLA's
DebugOptions and only the CPU compiler reads them (not checked on a GPU)."""


def compiler_options(physics):
    """:data:`COMPILER_OPTIONS` for a :class:`sintercond.simulate.Physics` with a mechanics sub-spec, else None."""
    return dict(COMPILER_OPTIONS) if physics.mechanics is not None else None


# --------------------------------------------------------------------------
# geometry


class PairGeometry(NamedTuple):
    """The pairs of a half pair list ``[c, 2]`` (``i < j``; padding ``(n, n)``).

    ``pairs``: the list (for :func:`sintercond.contacts.pair_list.pair_sum`); ``i``,
    ``j``: its ends, padding replaced by particle 0 (safe to gather);
    ``valid`` (a real pair); ``touching`` (overlap > 0); ``normal``
    ``[c, 3]`` unit vector from ``i`` to ``j`` (``e_z`` for padding);
    ``overlap`` (m, 0 where not touching).
    """

    pairs: Any
    i: Any
    j: Any
    valid: Any
    touching: Any
    normal: Any
    overlap: Any


def pair_geometry(positions, radii, pairs, gap=0.0) -> PairGeometry:
    """Overlaps ``delta = r_i + r_j - |x_j - x_i|`` (Eq. 4) and normals (Eq. 5) of every pair of a half list ``[c, 2]``.

    ``gap`` (static float): pairs whose surfaces are less than ``gap (r_i + r_j)`` apart count as touching, with
    their (negative) overlap: point contacts of a touching lattice, for sintering (0: overlapping pairs only).
    """
    valid = pairs[:, 0] < pairs[:, 1]
    i, j = jnp.where(valid, pairs[:, 0], 0), jnp.where(valid, pairs[:, 1], 0)
    delta = positions[j] - positions[i]
    distance_sq = jnp.sum(delta * delta, axis=-1)
    contact_range = (radii[i] + radii[j]) ** 2
    touching = valid & (distance_sq < (contact_range if not gap else contact_range * (1.0 + gap) ** 2))
    apart = valid & (distance_sq > 0)
    distance = jnp.sqrt(jnp.where(apart, distance_sq, contact_range))
    overlap = jnp.where(touching, radii[i] + radii[j] - distance, 0.0)
    e_z = jnp.zeros_like(delta).at[..., 2].set(1.0)
    normal = jnp.where(apart[..., None], delta / distance[..., None], e_z)
    return PairGeometry(pairs, i, j, valid, touching, normal, overlap)


def wall_penetration(walls, positions, radii, t):
    """``[n_walls, n]`` penetrations ``r - (x - p(t)) . n_w`` (m) of the walls at time ``t`` (``p(t) = p + v t``)."""
    dtype = positions.dtype
    return jnp.stack([radii - jnp.sum((positions - (jnp.asarray(w.point, dtype) + t * jnp.asarray(w.velocity, dtype)))
                                      * jnp.asarray(w.normal, dtype), axis=-1) for w in walls])


def particle_modulus(spec, params: MechanicalParams, temperature, material):
    """Young's modulus ``[n]`` (Pa) per particle: ``E0``, or the softened Eq. 42 (erratum 6) when ``spec.softening``."""
    pick = lambda x: jnp.atleast_1d(jnp.asarray(x))[material]  # noqa: E731
    e0 = pick(params.E0).astype(temperature.dtype)
    if not spec.softening:
        return e0
    return softened_modulus(temperature, e0, pick(params.theta_star), pick(params.rate), pick(params.E_min))


# --------------------------------------------------------------------------
# forces


@pytree_dataclass
class Body:
    """One side of a set of contacts as the contact laws see it (SI units; arrays over the contacts).

    A wall is a body of infinite radius and mass (:mod:`sintercond.laws.walls`) that does not spin.

    Attributes:
      radius: (m).
      mass: (kg).
      modulus: Young's modulus (Pa), softened or not.
      poisson: Poisson ratio.
      velocity: ``[..., 3]`` (m/s).
      spin: ``[..., 3]`` angular velocity (rad/s).
    """

    radius: Any
    mass: Any
    modulus: Any
    poisson: Any
    velocity: Any
    spin: Any


@pytree_dataclass
class Contact:
    """Contacts ``(i, j)`` as the contact laws see them (SI units; arrays over the contacts).

    Attributes:
      normal: ``[..., 3]`` unit normal from ``i`` to ``j``.
      overlap: ``delta = r_i + r_j - d`` (m).
      i, j: the two :class:`Body` s.
      arm_j: the lever arm of ``j`` (its radius; 0 for a wall, whose radius is ``inf``) (m).
    """

    normal: Any
    overlap: Any
    i: Body
    j: Body
    arm_j: Any


def _contact_laws(spec, params, dt, contact: Contact, spring, rolling, mu, mu_r):
    """Force on ``i``, torques on ``i`` and ``j`` and the new springs of ``contact`` (Eqs. 2-20).

    Normal Hertz with damping (Eqs. 2-6; ``spec.damping_clamp``: no
    tension), Mindlin friction with the spring (Eqs. 7-13) when
    ``spec.friction`` and its torques (Eq. 14, erratum 2), rolling
    resistance (Eqs. 15-20) when ``spec.rolling``.
    """
    normal, delta, arm_j = contact.normal, contact.overlap, contact.arm_j
    r_i, m_i, E_i, nu_i, v_i, omega_i = (contact.i.radius, contact.i.mass, contact.i.modulus, contact.i.poisson,
                                         contact.i.velocity, contact.i.spin)
    r_j, m_j, E_j, nu_j, v_j, omega_j = (contact.j.radius, contact.j.mass, contact.j.modulus, contact.j.poisson,
                                         contact.j.velocity, contact.j.spin)
    r_star = forces.effective_radius(r_i, r_j)
    m_star = forces.effective_mass(m_i, m_j)
    e_star = forces.effective_modulus(E_i, nu_i, E_j, nu_j)
    delta_dot, v_t = forces.relative_contact_velocity(v_i, v_j, omega_i, omega_j, normal, r_i, arm_j)
    # f_n, f_t and m_r each feed several [..., 3] outputs: computed once (materialized), XLA's CPU fusion
    # would evaluate their whole chains again in every output, per component (1.35x on the 1e5-sphere step)
    f_n = materialized(forces.hertz_normal_force(delta, delta_dot, r_star, m_star, e_star, params.xi_con,
                                                 no_tension=spec.damping_clamp))
    force = -f_n[..., None] * normal
    torque_i = torque_j = jnp.zeros_like(force)
    if spec.friction or spec.rolling:
        g_star = forces.effective_shear_modulus(E_i, nu_i, E_j, nu_j, spec.shear)
    if spec.friction:
        f_t, spring, _ = forces.mindlin_tangential_force(spring, v_t, normal, dt, delta, f_n, r_star, m_star, g_star,
                                                         params.xi_fric, mu, slip_direction=spec.slip_direction)
        f_t = materialized(f_t)
        force = force + f_t
        torque_i, torque_j = forces.friction_torque(f_t, normal, r_i, arm_j)
    if spec.rolling:
        j_star = forces.effective_rolling_inertia(m_i, r_i, m_j, r_j)
        m_r, rolling, _ = forces.rolling_resistance_torque(
            rolling, omega_i, omega_j, normal, dt, delta, f_n, r_star, j_star, g_star, params.xi_rol, mu_r,
            projection=spec.rolling_projection, slip_direction=spec.slip_direction)
        m_r = materialized(m_r)
        torque_i, torque_j = torque_i + m_r, torque_j - m_r
    return force, torque_i, torque_j, spring, rolling, f_n


class Loads(NamedTuple):
    """Forces and torques ``[n, 3]`` (N, N m) at ``t``, the springs to store, and the wall contacts' state."""

    force: Any
    torque: Any
    mechanics: MechanicalState
    wall_penetration: Any  # [n_walls, n] (m)
    wall_normal_force: Any  # [n_walls, n] (N)


def pair_loads(spec, params: MechanicalParams, geometry: PairGeometry, radii, mass, modulus, nu, velocity, spin,
               spring, rolling, dt, dtype):
    """Per pair: force on ``i``, torques on ``i`` and ``j`` (in ``dtype``), and the new springs."""
    params, dt, radii_f, mass_f, modulus, nu, v, omega, normal, overlap = in_force_dtype(
        spec, dtype, params, dt, radii, mass, modulus, nu, velocity, spin, geometry.normal, geometry.overlap)
    i, j = geometry.i, geometry.j
    # gathered in this order (the same program as before the laws took a Contact)
    r_i, r_j, m_i, m_j, e_i, nu_i, e_j, nu_j = (radii_f[i], radii_f[j], mass_f[i], mass_f[j], modulus[i], nu[i],
                                                modulus[j], nu[j])
    v_i, v_j, w_i, w_j = v[i], v[j], omega[i], omega[j]
    contact = Contact(normal, overlap, Body(r_i, m_i, e_i, nu_i, v_i, w_i), Body(r_j, m_j, e_j, nu_j, v_j, w_j),
                      arm_j=radii_f[j])
    f, t_i, t_j, spring, rolling, _ = _contact_laws(spec, params, dt, contact, spring, rolling, params.mu, params.mu_r)
    # summed in the positions' dtype: momentum conserved to its round-off whatever the force dtype
    return f.astype(dtype), t_i.astype(dtype), t_j.astype(dtype), spring, rolling


def body_loads(spec, params, positions, radii, mass, modulus, nu, state, t, dt, force, torque) -> Loads:
    """:class:`Loads` from the pair sums ``force``, ``torque`` ``[n, 3]``: the walls' and gravity's loads added."""
    dtype = positions.dtype
    fd = force_dtype(spec, dtype)
    params, dt, radii_f, mass_f, modulus, nu, v, omega = in_force_dtype(
        spec, dtype, params, dt, radii, mass, modulus, nu, state.velocity, state.spin)
    n = radii.shape[0]
    new = state
    h = wall_n = None
    if spec.walls:
        h = wall_penetration(spec.walls, positions, radii, t)  # in the positions' precision
        inward = jnp.stack([jnp.asarray(w.normal, fd) for w in spec.walls])[:, None, :]
        wall_v = jnp.stack([jnp.asarray(w.velocity, fd) for w in spec.walls])[:, None, :]
        inf = jnp.asarray(jnp.inf, fd)
        mu_w, mu_r_w = wall_coefficients(params)
        # the wall is j: the normal from the particle to the wall is -n_w
        shape = (len(spec.walls), n, 3)
        normal, overlap = jnp.broadcast_to(-inward, shape), h.astype(fd)
        wall = Body(inf, inf, inf, nu, jnp.broadcast_to(wall_v, shape), jnp.zeros_like(omega))
        contact = Contact(normal, overlap, Body(radii_f, mass_f, modulus, nu, v, omega), wall, jnp.zeros((), fd))
        f_w, t_w, _, wall_spring, wall_rolling, wall_n = _contact_laws(
            wall_spec(spec), params, dt, contact, state.wall_spring, state.wall_rolling, mu_w, mu_r_w)
        force = force + jnp.sum(f_w.astype(dtype), axis=0)
        torque = torque + jnp.sum(t_w.astype(dtype), axis=0)
        new = dataclasses.replace(new, wall_spring=wall_spring, wall_rolling=wall_rolling)
    force = force + mass[:, None] * jnp.asarray(spec.gravity, dtype)
    return Loads(force, torque, new, h, wall_n)


def force_dtype(spec, dtype):
    """The dtype the contact laws run in: ``spec.force_dtype``, or the positions' ``dtype`` if None."""
    return jnp.dtype(dtype if spec.force_dtype is None else spec.force_dtype)


def in_force_dtype(spec, dtype, *values):
    """``values`` (arrays, pytrees such as :class:`MechanicalParams`, or None) cast to :func:`force_dtype`."""
    fd = force_dtype(spec, dtype)
    return [jax.tree.map(lambda x: jnp.asarray(x).astype(fd), v) for v in values]


PAIR_HISTORY = ("spring", "rolling", "neck", "neck_overlap")
"""The fields of :class:`MechanicalState` that live on the half pair list (one row per pair)."""


def remap_history(state: MechanicalState, old_pairs, new_pairs) -> MechanicalState:
    """Carry the pair springs (and sintered necks) from the half list ``old_pairs`` to ``new_pairs`` by ``(i, j)``
    identity.

    :func:`sintercond.contacts.pair_list.remap_half_pairs`: a pair new to the list
    starts at zero; the lists may differ in capacity (a reallocation). Call
    it when the list is rebuilt (under the rebuild's ``lax.cond``).
    """
    fields = {f: remap_half_pairs(old_pairs, new_pairs, getattr(state, f))
              for f in PAIR_HISTORY if getattr(state, f) is not None}
    return dataclasses.replace(state, **fields)


def integrate(positions, state: MechanicalState, force, torque, mass, radii, dt):
    """Symplectic Euler (Eqs. 43-44): ``v += dt F/m``, ``x += dt v``, ``omega += dt T/I``, ``I = (2/5) m r^2``.

    Returns ``(positions, velocity, spin)`` at ``t + dt``.
    """
    velocity = state.velocity + dt * force / mass[:, None]
    inertia = forces.SOLID_SPHERE_INERTIA * mass * radii**2
    spin = state.spin + dt * torque / inertia[:, None]
    return positions + dt * velocity, velocity, spin


# --------------------------------------------------------------------------
# time step


def mechanical_time_step(spec, particles, neighbors, params: MechanicalParams, v_rel, delta=None, **kwargs):
    """Time step of the packing: :func:`sintercond.laws.forces.contact_time_step` for its stiffest contact (s).

    Evaluated for every pair of the neighbour table (touching or not) and
    every particle against every wall, at the unsoftened modulus ``E0``
    (softening only lowers the stiffness at a given overlap; pass ``delta``
    for the static overlap under a load if that exceeds the collision's),
    approach speed ``v_rel`` (m/s), and the damping ratios of ``params``.
    The tangential and rolling modes count only when friction or rolling is
    on. ``kwargs`` go to :func:`sintercond.laws.forces.contact_time_step`
    (``fraction``, ``safety``). Compiled once per :class:`Mechanics` spec and shapes
    (eagerly it dispatches ~100 operations: seconds at set-up). Concrete inputs are checked first: ``v_rel``
    finite and > 0 m/s, ``delta`` None or finite and >= 0 m, ``params`` by :func:`validate_mechanical_params`
    (a NaN step came back for v_rel = 0 or E0 = -1).
    """
    if all_concrete(v_rel, delta, params):
        for name, value, rule, ok in (("v_rel", v_rel, "finite and > 0 m/s", lambda v: v > 0),
                                      ("delta", delta, "None or finite and >= 0 m", lambda v: v >= 0)):
            if value is None and name == "delta":
                continue
            v = np.asarray(value, np.float64)
            bad = ~(np.isfinite(v) & ok(v))
            if bad.any():
                raise ValueError(f"mechanical_time_step: {name} must be {rule}; got {shown(v[bad].ravel()[0])}")
        validate_mechanical_params(params)
    return _mechanical_time_step(spec, particles, neighbors, params, v_rel, delta, **kwargs)


@functools.partial(jax.jit, static_argnums=0, static_argnames=("fraction", "safety"))
def _mechanical_time_step(spec, particles, neighbors, params: MechanicalParams, v_rel, delta=None, **kwargs):
    """:func:`mechanical_time_step` without the checks, compiled."""
    radii, mass = particles.radii, particles.mass
    n = radii.shape[0]
    modulus = jnp.atleast_1d(jnp.asarray(params.E0, radii.dtype))[particles.material]
    nu = jnp.atleast_1d(jnp.asarray(params.nu, radii.dtype))[particles.material]
    shear = spec.friction or spec.rolling
    rows = jnp.arange(n, dtype=neighbors.dtype)[:, None]
    valid = (neighbors < n) & (neighbors != rows)
    j = jnp.where(valid, neighbors, rows)
    inf = jnp.asarray(jnp.inf, radii.dtype)
    candidates = [(radii[:, None], mass[:, None], modulus[:, None], nu[:, None], jnp.where(valid, radii[j], inf),
                   jnp.where(valid, mass[j], inf), jnp.where(valid, modulus[j], inf), nu[j], valid)]
    steps = []
    if spec.walls:
        wall = jnp.full((n,), jnp.inf, radii.dtype)
        candidates.append((radii, mass, modulus, nu, wall, wall, wall, nu, jnp.ones((n,), bool)))
    for ri, mi, ei, nui, rj, mj, ej, nuj, real in candidates:
        g_star = forces.effective_shear_modulus(ei, nui, ej, nuj, spec.shear) if shear else 0.0 * ei
        dt = forces.contact_time_step(forces.effective_radius(ri, rj), forces.effective_mass(mi, mj),
                                     forces.effective_modulus(ei, nui, ej, nuj), g_star, v_rel, delta=delta,
                                     xi_con=params.xi_con, xi_fric=params.xi_fric if spec.friction else 0.0,
                                     xi_rol=params.xi_rol if spec.rolling else 0.0, **kwargs)
        steps.append(jnp.min(jnp.where(real, dt, jnp.inf), initial=jnp.inf))
    return jnp.min(jnp.stack(steps))


def check_mechanical_time_step(dt, spec, particles, neighbors, params: MechanicalParams, v_rel, delta=None, **kwargs) -> float:
    """Raise ``ValueError`` naming the limit if ``dt`` exceeds :func:`mechanical_time_step`; returns the limit (s)."""
    limit = float(mechanical_time_step(spec, particles, neighbors, params, v_rel, delta, **kwargs))
    if math.isnan(limit):
        raise ValueError(f"the mechanical time step is undefined for v_rel = {float(v_rel)!r} m/s (the largest "
                         f"normal approach speed must be finite and > 0) and delta = {delta!r}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0 s; got {shown(dt)}")
    if dt > limit:
        raise ValueError(f"dt = {dt:.6g} s exceeds the mechanical time step {limit:.6g} s (Eq. 47 and the "
                         f"symplectic-Euler bounds of the stiffest contact at v_rel = {float(v_rel):.3g} m/s); "
                         f"use dt <= {limit:.6g} s")
    return limit


# Old names, kept for one release: each time-step function has its own name (issue 24).
__getattr__ = old_names("sintercond.sim.mechanics", {
    "stable_time_step": ("sintercond.sim.mechanics", "mechanical_time_step"),
    "check_time_step": ("sintercond.sim.mechanics", "check_mechanical_time_step"),
})
