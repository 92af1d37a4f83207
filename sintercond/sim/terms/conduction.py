"""The conduction term: heat through the contacts of a thermal step and the temperature update.

The pipe network of Rojek et al. (2022), Eqs. 1-4: capacities ``C_i = m_i c`` (Eq. 1), heat ``K_ij (T_j - T_i)``
through each contact (Eq. 3), explicit Euler (:func:`sintercond.sim.thermal.explicit_update`), the enthalpy step of a
specific-heat table (:func:`sintercond.sim.thermal.enthalpy_update`) or backward Euler
(:func:`sintercond.sim.thermal.backward_euler_solve`). Its parameters are ``Params.conductivity``,
``Params.specific_heat``, ``Params.law`` and ``Params.held_ramp``; held particles end every step at their fixed
temperature or on their ramp (Rizza & Galati 2024, Eq. 6).

Every function takes the static :class:`~sintercond.sim.physics.Physics` first; :func:`sintercond.sim.step.simulator`
closes over it.
"""

from __future__ import annotations

import dataclasses
import functools

import jax.numpy as jnp

from sintercond.sim import mechanics, thermal
from sintercond.contacts.network import network_laplacian
from sintercond.contacts.pair_list import pair_sum
from sintercond.sim.contacts import (conductivity_lookup, follow_contacts, merged_law_params, neck_conductance,
                                     pair_conductance, pair_heat_power, sintered_pair_conductance)
from sintercond.sim.physics import Physics
from sintercond.sim.state import Params, Prepared, SimState, held_ramp_temperature, params_in_precision
from sintercond.sim.terms import coupling, sources, walls
from sintercond.state import ParticleState, heat_capacity


def particle_capacity(physics: Physics, params: Params, particles: ParticleState):
    """Heat capacities ``C_i = m_i c`` (J/K), Rojek et al. (2022) Eq. 1: ``c`` of each particle's material, or with
    ``Conduction.specific_heat_table`` the table at each particle's temperature."""
    if physics.conduction.specific_heat_table:
        return particles.mass * params.specific_heat(particles.temperature)
    return heat_capacity(particles, params.specific_heat)


def conductances_change(physics: Physics) -> bool:
    """Whether a static lifted table's conductances change during a rollout (growing necks, kappa(T))."""
    return physics.sintering is not None or physics.conduction.conductivity_table


def fast_static_step(physics: Physics) -> bool:
    """Whether the step is the static explicit update with the network inside it (its reverse mode written for the
    CPU, the conduction rates computed once per rollout)."""
    c = physics.conduction
    return (c.integrator == "explicit" and physics.contacts == "static" and not c.specific_heat_table
            and not coupling.on(physics))


def prepare(physics: Physics, state: SimState, params: Params) -> Prepared:
    """What a rollout computes once from ``(state, params)``: capacities, static conductances, wall conductances."""
    particles, contacts = state.particles, state.contacts
    params = params_in_precision(params, particles.temperature.dtype)
    capacity = particle_capacity(physics, params, particles)
    wall_k = wall_t = None
    if physics.conduction.conductance == "table":
        conductance, scale = contacts.conductance, jnp.atleast_1d(jnp.asarray(params.conductivity))[0]
        if physics.conduction.conducting_walls:
            wall_k, wall_t = contacts.wall_conductance[None], contacts.wall_temperature[None]
    else:
        law_params = merged_law_params(physics, params)
        scale = jnp.ones((), capacity.dtype)
        conductance = None
        if physics.contacts == "static" and not conductances_change(physics):
            conductance = neck_conductance(physics, state, params)
        if physics.conduction.conducting_walls:
            wall_k = walls.wall_lift(physics, particles, contacts, params, law_params)
            wall_t = contacts.wall_temperature[:, None]
    rates = None
    if fast_static_step(physics) and physics.mechanics is None:
        # computed once per rollout: reverse mode then accumulates their cotangents per particle
        rates = thermal.conduction_rates(scale, capacity)
    blocks = None
    if coupling.on(physics) and not coupling.blocks_change(physics):
        blocks = coupling.neck_blocks(physics, state, params)
    return Prepared(params, capacity, conductance, scale, wall_k, wall_t, rates, blocks)


def conduction_power(physics: Physics, state: SimState, prep: Prepared, temperature, conductance, neighbors):
    """Heat into each particle through the contacts (None: walls only) and conducting walls (W).

    Dynamic contacts: a half pair list ``[c, 2]`` and its conductances ``[c]``; static: the table.
    """
    power = jnp.zeros_like(temperature)
    if coupling.on(physics):
        power = coupling.contact_power(physics, state, coupling.current_blocks(physics, state, prep))[0]
    elif conductance is not None and physics.contacts == "dynamic":
        power = pair_heat_power(conductance, neighbors, temperature)
    elif conductance is not None:
        power = -prep.scale * network_laplacian(conductance, neighbors, temperature)
    if physics.conduction.conducting_walls:
        power = power + walls.thermal_wall_power(physics, state, prep, temperature)
    return power


def current_network(physics: Physics, neighbor_fn, state: SimState, prep: Prepared):
    """``(state, conductance, neighbors)`` at this step: static tables, or the dynamic list updated."""
    if physics.contacts == "static":
        conductance = neck_conductance(physics, state, prep.params) if conductances_change(physics) else prep.conductance
        return state, conductance, state.contacts.neighbors
    particles, contacts = state.particles, state.contacts
    if physics.motion is not None:
        positions = physics.motion(state.time).astype(particles.positions.dtype)
        particles = dataclasses.replace(particles, positions=positions)
    contacts, _, overflow = follow_contacts(neighbor_fn, particles.positions, particles.radii, contacts)
    geometry = mechanics.pair_geometry(particles.positions, particles.radii, contacts.pairs.pairs)
    index, kappa = conductivity_lookup(physics, prep.params, particles)
    conductance = pair_conductance(physics, particles.radii, index, geometry, kappa,
                                   merged_law_params(physics, prep.params))
    state = dataclasses.replace(state, particles=particles, overflow=state.overflow | overflow, contacts=contacts)
    return state, conductance, contacts.pairs.pairs


def heat_power(physics: Physics, neighbor_fn, state: SimState, prep: Prepared, conductance=None, neighbors=None):
    """Heat power into every particle (W): conduction, walls and sources at the state's time."""
    if conductance is None:
        state, conductance, neighbors = current_network(physics, neighbor_fn, state, prep)
    temperature = state.particles.temperature
    power = conduction_power(physics, state, prep, temperature, conductance, neighbors)
    return power + sources.power(physics, state, prep.params)


def total_conductance(physics: Physics, state: SimState, prep: Prepared):
    """``[n]`` each particle's ``sum_j K_ij + sum_w K_iw`` (W/K) at the state's contacts, necks and temperatures:
    the denominator of the explicit limit ``C_i / sum K`` (:func:`sintercond.sim.thermal.explicit_stability_limit`).

    Static contacts: the table's rows (the rollout's conductances, or the necks' now) and the conducting walls.
    Dynamic contacts: the half pair list at the state's positions (with the mechanics' sintered necks, the
    geometry they conduct through, :func:`sintercond.sim.contacts.sintered_pair_conductance`) and the
    conducting walls of ``Mechanics.walls`` the particles touch now."""
    particles = state.particles
    if coupling.on(physics):
        return coupling.stability_conductance(coupling.current_blocks(physics, state, prep))
    if physics.contacts == "static":
        conductance = neck_conductance(physics, state, prep.params) if conductances_change(physics) else prep.conductance
        total = prep.scale * jnp.sum(conductance, axis=1)
        if physics.conduction.conducting_walls:
            total = total + prep.scale * jnp.sum(walls.thermal_wall_conductance(physics, state, prep), axis=0)
        return total
    index, kappa = conductivity_lookup(physics, prep.params, particles)
    law_params = merged_law_params(physics, prep.params)
    if state.mechanics is not None and state.mechanics.neck is not None:
        _, k = sintered_pair_conductance(physics, state, prep.params)
    else:
        geometry = mechanics.pair_geometry(particles.positions, particles.radii, state.contacts.pairs.pairs)
        k = pair_conductance(physics, particles.radii, index, geometry, kappa, law_params)
    total = pair_sum(k, k, state.contacts.pairs.pairs, particles.radii.shape[0])
    if physics.mechanics is not None:
        conducting = [wall for _, wall in walls.conducting_mechanical_walls(physics)]
        if conducting:
            h = mechanics.wall_penetration(conducting, particles.positions, particles.radii, state.time)
            for w in range(len(conducting)):
                total = total + walls.mechanical_wall_conductance(physics, particles.radii, h[w], kappa[index],
                                                                  law_params)
    return total


def capacity_now(physics: Physics, state: SimState, prep: Prepared):
    """The capacities (J/K) at this step: the rollout's, or with a specific-heat table at today's temperatures."""
    if physics.conduction.specific_heat_table:
        return particle_capacity(physics, prep.params, state.particles)
    return prep.capacity


def held_temperature(physics: Physics, state: SimState, prep: Prepared):
    """The held particles' temperatures at the end of the step (K): fixed, or on their ramp."""
    fixed = state.particles.fixed_temperature
    if not physics.conduction.held_ramp:
        return fixed
    return held_ramp_temperature(prep.params.held_ramp, fixed, state.time + state.dt)


def explicit_heat(physics: Physics, state: SimState, prep: Prepared, power):
    """The temperatures after an explicit step with heat power ``power`` (W) in: ``T + dt P / C``, or with a
    specific-heat table the enthalpy's step (:func:`sintercond.sim.thermal.enthalpy_update`)."""
    particles = state.particles
    fixed = particles.fixed if physics.conduction.held else None
    if physics.conduction.specific_heat_table:
        return thermal.enthalpy_update(particles.temperature, power, particles.mass, state.dt,
                                       prep.params.specific_heat, fixed, held_temperature(physics, state, prep))
    return thermal.explicit_update(particles.temperature, power, prep.capacity, state.dt, fixed,
                                   held_temperature(physics, state, prep))


def advance(physics: Physics, neighbor_fn, state: SimState, prep: Prepared) -> SimState:
    """One thermal step: the contacts at this step, then the temperatures (explicit, enthalpy or backward Euler)."""
    state, conductance, neighbors = current_network(physics, neighbor_fn, state, prep)
    particles = state.particles
    fixed = particles.fixed if physics.conduction.held else None
    c = physics.conduction
    if fast_static_step(physics):
        # the network term inside the update, whose reverse mode is written for the CPU; the pulse apart (its
        # switch, a scalar, is what reverse mode stores per step) and no field of zeros without walls or sources
        terms, pulse = sources.power_parts(physics, state, prep.params)
        if c.conducting_walls:
            terms = [conduction_power(physics, state, prep, particles.temperature, None, None)] + terms
        power = functools.reduce(jnp.add, terms) if terms else jnp.zeros((), particles.temperature.dtype)
        temperature = thermal.explicit_update(particles.temperature, power, prep.capacity, state.dt, fixed,
                                              held_temperature(physics, state, prep),
                                              network=(prep.scale, conductance, neighbors), pulse=pulse,
                                              rates=prep.rates)
    elif coupling.on(physics):
        power, correction, _ = coupling.contact_power(physics, state, coupling.current_blocks(physics, state, prep))
        temperature = explicit_heat(physics, state, prep, power + sources.power(physics, state, prep.params))
        state = coupling.with_necks(state, correction)
    elif c.integrator == "explicit":
        power = heat_power(physics, neighbor_fn, state, prep, conductance, neighbors)
        temperature = explicit_heat(physics, state, prep, power)
    else:
        wall_k = prep.wall_conductance
        temperature = thermal.backward_euler_solve(
            particles.temperature, lambda x: prep.scale * network_laplacian(conductance, neighbors, x),
            None if wall_k is None else prep.scale * jnp.sum(wall_k, axis=0),
            None if wall_k is None else prep.scale * jnp.sum(wall_k * prep.wall_temperature, axis=0),
            prep.capacity, state.dt, fixed, held_temperature(physics, state, prep), c.implicit_tol)
    return dataclasses.replace(state, particles=dataclasses.replace(particles, temperature=temperature),
                               step=state.step + 1)
