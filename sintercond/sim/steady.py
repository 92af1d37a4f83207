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

import typing

import jax.numpy as jnp
import numpy as np
from jax.scipy.sparse.linalg import cg

from sintercond import simulate as sim_module
from sintercond._validation import all_concrete
from sintercond.laws.conductance import validate_pair_conductance_inputs
from sintercond.contacts.network import ContactTable, contact_pairs, ell_table, heat_inflow, laplacian, wall_inflow


def steady_state(table: ContactTable, fixed_mask, fixed_temperature, tol=1e-13):
    """Steady temperatures with the ``fixed_mask`` particles held at ``fixed_temperature``.

    Solves ``(L T)_i = K_iw T_w`` on free particles by conjugate gradients
    (conducting walls, if the table has them, act like held neighbours). Free
    particles not connected to any held one have no defined temperature; they
    come out at 0.
    """
    fixed_mask = jnp.asarray(fixed_mask)
    held = jnp.where(fixed_mask, jnp.asarray(fixed_temperature, table.conductance.dtype), 0.0)

    def matvec(x):
        return jnp.where(fixed_mask, 0.0, laplacian(jnp.where(fixed_mask, 0.0, x), table))

    rhs = jnp.where(fixed_mask, 0.0, wall_inflow(table, held.dtype) - laplacian(held, table))
    solution, _ = cg(matvec, rhs, tol=tol, maxiter=10 * fixed_mask.shape[0])
    return jnp.where(fixed_mask, held, solution)


def steady_state_conductivity(centres, radii, kappa, axis=0, *, law="rojek", params=None, neck_model=None,
                              box=None, tol=1e-13, field=False):
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
    setup = _conductivity_setup(centres, radii, axis, law, neck_model, box)
    concrete = all_concrete(kappa, params)
    if concrete:
        validate_pair_conductance_inputs(law, setup.pairs.r_i, setup.pairs.r_j, setup.pairs.overlap,
                                         np.broadcast_to(np.asarray(kappa, np.float64), setup.radii.shape)[setup.pairs.i],
                                         np.broadcast_to(np.asarray(kappa, np.float64), setup.radii.shape)[setup.pairs.j],
                                         params, neck_model)
    physics = setup.physics
    n = len(setup.radii)
    kappa = jnp.broadcast_to(jnp.asarray(kappa, float), (n,))
    conductance = sim_module.conductance_lift(
        physics, jnp.asarray(setup.radii), jnp.arange(n, dtype=jnp.int32), setup.contacts, kappa,
        sim_module.merged_law_params(
            physics, sim_module.Params(kappa, kappa, law={} if params is None else dict(params))))
    table = ContactTable(setup.contacts.neighbors, conductance)
    hot = jnp.asarray(setup.hot)
    temperature = steady_state(table, jnp.asarray(setup.hot | setup.cold), jnp.where(hot, 1.0, 0.0), tol=tol)
    q = -jnp.sum(jnp.where(hot, heat_inflow(temperature, table), 0.0))
    k_star = q * setup.length / setup.area
    k_star = float(k_star) if concrete else k_star
    if not field:
        return k_star
    held = setup.hot | setup.cold
    label = connected_components(n, setup.pairs.i, setup.pairs.j)
    reached = np.isin(label, label[held])
    return k_star, jnp.where(jnp.asarray(reached), temperature, jnp.nan)


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
    radii: np.ndarray
    pairs: object
    contacts: object
    hot: np.ndarray
    cold: np.ndarray
    length: float
    area: float


def _conductivity_setup(centres, radii, axis, law, neck_model, box):
    """Host-side geometry of :func:`steady_state_conductivity`: contacts, necks, faces, ``L`` and ``A``."""
    centres = np.asarray(centres, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    physics = sim_module.Physics(conduction=sim_module.Conduction(law=law, neck_model=neck_model, conductance="lifted"))
    pairs = contact_pairs(centres, radii)
    hot, cold, length, area = _hot_and_cold_faces(centres, radii, pairs, axis, box)
    contacts = sim_module.lifted_contacts(physics, centres, radii, pairs=pairs)
    return _ConductivitySetup(physics, radii, pairs, contacts, hot, cold, length, area)


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
        raise ValueError(f"no particle reaches the box faces along axis {axis}; check box")
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


def steady_state_network_conductivity(centres, radii, pairs, pair_conductance, axis=0, box=None, tol=1e-13):
    """``k*`` (W/(m K)) of a packing whose contacts' conductances are given, from one steady solve.

    As :func:`steady_state_conductivity` (same hot and cold sets, ``L`` and
    ``A``), with ``K_ij`` supplied per pair instead of computed from the
    overlaps: necks grown by :mod:`sintercond.laws.sintering`, or any other law.

    Args:
      centres: ``[n, 3]`` (m). radii: ``[n]`` (m).
      pairs: :class:`sintercond.contacts.network.ContactPairs` of the packing.
      pair_conductance: ``[n_pairs]`` ``K_ij`` (W/K) in the order of ``pairs`` (differentiable).
      axis, box, tol: as :func:`steady_state_conductivity`.
    """
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
    table = ContactTable(jnp.asarray(neighbors, dtype=jnp.int32), conductance)
    hot_mask = jnp.asarray(hot)
    temperature = steady_state(table, jnp.asarray(hot | cold), jnp.where(hot_mask, 1.0, 0.0), tol=tol)
    q = -jnp.sum(jnp.where(hot_mask, heat_inflow(temperature, table), 0.0))
    return q * length / area
