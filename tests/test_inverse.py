"""Inverse problem through the thermal DEM: the checkpointed adjoint against JAX's own reverse mode and
finite differences, the stability flag, and recovery of kappa from noisy probe histories."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fitting import inverse
from sintercond.contacts import network
from sintercond.sim import thermal

D = 1e-4  # 100 um particles
RHO, C_TRUE, KAPPA_TRUE = 4430.0, 560.0, 7.0


def _lattice(n, squeeze=0.97):
    grid = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    return grid * D * squeeze, np.full(len(grid), D / 2)


@pytest.fixture(scope="module")
def experiment():
    centres, radii = _lattice(5)
    return inverse.flash_experiment(centres, radii, RHO, n_steps=403, save_every=10, kappa_max=20.0,
                                    specific_heat_min=500.0)


def _weighted_loss(experiment, gradient):
    weights = jnp.asarray(np.random.default_rng(1).normal(size=(experiment.n_steps // experiment.save_every,
                                                                len(experiment.probes))))
    return lambda kappa, c: jnp.sum(weights * experiment.temperatures(kappa, c, gradient))


def test_adjoint_and_simulate_give_the_same_readings(experiment):
    adjoint = experiment.temperatures(KAPPA_TRUE, C_TRUE)
    simulated = experiment.temperatures(KAPPA_TRUE, C_TRUE, "autodiff")
    assert adjoint.shape == (40, len(experiment.probes))
    np.testing.assert_allclose(adjoint, simulated, rtol=0, atol=1e-11)
    # energy check: after the pulse the mean rise is what the flash was sized for, at c = 500
    final = experiment.temperatures(KAPPA_TRUE, 500.0)
    assert float(final[-1].mean()) > 300.0


@pytest.mark.slow
@pytest.mark.parametrize("n_steps,save_every", [(403, 10), (400, 1), (37, 37), (1, 1)])
def test_adjoint_gradient_equals_reverse_mode_and_finite_differences(n_steps, save_every):
    centres, radii = _lattice(4)
    ex = inverse.flash_experiment(centres, radii, RHO, n_steps=n_steps, save_every=save_every, kappa_max=20.0,
                                  specific_heat_min=500.0)
    adjoint = jax.grad(_weighted_loss(ex, "adjoint"), argnums=(0, 1))(KAPPA_TRUE, C_TRUE)
    reverse = jax.grad(_weighted_loss(ex, "autodiff"), argnums=(0, 1))(KAPPA_TRUE, C_TRUE)
    np.testing.assert_allclose(adjoint, reverse, rtol=1e-10)
    f = _weighted_loss(ex, "autodiff")
    for k, step in ((0, 1e-4), (1, 1e-2)):
        args = [KAPPA_TRUE, C_TRUE]
        up, down = list(args), list(args)
        up[k] += step
        down[k] -= step
        fd = (float(f(*up)) - float(f(*down))) / (2 * step)
        assert float(adjoint[k]) == pytest.approx(fd, rel=1e-6, abs=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("heated", ["face", "edge"])
def test_adjoint_with_held_particles_and_walls(heated):
    """150 steps: 11 segments of 13 and a tail of 7; probe 5 is held. The pulse heats a face (16 of 64 particles)
    or an edge (4: the adjoint then accumulates the pulse's cotangent on the heated particles alone)."""
    centres, radii = _lattice(4)
    table = network.contact_table(centres, radii, 1.0)
    walls = network.wall_conductance(centres, radii, 1.0, axis=2, position=-0.47 * D)
    table = table.with_walls(walls, jnp.full(len(radii), 350.0))
    mass = RHO * 4 / 3 * np.pi * radii**3
    held = jnp.asarray(centres[:, 0] == 0.0)
    on_face = centres[:, 1] == 0.0
    on_edge = on_face & (centres[:, 2] == 0.0)
    ex = inverse.ProbeExperiment(table=table, mass=jnp.asarray(mass), initial=jnp.full(len(radii), 300.0),
                                 power=jnp.where(jnp.asarray(on_edge if heated == "edge" else on_face), 1e-3, 0.0),
                                 pulse_duration=0.02,
                                 dt=0.4 * float(thermal.table_time_step(mass * C_TRUE, table)) / KAPPA_TRUE,
                                 n_steps=150, save_every=3, probes=jnp.asarray([5, 40, 63]), fixed_mask=held,
                                 fixed_temperature=jnp.full(len(radii), 320.0))
    np.testing.assert_allclose(ex.temperatures(KAPPA_TRUE, C_TRUE), ex.temperatures(KAPPA_TRUE, C_TRUE, "autodiff"),
                               atol=1e-11)
    adjoint = jax.grad(_weighted_loss(ex, "adjoint"), argnums=(0, 1))(KAPPA_TRUE, C_TRUE)
    reverse = jax.grad(_weighted_loss(ex, "autodiff"), argnums=(0, 1))(KAPPA_TRUE, C_TRUE)
    np.testing.assert_allclose(adjoint, reverse, rtol=1e-10)


@pytest.mark.slow
def test_unstable_parameters_are_flagged(experiment):
    limit = experiment.max_diffusivity_ratio()
    assert limit == pytest.approx(20.0 / 500.0, rel=1e-12)
    assert np.all(np.isfinite(experiment.temperatures(0.99 * limit * 500.0, 500.0)))
    assert np.all(np.isnan(experiment.temperatures(1.01 * limit * 500.0, 500.0)))
    value, grad = jax.value_and_grad(lambda k: jnp.sum(experiment.temperatures(k, 500.0)))(1.01 * limit * 500.0)
    assert np.isnan(float(value))


def test_bad_input_names_the_field(experiment):
    with pytest.raises(ValueError, match="gradient"):
        experiment.temperatures(1.0, 500.0, gradient="numeric")
    with pytest.raises(ValueError, match="density"):
        inverse.flash_experiment(*_lattice(3), -1.0)
    with pytest.raises(ValueError, match="probes"):
        inverse.ProbeExperiment(experiment.table, experiment.mass, experiment.initial, experiment.power, 0.1,
                                experiment.dt, 10, 1, jnp.asarray([10_000]))
    with pytest.raises(ValueError, match="kappa0"):
        inverse.fit_conductivity(experiment, experiment.temperatures(7.0, 560.0), 560.0, kappa0=1e6)


@pytest.mark.slow
def test_kappa_recovered_from_noisy_probe_histories(experiment):
    clean = experiment.temperatures(KAPPA_TRUE, C_TRUE)
    noise = 0.05  # K, about 1 % of the probes' rise
    estimates, covered = [], 0
    for seed in range(6):
        noisy = clean + noise * jax.random.normal(jax.random.key(seed), clean.shape)
        fit = inverse.fit_conductivity(experiment, noisy, C_TRUE, kappa0=3.0, noise=noise, learning_rate=0.1,
                                       max_steps=300)
        estimates.append(fit.params["kappa"])
        covered += abs(fit.params["kappa"] - KAPPA_TRUE) <= 2.5 * fit.stderr["kappa"]
        assert fit.stderr["kappa"] < 0.05 * KAPPA_TRUE
    assert covered >= 5  # about 99 % coverage at 2.5 sigma
    assert abs(np.mean(estimates) - KAPPA_TRUE) < 3 * np.std(estimates) + 1e-3


@pytest.mark.slow
def test_levenberg_marquardt_agrees_with_gradient_descent(experiment):
    noisy = experiment.temperatures(KAPPA_TRUE, C_TRUE) + 0.05 * jax.random.normal(jax.random.key(7), (40, 4))
    adam = inverse.fit_conductivity(experiment, noisy, C_TRUE, kappa0=3.0, noise=0.05, learning_rate=0.1,
                                    max_steps=300)
    lm = inverse.fit_conductivity(experiment, noisy, C_TRUE, kappa0=3.0, noise=0.05, method="levenberg_marquardt",
                                  max_steps=50)
    assert lm.params["kappa"] == pytest.approx(adam.params["kappa"], rel=1e-8)
    assert lm.stderr["kappa"] == pytest.approx(adam.stderr["kappa"], rel=1e-6)
    assert lm.steps < 15 < adam.steps


@pytest.mark.slow
def test_a_whole_number_kappa0_is_a_starting_value(experiment):
    """least_squares refuses an integer leaf in params0 (issue 24); fit_conductivity's kappa0=3 is the number 3."""
    noisy = experiment.temperatures(KAPPA_TRUE, C_TRUE) + 0.05 * jax.random.normal(jax.random.key(7), (40, 4))
    whole, real = (inverse.fit_conductivity(experiment, noisy, C_TRUE, kappa0=k0, noise=0.05,
                                            method="levenberg_marquardt", max_steps=50) for k0 in (3, 3.0))
    assert whole.params == real.params and whole.stderr == real.stderr


@pytest.mark.slow
def test_float32_readings_and_gradient_against_float64(experiment):
    """The same experiment built with x64 off (a subprocess): readings within 1e-3 K, gradient within 1e-4."""
    import json
    import os
    import subprocess
    import sys

    script = (
        "import json, numpy as np, jax, jax.numpy as jnp\n"
        "from fitting import inverse\n"
        "D = 1e-4\n"
        "g = np.stack(np.meshgrid(*[np.arange(5)] * 3, indexing='ij'), -1).reshape(-1, 3) * D * 0.97\n"
        "ex = inverse.flash_experiment(g, np.full(len(g), D / 2), 4430.0, n_steps=403, save_every=10,"
        " kappa_max=20.0, specific_heat_min=500.0)\n"
        "y = ex.temperatures(7.0, 560.0)\n"
        "gr = jax.grad(lambda k: jnp.sum(ex.temperatures(k, 560.0)))(7.0)\n"
        "print(json.dumps({'dtype': str(y.dtype), 'y': np.asarray(y, float).tolist(), 'grad': float(gr)}))\n"
    )
    env = dict(os.environ, SINTERCOND_ENABLE_X64="0")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["dtype"] == "float32"
    np.testing.assert_allclose(out["y"], experiment.temperatures(7.0, 560.0), rtol=0, atol=1e-3)
    grad64 = float(jax.grad(lambda k: jnp.sum(experiment.temperatures(k, 560.0)))(7.0))
    assert out["grad"] == pytest.approx(grad64, rel=1e-4)
