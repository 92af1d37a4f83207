"""The sintering term: necks that grow with each contact's temperature history (:mod:`sintercond.sim.neck_growth`).

At the end of every growth interval (``Sintering.every`` steps) each neck grows over the interval at its pair's
temperatures (Rojek et al. 2022's volume-conserving geometry; the kinetic laws of :mod:`sintercond.laws.sintering`),
independently or by the many-body balance that moves the particles, and the explicit step is checked against the
stability limit on the grown necks (a flag in ``NeckState.unstable``, refused on the host). Without mechanics the
necks are the static table's (``LiftedContacts.neck``); with mechanics they live on the dynamic half pair list
(``MechanicalState.neck``). Its parameters are ``Params.sintering``.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from sintercond.sim import mechanics, neck_growth, thermal
from sintercond.contacts.pair_list import pair_sum
from sintercond.sim.contacts import conductivity_lookup, merged_law_params, neck_conductance, sintered_pair_conductance
from sintercond.sim.physics import Physics
from sintercond.sim.state import Prepared, SimState
from sintercond.sim.terms import conduction, walls


def _at_interval_end(spec, state: SimState, grow, *carried):
    """``grow(*carried)`` at the end of a growth interval, ``carried`` unchanged otherwise."""
    if spec.every == 1:
        return grow(*carried)
    return jax.lax.cond(neck_growth.update_interval(spec, state.step), grow, lambda *kept: kept, *carried)


def _next_interval(physics: Physics, state: SimState, prep: Prepared, carried, particles, total):
    """``carried`` (a :class:`sintercond.sim.neck_growth.NeckState`) starting the next interval, flagged unstable when the
    step exceeds the explicit limit ``C_i / sum K`` on the grown conductances ``total`` ``[n]`` (W/K)."""
    if physics.conduction.held:  # held particles are reset every step: their rows do not count
        total = jnp.where(particles.fixed, 0.0, total)
    limit = thermal.explicit_stability_limit(conduction.capacity_now(physics, state, prep), total)
    return dataclasses.replace(carried, interval_temperature=particles.temperature, interval_start=state.step,
                               unstable=carried.unstable | jnp.any(state.dt > limit))


def grow_table_necks(physics: Physics, state: SimState, prep: Prepared) -> SimState:
    """Necks of a static table grown at the end of an interval (the many-body balance moving the particles)."""
    spec, particles = physics.sintering, state.particles
    law = neck_growth.law_params(spec, prep.params.sintering)

    def grow(contacts, carried, positions):
        elapsed = (state.step - carried.interval_start).astype(state.dt.dtype) * state.dt
        if spec.shrinkage == "many_body":
            neck, overlap, displacement, unbalanced = neck_growth.balance_table_necks(
                spec, law, carried, contacts.neck, positions, particles.radii, particles.temperature, elapsed)
            positions = positions + displacement
            carried = dataclasses.replace(carried, unbalanced=carried.unbalanced | unbalanced)
        else:
            neck, overlap = neck_growth.grow_table_necks(spec, law, carried, contacts.neck, particles.radii,
                                                         particles.temperature, elapsed)
        contacts = dataclasses.replace(contacts, neck=neck, overlap=overlap)
        total = jnp.sum(neck_conductance(physics, dataclasses.replace(state, contacts=contacts), prep.params), axis=1)
        if physics.conduction.conducting_walls:
            total = total + prep.scale * jnp.sum(walls.thermal_wall_conductance(physics, state, prep), axis=0)
        return contacts, _next_interval(physics, state, prep, carried, particles, total), positions

    contacts, carried, positions = _at_interval_end(spec, state, grow, state.contacts, state.sintering,
                                                    particles.positions)
    if spec.shrinkage == "many_body":
        particles = dataclasses.replace(particles, positions=positions)
    return dataclasses.replace(state, particles=particles, contacts=contacts, sintering=carried)


def grow_pair_necks(physics: Physics, state: SimState, prep: Prepared) -> SimState:
    """With the mechanics: the necks on the half pair list grown at the end of an interval (the many-body balance
    moving the particles)."""
    spec = physics.sintering
    law = neck_growth.law_params(spec, prep.params.sintering)
    pairs = state.contacts.pairs.pairs

    def grow(particles, motion, carried):
        radii, n = particles.radii, particles.radii.shape[0]
        elapsed = (state.step - carried.interval_start).astype(state.dt.dtype) * state.dt
        geometry = mechanics.pair_geometry(particles.positions, radii, pairs, neck_growth.POINT_CONTACT_GAP)
        neck, overlap, displacement, unbalanced = neck_growth.grow_pair_necks(
            spec, law, carried, motion.neck, geometry, particles.positions, radii, particles.temperature, elapsed)
        if displacement is not None:
            particles = dataclasses.replace(particles, positions=particles.positions + displacement)
            carried = dataclasses.replace(carried, unbalanced=carried.unbalanced | unbalanced)
        motion = dataclasses.replace(motion, neck=neck, neck_overlap=overlap)
        _, k = sintered_pair_conductance(physics, dataclasses.replace(state, particles=particles, mechanics=motion),
                                         prep.params)
        total = pair_sum(k, k, pairs, n)
        conducting = [wall for _, wall in walls.conducting_mechanical_walls(physics)]
        if conducting:
            index, kappa = conductivity_lookup(physics, prep.params, particles)
            h = mechanics.wall_penetration(conducting, particles.positions, radii, state.time)
            for w in range(len(conducting)):
                total = total + walls.mechanical_wall_conductance(physics, radii, h[w], kappa[index],
                                                                  merged_law_params(physics, prep.params))
        return particles, motion, _next_interval(physics, state, prep, carried, particles, total)

    particles, motion, carried = _at_interval_end(spec, state, grow, state.particles, state.mechanics,
                                                  state.sintering)
    return dataclasses.replace(state, particles=particles, mechanics=motion, sintering=carried)


def grow(physics: Physics, state: SimState, prep: Prepared) -> SimState:
    """The necks grown at the end of a growth interval: on the pair list with the mechanics, else on the table."""
    if physics.mechanics is not None:
        return grow_pair_necks(physics, state, prep)
    return grow_table_necks(physics, state, prep)
