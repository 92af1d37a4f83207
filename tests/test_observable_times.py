"""When observables are saved: rollout's SaveAt and a run's history rows against the step count (issue 28).

The reference is the step itself applied k times in a Python loop: saved[k] must be the observable of the state
after (k + 1) * every steps, whatever the checkpointed segments; history.csv's rows fall at every
run.output_every steps and at the last step, each at time step * dt.
"""

import copy

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import simulate
from sintercond.contacts import network
from sintercond import run as runner
from sintercond.scene import validate_scene
from sintercond.state import particle_state
from tests.test_scene_run import SMALL


@pytest.fixture(scope="module", params=[3, 100], ids=["written-on-the-interval", "written-every-step"])
def chain(request):
    """A touching chain of spheres, the first hot: explicit conduction. The observable (step, time and two
    temperatures) is large beside 3 temperatures and small beside 100: rollout then takes its two ways of
    writing it (a branch at the end of each interval, or a write after every step whose last one stands)."""
    n, r = request.param, 1e-4
    x = np.zeros((n, 3))
    x[:, 0] = 1.9 * r * np.arange(n)
    temperature = np.full(n, 300.0)
    temperature[0] = 900.0
    particles = particle_state(x, r, temperature, 4430.0)
    table = network.contact_table(x, np.full(n, r), 1.0, "rojek")
    sim = simulate.simulator(simulate.Physics.create(law="rojek"))
    params = simulate.Params(conductivity=jnp.asarray([12.6]), specific_heat=jnp.asarray([560.0]))
    state = simulate.init_state(particles, simulate.table_contacts(table), 1.0)
    dt = 0.5 * float(simulate.thermal_time_step(sim, state, params))
    return sim, simulate.init_state(particles, simulate.table_contacts(table), dt), params


def _watch(s):
    return jnp.concatenate([jnp.stack([s.step.astype(s.dt.dtype), s.time]), s.particles.temperature[:2]])


@pytest.mark.parametrize("n_steps,every,checkpoint", [(1, 1, True), (36, 3, True), (35, 5, True), (35, 7, False),
                                                      (50, 50, True)])
def test_saved_k_is_the_state_after_k_plus_one_times_every_steps(chain, n_steps, every, checkpoint):
    sim, state, params = chain
    final, saved = simulate.rollout(sim, state, params, n_steps, simulate.SaveAt(every, _watch), checkpoint=checkpoint)
    saved = np.asarray(saved)
    assert saved.shape == (n_steps // every, 4)
    step = jax.jit(sim.step_fn)
    s, expected = state, []
    for k in range(1, n_steps + 1):
        s = step(s, params)
        if k % every == 0:
            expected.append(np.asarray(_watch(s)))
    expected = np.asarray(expected)
    np.testing.assert_array_equal(saved[:, 0], np.arange(1, n_steps // every + 1) * every)
    np.testing.assert_allclose(saved[:, 1], saved[:, 0] * float(state.dt), rtol=1e-15)
    np.testing.assert_allclose(saved[:, 2:], expected[:, 2:], rtol=1e-13)
    assert int(final.step) == n_steps


def test_history_rows_fall_at_the_output_steps_and_at_the_end(tmp_path):
    scene = copy.deepcopy(SMALL)
    scene["run"].update(duration=1.3e-3, output_every=7, checkpoint_every=7)
    model = runner.build_model(validate_scene(copy.deepcopy(scene)))
    assert model.n_steps % 7  # the last chunk is shorter
    runner.run_scene(validate_scene(scene), tmp_path, progress=False)
    history = np.genfromtxt(tmp_path / "history.csv", delimiter=",", names=True, ndmin=1)
    expected = np.append(np.arange(0, model.n_steps, 7), model.n_steps)
    np.testing.assert_array_equal(history["step"], expected)
    np.testing.assert_allclose(history["time_s"], expected * model.dt, rtol=1e-12, atol=0)
    frames = sorted((tmp_path / "vtp").iterdir())
    assert len(frames) == len(expected)
