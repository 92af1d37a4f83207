"""The physics terms of the step, one module each: :mod:`~sintercond.sim.terms.conduction` (heat through the
contacts and the temperature update), :mod:`~sintercond.sim.terms.sources` (beam, convection, radiation, pulse, a
user source), :mod:`~sintercond.sim.terms.walls` (conducting walls), :mod:`~sintercond.sim.terms.mechanics` (the
coupled thermo-mechanical step) and :mod:`~sintercond.sim.terms.sintering` (necks that grow).

A term is a set of pure functions that take the static :class:`~sintercond.sim.physics.Physics` first: its
contribution to the step (a heat power, a force, a neck update) and the checks of its part of
:class:`~sintercond.sim.state.Params`. :func:`sintercond.sim.step.simulator` composes the terms that are on. A new
physics is a new term here and a sub-spec in :mod:`sintercond.sim.physics`; a term may import the layers below the
simulator, :mod:`sintercond.sim.contacts`, :mod:`~sintercond.sim.state`, :mod:`~sintercond.sim.physics` and other
terms, never :mod:`~sintercond.sim.step` or :mod:`~sintercond.sim.rollout`.
"""
