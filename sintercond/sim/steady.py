"""Steady states of a pipe network and the effective conductivity ``k*`` of a packing.

* :func:`steady_state`: the field between held particles, from the graph
  Laplacian by conjugate gradients (differentiated implicitly:
  ``jax.scipy.sparse.linalg.cg`` is a ``custom_linear_solve``).
* :func:`steady_state_conductivity`: ``k*`` of a packing between two held
  faces, conductances lifted from the overlaps through a law.
* :func:`steady_state_network_conductivity`: the same with ``K_ij`` given per
  pair (necks grown by :mod:`sintercond.laws.sintering`, or any other law).

These sit above the simulator (they build its contacts and lift), which is why
they are not in :mod:`sintercond.sim.thermal`.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import typing

import jax
import jax.numpy as jnp
import numpy as np

from sintercond import simulate as sim_module
from sintercond._numerics import safe_divide
from sintercond._validation import all_concrete, require_positive
from sintercond.laws.conductance import validate_pair_conductance_inputs
from sintercond.laws.neck import neck_radius
from sintercond.contacts.network import ContactTable, contact_pairs, ell_table, heat_inflow, laplacian, wall_inflow
from sintercond.sim.thermal import held_solve
from sintercond.contacts.sphere_coupling import (
    BEYOND_DOMAIN,
    SphereGeometry,
    at_necks,
    block_total,
    coupled_blocks,
    half_resistances,
    neck_flows,
    neck_system,
    outside_domain,
    row_sums,
    slot_diagonal,
    slot_flows,
    sphere_geometry,
)


class NoFaceLayer(ValueError):
    """No particle touches one of the two faces of the box k* is measured in along its axis: no heat can be
    imposed there."""


def steady_state(table: ContactTable, fixed_mask, fixed_temperature, tol=1e-13):
    """Steady temperatures with the ``fixed_mask`` particles held at ``fixed_temperature``.

    Solves ``(L T)_i = K_iw T_w`` on free particles by conjugate gradients
    (conducting walls, if the table has them, act like held neighbours). Free
    particles not connected to any held one have no defined temperature; they
    come out at 0.
    """
    fixed_mask = jnp.asarray(fixed_mask)
    held = jnp.where(fixed_mask, jnp.asarray(fixed_temperature, table.conductance.dtype), 0.0)
    return held_solve(lambda x: laplacian(x, table), fixed_mask, held, wall_inflow(table, held.dtype), tol)


def coupled_steady_state(geometry: SphereGeometry, conductance, fixed_mask, fixed_temperature, tol=1e-13):
    """Steady state of the coupled neck network (:mod:`sintercond.contacts.sphere_coupling`) with held spheres.

    In float64 the free spheres are eliminated exactly (each touches only its necks:
    :func:`sintercond.contacts.sphere_coupling.neck_system`) and the necks' temperatures solved alone: the solve
    2.7x (10,841 spheres) and 3.5x (109,283) faster than on the joint system of spheres and necks, rolled beds
    densified by 4 % (the iterations of the isolated network's solve). In float32 the elimination's rank-one
    difference loses digits (k* up to 8e-4 off on an FCC block at a/r = 0.4, against 5e-6 for the joint system),
    so float32 solves the joint system
    (:func:`sintercond.contacts.sphere_coupling.slot_flows`). Jacobi-preconditioned conjugate gradients,
    differentiated implicitly; a neck in no sphere's block is left at 0.

    Args:
      geometry: :func:`sintercond.contacts.sphere_coupling.sphere_geometry`.
      conductance: the neck conductance blocks ``C_s`` (W/K), packed
        (:func:`sintercond.contacts.sphere_coupling.conductance_blocks`).
      fixed_mask: ``[n]`` held spheres. fixed_temperature: their temperatures (K), ``[n]`` or scalar.

    Returns:
      ``(temperature [n], outflow [n])``: sphere temperatures (K) and the heat leaving each sphere through
      its necks (W; 0 on free spheres at convergence).
    """
    fixed_mask = jnp.asarray(fixed_mask)
    dtype = conductance[0].dtype
    held = jnp.where(fixed_mask, jnp.asarray(fixed_temperature, dtype), 0.0)
    if dtype != jnp.float64:
        return _joint_steady_state(geometry, conductance, fixed_mask, held, tol)
    system = neck_system(geometry, conductance, ~fixed_mask)

    def into_necks(neck_x, held_x=None):  # the net heat into each neck from its two spheres (W)
        q, sphere_x = neck_flows(geometry, conductance, system, neck_x, held_x)
        return jnp.sum(at_necks(geometry, q), axis=1), q, sphere_x

    unknown = geometry.neck_fixed.shape[0]
    inflow = into_necks(jnp.zeros(unknown, dtype), held)[0]  # from the held spheres, the necks at 0
    inverse_diagonal = safe_divide(1.0, system.diagonal, fill=1.0)
    necks = held_solve(lambda x: -into_necks(x)[0], geometry.neck_fixed, jnp.zeros(unknown, dtype), inflow, tol,
                       preconditioner=lambda r: inverse_diagonal * r)
    _, q, temperature = into_necks(necks, held)
    return temperature, row_sums(geometry, q)


def _joint_steady_state(geometry, conductance, fixed_mask, held, tol):
    """:func:`coupled_steady_state` on the joint system of sphere and neck temperatures, ``A = sum_s B_s^T C_s B_s``
    with ``B_s x = x_s 1 - x_N(s)`` (its diagonal: ``1^T C_s 1`` on the spheres, the blocks' diagonals summed on
    the necks): the float32 path."""
    n = fixed_mask.shape[0]
    fixed = jnp.concatenate([fixed_mask, geometry.neck_fixed])

    def apply(x):
        q = slot_flows(geometry, conductance, x[:n], x[n:])
        return jnp.concatenate([row_sums(geometry, q), -jnp.sum(at_necks(geometry, q), axis=1)])

    diagonal = jnp.concatenate([block_total(geometry, conductance),
                                jnp.sum(at_necks(geometry, slot_diagonal(conductance)), axis=1)])
    inverse_diagonal = safe_divide(1.0, diagonal, fill=1.0)
    start = jnp.concatenate([held, jnp.zeros(fixed.shape[0] - n, held.dtype)])
    x = held_solve(apply, fixed, start, jnp.zeros_like(start), tol, preconditioner=lambda r: inverse_diagonal * r)
    return x[:n], apply(x)[:n]


COUPLINGS = ("none", "sphere")
"""Values of ``coupling=``: the isolated pipe network, or necks coupled through their sphere
(:mod:`sintercond.contacts.sphere_coupling`)."""


def steady_state_conductivity(centres, radii, kappa, axis=0, *, law="rojek", params=None, neck_model=None,
                              box=None, tol=1e-13, field=False, coupling="sphere", periodic_box=None,
                              beyond_domain="refuse", domain=False):
    """Effective conductivity ``k*`` (W/(m K)) of a packing along ``axis``, from one steady solve.

    Definition: the box (default: the bounding box of the centres, widened on
    every side by half the mean centre distance of the contacts, i.e. the
    lattice cell for a lattice) has faces ``lo`` and ``hi`` along ``axis``.
    Particles whose sphere reaches the ``lo`` face are held at ``T = 1``,
    those reaching the ``hi`` face at ``T = 0``. ``Q`` is the heat leaving the
    hot set at steady state, ``L`` the distance between the mean centre
    planes of the hot and cold sets, and ``A`` the box cross-section normal
    to ``axis``: ``k* = Q L / (A (T_hot - T_cold))``. For a simple-cubic
    lattice of spacing ``a`` this is ``K_pair / a`` exactly.

    ``coupling``: ``"sphere"`` (default) couples the necks that share a sphere through its surface Green function
    (:mod:`sintercond.contacts.sphere_coupling`: same pair law, chains and the simple-cubic cell unchanged, within
    2 % of full-field solves on FCC and BCC cells up to a/r = 0.4 where the isolated network is 2-39 %
    high; held spheres by mirror images); ``"none"`` sums each contact's pair law as if its neck were alone on its
    sphere (the pipe network of the peers). ``beyond_domain``: where two necks of a sphere are closer than their
    discs' angular half-widths (outside point coupling), ``"refuse"`` (default) raises ``ValueError`` naming them,
    ``"isolated"`` keeps that sphere's pair-law halves, as the isolated network (``domain=True`` adds to the result,
    last, the ``[n]`` bool mask of those particles: :func:`sintercond.contacts.sphere_coupling.outside_domain`; all
    False with ``"none"``). float64 by default; in float32
    (x64 off) the coupled ``k*`` agrees with float64 to about 1e-5 relative (measured 4e-7 to 5e-6 on the FCC and
    BCC cells), with ``tol`` of 1e-6 or looser.

    ``periodic_box``: ``[3]`` side lengths (m) of a packing periodic across the axis (contacts and neck
    directions by minimum image); its entry along ``axis`` is ignored (the held faces bound the packing
    there). Needs ``box``, whose sides across the axis are the periods.

    ``field=True`` returns ``(k*, temperature [n])``: the steady field between ``T = 1`` (hot) and ``0`` (cold),
    NaN on particles no chain of contacts joins to a held one (isolated particles and floating clusters: their
    temperature is undefined, not 0).

    Differentiable in ``kappa`` (scalar or ``[n]``) and the law's ``params``:
    the geometry (contacts, necks, hot and cold sets, ``L``, ``A``) is
    prepared on the host once, the conductances are lifted from the necks in
    JAX, and the conjugate-gradient solve is differentiated implicitly
    (``jax.scipy.sparse.linalg.cg``, a ``custom_linear_solve``). Returns a
    float for concrete input, a JAX scalar under a transformation.
    """
    _check_coupling(coupling, beyond_domain)
    setup = _conductivity_setup(centres, radii, axis, law, neck_model, box, periodic_box)
    concrete = all_concrete(kappa, params)
    if concrete:
        validate_pair_conductance_inputs(law, setup.pairs.r_i, setup.pairs.r_j, setup.pairs.overlap,
                                         np.broadcast_to(np.asarray(kappa, np.float64), setup.radii.shape)[setup.pairs.i],
                                         np.broadcast_to(np.asarray(kappa, np.float64), setup.radii.shape)[setup.pairs.j],
                                         params, neck_model)
    physics = setup.physics
    n = len(setup.radii)
    kappa = jnp.broadcast_to(jnp.asarray(kappa, float), (n,))
    law_params = sim_module.merged_law_params(
        physics, sim_module.Params(kappa, kappa, law={} if params is None else dict(params)))
    contacts = setup.contacts
    radii = jnp.asarray(setup.radii)
    hot = jnp.asarray(setup.hot)
    fixed = jnp.asarray(setup.hot | setup.cold)
    outside = np.zeros(n, bool)
    if coupling == "sphere":
        geometry = _sphere_geometry(setup, contacts.neighbors, contacts.table_neck, axis, beyond_domain)
        q, temperature, outside = _compiled(_compiled_coupled_solve, physics, tol)(geometry, radii, contacts, kappa,
                                                                                    law_params, fixed, hot)
    else:
        q, temperature = _compiled(_compiled_lifted_solve, physics, tol)(radii, contacts, kappa, law_params, fixed,
                                                                          hot)
    k_star = q * setup.length / setup.area
    out = [float(k_star) if concrete else k_star]
    if field:
        held = setup.hot | setup.cold
        label = connected_components(n, setup.pairs.i, setup.pairs.j)
        reached = np.isin(label, label[held])
        out.append(jnp.where(jnp.asarray(reached), temperature, jnp.nan))
    if domain:
        out.append(outside)
    return out[0] if len(out) == 1 else tuple(out)


def _compiled(program, physics, tol):
    """``program(physics, tol)``, a compiled solve of :func:`steady_state_conductivity` from the necks cached per
    law and tolerance (a law object, unhashable, is compiled afresh): ``(Q_hot, temperature)``. Compiled, not
    eager: dispatched op by op, the conjugate-gradient loop costs far more than the solve (benchmarks/RESULTS.md,
    ``time_scales``)."""
    try:
        return program(physics, tol)
    except TypeError:  # unhashable law object
        return program.__wrapped__(physics, tol)


def _lift(physics, radii, contacts, kappa, law_params):
    """``K_ij`` ``[n, m]`` (W/K) of a packing's table from its necks, each particle its own material."""
    return sim_module.conductance_lift(physics, radii, jnp.arange(radii.shape[0], dtype=jnp.int32), contacts, kappa,
                                       law_params)


@functools.cache
def _compiled_lifted_solve(physics, tol):
    def solve(radii, contacts, kappa, law_params, fixed, hot):
        return _network_heat(contacts.neighbors, _lift(physics, radii, contacts, kappa, law_params), fixed, hot, tol)

    return jax.jit(solve)


@functools.cache
def _compiled_network_solve(tol):
    """The isolated-neck solve of :func:`steady_state_network_conductivity` (``K_ij`` given), one compiled program."""
    return jax.jit(functools.partial(_network_heat, tol=tol))


def _network_heat(neighbors, conductance, fixed, hot, tol):
    """``(Q, temperature [n])`` of the isolated-neck network: the heat leaving the ``hot`` spheres (held at 1, the
    rest of ``fixed`` at 0)."""
    table = ContactTable(neighbors, conductance)
    temperature = steady_state(table, fixed, jnp.where(hot, 1.0, 0.0), tol=tol)
    return -jnp.sum(jnp.where(hot, heat_inflow(temperature, table), 0.0)), temperature


@functools.cache
def _compiled_coupled_solve(physics, tol):
    law = physics.conduction.law

    def solve(geometry, radii, contacts, kappa, law_params, fixed, hot):
        conductance = _lift(physics, radii, contacts, kappa, law_params)
        half = half_resistances(law, radii, contacts.neighbors, contacts.table_neck, contacts.table_overlap, kappa,
                                law_params, conductance)
        return _coupled_heat(geometry, half, radii, kappa, contacts.table_neck, fixed, hot, tol)

    return jax.jit(solve)


@functools.cache
def _compiled_network_coupled_solve(tol):
    """The coupled solve of :func:`steady_state_network_conductivity` (``K_ij`` given), one compiled program."""
    def solve(geometry, conductance, neighbors, radii, kappa, neck, fixed, hot):
        # Rojek's halves on a shared neck (Eq. 43, slope kappa_k pi a): the resistance in the proportion 1/kappa_k
        kappa_n = kappa[neighbors]
        half = safe_divide(kappa_n, (kappa[:, None] + kappa_n) * conductance)
        geometry = dataclasses.replace(geometry, coupled=geometry.coupled & (conductance > 0))
        return _coupled_heat(geometry, half, radii, kappa, neck, fixed, hot, tol)

    return jax.jit(solve)


def _coupled_heat(geometry, half, radii, kappa, neck, fixed, hot, tol):
    """``(Q, temperature [n], outside [n])``: the heat leaving the ``hot`` spheres (held at 1, the rest of ``fixed``
    at 0), and the spheres outside the domain of point coupling at the necks ``neck``, kept at their halves."""
    blocks = coupled_blocks(geometry, half, radii, kappa, neck)
    temperature, outflow = coupled_steady_state(geometry, blocks, fixed, jnp.where(hot, 1.0, 0.0), tol=tol)
    return jnp.sum(jnp.where(hot, outflow, 0.0)), temperature, outside_domain(geometry, neck, radii)


_GEOMETRY = {}
"""The last geometry :func:`_network_geometry` built, by a digest of what it depends on: a run measures k* of the
same static packing at every output, its necks growing (one entry: a geometry of 1e5 spheres is hundreds of MB)."""


def _network_geometry(centres, radii, neighbors, pair_id, held, axis, periods):
    """:func:`sintercond.contacts.sphere_coupling.sphere_geometry` with every pair a possible neck (the domain and
    the necks that conduct are decided in the solve), cached while the packing stays."""
    digest = hashlib.blake2b(digest_size=16)
    for part in (centres, radii, neighbors, pair_id, held, np.asarray(axis), periods):
        digest.update(np.ascontiguousarray(np.asarray(part if part is not None else np.nan, np.float64)).tobytes())
    key = digest.digest()
    if key not in _GEOMETRY:
        _GEOMETRY.clear()
        with jax.ensure_compile_time_eval():  # concrete arrays even while a caller is traced: the cache outlives it
            _GEOMETRY[key] = sphere_geometry(centres, radii, neighbors, pair_id, (pair_id > 0).astype(np.float64),
                                             held=held, axis=axis, periodic_box=periods, beyond_domain="isolated")
    return _GEOMETRY[key]


def _check_coupling(coupling, beyond_domain):
    if not isinstance(coupling, str) or coupling not in COUPLINGS:
        raise ValueError(f"coupling must be one of {list(COUPLINGS)}; got {coupling!r}")
    if not isinstance(beyond_domain, str) or beyond_domain not in BEYOND_DOMAIN:
        raise ValueError(f"beyond_domain must be one of {list(BEYOND_DOMAIN)}; got {beyond_domain!r}")


def _sphere_geometry(setup, neighbors, neck, axis, beyond_domain):
    """:func:`sintercond.contacts.sphere_coupling.sphere_geometry` of a steady setup: hot spheres labelled 1, cold 2."""
    pairs = setup.pairs
    id_neighbors, pair_id = ell_table(pairs.n_particles, pairs.i, pairs.j, np.arange(1, len(pairs.i) + 1))
    if not np.array_equal(id_neighbors, np.asarray(neighbors)):
        raise AssertionError("the contact table and the pair numbering disagree")
    held = np.where(setup.hot, 1, np.where(setup.cold, 2, 0))
    return sphere_geometry(setup.centres, setup.radii, id_neighbors, pair_id, neck, held=held, axis=axis,
                           periodic_box=setup.periodic_box, beyond_domain=beyond_domain)


def connected_components(n, i, j) -> np.ndarray:
    """A label ``[n]`` per particle, equal within each cluster of the contacts ``(i, j)`` (min-label propagation
    with pointer jumping, vectorised: O(contacts) per sweep, a few sweeps)."""
    label = np.arange(n)
    i, j = np.asarray(i, np.int64), np.asarray(j, np.int64)
    while True:
        new = label.copy()
        np.minimum.at(new, i, label[j])
        np.minimum.at(new, j, label[i])
        new = new[new]  # jump: a particle takes its label's label
        if np.array_equal(new, label):
            return label
        label = new


class _ConductivitySetup(typing.NamedTuple):
    physics: object
    centres: np.ndarray
    radii: np.ndarray
    pairs: object
    contacts: object
    hot: np.ndarray
    cold: np.ndarray
    length: float
    area: float
    periodic_box: np.ndarray | None


def _conductivity_setup(centres, radii, axis, law, neck_model, box, periodic_box=None):
    """Host-side geometry of :func:`steady_state_conductivity`: contacts, necks, faces, ``L`` and ``A``."""
    centres = np.asarray(centres, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    periodic_box = _across_axis(periodic_box, centres, radii, axis, box)
    physics, pairs, contacts = _packing_contacts(centres, radii, law, neck_model, periodic_box)
    hot, cold, length, area = _hot_and_cold_faces(centres, radii, pairs, axis, box)
    return _ConductivitySetup(physics, centres, radii, pairs, contacts, hot, cold, length, area, periodic_box)


def _packing_contacts(centres, radii, law, neck_model, periodic_box):
    """``(physics, pairs, contacts)``: the lifted contacts of a packing under ``law``'s neck model (host)."""
    physics = sim_module.Physics(conduction=sim_module.Conduction(law=law, neck_model=neck_model, conductance="lifted"))
    pairs = contact_pairs(centres, radii, periodic_box=periodic_box)
    return physics, pairs, sim_module.lifted_contacts(physics, centres, radii, pairs=pairs)


def _across_axis(periodic_box, centres, radii, axis, box):
    """The periods of a packing periodic across ``axis`` (``[3]``, m), its entry along ``axis`` replaced by
    one no contact wraps around (four times the packing's extent); None stays None."""
    if periodic_box is None:
        return None
    if box is None:
        raise ValueError("periodic_box needs box (its sides across the axis are the periods)")
    periodic_box = np.array(periodic_box, dtype=np.float64)
    if periodic_box.shape != (3,):
        raise ValueError(f"periodic_box must be [3] side lengths; got shape {periodic_box.shape}")
    extent = np.ptp(centres[:, axis]) + 2.0 * float(np.max(radii))
    periodic_box[axis] = 4.0 * extent
    require_positive("periodic_box (m)", periodic_box)
    return periodic_box


def _hot_and_cold_faces(centres, radii, pairs, axis, box):
    """``(hot, cold, L, A)`` of :func:`steady_state_conductivity`'s definition."""
    if box is None:
        if len(pairs.i) == 0:
            raise ValueError("the packing has no contacts")
        half_spacing = 0.5 * float(np.mean(np.linalg.norm(centres[pairs.i] - centres[pairs.j], axis=1)))
        box = (centres.min(axis=0) - half_spacing, centres.max(axis=0) + half_spacing)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in box)
    hot = centres[:, axis] - radii <= lo[axis] + 1e-12 * (hi[axis] - lo[axis])
    cold = centres[:, axis] + radii >= hi[axis] - 1e-12 * (hi[axis] - lo[axis])
    if not hot.any() or not cold.any():
        raise NoFaceLayer(f"no particle reaches the box faces along axis {axis}; check box")
    if np.any(hot & cold):
        raise ValueError("a particle reaches both faces: the packing is too thin along the axis")
    length = float(np.mean(centres[cold, axis]) - np.mean(centres[hot, axis]))
    area = float(np.prod(np.delete(hi - lo, axis)))
    return hot, cold, length, area


def face_layer_box(centres, radii, axis):
    """``(lo, hi)`` (m): the bounding box of the particles' surfaces with its two faces along ``axis`` moved half a
    mean radius inward, so that each face layer (every particle whose surface comes within half a mean radius of the
    outermost) reaches a face and is held by :func:`steady_state_conductivity`: the box of a random packing."""
    centres, radii = np.asarray(centres, np.float64), np.asarray(radii, np.float64)
    lo, hi = (centres - radii[:, None]).min(axis=0), (centres + radii[:, None]).max(axis=0)
    lo[axis] += 0.5 * float(np.mean(radii))
    hi[axis] -= 0.5 * float(np.mean(radii))
    return lo, hi


def steady_state_network_conductivity(centres, radii, pairs, pair_conductance, axis=0, box=None, tol=1e-13, *,
                                      coupling="sphere", kappa=None, neck_radii=None, periodic_box=None,
                                      beyond_domain="refuse", domain=False):
    """``k*`` (W/(m K)) of a packing whose contacts' conductances are given, from one steady solve.

    As :func:`steady_state_conductivity` (same hot and cold sets, ``L`` and
    ``A``), with ``K_ij`` supplied per pair instead of computed from the
    overlaps: necks grown by :mod:`sintercond.laws.sintering`, or any other law.

    Args:
      centres: ``[n, 3]`` (m). radii: ``[n]`` (m).
      pairs: :class:`sintercond.contacts.network.ContactPairs` of the packing.
      pair_conductance: ``[n_pairs]`` ``K_ij`` (W/K) in the order of ``pairs`` (differentiable).
      axis, box, tol: as :func:`steady_state_conductivity`.
      coupling: ``"sphere"`` (default) or ``"none"``, as :func:`steady_state_conductivity`. With ``"sphere"``, each
        ``1/K_ij`` is split between the two spheres as the halves of Rojek et al. (2022), Eq. 43 are
        (``slope kappa_k pi a`` on a shared neck: in the proportion ``1/kappa_k``; equal halves for one
        material), and a contact with ``K_ij = 0`` carries no neck.
      kappa: conductivity (W/(m K)), scalar or ``[n]`` (differentiable); needed by ``"sphere"`` (the Green
        function's scale).
      neck_radii: ``[n_pairs]`` neck radii ``a`` (m) for the domain of ``"sphere"``; default the
        volume-conserving neck of each pair's overlap. They may be traced (necks grown inside a jitted or
        differentiated function) with ``beyond_domain="isolated"``: the domain is then decided in the solve.
      periodic_box: ``[3]`` periods for minimum-image neck directions (``pairs`` found with the same box), as
        :func:`steady_state_conductivity`.
      beyond_domain: ``"refuse"`` or ``"isolated"``, as :func:`steady_state_conductivity`.
      domain: return ``(k*, outside [n] bool)``, the particles outside the domain of point coupling (kept at their
        halves; all False with ``"none"``), as :func:`steady_state_conductivity`.
    """
    _check_coupling(coupling, beyond_domain)
    centres = np.asarray(centres, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    pair_conductance = jnp.asarray(pair_conductance)
    if pair_conductance.shape != (len(pairs.i),):
        raise ValueError(f"pair_conductance must have one value per pair ({len(pairs.i)}); got shape "
                         f"{pair_conductance.shape}")
    hot, cold, length, area = _hot_and_cold_faces(centres, radii, pairs, axis, box)
    # the pair's index (+1; 0 on padding) in both rows of the padded table
    neighbors, slot = ell_table(len(radii), pairs.i, pairs.j, np.arange(1, len(pairs.i) + 1))
    conductance = jnp.concatenate([jnp.zeros((1,), pair_conductance.dtype), pair_conductance])[slot]
    hot_mask = jnp.asarray(hot)
    if coupling == "sphere":
        if kappa is None:
            raise ValueError("coupling='sphere' (the default) needs kappa (W/(m K)): the surface Green function "
                             "scales as 1/kappa; pass kappa=, or coupling='none' for the isolated pipe network")
        if all_concrete(kappa):
            require_positive("kappa (W/(m K))", np.asarray(kappa, np.float64))
        kappa = jnp.broadcast_to(jnp.asarray(kappa, pair_conductance.dtype), radii.shape)
        if neck_radii is None:
            neck_radii = np.where(pairs.overlap > 0, np.asarray(neck_radius(pairs.r_i, pairs.r_j, pairs.overlap)),
                                  0.0)
        held = np.where(hot, 1, np.where(cold, 2, 0))
        box_periods = _across_axis(periodic_box, centres, radii, axis, box)
        if beyond_domain == "isolated":  # every pair may carry a neck; which do, and the domain, in the solve
            geometry = _network_geometry(centres, radii, neighbors, slot, held, axis, box_periods)
        elif all_concrete(neck_radii):
            geometry = sphere_geometry(centres, radii, neighbors, slot,
                                       np.concatenate([[0.0], np.asarray(neck_radii, np.float64)])[slot], held=held,
                                       axis=axis, periodic_box=box_periods)
        else:
            raise ValueError("neck_radii are traced (under jit, vmap or grad): the domain of point coupling cannot "
                             "be checked on the host; pass beyond_domain='isolated' (a sphere whose necks' discs "
                             "overlap keeps the pair law's halves) or coupling='none'")
        neck = jnp.concatenate([jnp.zeros((1,), pair_conductance.dtype),
                                jnp.asarray(neck_radii, pair_conductance.dtype)])[slot]
        q, _, outside = _compiled_network_coupled_solve(tol)(geometry, conductance, jnp.asarray(neighbors),
                                                             jnp.asarray(radii), kappa, neck, jnp.asarray(hot | cold),
                                                             hot_mask)
        return (q * length / area, outside) if domain else q * length / area
    q, _ = _compiled_network_solve(tol)(jnp.asarray(neighbors, dtype=jnp.int32), conductance, jnp.asarray(hot | cold),
                                        hot_mask)
    return (q * length / area, np.zeros(len(radii), bool)) if domain else q * length / area
