"""The conducting-walls term: heat between the particles and plane walls at a temperature.

A wall is a neighbour of infinite radius (:mod:`sintercond.laws.walls`): the conductance law on the wall's neck,
``r_j -> inf``, both halves at the particle's conductivity. A thermal step's walls are fixed
(``Conduction.conducting_walls``: their penetrations, or conductances at unit conductivity, are in the contacts);
a mechanical step's walls are ``Mechanics.walls`` in mode ``"conducting"``, at the penetration of the step.
"""

from __future__ import annotations

import jax.numpy as jnp

from sintercond.sim.contacts import conductivity_lookup, merged_law_params
from sintercond.sim.physics import Physics
from sintercond.sim.state import Prepared, SimState
from sintercond.laws.walls import wall_conductance_from_neck, wall_neck_radius


def wall_lift(physics: Physics, particles, contacts, params, law_params):
    """``[n_walls, n]`` conductances (W/K) to a thermal step's conducting walls from the necks the contacts hold."""
    index, conductivity = conductivity_lookup(physics, params, particles)
    kappa = conductivity[index]
    return wall_conductance_from_neck(physics.conduction.law, contacts.wall_neck, particles.radii, contacts.wall_overlap,
                                      kappa, kappa, law_params)


def thermal_wall_conductance(physics: Physics, state: SimState, prep: Prepared):
    """``[n_walls or 1, n]`` conductances (W/K, times ``prep.scale``) to a thermal step's conducting walls now: the
    rollout's, or with a conductivity table at the particles' temperatures."""
    if physics.conduction.conductivity_table:
        return wall_lift(physics, state.particles, state.contacts, prep.params, merged_law_params(physics, prep.params))
    return prep.wall_conductance


def thermal_wall_power(physics: Physics, state: SimState, prep: Prepared, temperature):
    """Heat power ``[n]`` (W) from a thermal step's conducting walls into the particles at ``temperature``."""
    wall_k = thermal_wall_conductance(physics, state, prep)
    return prep.scale * jnp.sum(wall_k * (prep.wall_temperature - temperature), axis=0)


def conducting_mechanical_walls(physics: Physics):
    """``[(w, wall)]``: the conducting walls of ``Mechanics.walls`` with their index among all walls."""
    return [(w, wall) for w, wall in enumerate(physics.mechanics.walls) if wall.mode == "conducting"]


def mechanical_wall_conductance(physics: Physics, radii, penetration, conductivity, law_params):
    """``[n]`` conductances (W/K) of the particles to a conducting mechanical wall at their ``penetration`` (m):
    the law on the wall's neck (:mod:`sintercond.laws.walls`, ``r_j -> inf``), both halves at the particle's
    ``conductivity``."""
    return wall_conductance_from_neck(physics.conduction.law, wall_neck_radius(physics.neck, radii, penetration),
                                      radii, penetration, conductivity, conductivity, law_params)
