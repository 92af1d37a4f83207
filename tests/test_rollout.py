"""The one host loop, sintercond.rollout.advance: chunks are the rollout, stopping rules, overflow policy."""

import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import rollout, simulate
from sintercond.beds import packing, settle
from sintercond.state import ParticleState


def _conduction(n_side=4):
    spacing = 1e-4
    grid = np.stack(np.meshgrid(*[np.arange(n_side)] * 3, indexing="ij"), -1).reshape(-1, 3) * spacing
    radii = np.full(len(grid), 0.52 * spacing)
    n = len(radii)
    t0 = jnp.asarray(np.linspace(300.0, 900.0, n))
    capacity = jnp.full(n, 4 / 3 * np.pi * radii[0] ** 3 * 4430 * 560)
    physics = simulate.Physics.create(law="rojek", conductance="lifted")
    contacts = simulate.lifted_contacts(physics, grid, radii)
    sim = simulate.simulator(physics)
    particles = ParticleState(jnp.asarray(grid), jnp.asarray(radii), t0, capacity, jnp.zeros(n, jnp.int32),
                              jnp.zeros(n, bool), t0)
    params = simulate.Params(conductivity=jnp.array([7.0]), specific_heat=jnp.array([1.0]))
    probe = simulate.init_state(particles, contacts, 1.0)
    dt = 0.5 * float(simulate.thermal_time_step(sim, probe, params))
    return sim, simulate.init_state(particles, contacts, dt), params


@pytest.mark.slow
def test_chunks_are_one_rollout_bitwise():
    """30 steps as chunks of 7, 7, 7, 7 and 2 are the same numbers as one rollout of 30 steps."""
    sim, state, params = _conduction()
    whole, _ = simulate.rollout(sim, state, params, 30, simulate.SaveAt(30, lambda s: ()))
    calls = []
    chunked, report = rollout.advance(sim, state, params, 30, 7, on_chunk=lambda s: calls.append(int(s.step)))
    assert calls == [7, 14, 21, 28, 30] and report == rollout.Report(chunks=5, reallocations=0)
    np.testing.assert_array_equal(np.asarray(chunked.particles.temperature), np.asarray(whole.particles.temperature))
    assert int(chunked.step) == 30


def test_measure_reaches_on_chunk_and_a_stopping_rule_stops_at_that_chunk():
    sim, state, params = _conduction()
    spread0 = float(jnp.max(state.particles.temperature) - jnp.min(state.particles.temperature))
    seen = []

    def stop(s, figures):
        spread, mean = figures
        seen.append((int(s.step), float(spread), float(mean)))
        return float(spread) < 0.5 * spread0

    final, report = rollout.advance(sim, state, params, 100000, 2, stop, measure=_spread_and_mean)
    steps = [s for s, *_ in seen]
    assert len(steps) >= 2 and steps == list(range(2, 2 * (len(steps) + 1), 2))
    assert int(final.step) == steps[-1] < 100000
    t = np.asarray(final.particles.temperature)
    assert seen[-1][1] == pytest.approx(t.max() - t.min(), rel=1e-15)
    assert seen[-1][1] < 0.5 * spread0 <= seen[-2][1]
    # an insulated network conserves heat: the mean temperature (equal capacities) stays put
    assert seen[-1][2] == pytest.approx(float(jnp.mean(state.particles.temperature)), rel=1e-12)
    assert report.chunks == len(steps)


def _spread_and_mean(sim, state, params):
    t = state.particles.temperature
    return (jnp.max(t) - jnp.min(t), jnp.mean(t)), jnp.zeros((), bool)


@pytest.mark.slow
def test_an_overflow_with_no_reallocation_is_refused_and_a_flag_from_measure_counts_as_one():
    """A shrinking powder bed on a list with no spare room (tests/test_moving.py's run): new contacts overflow it.

    Two chunks of 50 steps, not that test's eight: each chunk of the shrinking bed overflows and is redone on a
    reallocated (so recompiled, about 5 s) list, so two chunks already show a refusal, a reallocation and one after
    it, the run reaching its last step without an overflow; test_moving.py runs all 400 steps and checks the
    temperatures and contacts of the end."""
    bed = packing.powder_bed(320.0, 260.0, seed=11)
    centres, radii = bed.centres * 1e-6, bed.radii * 1e-6
    physics = simulate.Physics.create(law="batchelor_obrien", neck_model="intersection", conductance="lifted",
                                      contacts="dynamic", motion=simulate.affine_shrinkage(centres, 40.0))
    contacts, fns = simulate.dynamic_contacts(centres, radii, 0.0, 1.0)
    t0 = jnp.asarray(np.random.default_rng(0).uniform(300, 1000, len(radii)))
    particles = ParticleState(jnp.asarray(centres), jnp.asarray(radii), t0,
                              jnp.asarray(4 / 3 * np.pi * radii**3 * 4430 * 560), jnp.zeros(len(radii), jnp.int32),
                              jnp.zeros(len(radii), bool), t0)
    state = simulate.init_state(particles, contacts, 2e-5)
    params = simulate.Params(conductivity=jnp.array([7.0]), specific_heat=jnp.array([1.0]))
    sim = simulate.simulator(physics, fns)
    with pytest.raises(rollout.ListOverflow, match="overflowed at step 0 and no reallocation"):
        rollout.advance(sim, state, params, 100, 50)
    final, report = rollout.advance(sim, state, params, 100, 50, reallocate=simulate.reallocate_neighbors(fns))
    assert report.reallocations >= 1 and int(final.step) == 100 and not bool(final.overflow)

    static, state, params = _conduction()

    def always(sim, state, params):
        return (), jnp.ones((), bool)

    with pytest.raises(rollout.ListOverflow):
        rollout.advance(static, state, params, 20, 10, measure=always)


def test_a_state_that_fails_its_check_is_not_handed_on():
    import dataclasses

    sim, state, params = _conduction()
    seen = []

    def check(s):
        if int(s.step) >= 20:
            raise FloatingPointError("refused at step 20")

    with pytest.raises(FloatingPointError, match="refused at step 20"):
        rollout.advance(sim, state, params, 30, 10, on_chunk=lambda s: seen.append(int(s.step)), check=check)
    assert seen == [10]
    # the default check: a step far above the stable one overflows the temperatures to inf, then NaN
    unstable = dataclasses.replace(state, dt=state.dt * 1e250)
    with pytest.raises(FloatingPointError, match="non-finite temperature at step 10"):
        rollout.advance(sim, unstable, params, 30, 10, on_chunk=lambda s: pytest.fail("handed on"))


@pytest.mark.slow
def test_settling_runs_on_the_host_loop():
    """settle.dem_settle's chunks are rollout.advance's (measure: kinetic energy and net force of a probe step)."""
    r = np.full(2, 1e-3)
    centres = np.array([[2e-3, 2e-3, 1.0e-3], [2e-3, 2e-3, 3.2e-3]])
    settled = settle.dem_settle(centres, r, settle.box_walls(4e-3), check_every=500, max_time=0.5)
    assert settled.report.steps % 500 == 0
    # resting one on the other on the floor: the centres sit near r and 3 r, less the Hertz overlaps
    z = np.sort(settled.centres[:, 2])
    assert z[0] == pytest.approx(1e-3, rel=2e-3) and z[1] - z[0] == pytest.approx(2e-3, rel=2e-3)
    # the settling criterion stops at the first chunk that meets it: a settled pile settles again in one chunk
    again = settle.dem_settle(settled.centres, r, settle.box_walls(4e-3), check_every=500, max_time=0.5)
    assert again.report.steps == 500 and settled.report.steps > 500
    assert again.report.kinetic_ratio < again.report.kinetic_tol and again.report.force_ratio < again.report.force_tol
