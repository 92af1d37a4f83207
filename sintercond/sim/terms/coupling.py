"""The coupled-neck term: heat through necks that share a sphere, in the explicit step (``Conduction.coupling="sphere"``).

The network of :mod:`sintercond.contacts.sphere_coupling`: per sphere ``s`` the neck conductance block
``C_s = R_s^{-1}`` (W/K; Eqs. 2-4, with the transient's net-flow term, Eq. 5), one massless temperature per neck
(contact), the coupled operator ``A = sum_s B_s^T C_s B_s`` over sphere and neck temperatures. Each step:

1. the neck temperatures balance the spheres' temperatures ``T^n``: ``A_nn x = -A_ns T^n`` (the net heat into
   every neck is zero), by conjugate gradients with a Jacobi preconditioner, warm-started from the last step's
   necks (``LiftedContacts.neck_temperature``), solved for ``x - mean(T)`` to :data:`NECK_TOLERANCE` relative
   to its right-hand side (the temperature differences set the scale, not the temperature level);
2. the heat through each contact is the mean of its two spheres' outflows into its neck
   (:func:`sintercond.contacts.sphere_coupling.contact_flows`), added to one sphere and taken from the other:
   heat is conserved to round-off whatever the solve's residual;
3. explicit Euler on the sphere temperatures, with the sources and held particles as in the isolated step.

Why an iterative neck solve and not a per-sphere elimination: every neck belongs to two spheres, so ``A_nn``
couples the necks of neighbouring spheres and its inverse is dense over a connected packing; the neck
temperatures cannot be eliminated sphere by sphere exactly (only the blocks ``C_s`` are per sphere, computed once
per rollout in :func:`neck_blocks`, or at every step while necks grow). The solve is ``jax.scipy.sparse.linalg.cg``,
a ``custom_linear_solve``: gradients are those of the exact solve, with no derivative through the warm start. A
step whose solve ends above ten times the tolerance (it ran out of iterations) is recorded in
``LiftedContacts.neck_residual``, which the rollout's host check refuses (:func:`check_neck_solve`).

Stability: :func:`stability_conductance`, half of ``1^T C_s 1``, in the place of the isolated ``sum_j K_ij``:
``dt <= 2 C_s / (1^T C_s 1)`` (:func:`sintercond.contacts.sphere_coupling.block_total`).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from jax.scipy.sparse.linalg import cg

from sintercond._numerics import safe_divide
from sintercond.contacts.pair_list import pair_exchange
from sintercond.contacts.sphere_coupling import (block_total, contact_flows, coupled_blocks, half_resistances,
                                                 neck_balance)
from sintercond.sim.contacts import conductivity_lookup, merged_law_params, neck_conductance
from sintercond.sim.physics import Physics
from sintercond.sim.state import Params, SimState

NECK_TOLERANCE = {"float64": 1e-12, "float32": 1e-5}
"""Relative residual of the neck solve, per float type."""


def on(physics: Physics) -> bool:
    """Whether the necks are coupled through their spheres."""
    return physics.conduction.coupling == "sphere"


def neck_blocks(physics: Physics, state: SimState, params: Params):
    """``(geometry, C_s [n, m, m])`` (W/K) of a static lifted state at its necks now: the pair law on each neck, its
    resistance split between the two spheres (:func:`sintercond.contacts.sphere_coupling.half_resistances`), the
    blocks inverted; ``geometry`` the contacts' with only the necks that conduct now coupled (a neck grows from
    zero under sintering)."""
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
    return geometry, coupled_blocks(geometry, half, p.radii, kappa)


def current_blocks(physics: Physics, state: SimState, prep):
    """:func:`neck_blocks` at this step: the rollout's, or with growing necks the state's now."""
    return neck_blocks(physics, state, prep.params) if physics.sintering is not None else prep.neck_blocks


def neck_temperatures(geometry, blocks, temperature, guess):
    """``(x [p], relative residual)``: the neck temperatures (K) that balance the sphere temperatures.

    Conjugate gradients on ``A_nn (x - t) = -A_ns (T - t)``, ``t`` the mean sphere temperature, from ``guess``.
    """
    tol = NECK_TOLERANCE["float64" if temperature.dtype == jnp.float64 else "float32"]
    level = jnp.mean(temperature)
    shifted = temperature - level
    zero = jnp.zeros_like(guess)
    rhs = -neck_balance(geometry, blocks, shifted, zero)

    def matvec(x):
        return neck_balance(geometry, blocks, jnp.zeros_like(shifted), x)

    diagonal = jnp.sum(jnp.diagonal(blocks, axis1=1, axis2=2).reshape(-1)[geometry.neck_slots], axis=1)
    inverse = safe_divide(1.0, jnp.where(geometry.neck_fixed, 1.0, diagonal), fill=1.0)
    start = jnp.where(geometry.neck_fixed, 0.0, guess.astype(temperature.dtype) - level)
    x, _ = cg(matvec, rhs, x0=start, tol=tol, maxiter=2 * guess.shape[0] + 10, M=lambda r: inverse * r)
    residual = jax.lax.stop_gradient(safe_divide(jnp.linalg.norm(rhs - matvec(x)), jnp.linalg.norm(rhs)))
    return x + level, residual


def contact_power(physics: Physics, state: SimState, network):
    """``(power [n], neck temperatures [p], residual)``: heat into each sphere (W) through its coupled necks;
    ``network``: ``(geometry, blocks)`` of :func:`neck_blocks`."""
    contacts, temperature = state.contacts, state.particles.temperature
    geometry, blocks = network
    x, residual = neck_temperatures(geometry, blocks, temperature, contacts.neck_temperature)
    flow = contact_flows(geometry, blocks, temperature, x)
    return pair_exchange(-flow, contacts.pairs, temperature.shape[0]), x, residual


def with_necks(state: SimState, neck_temperature, residual) -> SimState:
    """``state`` with the step's neck temperatures, and the largest residual so far."""
    contacts = state.contacts
    tol = NECK_TOLERANCE["float64" if state.particles.temperature.dtype == jnp.float64 else "float32"]
    worst = jnp.maximum(contacts.neck_residual, jnp.where(residual > 10.0 * tol, residual, 0.0).astype(
        contacts.neck_residual.dtype))
    return dataclasses.replace(state, contacts=dataclasses.replace(
        contacts, neck_temperature=jax.lax.stop_gradient(neck_temperature).astype(contacts.neck_temperature.dtype),
        neck_residual=worst))


def stability_conductance(network):
    """``[n]`` (W/K): the denominator of the explicit limit ``C_s / (1^T C_s 1 / 2)`` in place of ``sum_j K_ij``;
    ``network``: ``(geometry, blocks)`` of :func:`neck_blocks`."""
    return 0.5 * block_total(network[1])


def check_neck_solve(state: SimState) -> None:
    """Raise ``FloatingPointError`` if a neck solve of the run ended above ten times its tolerance (host check)."""
    contacts = state.contacts
    residual = getattr(contacts, "neck_residual", None)
    if residual is not None and float(residual) > 0.0:
        raise FloatingPointError(f"the coupled neck solve ended at relative residual {float(residual):.3g} by step "
                                 f"{int(state.step)} (tolerance {NECK_TOLERANCE}): its conjugate gradients ran out of "
                                 "iterations; the neck temperatures are not balanced")
