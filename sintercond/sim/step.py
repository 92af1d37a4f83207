"""The step of a :class:`~sintercond.sim.physics.Physics`: the terms that are on, composed.

jax-md's ``simulate.nve`` pattern: :func:`simulator` closes over the static spec and returns pure functions of
``(state, params)``; what a spec does not use is not traced, and each distinct spec compiles one step. A thermal step
is the conduction term (with its sources and walls), a coupled step the mechanics term; the sintering term then grows
the necks at the end of its interval.
"""

from __future__ import annotations

import functools

from sintercond.sim import adaptive
from sintercond.sim.physics import Physics
from sintercond.sim.state import Params, Prepared, SimState, Simulator
from sintercond.sim.terms import conduction, mechanics, sintering


def simulator(physics: Physics, neighbor_fn=None) -> Simulator:
    """The step of ``physics``: ``step_fn(state, params) -> state``.

    Args:
      physics: the spec.
      neighbor_fn: for ``contacts="dynamic"``, the neighbour-list
        function (``update(positions, nbrs)``) the state's list came from
        (:func:`sintercond.simulate.dynamic_contacts` builds both).
    """
    if physics.contacts == "dynamic" and neighbor_fn is None:
        raise ValueError("contacts='dynamic' needs the neighbour-list function (see dynamic_contacts)")
    prepare_fn = functools.partial(conduction.prepare, physics)
    move = mechanics.advance if physics.mechanics is not None else conduction.advance

    def advance_fn(state: SimState, prep: Prepared) -> SimState:
        state = move(physics, neighbor_fn, state, prep)
        return state if physics.sintering is None else sintering.grow(physics, state, prep)

    if physics.conduction.integrator == "implicit" and adaptive.needs_tr_bdf2(physics):
        def advance_fn(state: SimState, prep: Prepared) -> SimState:  # noqa: F811 (the necks grow in its stages)
            return adaptive.fixed_step(physics, state, prep)

    def step_fn(state: SimState, params: Params) -> SimState:
        return advance_fn(state, prepare_fn(state, params))

    return Simulator(physics, step_fn, prepare_fn, advance_fn,
                     functools.partial(conduction.heat_power, physics, neighbor_fn))
