"""Particle state of the discrete-element models, as a registered (frozen) dataclass PyTree.

One container for everything per particle, so that a step function can take
and return it under ``jit``/``scan`` and the thermo-mechanical model can add
velocities, rotations and per-pair history next to it without changing the
thermal code. Heat capacities are not stored: ``C_i = m_i c`` with the
specific heat ``c`` a (differentiable) parameter of the simulation
(:class:`sintercond.simulate.Params`); :func:`heat_capacity` forms them.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from sintercond._validation import concrete_arrays, fail_where, require_positive


def pytree_dataclass(cls):
    """A frozen dataclass registered as a JAX PyTree: the one container style of the package's states and
    parameters (every field a leaf or a sub-tree; None fields are empty)."""
    return jax.tree_util.register_dataclass(dataclasses.dataclass(frozen=True)(cls))


@pytree_dataclass
class ParticleState:
    """Per-particle state (SI units).

    Attributes:
      positions: ``[n, 3]`` centres (m).
      radii: ``[n]`` (m).
      temperature: ``[n]`` (K).
      mass: ``[n]`` particle masses ``m_i`` (kg).
      material: ``[n]`` int32 index into the scene's material table.
      fixed: ``[n]`` bool, particles held at ``fixed_temperature``.
      fixed_temperature: ``[n]`` (K), used where ``fixed``.
    """

    positions: jax.Array
    radii: jax.Array
    temperature: jax.Array
    mass: jax.Array
    material: jax.Array
    fixed: jax.Array
    fixed_temperature: jax.Array

    @property
    def n_particles(self) -> int:
        return self.radii.shape[0]


def heat_capacity(particles: ParticleState, specific_heat):
    """``C_i = m_i c[material_i]`` (J/K), Rojek et al. (2022) Eq. 1; ``specific_heat`` ``[n_materials]`` or scalar."""
    c = jnp.atleast_1d(jnp.asarray(specific_heat))
    return particles.mass * c[particles.material]


def particle_state(positions, radii, temperature, density, specific_heat=None, material=None, fixed=None,
                   fixed_temperature=None) -> ParticleState:
    """Build and validate a :class:`ParticleState`; densities (and heats, only validated) per material or scalar.

    Args:
      positions: ``[n, 3]`` (m). radii: ``[n]`` (m), > 0.
      temperature: scalar or ``[n]`` (K), > 0.
      density: scalar, or ``[n_materials]`` indexed by ``material`` (kg/m^3), > 0.
      specific_heat: optional, validated the same way (J/(kg K)), > 0; it is a
        simulation parameter, not part of the state (see :func:`heat_capacity`).
      material: ``[n]`` ints (default all 0).
      fixed, fixed_temperature: held particles and their temperatures.

    Raises:
      ValueError: naming the field and range, on invalid input.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"positions must be [n, 3]; got shape {positions.shape}")
    n = positions.shape[0]
    fail_where(~np.isfinite(positions).all(axis=1), lambda i: f"positions must be finite; row {i[0]} is not")
    (radii,) = concrete_arrays("particle_state", radii)
    radii = np.broadcast_to(radii, (n,))
    require_positive("radii (m)", radii)
    (temperature,) = concrete_arrays("particle_state", temperature)
    temperature = np.broadcast_to(temperature, (n,))
    require_positive("temperature (K)", temperature)
    material = np.zeros(n, np.int32) if material is None else np.asarray(material, np.int32)
    density = np.atleast_1d(np.asarray(density, np.float64))
    require_positive("density (kg/m^3)", density)
    n_materials = len(density)
    if specific_heat is not None:
        specific_heat = np.atleast_1d(np.asarray(specific_heat, np.float64))
        require_positive("specific_heat (J/(kg K))", specific_heat)
        n_materials = max(n_materials, len(specific_heat))
    fail_where((material < 0) | (material >= n_materials),
               lambda i: f"material must be in [0, {n_materials - 1}]; got {int(material[i])} at index {i}")
    rho = np.broadcast_to(density, (n_materials,))[material]
    mass = 4.0 / 3.0 * np.pi * radii**3 * rho
    fixed = np.zeros(n, bool) if fixed is None else np.broadcast_to(np.asarray(fixed, bool), (n,))
    held = temperature if fixed_temperature is None else np.broadcast_to(np.asarray(fixed_temperature, np.float64), (n,))
    require_positive("fixed_temperature (K)", np.where(fixed, held, 1.0))
    return ParticleState(
        positions=jnp.asarray(positions), radii=jnp.asarray(radii), temperature=jnp.asarray(np.where(fixed, held, temperature)),
        mass=jnp.asarray(mass), material=jnp.asarray(material), fixed=jnp.asarray(fixed),
        fixed_temperature=jnp.asarray(held),
    )


@pytree_dataclass
class TableContacts:
    """The contacts of a static packing with ``Conduction(conductance="table")``: conductances at unit conductivity.

    Attributes:
      neighbors: ``[n, m]`` int32 neighbour indices, padding the row's own index.
      conductance: ``[n, m]`` conductances at unit conductivity (W/K per W/(m K)), 0 in padding.
      wall_conductance: ``[n]`` conductance to the conducting walls at unit conductivity, or None.
      wall_temperature: ``[n]`` the temperature (K) each particle's conducting wall is at, or None.
    """

    neighbors: jax.Array
    conductance: jax.Array
    wall_conductance: jax.Array | None = None
    wall_temperature: jax.Array | None = None


@pytree_dataclass
class LiftedContacts:
    """The contacts of a static packing with ``Conduction(conductance="lifted")``: a half pair list that never
    rebuilds, its necks, and the padded table the conduction update runs on (the law applied to the parameters
    at each rollout).

    The pairs hold the state (each contact once, ``i < j``: its neck and approach); the table is derived from
    them once, when the contacts are built (:func:`sintercond.simulate.lifted_contacts`), and only lays each
    pair's conductance into its two slots (:meth:`on_table`) for the network mat-vec.

    Attributes:
      neighbors: ``[n, m]`` int32 neighbour indices, padding the row's own index.
      pairs: ``[c, 2]`` int32 the contacts ``(i, j)``, ``i < j``, sorted by ``(i, j)``.
      slot_pair: ``[n, m]`` int32 the pair each slot of the table holds; ``c`` in padding.
      neck: ``[c]`` neck radius of each pair (m).
      overlap: ``[c]`` overlap ``h = r_i + r_j - d`` of each pair (m).
      wall_neck, wall_overlap: ``[n_walls, n]`` neck radius and penetration (m) of each particle on each
        conducting wall, or None.
      wall_temperature: ``[n_walls]`` conducting wall temperatures (K), or None.
      sphere: with ``Conduction.coupling="sphere"``, the necks' directions on their spheres
        (:class:`sintercond.contacts.sphere_coupling.SphereGeometry`, on this table's layout, the neck unknowns
        in the order of ``pairs``); else None.
      neck_correction: with ``"sphere"``, ``[c]`` each neck's temperature less the isolated network's (K) at the
        last step, where the next step's neck balance starts (:mod:`sintercond.sim.terms.coupling`); else None.
    """

    neighbors: jax.Array
    pairs: jax.Array
    slot_pair: jax.Array
    neck: jax.Array
    overlap: jax.Array
    wall_neck: jax.Array | None = None
    wall_overlap: jax.Array | None = None
    wall_temperature: jax.Array | None = None
    sphere: object = None
    neck_correction: jax.Array | None = None

    def on_table(self, per_pair) -> jax.Array:
        """A ``[c]`` per-pair value in both slots of the padded table ``[n, m]``, 0 in padding."""
        per_pair = jnp.asarray(per_pair)
        return jnp.concatenate([per_pair, jnp.zeros((1,), per_pair.dtype)])[self.slot_pair]

    @property
    def table_neck(self) -> jax.Array:
        """``[n, m]`` the necks (m) in the table's slots, 0 in padding."""
        return self.on_table(self.neck)

    @property
    def table_overlap(self) -> jax.Array:
        """``[n, m]`` the overlaps (m) in the table's slots, 0 in padding."""
        return self.on_table(self.overlap)


@pytree_dataclass
class DynamicContacts:
    """The contacts of a moving packing (``Physics(contacts="dynamic")``), found again as it moves.

    Attributes:
      neighbor_list: the Dense neighbour list with a skin (:class:`sintercond.contacts.neighbors.NeighborList`).
      pairs: the half pair list (:class:`sintercond.contacts.pair_list.HalfPairs`, ``[capacity, 2]``, each pair
        ``i < j`` once) the laws run on, rebuilt with the Dense list.
    """

    neighbor_list: object
    pairs: object

    @property
    def neighbors(self) -> jax.Array:
        """``[n, m]`` int32 neighbour indices of the Dense list (padding ``n``)."""
        return self.neighbor_list.idx


Contacts = TableContacts | LiftedContacts | DynamicContacts
"""The contacts of a state, one class per mode (for annotations and ``isinstance``)."""
