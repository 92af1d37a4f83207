"""The sintering term: necks that grow with each contact's temperature history (:mod:`sintercond.sim.neck_growth`).

At the end of every growth interval (``Sintering.every`` steps, or with ``Sintering.neck_rtol`` as many as the
necks' growth sets) each neck grows over the interval at its pair's
temperatures (Rojek et al. 2022's volume-conserving geometry; the kinetic laws of :mod:`sintercond.laws.sintering`),
independently or by the many-body balance that moves the particles, and the explicit step is checked against the
stability limit on the grown necks (a flag in ``NeckState.unstable``, refused on the host). Without mechanics the
necks live on the contacts' pairs: a static packing's (``LiftedContacts.neck``, a pair list that never rebuilds), or
with the mechanics the dynamic half pair list's (``MechanicalState.neck``); one growth path serves both. Its
parameters are ``Params.sintering``.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from sintercond.sim import mechanics, neck_growth, thermal
from sintercond.sim.physics import Physics
from sintercond.sim.state import Prepared, SimState
from sintercond.sim.terms import conduction


def _at_interval_end(spec, state: SimState, grow, *carried):
    """``grow(*carried)`` at the end of a growth interval, ``carried`` unchanged otherwise."""
    if spec.every == 1:
        return grow(*carried)
    return jax.lax.cond(neck_growth.update_interval(spec, state.step, state.sintering), grow, lambda *kept: kept,
                        *carried)


def _next_interval(physics: Physics, state: SimState, prep: Prepared, carried, particles, total, length):
    """``carried`` (a :class:`sintercond.sim.neck_growth.NeckState`) starting the next interval of ``length`` steps,
    flagged unstable when the step exceeds the explicit limit ``C_i / sum K`` on the grown conductances ``total``
    ``[n]`` (W/K)."""
    if physics.conduction.held:  # held particles are reset every step: their rows do not count
        total = jnp.where(particles.fixed, 0.0, total)
    limit = thermal.explicit_stability_limit(conduction.capacity_now(physics, state, prep), total)
    return dataclasses.replace(carried, interval_temperature=particles.temperature, interval_start=state.step,
                               unstable=carried.unstable | jnp.any(state.dt > limit), interval_length=length)


def _contact_set(physics: Physics, state: SimState, particles):
    """``(pairs, neck, active, normal, geometry)`` of the contacts whose necks grow: a static packing's pairs (all
    active, normals from the positions), or with the mechanics the half pair list (the pairs whose spheres touch,
    :data:`sintercond.sim.neck_growth.POINT_CONTACT_GAP`)."""
    if physics.mechanics is None:
        return state.contacts.pairs, state.contacts.neck, True, None, None
    geometry = mechanics.pair_geometry(particles.positions, particles.radii, state.contacts.pairs.pairs,
                                       neck_growth.POINT_CONTACT_GAP)
    return (jnp.stack([geometry.i, geometry.j], axis=1), state.mechanics.neck, geometry.touching, geometry.normal,
            geometry)


def grow(physics: Physics, state: SimState, prep: Prepared) -> SimState:
    """The necks grown at the end of a growth interval (:func:`sintercond.sim.neck_growth.grow_necks`, the many-body
    balance moving the particles), on the contacts' pairs: the static packing's, or with the mechanics the half
    pair list's. The next interval is flagged unstable when the grown network exceeds the explicit limit."""
    spec = physics.sintering
    law = neck_growth.law_params(spec, prep.params.sintering)

    def grow_(particles, contacts, motion, carried):
        elapsed = (state.step - carried.interval_start).astype(state.dt.dtype) * state.dt
        pairs, neck, active, normal, geometry = _contact_set(physics, state, particles)
        grown = neck_growth.grow_necks(
            spec, law, carried, pairs, neck, active, positions=particles.positions, radii=particles.radii,
            end_temperature=particles.temperature, duration=elapsed, normal=normal,
            table=None if geometry is not None else (contacts.slot_pair, contacts.neighbors))
        a, h = grown.neck, grown.neck_overlap
        length = neck_growth.next_interval_length(spec, carried, state.step, neck, a, active)
        if grown.displacement is not None:
            moved = particles.positions + grown.displacement
            if geometry is not None:
                a, h = neck_growth.met_necks(geometry, a, h, moved, particles.radii)
            particles = dataclasses.replace(particles, positions=moved)
            carried = neck_growth.with_displacement(carried, grown)
        if geometry is None:
            contacts = dataclasses.replace(contacts, neck=a, overlap=h)
            after = dataclasses.replace(state, contacts=contacts)
        else:
            motion = dataclasses.replace(motion, neck=a, neck_overlap=h)
            after = dataclasses.replace(state, particles=particles, mechanics=motion)
        total = conduction.total_conductance(physics, after, prep)
        return particles, contacts, motion, _next_interval(physics, state, prep, carried, particles, total, length)

    static = state.contacts if physics.mechanics is None else None  # the half pair list is not grown, only read
    particles, static, motion, carried = _at_interval_end(spec, state, grow_, state.particles, static,
                                                          state.mechanics, state.sintering)
    return dataclasses.replace(state, particles=particles, contacts=state.contacts if static is None else static,
                               mechanics=motion, sintering=carried)
