"""The explicit step's stability limit of a state: the largest step with the maximum principle."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from sintercond.sim import thermal
from sintercond.sim.state import Params, SimState, Simulator
from sintercond.sim.step import simulator
from sintercond.sim.terms.conduction import total_conductance


def thermal_time_step(sim: Simulator, state: SimState, params: Params, source_conductance=None):
    """Largest explicit-Euler step with the maximum principle, ``min_i C_i / (sum_j K_ij + sum_w K_iw + G_i)`` (s).

    The contacts at the state's geometry (static, or the dynamic half pair list at its positions with the
    conducting walls it touches: :func:`sintercond.sim.terms.conduction.total_conductance`);
    ``source_conductance`` ``G_i`` (W/K, optional) linearises sources that depend on the temperature
    (:func:`sintercond.sim.thermal.source_conductance`). inf for a particle with
    no conductance. At or below it every new temperature is a convex
    combination of old ones and the sources' reference temperatures.
    """
    conduction = sim.physics.conduction
    if conduction.conductivity_table or conduction.specific_heat_table:
        # the tables' largest conductivity and smallest specific heat bound it at every temperature
        if conduction.conductivity_table:
            params = dataclasses.replace(params, conductivity=jnp.max(jnp.asarray(params.conductivity.values))[None])
        if conduction.specific_heat_table:
            params = dataclasses.replace(params, specific_heat=jnp.min(jnp.asarray(params.specific_heat.values))[None])
        conduction = dataclasses.replace(conduction, conductivity_table=False, specific_heat_table=False)
        sim = simulator(dataclasses.replace(sim.physics, conduction=conduction))
    # one compiled program: run op by op, its dozen small operations each cost an XLA compile on the host
    return jax.jit(lambda st, p, g: _stable_step(sim, st, p, g))(state, params, source_conductance)


def _stable_step(sim: Simulator, state: SimState, params: Params, source_conductance):
    """:func:`thermal_time_step`'s limit, traced."""
    prep = sim.prepare_fn(state, params)
    total = total_conductance(sim.physics, state, prep)
    if source_conductance is not None:
        total = total + source_conductance
    return thermal.explicit_stability_limit(prep.capacity, total)
