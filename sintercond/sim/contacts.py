"""The contacts every term sees, and the conductance laws lifted onto them.

Three representations (:data:`sintercond.state.Contacts`): a table of ``K_ij`` at unit conductivity
(``conductance="table"``, the fast path of one material), a padded ``[n, m]`` table of necks
(``conductance="lifted"``: the law turns necks into conductances from ``Params`` at every rollout, so law
parameters and per-material conductivities are differentiable) and a half pair list that follows the motion
(``contacts="dynamic"``: a Dense neighbour list with a skin, rebuilt inside the step, and the pairs ``i < j``
within ``r_i + r_j + skin``; :class:`sintercond.contacts.pair_list.HalfPairs`). The law is lifted once per representation:
:func:`conductance_lift` onto the table, :func:`pair_conductance` onto the pair list, each evaluating it once per
pair (the table: with the pair in index order, so both rows get bitwise the same ``K``).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from sintercond.sim import mechanics, neck_growth
from sintercond.laws.conductance import CONDUCTANCE_LAWS, conductance_from_neck
from sintercond.laws.neck import NECK_MODELS
from sintercond.contacts.neighbors import did_buffer_overflow, did_rebuild
from sintercond.contacts.sphere_coupling import sphere_geometry
from sintercond.contacts.pair_list import (allocate_half_pairs, half_pair_capacity, half_pair_count, half_pairs,
                                           half_pairs_overflowed, padded_half_pairs, pair_exchange)
from sintercond.sim.physics import Physics
from sintercond.sim.state import Params, SimState
from sintercond.state import DynamicContacts, LiftedContacts, ParticleState, TableContacts
from sintercond.laws.walls import wall_neck_radius


def merged_law_params(physics: Physics, params: Params) -> dict:
    """The law's default parameters overridden by ``params.law``; unknown names raise."""
    defaults = CONDUCTANCE_LAWS[physics.conduction.law].default_params
    unknown = set(params.law) - set(defaults)
    if unknown:
        raise ValueError(f"Params.law of law {physics.conduction.law!r} must be among {sorted(defaults)}; got {sorted(unknown)}")
    return {**defaults, **params.law}


def conductance_lift(physics: Physics, radii, material, contacts: LiftedContacts, conductivity, law_params):
    """Conductances ``[n, m]`` (W/K) of a lifted table from the necks of its pairs: the one law -> table lift.

    The law is evaluated once per pair (:func:`lifted_pair_conductance`) and laid into both slots of the pair
    (:meth:`sintercond.state.LiftedContacts.on_table`), so both rows get the same ``K`` and the network stays
    exactly symmetric (heat conserved to round-off). Padding slots give 0.
    """
    return contacts.on_table(lifted_pair_conductance(physics, radii, material, contacts, conductivity, law_params))


def lifted_pair_conductance(physics: Physics, radii, material, contacts: LiftedContacts, conductivity, law_params):
    """Conductances ``[c]`` (W/K) of the pairs of a lifted table from their necks."""
    i, j = contacts.pairs[:, 0], contacts.pairs[:, 1]
    return _law_on_pairs(physics, radii, material, (i, j, jnp.ones(i.shape, bool)), contacts.neck, contacts.overlap,
                         conductivity, law_params)


def _law_on_pairs(physics, radii, material, pairs, neck, overlap, conductivity, law_params):
    """The conductance law on ``pairs = (lo, hi, valid)`` (index arrays of any shape, and a mask) from their necks
    (W/K); 0 where not ``valid``."""
    lo, hi, valid = pairs
    kappa = jnp.asarray(conductivity)
    k = conductance_from_neck(physics.conduction.law, neck, radii[lo], radii[hi], overlap, kappa[material[lo]],
                              kappa[material[hi]], law_params)
    return jnp.where(valid, k, 0.0)


def conductivity_lookup(physics: Physics, params: Params, particles: ParticleState):
    """``(index [n], conductivity [k])``: particle ``i`` conducts at ``conductivity[index[i]]`` (W/(m K)).

    The material table (``index`` the materials) or, with ``Conduction.conductivity_table``, each particle's
    conductivity at its own temperature (``index`` the particles): the laws' lifts take either.
    """
    if physics.conduction.conductivity_table:
        return jnp.arange(particles.radii.shape[0]), params.conductivity(particles.temperature)
    return particles.material, jnp.atleast_1d(jnp.asarray(params.conductivity))


def neck_conductance(physics: Physics, state: SimState, params: Params):
    """Conductances ``[n, m]`` (W/K) of a static lifted state from the necks and temperatures it holds now."""
    return state.contacts.on_table(pair_neck_conductance(physics, state, params))


def pair_neck_conductance(physics: Physics, state: SimState, params: Params):
    """Conductances ``[c]`` (W/K) of the pairs of a static lifted state (:func:`neck_conductance` per pair)."""
    p = state.particles
    index, kappa = conductivity_lookup(physics, params, p)
    return lifted_pair_conductance(physics, p.radii, index, state.contacts, kappa, merged_law_params(physics, params))


def pair_conductance(physics: Physics, radii, material, geometry, conductivity, law_params):
    """Conductances ``[c]`` (W/K) of the pairs of a half list from their current overlaps: neck, then the law, once per pair.

    ``geometry``: :func:`sintercond.sim.mechanics.pair_geometry` of the list.
    """
    return _pair_neck_and_conductance(physics, radii, material, geometry, conductivity, law_params)[1]


def _pair_neck_and_conductance(physics, radii, material, geometry, conductivity, law_params):
    """``(neck [c] m, conductance [c] W/K)`` of the pairs of a half list from their current overlaps."""
    neck = _pair_neck(physics, radii, geometry)
    return neck, _law_on_pairs(physics, radii, material, (geometry.i, geometry.j, geometry.valid), neck,
                               geometry.overlap, conductivity, law_params)


def _pair_neck(physics, radii, g):
    """Neck radii ``[c]`` (m) of the touching pairs of a :class:`sintercond.sim.mechanics.PairGeometry`."""
    return jnp.where(g.touching, NECK_MODELS[physics.neck](radii[g.i], radii[g.j], g.overlap), 0.0)


def sintered_geometry(geometry, neck_overlap):
    """The :class:`sintercond.sim.mechanics.PairGeometry` the elastic laws see on sintered pairs: each overlap less the
    approach ``H(a)`` its neck accounts for (``neck_overlap`` ``[c]``, m), touching only where that stays positive.

    Sintering moves the spheres together by the neck's approach without loading them (Rojek et al. 2022); the
    elastic contact acts on what is left, as a plastic overlap does in MercuryDPM's sinter species."""
    overlap = geometry.overlap - neck_overlap
    touching = geometry.touching & (overlap > 0)
    return geometry._replace(touching=touching, overlap=jnp.where(touching, overlap, 0.0))


def conducting_geometry(geometry, neck_overlap):
    """The :class:`sintercond.sim.mechanics.PairGeometry` the conductance laws see on sintered pairs: each touching
    pair's overlap, or its neck's approach ``H(a)`` (``neck_overlap`` ``[c]``, m) where that is larger (necks grown
    on pairs that have not moved together: independent contacts, point contacts), so the volume-conserving neck of
    it is ``max(a, neck(delta))``. ``geometry``: with the gap :data:`sintercond.sim.neck_growth.POINT_CONTACT_GAP`."""
    overlap = jnp.where(geometry.touching, jnp.maximum(geometry.overlap, neck_overlap), 0.0)
    return geometry._replace(touching=geometry.touching & (overlap > 0), overlap=overlap)


def sintered_pair_conductance(physics: Physics, state: SimState, params: Params):
    """``(geometry, conductance [c])`` of a mechanical sintering state's half pair list (W/K): what its step
    conducts through (:func:`conducting_geometry`)."""
    geometry, _, conductance = sintered_pair_network(physics, state, params)
    return geometry, conductance


def sintered_pair_network(physics: Physics, state: SimState, params: Params):
    """``(geometry, neck [c], conductance [c])`` of a mechanical sintering state's half pair list: the geometry its
    step conducts through (:func:`conducting_geometry`), each pair's neck radius (m, 0 where not touching) and
    conductance (W/K)."""
    p = state.particles
    geometry = conducting_geometry(mechanics.pair_geometry(p.positions, p.radii, state.contacts.pairs.pairs,
                                                           neck_growth.POINT_CONTACT_GAP),
                                   state.mechanics.neck_overlap)
    index, kappa = conductivity_lookup(physics, params, p)
    return geometry, *_pair_neck_and_conductance(physics, p.radii, index, geometry, kappa,
                                                 merged_law_params(physics, params))


def particle_conductivity(physics: Physics, params: Params, particles: ParticleState):
    """``[n]`` conductivity (W/(m K)) of each particle: its material's, or at its temperature
    (:func:`conductivity_lookup`)."""
    index, kappa = conductivity_lookup(physics, params, particles)
    return kappa[index]


def pair_heat_power(conductance, pairs, temperature):
    """Heat power ``[n]`` (W) into each particle through the pairs ``[c, 2]`` of a half list, ``K (T_j - T_i)`` into ``i``.

    Each pair's flow is added to one end and taken from the other: the total is zero to round-off.
    """
    n = temperature.shape[0]
    i, j = jnp.minimum(pairs[:, 0], n - 1), jnp.minimum(pairs[:, 1], n - 1)
    return pair_exchange(pair_heat_flow(conductance, i, j, temperature), pairs, n)


def pair_heat_flow(conductance, i, j, temperature):
    """Heat flow ``K (T_j - T_i)`` (W) from ``j`` to ``i`` of each pair (Rojek et al. 2022, Eq. 3)."""
    return conductance * (temperature[j] - temperature[i])


def follow_contacts(neighbor_fn, positions, radii, contacts: DynamicContacts, history=None):
    """Dynamic contacts at ``positions``: ``(contacts, history, overflow)``.

    Updates the Dense list (it rebuilds once a particle moved half the
    skin); when it rebuilt, rebuilds the half pair list from it and carries
    the per-pair ``history`` (a :class:`sintercond.sim.mechanics.MechanicalState`
    or None) to the new pairs (:func:`sintercond.sim.mechanics.remap_history`),
    all under one ``lax.cond``. ``overflow``: either list ran out of room.
    """
    nbrs = neighbor_fn.update(positions, contacts.neighbor_list)
    old = contacts.pairs

    def rebuild(history):
        new = half_pairs(nbrs.idx, positions, radii, neighbor_fn.skin, old.capacity, old.demand)
        return new, None if history is None else mechanics.remap_history(history, old.pairs, new.pairs)

    half, history = jax.lax.cond(did_rebuild(contacts.neighbor_list, nbrs), rebuild, lambda h: (old, h), history)
    overflow = did_buffer_overflow(nbrs) | half_pairs_overflowed(half)
    return DynamicContacts(neighbor_list=nbrs, pairs=half), history, overflow


def table_contacts(table, wall_conductance=None, wall_temperature=None) -> TableContacts:
    """Contacts of ``conductance="table"`` from a :class:`sintercond.contacts.network.ContactTable` at unit conductivity."""
    return TableContacts(neighbors=table.neighbors, conductance=table.conductance,
                         wall_conductance=None if wall_conductance is None else jnp.asarray(wall_conductance),
                         wall_temperature=None if wall_temperature is None else jnp.asarray(wall_temperature))


def lifted_contacts(physics: Physics, centres, radii, walls=(), periodic_box=None, tolerance=1e-9,
                    pairs=None, *, held=None, held_axis=0) -> LiftedContacts:
    """Contacts of ``conductance="lifted"``: the neck of every pair and of every conducting wall (host, once).

    Pairs as :func:`sintercond.contacts.network.contact_pairs` finds them, necks by
    ``physics.neck``, laid out with :func:`sintercond.contacts.network.ell_table`.
    ``walls``: ``(penetration [n], temperature)`` per conducting wall (m, K),
    penetration <= 0 where a particle does not touch it. ``pairs``: the
    :class:`~sintercond.contacts.network.ContactPairs` if the caller already searched.

    With ``Conduction.coupling="sphere"`` the necks' directions on their spheres too
    (:func:`sintercond.contacts.sphere_coupling.sphere_geometry` with the transient's net-flow term, Eq. 5, after
    its domain check, which raises ``ValueError`` on necks too large or too close): ``held`` ``[n]`` int labels
    (0 free, equal non-zero labels for particles held at the same temperature) and ``held_axis``, the axis
    normal to the held faces, give the held spheres their mirror images as in the steady solver (``held=None``:
    every sphere's block is a free sphere's, held or not).
    """
    from sintercond.contacts.network import contact_pairs, ell_table

    radii = np.asarray(radii, np.float64)
    p = contact_pairs(centres, radii, tolerance, periodic_box) if pairs is None else pairs
    a = np.where(p.overlap > 0, np.asarray(NECK_MODELS[physics.neck](p.r_i, p.r_j, p.overlap)), 0.0)
    count = len(p.i)
    neighbors, slot = ell_table(p.n_particles, p.i, p.j, np.arange(1, count + 1))
    contacts = LiftedContacts(neighbors=jnp.asarray(neighbors, jnp.int32),
                              pairs=jnp.asarray(np.stack([p.i, p.j], axis=1).reshape(-1, 2), jnp.int32),
                              slot_pair=jnp.asarray(np.where(slot > 0, slot - 1, count), jnp.int32),
                              neck=jnp.asarray(a), overlap=jnp.asarray(np.asarray(p.overlap, np.float64)))
    if physics.conduction.coupling == "sphere":
        contacts = coupled_contacts(contacts, centres, radii, a, held=held, held_axis=held_axis,
                                    periodic_box=periodic_box)
    if walls:
        h = np.stack([np.maximum(np.asarray(p, np.float64), 0.0) for p, _ in walls])
        a = np.asarray(wall_neck_radius(physics.neck, radii, h))
        contacts = dataclasses.replace(contacts, wall_neck=jnp.asarray(a), wall_overlap=jnp.asarray(h),
                                       wall_temperature=jnp.asarray([float(t) for _, t in walls]))
    return contacts


def coupled_contacts(contacts: LiftedContacts, centres, radii, necks, *, held=None, held_axis=0,
                     periodic_box=None, beyond_domain="refuse") -> LiftedContacts:
    """``contacts`` with the necks' directions on their spheres for ``Conduction.coupling="sphere"`` (host, once).

    :func:`sintercond.contacts.sphere_coupling.sphere_geometry` (with the transient's net-flow term, Eq. 5) on the
    necks ``necks`` ``[c]`` (m): the contacts with a neck there are the ones coupled. For necks that stay, the
    contacts' own (:func:`lifted_contacts` does this); ``beyond_domain="refuse"`` (default) raises ``ValueError`` on
    two necks of a sphere closer than their discs' half-widths there. With ``Physics.sintering``, the largest
    necks the run can reach (:func:`sintercond.sim.neck_growth.necks_at_cap`) with ``beyond_domain="isolated"``,
    so that a neck that grows from zero is coupled once it conducts; the domain is then taken at each step's necks
    (a sphere whose necks' discs have come to overlap keeps the pair law's halves,
    :func:`sintercond.contacts.sphere_coupling.kept_green`). ``held``, ``held_axis``: as :func:`lifted_contacts`.
    """
    count = int(contacts.pairs.shape[0])
    slot = np.asarray(contacts.slot_pair)
    padded = np.concatenate([np.asarray(necks, np.float64), [0.0]])[slot]
    geometry = sphere_geometry(centres, radii, np.asarray(contacts.neighbors), np.where(slot < count, slot + 1, 0),
                               padded, held=held, axis=held_axis, periodic_box=periodic_box, net_flow=True,
                               beyond_domain=beyond_domain)
    return dataclasses.replace(contacts, sphere=geometry, neck_correction=jnp.zeros(count, float))


def list_region(positions, radii, margin=None):
    """``(lo, hi)`` ``[3]`` corners (m) of the cell grid of :func:`dynamic_contacts`: the packing's extent
    widened by ``margin`` (m, scalar or ``[3]``; default a tenth of the extent plus ``2 r_max`` on every side).

    A particle that leaves the region is still found (it falls into the face cells), so the margin only
    trades crowded face cells against empty ones: a rebuild's cell counts run over the whole region.
    """
    positions, radii = np.asarray(positions, np.float64), np.asarray(radii, np.float64)
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    margin = 0.1 * (hi - lo) + 2.0 * radii.max() if margin is None else margin
    return lo - margin, hi + margin


def dynamic_contacts(positions, radii, skin, capacity_multiplier=1.25, margin=None):
    """Contacts of ``contacts="dynamic"`` and their neighbour-list functions: ``(contacts, neighbor_fns)``.

    A Dense list with a Verlet skin from a sorted cell list (:func:`sintercond.contacts.neighbors.neighbor_list`):
    inside the step it is rebuilt only once a particle moved ``skin / 2``,
    and the half pair list (``DynamicContacts.pairs``, the pairs the laws run on)
    with it. Both are sized here with ``capacity_multiplier`` spare room.
    The cell-list region is :func:`list_region` (the packing's extent widened by ``margin``, m). Pass
    ``neighbor_fns`` to :func:`simulator`. The list keeps the float dtype of
    ``positions`` (float32 positions give a float32 list; others float64).
    """
    from sintercond.contacts.neighbors import neighbor_list

    dtype = jnp.float32 if np.asarray(positions).dtype == np.float32 else jnp.float64
    positions = np.asarray(positions, np.float64)
    radii = np.asarray(radii, np.float64)
    fns = neighbor_list(radii, skin, *list_region(positions, radii, margin), capacity_multiplier=capacity_multiplier)
    nbrs = fns.allocate(jnp.asarray(positions, dtype))
    half = allocate_half_pairs(nbrs.idx, jnp.asarray(positions, dtype), jnp.asarray(radii, dtype), fns.skin,
                               capacity_multiplier)
    return DynamicContacts(neighbor_list=nbrs, pairs=half), fns


def reallocate_neighbors(neighbor_fns):
    """A ``reallocate(start, end)`` for :func:`sintercond.rollout.advance`: room for the chunk that overflowed.

    The Dense list is allocated at the chunk's end positions, with room for
    the most neighbours and cell-range particles any build of the chunk met
    (never narrower than before); the half pair list grows to
    ``capacity_multiplier`` times the most pairs any build of the chunk
    needed (or the end positions need), if it overflowed. The redone chunk
    starts from ``start``: its pairs and springs are kept (padded to the new
    capacity), and its first update rebuilds both lists at the start
    positions, carrying the springs to them pair by pair, exactly as a roomy
    list would have held them.
    """
    def reallocate(start: SimState, end: SimState) -> SimState:
        old, demand = start.contacts.neighbor_list, tuple(int(d) for d in end.contacts.neighbor_list.demand)
        nbrs = neighbor_fns.allocate(end.particles.positions, demand=demand)
        if nbrs.idx.shape[1] < old.idx.shape[1]:
            nbrs = neighbor_fns.allocate(end.particles.positions, old.idx.shape[1] - nbrs.idx.shape[1], demand)
        nbrs = dataclasses.replace(nbrs, reference_position=jnp.full_like(nbrs.reference_position, jnp.inf))
        half = start.contacts.pairs
        capacity = half.capacity
        if bool(half_pairs_overflowed(end.contacts.pairs)):
            need = max(int(end.contacts.pairs.demand), half_pair_count(nbrs.idx, end.particles.positions,
                                                                       end.particles.radii, neighbor_fns.skin))
            capacity = half_pair_capacity(max(capacity + 1, int(math.ceil(neighbor_fns.capacity_multiplier * need))))
        n = start.particles.radii.shape[0]
        contacts = DynamicContacts(neighbor_list=nbrs, pairs=padded_half_pairs(half, capacity, n))
        motion = start.mechanics
        if motion is not None and capacity > half.capacity:  # the springs stay with their pairs, zeros after them
            pad = lambda x: None if x is None else jnp.concatenate(  # noqa: E731
                [x, jnp.zeros((capacity - half.capacity,) + x.shape[1:], x.dtype)])
            motion = dataclasses.replace(motion, **{f: pad(getattr(motion, f)) for f in mechanics.PAIR_HISTORY})
        return dataclasses.replace(start, contacts=contacts, mechanics=motion)

    return reallocate


def affine_shrinkage(centres, rate):
    """Positions shrinking toward the centroid at a linear strain ``rate`` (1/s): ``c0 + (1 - rate t)(c - c0)``."""
    centres = jnp.asarray(centres)
    centroid = jnp.mean(centres, axis=0)
    return lambda t: centroid + (1.0 - rate * t) * (centres - centroid)
