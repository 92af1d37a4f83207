"""Compositions of library functions that only the tests use (they were public functions of the package that no
caller of it needed; issue 24)."""

import dataclasses

import jax.numpy as jnp

from sintercond import mechanics, network, thermal
from sintercond.pair_list import pair_exchange, pair_sum


def find_contacts(centres, radii, tolerance=1e-9, periodic_box=None):
    """Contacts of every particle as a padded ``[n, m]`` index table (padding the row's own index), ascending:
    :func:`sintercond.network.contact_pairs` laid out by :func:`sintercond.network.ell_table`."""
    pairs = network.contact_pairs(centres, radii, tolerance, periodic_box)
    (table,) = network.ell_table(pairs.n_particles, pairs.i, pairs.j)
    return table


def explicit_euler_step(temperature, table, capacity, dt, fixed_mask=None, fixed_temperature=None):
    """One explicit Euler step on a table, ``T + dt / C sum_j K_ij (T_j - T_i)``; held particles stay."""
    return thermal.explicit_update(temperature, network.heat_inflow(temperature, table), capacity, dt, fixed_mask,
                                   fixed_temperature)


def contact_loads(spec, params, geometry, positions, radii, mass, modulus, nu, state, t, dt):
    """Forces and torques on every particle from its pair and wall contacts and gravity at ``t``
    (:class:`sintercond.mechanics.Loads`): the pair laws on the whole list at once, then the walls and gravity."""
    n = radii.shape[0]
    f, t_i, t_j, spring, rolling = mechanics.pair_loads(spec, params, geometry, radii, mass, modulus, nu,
                                                        state.velocity, state.spin, state.spring, state.rolling, dt,
                                                        positions.dtype)
    state = dataclasses.replace(state, spring=spring, rolling=rolling)
    return mechanics.body_loads(spec, params, positions, radii, mass, modulus, nu, state, t, dt,
                                pair_exchange(f, geometry.pairs, n), pair_sum(t_i, t_j, geometry.pairs, n))


def forced_rebuild(state):
    """A dynamic state with its lists marked stale: the next update rebuilds both (as after a reallocation),
    carrying the pair history to the rebuilt list."""
    nbrs = state.contacts.neighbor_list
    nbrs = dataclasses.replace(nbrs, reference_position=jnp.full_like(nbrs.reference_position, jnp.inf))
    return dataclasses.replace(state, contacts=dataclasses.replace(state.contacts, neighbor_list=nbrs))
