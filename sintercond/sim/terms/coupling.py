"""The coupled-neck term: heat through necks that share a sphere, in the explicit step (``Conduction.coupling="sphere"``).

The network of :mod:`sintercond.contacts.sphere_coupling`: per sphere ``s`` the neck conductance block
``C_s = R_s^{-1}`` (W/K; Eqs. 2-4, with the transient's net-flow term, Eq. 5), one massless temperature per neck
(contact), the coupled operator ``A = sum_s B_s^T C_s B_s`` over sphere and neck temperatures. The neck
temperatures ``x`` balance the sphere temperatures ``T``: ``A_nn x = -A_ns T`` (no net heat into a neck).

Why no per-sphere elimination: every neck belongs to two spheres, so ``A_nn`` couples the necks of neighbouring
spheres and its inverse is dense over a connected packing; only the blocks ``C_s`` are per sphere (computed once
per rollout in :func:`neck_blocks`, or at every step while necks grow or the conductivities follow a table).

The step. The neck temperatures are written ``x = x_iso(T) + d``: ``x_iso`` the isolated network's (each neck
between its two spheres in the proportion of its halves' resistances, :func:`isolated_necks`), ``d`` the
coupling's correction, carried from step to step (``LiftedContacts.neck_correction``). Each step takes
:data:`NECK_SWEEPS` Jacobi-preconditioned conjugate-gradient iterations on the balance from ``x_iso(T^n) + d^(n-1)``
(:func:`neck_sweeps`), then

1. the heat through each contact is the mean of its two spheres' outflows into its neck
   (:func:`sintercond.contacts.sphere_coupling.mean_flow`), added to one sphere and taken from the other:
   heat is conserved to round-off whatever the balance's residual;
2. explicit Euler on the sphere temperatures, with the sources and held particles as in the isolated step.

The correction lags: it is what one sweep a step makes of last step's, so its error is set by how much ``T``
moved in one step, first order in ``dt`` as explicit Euler's own error. On a chain the correction is 0 and stays 0:
the run is the isolated network's to round-off; on the simple-cubic block heated along an axis (where the converged
balance is the isolated network too) the side necks follow the spheres' stored heat (Eq. 5) one sweep behind, 0.1 %
of Euler's own error. A steady state is exact (the balance's fixed point). On a random 12-sphere cluster from a
random field, 30 steps at 0.9 of the stable step: 0.27 mK against the balance solved at every step, where
Euler's own error (against ten times smaller steps) is 0.36 K; 32 times less at a tenth of the step
(``tests/test_sphere_coupling_transient.py``). The iterations are a fixed number of plain
operations (no loop to a tolerance), so reverse mode differentiates the discrete map exactly: the correction is part
of the carried state, with its derivative.

Stability: :func:`stability_conductance`, half of ``1^T C_s 1``, in the place of the isolated ``sum_j K_ij``:
``dt <= 2 C_s / (1^T C_s 1)`` (:func:`sintercond.contacts.sphere_coupling.block_total`). The bound is proved for
balanced necks; with the lagged sweep it is tested, not proved (the alternating mode of a periodic BCC lattice at
the bound, an FCC block at the bound).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp

from sintercond._numerics import safe_divide
from sintercond.contacts.pair_list import pair_exchange
from sintercond.contacts.sphere_coupling import (at_necks, block_total, coupled_blocks, half_resistances, mean_flow,
                                                 SphereGeometry, slot_diagonal, slot_flows)
from sintercond.sim.contacts import conductivity_lookup, merged_law_params, neck_conductance
from sintercond.sim.physics import Physics
from sintercond.sim.state import Params, SimState

NECK_SWEEPS = 1
"""Conjugate-gradient iterations on the neck balance a step (module docstring: the lag error this leaves)."""


def on(physics: Physics) -> bool:
    """Whether the necks are coupled through their spheres."""
    return physics.conduction.coupling == "sphere"


class NeckNetwork(NamedTuple):
    """The coupled necks of a lifted state at its necks now (:func:`neck_blocks`)."""

    geometry: SphereGeometry  # the contacts', with only the necks that conduct now coupled
    blocks: tuple  # C_s (W/K), packed (sintercond.contacts.sphere_coupling.conductance_blocks)
    split: jax.Array  # [p] the first sphere's share of each contact's resistance
    ends: jax.Array  # [p, 2] int, each contact's two spheres (its slots' rows)
    preconditioner: jax.Array  # [p] (K/W) the inverse of the neck balance's diagonal, 1 on a neck in no block


def neck_blocks(physics: Physics, state: SimState, params: Params) -> NeckNetwork:
    """The :class:`NeckNetwork` of a static lifted state at its necks now: the pair law on each neck, its
    resistance split between the two spheres (:func:`sintercond.contacts.sphere_coupling.half_resistances`), the
    blocks inverted; a neck grows from zero under sintering and is coupled once it conducts."""
    contacts, p = state.contacts, state.particles
    index, kappa = conductivity_lookup(physics, params, p)
    kappa = kappa[index]
    law_params = merged_law_params(physics, params)
    conductance = neck_conductance(physics, state, params)
    geometry = contacts.sphere
    coupled = geometry.coupled & (conductance > 0)
    geometry = dataclasses.replace(geometry, coupled=coupled,
                                   neck_fixed=~jnp.any(coupled.reshape(-1)[geometry.neck_slots], axis=1))
    half = half_resistances(physics.conduction.law, p.radii, contacts.neighbors, contacts.table_neck,
                            contacts.table_overlap, kappa, law_params, conductance)
    halves = half.reshape(-1)[geometry.neck_slots]
    split = safe_divide(halves[:, 0], halves[:, 0] + halves[:, 1], fill=0.5)
    blocks = coupled_blocks(geometry, half, p.radii, kappa, contacts.table_neck)
    diagonal = jnp.sum(at_necks(geometry, slot_diagonal(blocks)), axis=1)
    return NeckNetwork(geometry, blocks, split, geometry.neck_slots // geometry.coupled.shape[1],
                       safe_divide(1.0, jnp.where(geometry.neck_fixed, 1.0, diagonal), fill=1.0))


def blocks_change(physics: Physics) -> bool:
    """Whether the blocks change during a rollout: necks that grow, or conductivities at the temperatures now."""
    return physics.sintering is not None or physics.conduction.conductivity_table


def current_blocks(physics: Physics, state: SimState, prep):
    """:func:`neck_blocks` at this step: the rollout's, or with growing necks or a conductivity table the
    state's now."""
    return neck_blocks(physics, state, prep.params) if blocks_change(physics) else prep.neck_blocks


def isolated_necks(network: NeckNetwork, temperature):
    """``[p]`` the isolated network's neck temperatures (K): ``T_a - split (T_a - T_b)`` for a contact between
    spheres ``a`` and ``b``, ``split`` the share of its resistance on ``a``; 0 on a neck in no block."""
    t = temperature[network.ends]
    return jnp.where(network.geometry.neck_fixed, 0.0, t[:, 0] - network.split * (t[:, 0] - t[:, 1]))


def neck_sweeps(network: NeckNetwork, temperature, correction, sweeps):
    """``(flow [p], correction [p], relative residual)``: the heat through each contact (W, first sphere to second,
    :func:`sintercond.contacts.sphere_coupling.mean_flow`) at the neck temperatures left by ``sweeps``
    iterations of Jacobi-preconditioned conjugate gradients on the balance ``A_nn x = -A_ns T`` from
    ``x_iso(T) + correction`` (module docstring); the new correction ``x - x_iso(T)``; and the balance's residual
    relative to its value at the start (0 when the balance is met).

    Solved for ``x - mean(T)`` (the temperature differences set the scale, not the level). One product with the
    blocks for the start and one per sweep (the slots' outflows are updated with the iterate). A fixed number of
    plain operations: differentiable in every input, the correction included; with as many sweeps as necks it is
    the exact solve (conjugate gradients in exact arithmetic).
    """
    geometry, blocks, inverse = network.geometry, network.blocks, network.preconditioner
    shifted = temperature - jnp.mean(temperature)
    base = isolated_necks(network, shifted)
    x = base + jnp.where(geometry.neck_fixed, 0.0, correction.astype(temperature.dtype))
    q = slot_flows(geometry, blocks, shifted, x)
    r = jnp.sum(at_necks(geometry, q), axis=1)  # the net heat into each neck, 0 when balanced
    start = jnp.linalg.norm(r)
    z = inverse * r

    def sweep(_, carry):
        x, q, r, direction, rz = carry
        product = slot_flows(geometry, blocks, jnp.zeros_like(shifted), -direction)  # C_s d_N(s)
        image = jnp.sum(at_necks(geometry, product), axis=1)  # A_nn d
        alpha = safe_divide(rz, jnp.vdot(direction, image))
        r = r - alpha * image
        z = inverse * r
        rz_next = jnp.vdot(r, z)
        return (x + alpha * direction, q - alpha * product, r, z + safe_divide(rz_next, rz) * direction, rz_next)

    carry = (x, q, r, z, jnp.vdot(r, z))
    for k in range(sweeps):
        carry = sweep(k, carry)
    x, q, r, _, _ = carry
    residual = jax.lax.stop_gradient(safe_divide(jnp.linalg.norm(r), start))
    return mean_flow(at_necks(geometry, q)), x - base, residual


def contact_power(physics: Physics, state: SimState, network):
    """``(power [n], neck correction [p], residual)``: heat into each sphere (W) through its coupled necks, and
    what :func:`neck_sweeps` leaves of the balance; ``network``: :func:`neck_blocks`."""
    contacts, temperature = state.contacts, state.particles.temperature
    flow, correction, residual = neck_sweeps(network, temperature, contacts.neck_correction, NECK_SWEEPS)
    return pair_exchange(-flow, contacts.pairs, temperature.shape[0]), correction, residual


def with_necks(state: SimState, correction) -> SimState:
    """``state`` with the step's neck correction (carried with its derivative: the next step starts from it)."""
    contacts = state.contacts
    return dataclasses.replace(state, contacts=dataclasses.replace(
        contacts, neck_correction=correction.astype(contacts.neck_correction.dtype)))


def stability_conductance(network):
    """``[n]`` (W/K): the denominator of the explicit limit ``C_s / (1^T C_s 1 / 2)`` in place of ``sum_j K_ij``;
    ``network``: :func:`neck_blocks`."""
    return 0.5 * block_total(network.geometry, network.blocks)
