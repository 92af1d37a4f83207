"""The one host loop: a simulation advanced in compiled chunks, with overflow recovered and states checked.

:func:`sintercond.simulate.rollout` is one traced program (differentiable,
fixed list capacities). A run the host watches (``sintercond run``, the
settling of a bed, the settle before a fit's experiment) is :func:`advance`:
compiled chunks of the same rollout, and after each chunk the host

1. redoes the chunk from its saved start with wider lists when a neighbour
   or pair list overflowed (``reallocate``), so no contact is lost;
2. checks the new state (``check``: non-finite temperatures by default);
3. reports progress and hands the state, with the figures ``measure``
   computed on it inside the same compiled chunk, to ``on_chunk``, which may
   stop the run (a bed that has settled, a kill for a resume test).

Every chunk is compiled with :func:`sintercond.mechanics.compiler_options`
of the spec, and the same compiled chunk runs on the same inputs whatever the
history, so a run resumed from a checkpoint is bitwise identical to an
uninterrupted one.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from sintercond import mechanics, neck_growth, simulate

MAX_REALLOCATIONS = 100
"""Reallocations of the lists one :func:`advance` call allows before it gives up."""


class ListOverflow(RuntimeError):
    """A neighbour or pair list overflowed and :func:`advance` was given no way (or no more tries) to widen it."""


class Report(NamedTuple):
    """What :func:`advance` did: chunks completed and list reallocations (each redid one chunk)."""

    chunks: int
    reallocations: int


def advance(sim: simulate.Simulator, state: simulate.SimState, params: simulate.Params, n_steps: int, chunk: int,
            on_chunk: Callable | None = None, reallocate: Callable | None = None, progress: Callable | None = None,
            check: Callable | None = None, measure: Callable | None = None) -> tuple[simulate.SimState, Report]:
    """Advance ``n_steps`` steps in compiled chunks of ``chunk`` steps (the last one may be shorter).

    Args:
      sim, state, params: as :func:`sintercond.simulate.rollout`.
      n_steps: steps to take from ``state.step``.
      chunk: steps per compiled chunk (between two host checks).
      on_chunk: ``on_chunk(state)``, or ``on_chunk(state, figures)`` with ``measure``, after each chunk
        (outputs, checkpoints, a stopping rule); returning True stops the run.
      reallocate: ``reallocate(start, overflowed) -> start`` with wider lists
        (:func:`sintercond.simulate.reallocate_neighbors`); the chunk is then redone from ``start``. None: an
        overflow raises.
      progress: ``progress(steps)`` after each chunk (a progress bar's ``update``).
      check: ``check(state)`` raises on a state that must not go on (default :func:`finite_temperatures`:
        non-finite temperatures, or necks grown beyond the time step's stability).
      measure: ``measure(sim, state, params) -> (figures, overflowed)``, a hashable function traced into the
        chunk on its end state: figures for ``on_chunk`` (a pytree), and a flag that counts as an overflow of
        the chunk (a probe step that ran out of list room).

    Returns:
      ``(state, Report)``.

    Raises:
      ValueError: invalid input (:func:`sintercond.simulate.validate_inputs`), before anything compiles.
      ListOverflow: a list overflowed with no ``reallocate``, or kept overflowing.
    """
    simulate.validate_inputs(sim, state, params)
    compiled = {}
    reallocations = chunks = 0
    target = int(state.step) + int(n_steps)
    check = check or finite_temperatures
    while int(state.step) < target:
        length = min(int(chunk), target - int(state.step))
        if length not in compiled:
            compiled[length] = compiled_chunk(sim, length, measure)
        new, figures, overflowed = compiled[length](state, params)
        if bool(new.overflow) or bool(overflowed):
            if reallocate is None:
                raise ListOverflow(f"the neighbour list overflowed at step {int(state.step)} and no reallocation "
                                   "was given")
            state = reallocate(state, new)
            reallocations += 1
            if reallocations > MAX_REALLOCATIONS:
                raise ListOverflow("the neighbour list keeps overflowing; raise its capacity")
            continue
        check(new)
        state = new
        chunks += 1
        if progress is not None:
            progress(length)
        if on_chunk is not None and (on_chunk(state) if measure is None else on_chunk(state, figures)):
            break
    return state, Report(chunks, reallocations)


def finite_temperatures(state: simulate.SimState) -> None:
    """:func:`advance`'s default check: every temperature finite, and a sintering state still stable
    (:func:`sintercond.neck_growth.check_stable`, first: the cause of the other)."""
    neck_growth.check_stable(state)
    if not bool(jnp.all(jnp.isfinite(state.particles.temperature))):
        raise FloatingPointError(f"non-finite temperature at step {int(state.step)}; reduce the time step")


@functools.lru_cache(maxsize=16)
def compiled_chunk(sim: simulate.Simulator, length: int, measure: Callable | None = None):
    """``(state, params) -> (state, figures, overflowed)``: ``length`` steps of ``sim`` and ``measure`` on the end
    state, jitted with the spec's compiler options and kept across :func:`advance` calls (a second run of the same
    spec does not recompile)."""

    def run_chunk(state, params):
        state = simulate.rollout(sim, state, params, length, simulate.SaveAt(length, _nothing), checkpoint=False)[0]
        figures, overflowed = (None, jnp.zeros((), bool)) if measure is None else measure(sim, state, params)
        return state, figures, overflowed

    return jax.jit(run_chunk, compiler_options=mechanics.compiler_options(sim.physics))


def _nothing(state) -> tuple[Any, ...]:
    return ()
