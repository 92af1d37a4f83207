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
    Campello 2020 Eqs. 2-13), ``geometry`` the :class:`sintercond.sim.mechanics.PairGeometry` of the pairs."""
    if physics.mechanics is None:
        raise ValueError("contact_forces needs Physics.mechanics")
    particles, motion, mp = state.particles, state.mechanics, params.mechanics
    geometry = mechanics.pair_geometry(particles.positions, particles.radii, state.contacts.pairs.pairs)
    modulus, nu = elastic_constants(physics, mp, particles)
    f, *_ = mechanics.pair_loads(physics.mechanics, mp, geometry, particles.radii, particles.mass, modulus, nu,
                                 motion.velocity, motion.spin, motion.spring, motion.rolling, state.dt,
                                 particles.positions.dtype)
    return geometry, f


def advance(physics: Physics, neighbor_fn, state: SimState, prep: Prepared) -> SimState:
    """The coupled step (Eqs. 43-46): forces and heat powers at ``t`` from one state, then symplectic Euler."""
    particles, contacts, params = state.particles, state.contacts, prep.params
    mp = params.mechanics
    positions, radii, mass, t = particles.positions, particles.radii, particles.mass, state.time
    contacts, motion, overflow = follow_contacts(neighbor_fn, positions, radii, contacts, state.mechanics)
    state = dataclasses.replace(state, overflow=state.overflow | overflow, contacts=contacts)
    modulus, nu = elastic_constants(physics, mp, particles)
    index, kappa = conductivity_lookup(physics, params, particles)
    law_params = merged_law_params(physics, params)
    temperature = particles.temperature

    gap = 0.0 if physics.sintering is None else neck_growth.POINT_CONTACT_GAP

    def on_pairs(pairs, spring, rolling, sintered):
        geometry = mechanics.pair_geometry(positions, radii, pairs, gap)
        elastic = geometry if sintered is None else sintered_geometry(geometry, sintered)
        f, t_i, t_j, spring, rolling = mechanics.pair_loads(physics.mechanics, mp, elastic, radii, mass, modulus, nu,
                                                            motion.velocity, motion.spin, spring, rolling,
                                                            state.dt, positions.dtype)
        # heat through the contacts of this geometry (Eqs. 32-36); a sintered neck conducts as its approach does
        if sintered is not None:
            geometry = conducting_geometry(geometry, sintered)
        conductance = pair_conductance(physics, radii, index, geometry, kappa, law_params)
        return f, t_i, t_j, spring, rolling, pair_heat_flow(conductance, geometry.i, geometry.j, temperature)

    pairs = contacts.pairs.pairs
    f, t_i, t_j, spring, rolling, q = map_pair_blocks(on_pairs, pairs, motion.spring, motion.rolling,
                                                      motion.neck_overlap)
    n = radii.shape[0]
    motion = dataclasses.replace(motion, spring=spring, rolling=rolling)
    loads = mechanics.body_loads(physics.mechanics, mp, positions, radii, mass, modulus, nu, motion, t, state.dt,
                                 pair_exchange(f, pairs, n), pair_sum(t_i, t_j, pairs, n))
    power = pair_exchange(q, pairs, n)
    for w, wall in walls.conducting_mechanical_walls(physics):
        k_w = walls.mechanical_wall_conductance(physics, radii, loads.wall_penetration[w], kappa[index], law_params)
        power = power + k_w * (jnp.asarray(wall.temperature, power.dtype) - particles.temperature)
    power = power + sources.power(physics, state, params)
    temperature = conduction.explicit_heat(physics, state, prep, power)
    positions, velocity, spin = mechanics.integrate(positions, loads.mechanics, loads.force, loads.torque, mass,
                                                    radii, state.dt)
    particles = dataclasses.replace(particles, positions=positions, temperature=temperature)
    motion = dataclasses.replace(loads.mechanics, velocity=velocity, spin=spin)
    return dataclasses.replace(state, particles=particles, mechanics=motion, step=state.step + 1)
