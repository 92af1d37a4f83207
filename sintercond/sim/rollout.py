"""The rollout of a simulator, traced or watched by the host.

:func:`rollout` advances a state ``n_steps`` steps in one traced program: ``lax.scan`` over ``jax.checkpoint``-ed
segments of about ``sqrt(n_steps)`` steps, saving observables chosen by :class:`SaveAt` (probe temperatures, means,
heat flows), not whole states, so reverse mode keeps ``O(sqrt(n_steps))`` particle arrays.

:func:`advance` is the one host loop over it: a simulation advanced in compiled chunks of the same rollout (``sintercond
run``, the settling of a bed, the settle before a fit's experiment), and after each chunk the host

1. redoes the chunk from its saved start with wider lists when a neighbour
   or pair list overflowed (``reallocate``), so no contact is lost;
2. checks the new state (``check``: non-finite temperatures by default);
3. reports progress and hands the state, with the figures ``measure``
   computed on it inside the same compiled chunk, to ``on_chunk``, which may
   stop the run (a bed that has settled, a kill for a resume test).

Every chunk is compiled with :func:`sintercond.sim.mechanics.compiler_options`
of the spec, and the same compiled chunk runs on the same inputs whatever the
history, so a run resumed from a checkpoint is bitwise identical to an
uninterrupted one.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from sintercond.sim import adaptive, mechanics, neck_growth
from sintercond.sim.state import Params, SimState, Simulator
from sintercond.sim.validation import check_mechanical_step, check_save_interval, validate_inputs


@dataclasses.dataclass(frozen=True)
class SaveAt:
    """What :func:`rollout` saves: ``fn(state)`` every ``every`` steps (diffrax ``SaveAt(steps=, fn=)``).

    ``fn=None`` saves the temperatures; see :func:`probe_temperatures`,
    :func:`mean_temperature`. ``fn`` must be hashable (a function or a
    :class:`Observable`).
    """

    every: int = 1
    fn: Callable | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Observable:
    """An observable built from data (e.g. probe indices); hashed by identity."""

    fn: Callable
    data: Any = None

    def __call__(self, state):
        return self.fn(state, self.data)


def probe_temperatures(indices) -> Observable:
    """Temperatures ``[p]`` (K) of the particles ``indices``."""
    return Observable(lambda state, idx: state.particles.temperature[idx], jnp.asarray(indices))


def mean_temperature(state: SimState):
    """Mass-weighted mean temperature (K) of the free particles (all if none is held)."""
    p = state.particles
    weight = jnp.where(p.fixed, 0.0, p.mass)
    weight = jnp.where(jnp.sum(weight) > 0, weight, p.mass)
    return jnp.sum(weight * p.temperature) / jnp.sum(weight)


def _small_observable(shapes, state) -> bool:
    """Whether the observable holds at most 1/16 of the temperatures' elements (e.g. a few probes):
    cheap enough to write after every step."""
    size = sum(math.prod(x.shape) for x in jax.tree.leaves(shapes))
    return 16 * size <= math.prod(state.particles.temperature.shape)


def segment_length(n_steps: int) -> int:
    """``ceil(sqrt(n_steps))``: steps between the states reverse mode keeps."""
    return max(1, math.isqrt(max(n_steps, 1) - 1) + 1)


def rollout(sim: Simulator, state: SimState, params: Params, n_steps: int, saveat: SaveAt = SaveAt(),
            checkpoint: bool = True, step_checkpoint: bool = False):
    """Advance ``n_steps`` steps; returns ``(final state, saved)`` with ``saved[k] = fn(state after (k+1) every steps)``.

    ``lax.scan`` over ``jax.checkpoint``-ed segments of about ``sqrt(n_steps)``
    steps (``checkpoint=False``: one plain scan), so reverse mode through the
    rollout keeps ``O(sqrt(n_steps))`` states and recomputes each segment
    once. ``n_steps`` must be a multiple of ``saveat.every``. Pure and
    traceable: wrap it in ``jax.jit`` (with ``sim``, ``n_steps`` and
    ``saveat`` static) or call it inside a jitted loss.

    ``step_checkpoint=True`` also wraps each step in ``jax.checkpoint``:
    reverse mode then keeps only the state after every step of the segment
    it is working on and recomputes the step on the way back, instead of
    stacking every intermediate of every step (hundreds of small arrays per
    step for the coupled step): one more run of the step instead of a
    write and a read of each of them. The numbers are the same to
    round-off (tests/test_fit_softening.py: the bed's gradient against
    central differences); memory falls; the forward run is unchanged.
    """
    every = saveat.every
    check_save_interval(n_steps, every)
    observe = (lambda s: s.particles.temperature) if saveat.fn is None else saveat.fn
    validate_inputs(sim, state, params)
    if sim.physics.mechanics is not None and params.mechanics is not None:
        mechanics.check_wall_coefficients(sim.physics.mechanics, params.mechanics)
        check_mechanical_step(sim, state, params)
    prep = sim.prepare_fn(state, params)
    seg = segment_length(n_steps) if checkpoint else n_steps

    # leaves the step passes through unchanged (a static table, radii, masses) stay out of the loops' carries:
    # reverse mode would keep a copy of them at every checkpoint
    leaves, treedef = jax.tree.flatten(state)
    still = _unchanged_leaves(sim, prep, leaves, treedef)

    def full(moving):
        moving = iter(moving)
        return treedef.unflatten([x if kept else next(moving) for x, kept in zip(leaves, still)])

    def moving(s):
        return [x for x, kept in zip(treedef.flatten_up_to(s), still) if not kept]

    observe_state = observe
    observe = lambda m: observe_state(full(m))  # noqa: E731
    state = moving(state)

    def advance(s, _):
        return moving(sim.advance_fn(full(s), prep)), None

    if step_checkpoint:
        advance = jax.checkpoint(advance, prevent_cse=False)

    def run_steps(s, length):
        if length <= seg:
            return jax.lax.scan(advance, s, None, length=length)[0] if length else s
        # ceil(length / seg) checkpointed segments of equal size (<= seg); the unchecked rest is shorter
        # than their number, so over many saves it stays O(sqrt(n_steps)) steps
        count = -(-length // seg)
        size, r = divmod(length, count)
        s = jax.lax.scan(jax.checkpoint(lambda c, _: (run_steps(c, size), None), prevent_cse=False), s, None,
                         length=count)[0]
        return run_steps(s, r)

    def one_save(s, _):
        s = run_steps(s, every)
        return s, observe(s)

    def saving_steps(s, n_saved):
        """``n_saved * every`` steps in one flat scan, the observable written into a buffer every ``every`` steps.

        A scan over saves of a scan over steps would stack the per-step
        residuals of reverse mode twice (and copy them between the levels).
        """
        shapes = jax.eval_shape(observe, s)
        buffer = jax.tree.map(lambda x: jnp.zeros((n_saved,) + x.shape, x.dtype), shapes)

        def save(s, buffer, k):
            return jax.tree.map(lambda b, x: jax.lax.dynamic_update_index_in_dim(b, x, k // every, 0), buffer,
                                observe(s))

        def step(carry, k):
            s, buffer = carry
            s = advance(s, None)[0]
            if _small_observable(shapes, full(s)):
                # written after every step, the last write of an interval standing: no branch, whose transpose
                # adds a zero field to the state's cotangent at every step
                buffer = save(s, buffer, k)
            else:
                buffer = jax.lax.cond((k + 1) % every == 0, save, lambda s, b, k: b, s, buffer, k)
            return (s, buffer), None

        (s, buffer), _ = jax.lax.scan(step, (s, buffer), jnp.arange(n_saved * every))
        return s, buffer

    n_saves = n_steps // every
    group = max(1, seg // every)
    if group <= 1:
        if checkpoint and 1 < every <= seg < n_steps:
            # one save per segment: the segment is the save interval (unchecked, reverse mode would keep
            # every step of the run)
            state, saved = jax.lax.scan(jax.checkpoint(one_save, prevent_cse=False), state, None, length=n_saves)
        else:
            state, saved = jax.lax.scan(one_save, state, None, length=n_saves)
        return full(state), saved
    if group >= n_saves:
        state, saved = saving_steps(state, n_saves)
        return full(state), saved
    q, r = divmod(n_saves, group)
    state, saved = jax.lax.scan(jax.checkpoint(lambda s, _: saving_steps(s, group), prevent_cse=False), state, None,
                                length=q)
    saved = jax.tree.map(lambda x: x.reshape((q * group,) + x.shape[2:]), saved)
    if r:
        state, tail = saving_steps(state, r)
        saved = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), saved, tail)
    return full(state), saved


def _unchanged_leaves(sim, prep, leaves, treedef):
    """Per leaf of the flattened state: whether one step returns it unchanged (the same value, untouched)."""
    jaxpr = jax.make_jaxpr(lambda *xs: jax.tree.leaves(sim.advance_fn(treedef.unflatten(xs), prep)))(*leaves).jaxpr
    return [out is var for var, out in zip(jaxpr.invars, jaxpr.outvars)]


MAX_REALLOCATIONS = 100
"""Reallocations of the lists one :func:`advance` call allows before it gives up."""


class ListOverflow(RuntimeError):
    """A neighbour or pair list overflowed and :func:`advance` was given no way (or no more tries) to widen it."""


class Report(NamedTuple):
    """What :func:`advance` did: chunks completed and list reallocations (each redid one chunk); with the implicit
    integrator the adaptive steps accepted and rejected."""

    chunks: int
    reallocations: int
    accepted: int = 0
    rejected: int = 0


def advance(sim: Simulator, state: SimState, params: Params, n_steps: int, chunk: int,
            on_chunk: Callable | None = None, *, reallocate: Callable | None = None, progress: Callable | None = None,
            check: Callable | None = None, measure: Callable | None = None) -> tuple[SimState, Report]:
    """Advance ``n_steps`` steps in compiled chunks of ``chunk`` steps (the last one may be shorter).

    With ``Conduction.integrator="implicit"`` each chunk is the interval ``chunk * dt`` stepped adaptively
    (:func:`sintercond.sim.adaptive.integrate_interval`, TR-BDF2 within ``rtol`` / ``atol``), the next chunk
    starting from the step the last one ended with: ``dt`` is then the output clock, and ``Report`` counts the
    adaptive steps. A failed interval raises ``FloatingPointError``.

    Args:
      sim, state, params: as :func:`rollout`.
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
      ValueError: invalid input (:func:`sintercond.sim.validation.validate_inputs`), before anything compiles.
      ListOverflow: a list overflowed with no ``reallocate``, or kept overflowing.
    """
    validate_inputs(sim, state, params)
    compiled = {}
    reallocations = chunks = accepted = rejected = 0
    target = int(state.step) + int(n_steps)
    check = check or finite_temperatures
    implicit = sim.physics.conduction.integrator == "implicit"
    first_step = None
    while int(state.step) < target:
        length = min(int(chunk), target - int(state.step))
        if length not in compiled:
            compiled[length] = compiled_chunk(sim, length, measure)
        if implicit:  # the chunk is an interval of length * dt stepped adaptively from the last step it took
            if state.adaptive_step is not None:  # carried in the state: a checkpoint resumes exactly
                first_step = state.adaptive_step if float(state.adaptive_step) > 0 else None
            first_step = length * state.dt if first_step is None else first_step
            new, figures, overflowed, stats = compiled[length](state, params, first_step)
            if bool(stats.failed):
                raise FloatingPointError(
                    f"the adaptive implicit step failed between steps {int(state.step)} and {int(state.step) + length}"
                    f" (t = {float(state.time):.6g} s): its step fell to round-off of the time or it took "
                    f"{adaptive.MAX_STEPS} steps; loosen Conduction.rtol / atol or check the inputs")
            first_step = stats.next_step
            if new.adaptive_step is not None:
                new = dataclasses.replace(new, adaptive_step=jnp.asarray(stats.next_step, new.adaptive_step.dtype))
            accepted, rejected = accepted + int(stats.accepted), rejected + int(stats.rejected)
        else:
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
    return state, Report(chunks, reallocations, accepted, rejected)


def finite_temperatures(state: SimState) -> None:
    """:func:`advance`'s default check: every temperature finite, a sintering state still stable
    (:func:`sintercond.sim.neck_growth.check_stable`, first: the cause of the other)."""
    neck_growth.check_stable(state)
    if not bool(jnp.all(jnp.isfinite(state.particles.temperature))):
        raise FloatingPointError(f"non-finite temperature at step {int(state.step)}; reduce the time step")


@functools.lru_cache(maxsize=16)
def compiled_chunk(sim: Simulator, length: int, measure: Callable | None = None):
    """``(state, params) -> (state, figures, overflowed)``: ``length`` steps of ``sim`` and ``measure`` on the end
    state, jitted with the spec's compiler options and kept across :func:`advance` calls (a second run of the same
    spec does not recompile). With the implicit integrator ``(state, params, first_step) -> (state, figures,
    overflowed, stats)``: the interval ``length * dt`` stepped adaptively (:func:`sintercond.sim.adaptive.integrate_interval`)."""

    def run_chunk(state, params):
        state = rollout(sim, state, params, length, SaveAt(length, _nothing), checkpoint=False)[0]
        return (state,) + _measured(state, params)

    def _measured(state, params):
        figures, overflowed = (None, jnp.zeros((), bool)) if measure is None else measure(sim, state, params)
        return figures, overflowed

    def run_interval(state, params, first_step):
        state, stats = adaptive.integrate_interval(sim.physics, state, sim.prepare_fn(state, params), length,
                                                   first_step)
        return (state,) + _measured(state, params) + (stats,)

    implicit = sim.physics.conduction.integrator == "implicit"
    return jax.jit(run_interval if implicit else run_chunk, compiler_options=mechanics.compiler_options(sim.physics))


def _nothing(state) -> tuple[Any, ...]:
    return ()
