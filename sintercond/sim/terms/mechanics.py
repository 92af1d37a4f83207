"""The contact-mechanics term: the coupled thermo-mechanical step of Quintana-Ruiz & Campello (2020).

Forces and heat powers at ``t`` from one state, then symplectic Euler (their Eqs. 43-46): Hertz with damping,
Mindlin friction and rolling resistance on the half pair list (:func:`sintercond.sim.mechanics.pair_loads`, Eqs. 2-20),
gravity and walls (:func:`sintercond.sim.mechanics.body_loads`), heat through the contacts the motion opens and grows
(Eqs. 32-36) and through conducting walls. Its parameters are ``Params.mechanics``
(:class:`sintercond.sim.mechanics.MechanicalParams`); with sintering, the elastic laws act on each overlap less its
neck's approach (:func:`sintercond.sim.contacts.sintered_geometry`) and heat flows through the larger of the two
(:func:`sintercond.sim.contacts.conducting_geometry`).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from sintercond.sim import mechanics, neck_growth
from sintercond.contacts.pair_list import map_pair_blocks, pair_exchange, pair_sum
from sintercond.sim.contacts import (conducting_geometry, conductivity_lookup, follow_contacts, merged_law_params,
                                     pair_conductance, pair_heat_flow, sintered_geometry)
from sintercond.sim.physics import Physics
from sintercond.sim.state import Params, Prepared, SimState
from sintercond.sim.terms import conduction, sources, walls
from sintercond.state import ParticleState


def elastic_constants(physics: Physics, mp, particles: ParticleState):
    """``(E [n], nu [n])`` of each particle: its modulus at its temperature (Eq. 42) and its material's Poisson ratio."""
    modulus = mechanics.particle_modulus(physics.mechanics, mp, particles.temperature, particles.material)
    nu = jnp.broadcast_to(jnp.atleast_1d(jnp.asarray(mp.nu, particles.positions.dtype))[particles.material],
                          particles.radii.shape)
    return modulus, nu


def contact_forces(physics: Physics, state: SimState, params: Params):
    """``(geometry, force [c, 3])`` of a mechanical state's listed pairs: the force on ``i`` from ``j`` (N) that the
    step's contact laws give at this state (Hertz with damping, Mindlin friction and its spring, Quintana-Ruiz &
    Campello 2020 Eqs. 2-13; with sintering on each overlap less its neck's approach, as the step's),
    ``geometry`` the :class:`sintercond.sim.mechanics.PairGeometry` of the pairs."""
    if physics.mechanics is None:
        raise ValueError("contact_forces needs Physics.mechanics")
    particles, motion, mp = state.particles, state.mechanics, params.mechanics
    modulus, nu = elastic_constants(physics, mp, particles)
    geometry, f, *_ = _pair_forces(physics, state, mp, motion, modulus, nu, state.contacts.pairs.pairs, motion.spring,
                                   motion.rolling, motion.neck_overlap)
    return geometry, f


def advance(physics: Physics, neighbor_fn, state: SimState, prep: Prepared) -> SimState:
    """The coupled step (Eqs. 43-46): forces and heat powers at ``t`` from one state, then symplectic Euler; with
    ``Mechanics.quasi_static`` the heat alone (:func:`quasi_static_advance`)."""
    if physics.mechanics.quasi_static:
        return quasi_static_advance(physics, neighbor_fn, state, prep)
    particles, contacts, params = state.particles, state.contacts, prep.params
    mp = params.mechanics
    positions, radii, mass, t = particles.positions, particles.radii, particles.mass, state.time
    contacts, motion, overflow = follow_contacts(neighbor_fn, positions, radii, contacts, state.mechanics)
    state = dataclasses.replace(state, overflow=state.overflow | overflow, contacts=contacts)
    modulus, nu = elastic_constants(physics, mp, particles)
    index, kappa = conductivity_lookup(physics, params, particles)
    law_params = merged_law_params(physics, params)

    def on_pairs(pairs, spring, rolling, sintered):
        geometry, f, t_i, t_j, spring, rolling = _pair_forces(physics, state, mp, motion, modulus, nu, pairs, spring,
                                                              rolling, sintered)
        return f, t_i, t_j, spring, rolling, _pair_heat(physics, particles, geometry, sintered, index, kappa,
                                                        law_params)

    pairs = contacts.pairs.pairs
    f, t_i, t_j, spring, rolling, q = map_pair_blocks(on_pairs, pairs, motion.spring, motion.rolling,
                                                      motion.neck_overlap)
    n = radii.shape[0]
    motion = dataclasses.replace(motion, spring=spring, rolling=rolling)
    loads = mechanics.body_loads(physics.mechanics, mp, positions, radii, mass, modulus, nu, motion, t, state.dt,
                                 pair_exchange(f, pairs, n), pair_sum(t_i, t_j, pairs, n))
    temperature = _heated(physics, state, prep, pair_exchange(q, pairs, n), loads.wall_penetration, index, kappa,
                          law_params)
    positions, velocity, spin = mechanics.integrate(positions, loads.mechanics, loads.force, loads.torque, mass,
                                                    radii, state.dt)
    particles = dataclasses.replace(particles, positions=positions, temperature=temperature)
    motion = dataclasses.replace(loads.mechanics, velocity=velocity, spin=spin)
    return dataclasses.replace(state, particles=particles, mechanics=motion, step=state.step + 1)


def quasi_static_advance(physics: Physics, neighbor_fn, state: SimState, prep: Prepared) -> SimState:
    """The step of ``Mechanics(quasi_static=True)``: the heat through the contacts and walls at the present
    positions (Eqs. 32-36, as :func:`advance`'s), explicit; nothing moves (the particles move at the neck updates,
    by the many-body balance of :mod:`sintercond.sim.terms.sintering`). The pair list follows the positions."""
    particles, params = state.particles, prep.params
    positions, radii = particles.positions, particles.radii
    contacts, motion, overflow = follow_contacts(neighbor_fn, positions, radii, state.contacts, state.mechanics)
    state = dataclasses.replace(state, overflow=state.overflow | overflow, contacts=contacts, mechanics=motion)
    index, kappa = conductivity_lookup(physics, params, particles)
    law_params = merged_law_params(physics, params)

    def on_pairs(pairs, sintered):
        geometry = mechanics.pair_geometry(positions, radii, pairs, _gap(physics))
        return _pair_heat(physics, particles, geometry, sintered, index, kappa, law_params)

    pairs = contacts.pairs.pairs
    q = map_pair_blocks(on_pairs, pairs, motion.neck_overlap)
    penetration = (mechanics.wall_penetration(physics.mechanics.walls, positions, radii, state.time)
                   if physics.mechanics.walls else None)
    temperature = _heated(physics, state, prep, pair_exchange(q, pairs, radii.shape[0]), penetration, index, kappa,
                          law_params)
    particles = dataclasses.replace(particles, temperature=temperature)
    return dataclasses.replace(state, particles=particles, step=state.step + 1)


def resultant_forces(physics: Physics, state: SimState, params: Params):
    """``(resultant [n, 3], pair_force [c, 3])`` (N): the sum of the contact, wall and gravity forces on each particle
    and the force on ``i`` of each listed pair, by the step's laws at the state (:func:`advance`'s loads)."""
    particles, mp, motion = state.particles, params.mechanics, state.mechanics
    modulus, nu = elastic_constants(physics, mp, particles)
    pairs = state.contacts.pairs.pairs
    _, f, t_i, t_j, *_ = _pair_forces(physics, state, mp, motion, modulus, nu, pairs, motion.spring, motion.rolling,
                                      motion.neck_overlap)
    n = particles.radii.shape[0]
    loads = mechanics.body_loads(physics.mechanics, mp, particles.positions, particles.radii, particles.mass, modulus,
                                 nu, motion, state.time, state.dt, pair_exchange(f, pairs, n),
                                 pair_sum(t_i, t_j, pairs, n))
    return loads.force, f


def _pair_forces(physics: Physics, state: SimState, mp, motion, modulus, nu, pairs, spring, rolling, sintered):
    """``(geometry, f, t_i, t_j, spring, rolling)`` of the pairs ``[c, 2]`` at the state's positions and velocities
    (:func:`sintercond.sim.mechanics.pair_loads`); with sintering the elastic laws act on each overlap less its neck's
    approach ``sintered`` ``[c]``."""
    p = state.particles
    geometry = mechanics.pair_geometry(p.positions, p.radii, pairs, _gap(physics))
    elastic = geometry if sintered is None else sintered_geometry(geometry, sintered)
    f, t_i, t_j, spring, rolling = mechanics.pair_loads(physics.mechanics, mp, elastic, p.radii, p.mass, modulus, nu,
                                                        motion.velocity, motion.spin, spring, rolling, state.dt,
                                                        p.positions.dtype)
    return geometry, f, t_i, t_j, spring, rolling


def _gap(physics: Physics) -> float:
    """The gap within which a pair counts as touching: a sintering neck's point contact, else none."""
    return 0.0 if physics.sintering is None else neck_growth.POINT_CONTACT_GAP


def _pair_heat(physics: Physics, particles, geometry, sintered, index, kappa, law_params):
    """``[c]`` heat flow of the pairs of ``geometry`` (Eqs. 32-36); a sintered neck conducts as its approach
    ``sintered`` ``[c]`` does where that exceeds the overlap (:func:`sintercond.sim.contacts.conducting_geometry`)."""
    if sintered is not None:
        geometry = conducting_geometry(geometry, sintered)
    conductance = pair_conductance(physics, particles.radii, index, geometry, kappa, law_params)
    return pair_heat_flow(conductance, geometry.i, geometry.j, particles.temperature)


def _heated(physics: Physics, state: SimState, prep: Prepared, power, wall_penetration, index, kappa, law_params):
    """``[n]`` temperatures after the explicit step from the pairs' heat ``power`` ``[n]`` (W), the conducting
    walls' at ``wall_penetration`` ``[walls, n]`` (m) and the sources."""
    particles = state.particles
    for w, wall in walls.conducting_mechanical_walls(physics):
        k_w = walls.mechanical_wall_conductance(physics, particles.radii, wall_penetration[w], kappa[index],
                                                law_params)
        power = power + k_w * (jnp.asarray(wall.temperature, power.dtype) - particles.temperature)
    power = power + sources.power(physics, state, prep.params)
    return conduction.explicit_heat(physics, state, prep, power)
