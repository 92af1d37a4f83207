"""Adaptive implicit stepping of the slow physics: TR-BDF2 with its embedded error estimate.

Sintering and preheating take seconds to minutes while the explicit step is bounded by ``C_i / sum_j K_ij`` on the
necks (:func:`sintercond.sim.thermal.explicit_stability_limit`). Without inertial mechanics nothing else bounds the
step, and :func:`integrate` steps the heat balance of a static packing (Rojek et al. 2022, Eqs. 1-4)

    dH_i/dt = F_i(t, T) = -sum_j K_ij(a, T) (T_i - T_j) + sum_w K_iw (T_w - T_i) + Q_i(t, T),   H_i = m_i int c dT

(conduction through growing necks ``a``, conducting walls, beam, convection, radiation, pulse and user sources,
``c(T)`` and ``kappa(T)`` tables; held particles on their fixed values or ramp, Rizza & Galati 2024 Eq. 6) by
TR-BDF2 (Bank et al. 1985; Hosea & Shampine 1996, Applied Numerical Mathematics 20:21-37), ``gamma = 2 - sqrt(2)``:
a trapezoidal stage to ``t + gamma h`` and a BDF2 stage to ``t + h``,

    H_g - (gamma h / 2) F_g = H_n + (gamma h / 2) F_n                                       (Hosea & Shampine Eq. 4)
    H_1 - d h F_1 = (H_g - (1 - gamma)^2 H_n) / (gamma (2 - gamma)),  d = (1 - gamma) / (2 - gamma) = gamma / 2

both stages with the same matrix ``C / (d h) + L + K_w + G`` (``C = dH/dT``, ``L`` the conduction Laplacian, ``G``
the linearised convection and radiation, :func:`sintercond.sim.thermal.source_conductance`): symmetric positive
definite, solved by Jacobi-preconditioned conjugate gradients with the held particles as Dirichlet rows
(:func:`sintercond.sim.thermal.held_solve`). Each stage takes ``Conduction.picard`` simplified-Newton iterations
with the necks, ``c(T)``, ``kappa(T)`` and the radiation at the last iterate (one when the stage is linear). The
enthalpy form keeps ``sum_i H_i`` of an insulated network to the solver's tolerance.

The necks grow within each stage by the kinetic law integrated exactly at the mean of the stage's start and end
pair temperatures (:func:`sintercond.sim.neck_growth.grow_necks`, the trapezoid of the explicit growth interval):
second order, as the temperatures.

Error control: the local error of the step is the divided-difference estimate of TR-BDF2's truncation error
``k h^3 T'''``, ``k = (-3 gamma^2 + 4 gamma - 2) / (12 (2 - gamma))`` (Bank et al. 1985, Eq. 23; Hosea & Shampine
Sec. 2), from the three stage slopes, filtered through the stage matrix as Hosea & Shampine do for stiff problems
(``e = (C / (d h) + L + ...)^-1 C e_raw / (d h)``). A step is accepted when ``max_i |e_i| / (atol + rtol
max(|T_i^n|, |T_i^(n+1)|)) <= 1`` over the free particles, and the next one is ``h clip(0.9 err^(-1/3), 0.2, 5)``
(the standard controller of a second-order pair; Hairer & Wanner, Solving ODEs II, Sec. IV.8). Steps end on the
ramp's jumps and on the end of the interval. ``h`` is a value carried by one ``lax.while_loop`` per interval, so
a change of step never recompiles.

Gradients. Forward mode goes through the ``while_loop``, the controller included. Reverse mode cannot (JAX
differentiates no ``while_loop`` backwards), so with ``reverse_steps=N`` an interval is run twice: the loop above,
outside differentiation, writes the time and length of each accepted step into a buffer of ``N``; then a
``lax.scan`` over that buffer replays the accepted steps (no error estimate, no rejections), each step under
``jax.checkpoint``. The value is the replay's, equal to the loop's to round-off. The derivative is that of the
discrete map of the steps taken, with the step sizes held (the usual discretise-then-differentiate of an adaptive
solver, e.g. diffrax's ``RecursiveCheckpointAdjoint`` without the controller's derivative): it differs from the
derivative of the adaptive map by terms of the order of the local error control. Memory of the backward pass:
``N`` carries of the step (temperatures ``[n]``, necks and approaches ``[c]``, positions ``[n, 3]``) for the
interval being differentiated, plus one state per output interval (:func:`rollout`). An interval needing more than
``N`` accepted steps is flagged (``Stats.failed``), never truncated.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from sintercond.contacts.network import network_laplacian
from sintercond.laws import materials
from sintercond.sim import neck_growth, thermal
from sintercond.sim.physics import Physics
from sintercond.sim.state import Params, Prepared, SimState, held_ramp_temperature
from sintercond.sim.terms import conduction, walls
from sintercond.sim.validation import check_save_interval, validate_inputs

GAMMA = 2.0 - math.sqrt(2.0)
"""The TR-BDF2 stage fraction (Hosea & Shampine 1996): both stages then share one matrix."""

_D = GAMMA / 2.0  # = (1 - GAMMA) / (2 - GAMMA)
_BDF_G = 1.0 / (GAMMA * (2.0 - GAMMA))
_BDF_N = (1.0 - GAMMA) ** 2 / (GAMMA * (2.0 - GAMMA))
ERROR_CONSTANT = (-3.0 * GAMMA**2 + 4.0 * GAMMA - 2.0) / (12.0 * (2.0 - GAMMA))
"""``k`` of TR-BDF2's local truncation error ``k h^3 T'''`` (Bank et al. 1985)."""

SAFETY, SHRINK, GROW = 0.9, 0.2, 5.0
"""The step controller: ``h_new = h clip(SAFETY err^(-1/3), SHRINK, GROW)``."""

MAX_STEPS = 200_000
"""Steps (accepted and rejected) one interval of :func:`integrate` may take before it gives up (``Stats.failed``)."""


class Stats(NamedTuple):
    """What an adaptive interval did: accepted and rejected steps, the step to try next (s), and whether it failed
    (the step fell below round-off of the time, or :data:`MAX_STEPS`)."""

    accepted: jax.Array
    rejected: jax.Array
    next_step: jax.Array
    failed: jax.Array


def needs_tr_bdf2(physics: Physics) -> bool:
    """Whether a fixed implicit step of ``physics`` is one TR-BDF2 step (sources, necks, property tables) rather
    than the backward-Euler step of conduction and held particles (:func:`sintercond.sim.thermal.backward_euler_solve`)."""
    c = physics.conduction
    return bool(physics.sources.any or physics.sintering is not None or c.specific_heat_table
                or c.conductivity_table)


def check_supported(physics: Physics) -> None:
    """Raise ``ValueError`` unless ``physics`` is implicit on static contacts without mechanics."""
    if physics.conduction.integrator != "implicit":
        raise ValueError("adaptive.integrate steps a spec with Conduction.integrator='implicit'; got "
                         f"{physics.conduction.integrator!r}")
    if physics.mechanics is not None or physics.contacts != "static":
        raise ValueError("adaptive.integrate steps static contacts without mechanics (Physics.contacts='static', "
                         "mechanics=None)")


def _linear(physics: Physics) -> bool:
    """Whether every stage is linear in the temperatures (one iteration solves it)."""
    c, src = physics.conduction, physics.sources
    return not (physics.sintering is not None or src.radiation or src.source is not None or c.specific_heat_table
                or c.conductivity_table)


class _Slow(NamedTuple):
    """What a step advances: temperatures ``[n]`` (K), the contacts (necks), positions ``[n, 3]`` (m), and with
    many-body shrinkage the last steps' balances (``recent``, as
    :attr:`sintercond.sim.neck_growth.NeckState.recent_balances`: the start of the next balances) and the sum of
    this step's stages' (``balance``, the contact values of ``B u``,
    :func:`sintercond.sim.neck_growth.balance_displacements`)."""

    temperature: jax.Array
    contacts: object
    positions: jax.Array
    recent: jax.Array | None = None
    balance: jax.Array | None = None


def _slow(state: SimState) -> _Slow:
    """The :class:`_Slow` part of ``state``."""
    recent = None if state.sintering is None else state.sintering.recent_balances
    positions = state.particles.positions
    return _Slow(state.particles.temperature, state.contacts, positions, recent,
                 None if recent is None else jnp.zeros_like(recent[0]))


def _at(state: SimState, slow: _Slow, t) -> SimState:
    """``state`` holding ``slow`` at time ``t`` (s): a state of one step of length ``t`` (its ``time`` is ``t``)."""
    particles = dataclasses.replace(state.particles, temperature=slow.temperature, positions=slow.positions)
    return dataclasses.replace(state, particles=particles, contacts=slow.contacts,
                               step=jnp.ones_like(state.step), dt=jnp.asarray(t, state.dt.dtype))


def _enthalpy(physics: Physics, prep: Prepared, particles, temperature):
    """``H_i`` (J, from 0 K of the table or of the constant ``c``) and ``C_i = dH_i/dT_i`` (J/K)."""
    if physics.conduction.specific_heat_table:
        table = prep.params.specific_heat
        return (particles.mass * materials.integrate_table(temperature, table.temperatures, table.values),
                particles.mass * table(temperature))
    return prep.capacity * temperature, prep.capacity


class _Operator(NamedTuple):
    """The stage's linear part at an iterate: ``x -> L x`` and its diagonal with the walls and the sources."""

    conductance: jax.Array
    neighbors: jax.Array
    scale: jax.Array
    diagonal: jax.Array  # [n] K_w + G (W/K)

    def apply(self, x):
        return self.diagonal * x + self.scale * network_laplacian(self.conductance, self.neighbors, x)

    def jacobi(self):
        return self.diagonal + self.scale * jnp.sum(self.conductance, axis=1)


def _power_and_operator(physics: Physics, state: SimState, prep: Prepared):
    """``(F, operator)``: the heat power ``[n]`` (W) into each particle and the linear part of ``-F`` at ``state``."""
    _, conductance, neighbors = conduction.current_network(physics, None, state, prep)
    power = conduction.heat_power(physics, None, state, prep, conductance, neighbors)
    diagonal = thermal.source_conductance(physics.sources, state.particles.radii, prep.params,
                                          state.particles.temperature)
    if physics.conduction.conducting_walls:
        diagonal = diagonal + prep.scale * jnp.sum(walls.thermal_wall_conductance(physics, state, prep), axis=0)
    if conductance is None:
        conductance = jnp.zeros((power.shape[0], 1), power.dtype)
        neighbors = jnp.arange(power.shape[0])[:, None]
    return power, _Operator(conductance, neighbors, prep.scale, jnp.broadcast_to(diagonal, power.shape))


def _grow(physics: Physics, prep: Prepared, state: SimState, start: _Slow, temperature, duration):
    """``(contacts, positions, balance)``: the necks (and positions and the balance, many-body; else None) after
    ``duration`` (s) from ``start``, the pair temperature the mean of ``start``'s and ``temperature``
    (:func:`sintercond.sim.neck_growth.grow_necks`)."""
    if physics.sintering is None:
        return start.contacts, start.positions, None
    spec = physics.sintering
    carried = dataclasses.replace(state.sintering, interval_temperature=start.temperature,
                                  recent_balances=start.recent)
    contacts = start.contacts
    grown = neck_growth.grow_necks(
        spec, neck_growth.law_params(spec, prep.params.sintering), carried, contacts.pairs, contacts.neck, True,
        positions=start.positions, radii=state.particles.radii, end_temperature=temperature, duration=duration,
        table=(contacts.slot_pair, contacts.neighbors))
    positions = start.positions if grown.displacement is None else start.positions + grown.displacement
    return dataclasses.replace(contacts, neck=grown.neck, overlap=grown.neck_overlap), positions, grown.balance


def _stage(physics, prep, state, fixed, held, start: _Slow, guess, rhs, dh, t, duration, tol):
    """Solve ``H(T) - dh F(t, T) = rhs`` from ``guess`` (necks grown from ``start`` over ``duration``): the stage's
    ``(slow, H, operator)``, the operator (the stage matrix) at its solution."""

    def iterate(_, temperature):
        contacts, positions, _ = _grow(physics, prep, state, start, temperature, duration)
        here = _at(state, _Slow(temperature, contacts, positions), t)
        enthalpy, capacity = _enthalpy(physics, prep, here.particles, temperature)
        power, op = _power_and_operator(physics, here, prep)
        residual = (enthalpy - rhs) / dh - power
        shifted = op._replace(diagonal=op.diagonal + capacity / dh)
        inverse = 1.0 / shifted.jacobi()
        delta = thermal.held_solve(shifted.apply, fixed, jnp.where(fixed, held - temperature, 0.0), -residual, tol,
                                   preconditioner=lambda r: inverse * r)
        return jnp.where(fixed, held, temperature + delta)

    temperature = jnp.where(fixed, held, guess)
    if _linear(physics) or physics.conduction.picard == 1:
        temperature = iterate(0, temperature)
    else:  # a loop, not unrolled: the compiled stage stays one iteration long
        temperature = jax.lax.fori_loop(0, physics.conduction.picard, iterate, temperature)
    contacts, positions, balance = _grow(physics, prep, state, start, temperature, duration)
    slow = _Slow(temperature, contacts, positions, start.recent, None if balance is None else start.balance + balance)
    enthalpy, capacity = _enthalpy(physics, prep, state.particles, temperature)
    _, op = _power_and_operator(physics, _at(state, slow, t), prep)
    return slow, enthalpy, op._replace(diagonal=op.diagonal + capacity / dh)


def _solver_tolerance(physics: Physics, dtype) -> float:
    """The relative residual of the stage solves (of the increment): well below ``rtol``, above round-off."""
    return max(1e-3 * physics.conduction.rtol, 50.0 * float(jnp.finfo(dtype).eps))


def _held_values(physics: Physics, state: SimState, prep: Prepared, t):
    """``(fixed [n] bool, held [n] K)``: the held particles and their temperature at ``t`` (s), within a step."""
    particles = state.particles
    if not physics.conduction.held:
        return jnp.zeros(particles.temperature.shape, bool), particles.temperature
    if physics.conduction.held_ramp:
        return particles.fixed, held_ramp_temperature(prep.params.held_ramp, particles.fixed_temperature, t)
    return particles.fixed, jnp.broadcast_to(particles.fixed_temperature, particles.temperature.shape)


def _next_jump(physics: Physics, prep: Prepared, t):
    """The first jump of the held ramp after ``t`` (s), or ``inf``: a step ends there."""
    if not physics.conduction.held_ramp:
        return jnp.asarray(jnp.inf, t.dtype)
    ramp = prep.params.held_ramp
    width = ramp.duration / ramp.steps
    level = t / width
    k = jnp.floor(level + 64.0 * jnp.finfo(t.dtype).eps * (1.0 + level)) + 1.0
    return jnp.where(k <= ramp.steps, k * width, jnp.inf).astype(t.dtype)


def tr_bdf2_step(physics: Physics, state: SimState, prep: Prepared, slow: _Slow, t, h, estimate: bool = True):
    """One TR-BDF2 step of ``h`` (s) from ``slow`` at ``t`` (s): ``(slow at t + h, err)``, ``err`` the error norm
    (accepted when <= 1; module docstring; 0 without ``estimate``, which skips its solve)."""
    rtol, atol = physics.conduction.rtol, physics.conduction.atol
    tol = _solver_tolerance(physics, slow.temperature.dtype)
    fixed, held = _held_values(physics, state, prep, t + 0.5 * h)  # a step never crosses a jump of the ramp
    start = slow._replace(temperature=jnp.where(fixed, held, slow.temperature),
                          balance=None if slow.balance is None else jnp.zeros_like(slow.balance))
    here = _at(state, start, t)
    enthalpy_n, _ = _enthalpy(physics, prep, here.particles, start.temperature)
    power_n, _ = _power_and_operator(physics, here, prep)
    dh = _D * h  # = gamma h / 2: both stages solve with the same dh
    def stage(carry, coefficients):
        # rhs = w_prev H_prev + w_n H_n + w_f dh F_n: the trapezoid (0, 1, 1), then BDF2 (BDF_G, -BDF_N, 0);
        # one scanned stage, so the step compiles one stage body
        previous, enthalpy_previous = carry
        w_prev, w_n, w_f, fraction, duration = coefficients
        rhs = w_prev * enthalpy_previous + w_n * enthalpy_n + w_f * dh * power_n
        new, enthalpy, op = _stage(physics, prep, state, fixed, held, previous, previous.temperature, rhs, dh,
                                   t + fraction * h, duration * h, tol)
        return (new, enthalpy), (enthalpy, op)

    dtype = slow.temperature.dtype
    coefficients = tuple(jnp.asarray(c, dtype) for c in ([0.0, _BDF_G], [1.0, -_BDF_N], [1.0, 0.0], [GAMMA, 1.0],
                                                         [GAMMA, 1.0 - GAMMA]))
    (end, enthalpy_1), (enthalpies, ops) = jax.lax.scan(stage, (start, enthalpy_n), coefficients)
    if start.recent is not None:  # the step's many-body balances start the next steps'
        end = end._replace(recent=neck_growth.pushed(start.recent, end.balance))
    if not estimate:
        return end, jnp.zeros((), dtype)
    enthalpy_g = enthalpies[0]
    op = jax.tree.map(lambda x: x[1], ops)
    rhs = _BDF_G * enthalpy_g - _BDF_N * enthalpy_n
    # the stage slopes from the stage equations themselves, then Bank et al.'s estimate filtered by the matrix
    power_g = 2.0 * (enthalpy_g - enthalpy_n) / (GAMMA * h) - power_n
    power_1 = (enthalpy_1 - rhs) / dh
    raw = 2.0 * ERROR_CONSTANT * h * (power_n / GAMMA - power_g / (GAMMA * (1.0 - GAMMA)) + power_1 / (1.0 - GAMMA))
    inverse = 1.0 / op.jacobi()
    error = thermal.held_solve(op.apply, fixed, jnp.zeros_like(raw), raw / dh, tol,
                               preconditioner=lambda r: inverse * r)
    bound = atol + rtol * jnp.maximum(jnp.abs(start.temperature), jnp.abs(end.temperature))
    err = jnp.max(jnp.where(fixed, 0.0, jnp.abs(error) / bound), initial=0.0)
    return end, jnp.where(jnp.all(jnp.isfinite(end.temperature)), err, jnp.inf)


def _with(state: SimState, slow: _Slow) -> SimState:
    particles = dataclasses.replace(state.particles, temperature=slow.temperature, positions=slow.positions)
    return dataclasses.replace(state, particles=particles, contacts=slow.contacts)


def _interval_end(physics: Physics, state: SimState, slow: _Slow, steps) -> SimState:
    """``state`` holding ``slow`` ``steps`` steps (of the state's ``dt``) later; a sintering state's growth interval
    starts there."""
    new = dataclasses.replace(_with(state, slow), step=state.step + steps)
    if physics.sintering is None:
        return new
    carried = state.sintering if slow.recent is None else dataclasses.replace(state.sintering,
                                                                               recent_balances=slow.recent)
    return dataclasses.replace(new, sintering=dataclasses.replace(
        carried, interval_temperature=slow.temperature, interval_start=new.step))


def fixed_step(physics: Physics, state: SimState, prep: Prepared) -> SimState:
    """One TR-BDF2 step of the state's ``dt`` without error control: the fixed implicit step of a spec with
    sources, necks or property tables (:func:`needs_tr_bdf2`)."""
    slow = _slow(state)
    end, _ = tr_bdf2_step(physics, state, prep, slow, state.time, state.dt)
    return _interval_end(physics, state, end, 1)


def integrate_interval(physics: Physics, state: SimState, prep: Prepared, steps: int, first_step,
                       reverse_steps: int | None = None):
    """Advance ``state`` by ``steps`` of its ``dt`` (an interval of ``steps * dt`` s) adaptively: ``(state, Stats)``.

    Traceable; ``first_step`` (s) is the step to try first (the previous interval's ``Stats.next_step``), a traced
    value: neither it nor ``dt`` recompiles. ``reverse_steps``: None (one ``while_loop``: forward-mode gradients
    only), or the most accepted steps the interval may take, recorded and replayed so that reverse mode works
    (module docstring; more is flagged in ``Stats.failed``).
    """
    if reverse_steps is None:
        slow, stats, _, _ = _adapt(physics, state, prep, steps, first_step, 0)
        return _interval_end(physics, state, slow, steps), stats
    if not (isinstance(reverse_steps, int) and reverse_steps >= 1):
        raise ValueError(f"reverse_steps must be an integer >= 1 (accepted steps per interval); got {reverse_steps!r}")
    held = jax.tree.map(_no_gradient, (state, prep, first_step))
    _, stats, times, sizes = _adapt(physics, *held[:2], steps, held[2], reverse_steps)
    slow = _replay(physics, state, prep, times, sizes, stats.accepted)
    stats = stats._replace(failed=stats.failed | (stats.accepted > reverse_steps))
    return _interval_end(physics, state, slow, steps), stats


def _no_gradient(x):
    return jax.lax.stop_gradient(x) if jnp.issubdtype(jnp.result_type(x), jnp.inexact) else x


def _adapt(physics: Physics, state: SimState, prep: Prepared, steps: int, first_step, record: int):
    """The adaptive loop over one interval: ``(slow, Stats, times [record], sizes [record])``, the last two the
    start (s) and length (s) of each accepted step (zero past ``Stats.accepted``; dropped beyond ``record``)."""
    dtype = state.dt.dtype
    t0 = state.time
    t_end = t0 + steps * state.dt
    tiny = 64.0 * jnp.finfo(dtype).eps * jnp.maximum(jnp.abs(t_end), state.dt)

    def go_on(carry):
        t, _, _, accepted, rejected, failed, _, _ = carry
        return (t < t_end) & ~failed & (accepted + rejected < MAX_STEPS)

    def body(carry):
        t, slow, h_try, accepted, rejected, _, times, sizes = carry
        ends = jnp.minimum(t_end, _next_jump(physics, prep, t))
        h = jnp.minimum(h_try, ends - t)
        clipped = h_try >= ends - t
        new, err = tr_bdf2_step(physics, state, prep, slow, t, h)
        factor = jnp.clip(SAFETY * jnp.where(err > 0, err, 1e-30) ** (-1.0 / 3.0), SHRINK, GROW)
        factor = jnp.where(jnp.isfinite(err), factor, SHRINK)
        ok = err <= 1.0
        slow = jax.tree.map(lambda a, b: jnp.where(ok, a, b), new, slow)
        t_new = jnp.where(ok, jnp.where(clipped & (ends == t_end), t_end, jnp.where(clipped, ends, t + h)), t)
        h_next = jnp.where(ok & clipped, jnp.maximum(h * factor, h_try), h * factor)
        failed = ~ok & (h * SHRINK < tiny)
        if record:
            slot = jnp.where(ok, accepted, record)  # out of range (dropped) when rejected
            times = times.at[slot].set(t, mode="drop")
            sizes = sizes.at[slot].set(t_new - t, mode="drop")
        return (t_new, slow, h_next, accepted + ok.astype(jnp.int32), rejected + (~ok).astype(jnp.int32), failed,
                times, sizes)

    slow = _slow(state)
    zero = jnp.zeros((), jnp.int32)
    h0 = jnp.minimum(jnp.asarray(first_step, dtype), t_end - t0)
    buffer = jnp.zeros((record,), dtype)
    t, slow, h_next, accepted, rejected, failed, times, sizes = jax.lax.while_loop(
        go_on, body, (t0, slow, h0, zero, zero, jnp.zeros((), bool), buffer, buffer))
    failed = failed | (t < t_end)
    return slow, Stats(accepted, rejected, h_next, failed), times, sizes


def _replay(physics: Physics, state: SimState, prep: Prepared, times, sizes, accepted) -> _Slow:
    """The accepted steps ``(times, sizes)`` of :func:`_adapt` again, differentiably: a scan of checkpointed steps,
    those past ``accepted`` skipped."""

    def body(slow, step):
        t, h, k = step
        return jax.lax.cond(k < accepted, lambda s: tr_bdf2_step(physics, state, prep, s, t, h, estimate=False)[0],
                            lambda s: s, slow), None

    slow = _slow(state)
    slow, _ = jax.lax.scan(jax.checkpoint(body, prevent_cse=False), slow,
                           (times, sizes, jnp.arange(times.shape[0], dtype=accepted.dtype)))
    return slow


def integrate(sim, state: SimState, params: Params, steps: int, first_step=None, *, reverse_steps: int | None = None):
    """Advance ``state`` by ``steps`` of its ``dt`` adaptively (TR-BDF2 within ``Conduction.rtol`` / ``atol``):
    ``(state, Stats)``. ``first_step`` (s): the step to try first (default the whole interval);
    ``reverse_steps``: as :func:`integrate_interval` (set it for ``jax.grad``). Jit it with ``steps`` and
    ``reverse_steps`` static; raise ``ValueError`` on a spec it does not step."""
    check_supported(sim.physics)
    prep = sim.prepare_fn(state, params)
    first = steps * state.dt if first_step is None else first_step
    return integrate_interval(sim.physics, state, prep, steps, first, reverse_steps)


def rollout(sim, state: SimState, params: Params, n_steps: int, saveat=None, *, reverse_steps: int | None = None,
            first_step=None):
    """Advance ``n_steps`` steps of the state's ``dt`` adaptively, saving ``saveat.fn(state)`` (a
    :class:`sintercond.sim.rollout.SaveAt`; default the temperatures after every step) at the end of every
    ``saveat.every`` steps (each such interval one :func:`integrate_interval`, the next starting from the step the
    last one proposed): ``(state, saved, Stats)``, ``Stats`` summed over the intervals (``failed``: any failed).

    The adaptive counterpart of :func:`sintercond.sim.rollout.rollout` (``dt`` is the output clock only); with
    ``reverse_steps`` each interval is a ``jax.checkpoint``-ed record-and-replay, so ``jax.grad`` of a loss of the
    saved values works (memory: module docstring). Check ``Stats.failed`` on the host: a failed interval's values
    are not to be used. Jit it with ``sim``, ``n_steps``, ``saveat`` and ``reverse_steps`` static.
    """
    every = 1 if saveat is None else saveat.every
    check_save_interval(n_steps, every)
    check_supported(sim.physics)
    validate_inputs(sim, state, params)
    fn = None if saveat is None else saveat.fn
    observe = (lambda s: s.particles.temperature) if fn is None else fn
    prep = sim.prepare_fn(state, params)

    def interval(carry, _):
        state, first, total = carry
        state, stats = integrate_interval(sim.physics, state, prep, every, first, reverse_steps)
        total = Stats(total.accepted + stats.accepted, total.rejected + stats.rejected, stats.next_step,
                      total.failed | stats.failed)
        return (state, stats.next_step, total), observe(state)

    if reverse_steps is not None:
        interval = jax.checkpoint(interval, prevent_cse=False)
    first = jnp.asarray(every * state.dt if first_step is None else first_step, state.dt.dtype)
    zero = jnp.zeros((), jnp.int32)
    (state, _, total), saved = jax.lax.scan(interval, (state, first, Stats(zero, zero, first, jnp.zeros((), bool))),
                                            None, length=n_steps // every)
    return state, saved, total
