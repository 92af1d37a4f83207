"""Reverse-mode gradients through the adaptive implicit rollout, and a kinetic fit through a preheat.

References: central differences of the adaptive run, forward mode through the same recorded steps, and the
parameters a synthetic k*(t) was made with (:mod:`sintercond.sim.adaptive`, module docstring: record and replay).
"""

import copy
import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fitting.core import least_squares
from fitting.sintering import preheat_conductivity_model
from sintercond import run as runner
from sintercond.contacts.network import ContactPairs
from sintercond.scene import load_scene
from sintercond.sim import adaptive, rollout
from sintercond.sim.contacts import pair_neck_conductance
from sintercond.sim.steady import steady_state_network_conductivity
from test_adaptive import KAPPA, cell, pair

A_TRUE, Q_TRUE = 1e-17, 37.0  # the cell's law (m^4 K/s, kJ/mol)
T_END, SAVES = 1.9, 5  # five levels of the ramp, one k* per level


def hot_sphere(kappa, sim, state, params, reverse_steps):
    p = dataclasses.replace(params, conductivity=jnp.asarray([kappa]))
    end, stats = adaptive.integrate(sim, state, p, 2, 1e-4, reverse_steps=reverse_steps)
    return end.particles.temperature[1], stats


def test_reverse_mode_equals_forward_mode_on_the_steps_taken_and_central_differences_within_the_control():
    """Two spheres at rtol 1e-8: jax.grad through the recorded steps against jax.jvp through the same steps (the
    same discrete map: round-off), and against central differences of the adaptive run (whose steps move with
    kappa: measured 5.4e-6 relative)."""
    sim, state, params, _, _ = pair(integrator="implicit", rtol=1e-8, atol=1e-9)
    replayed = jax.jit(lambda k: hot_sphere(k, sim, state, params, 256))
    looped = jax.jit(lambda k: hot_sphere(k, sim, state, params, None)[0])
    value, stats = replayed(KAPPA)
    assert not bool(stats.failed) and 50 < int(stats.accepted) <= 256
    np.testing.assert_allclose(float(value), float(looped(KAPPA)), rtol=1e-14)  # the replay is the loop's run
    reverse = jax.jit(jax.grad(lambda k: hot_sphere(k, sim, state, params, 256)[0]))(KAPPA)
    _, forward = jax.jit(lambda k: jax.jvp(lambda k: hot_sphere(k, sim, state, params, 256)[0], (k,), (1.0,)))(
        KAPPA)
    np.testing.assert_allclose(float(reverse), float(forward), rtol=1e-10)
    central = (looped(KAPPA * (1 + 1e-4)) - looped(KAPPA * (1 - 1e-4))) / (2e-4 * KAPPA)
    assert float(reverse) < 0
    np.testing.assert_allclose(float(reverse), float(central), rtol=1e-4)


def test_an_interval_longer_than_its_record_is_flagged_not_truncated():
    sim, state, params, _, _ = pair(integrator="implicit", rtol=1e-8, atol=1e-9)
    _, stats = jax.jit(lambda k: hot_sphere(k, sim, state, params, 16))(KAPPA)
    assert bool(stats.failed) and int(stats.accepted) > 16
    with pytest.raises(ValueError, match="reverse_steps must be an integer >= 1"):
        hot_sphere(KAPPA, sim, state, params, 0)


def cell_conductivity_model(reverse_steps):
    """``k_star({log_A, Q}) -> ([SAVES] W/(m K), failed)``: the 2 x 2 x 2 cell on the ramp with growing
    necks (test_adaptive.cell), stepped adaptively to each level of the ramp, and the steady k* along x of the
    cell with the necks it has then (``reverse_steps``: :func:`sintercond.sim.adaptive.rollout`)."""
    sim, state, params = cell("implicit", rtol=1e-6, atol=1e-4)
    state = dataclasses.replace(state, dt=jnp.asarray(T_END / SAVES))
    pairs = np.asarray(state.contacts.pairs)
    x, radii = np.asarray(state.particles.positions), np.asarray(state.particles.radii)
    network = ContactPairs(pairs[:, 0], pairs[:, 1], np.asarray(state.contacts.overlap), radii[pairs[:, 0]],
                           radii[pairs[:, 1]], len(radii))
    saveat = rollout.SaveAt(every=1, fn=lambda s: s.contacts)

    def k_star(theta):
        p = dataclasses.replace(params, sintering={"A": jnp.exp(theta["log_A"]),
                                                   "activation_energy": theta["Q"]})
        _, contacts, stats = adaptive.rollout(sim, state, p, SAVES, saveat, reverse_steps=reverse_steps)
        conductance = jax.vmap(lambda c: pair_neck_conductance(sim.physics, dataclasses.replace(state, contacts=c),
                                                               p))(contacts)
        k = jax.vmap(lambda kk, c: steady_state_network_conductivity(
            x, radii, network, kk, axis=0, kappa=p.conductivity[0], neck_radii=c.neck,
            beyond_domain="isolated"))(conductance, contacts)
        return k, stats.failed

    return k_star


@pytest.mark.slow
def test_the_gradient_of_a_conductivity_misfit_in_the_kinetics_equals_central_differences():
    """A loss of k*(t) along the preheat in (ln A, Q): reverse mode against central differences of the adaptive
    run (rtol 1e-6; the steps move with the parameters, which the replay holds: measured 9e-9 relative)."""
    theta = {"log_A": jnp.asarray(math.log(A_TRUE) + 0.3), "Q": jnp.asarray(Q_TRUE + 2.0)}
    k_star_model = cell_conductivity_model(reverse_steps=64)

    def loss(theta):
        k, _ = k_star_model(theta)
        return jnp.sum(k**2)

    grad = jax.jit(jax.grad(loss))(theta)
    f = jax.jit(loss)
    k, failed = jax.jit(k_star_model)(theta)
    assert not bool(failed) and float(k[-1]) > 1.3 * float(k[0]) > 0  # the necks grew and k* with them
    for name, step in (("log_A", 1e-4), ("Q", 1e-3)):
        up, down = dict(theta), dict(theta)
        up[name], down[name] = theta[name] + step, theta[name] - step
        central = (f(up) - f(down)) / (2 * step)
        assert abs(float(grad[name])) > 0
        np.testing.assert_allclose(float(grad[name]), float(central), rtol=1e-5, err_msg=name)


@pytest.mark.slow
def test_a_kinetic_fit_through_the_preheat_recovers_the_law_from_its_conductivity():
    """Synthetic k*(t) of the cell made with (A, Q); fitted from ln A + 0.5 and Q - 4 kJ/mol by
    Levenberg-Marquardt (forward mode, the right one for two parameters, through the adaptive loop) with a failed
    adaptive run flagged to the fit."""
    k_star_model = cell_conductivity_model(reverse_steps=None)
    truth = {"log_A": jnp.asarray(math.log(A_TRUE)), "Q": jnp.asarray(Q_TRUE)}
    observed, failed = jax.jit(k_star_model)(truth)
    assert not bool(failed)
    start = {"log_A": math.log(A_TRUE) + 0.5, "Q": Q_TRUE - 4.0}
    fit = least_squares(lambda theta, _: k_star_model(theta), None, observed, start,
                        method="levenberg_marquardt", relative=True, max_steps=30, invalid=True)
    # noise-free data: the truth within the adaptive solve's own tolerance (k* to about rtol)
    assert fit.params["log_A"] == pytest.approx(math.log(A_TRUE), abs=1e-3)
    assert fit.params["Q"] == pytest.approx(Q_TRUE, abs=1e-2)


def small_preheating_bed(duration):
    """The built-in ti6al4v_preheating_bed on a rolled 0.5 mm bed (321 particles) for ``duration`` (s)."""
    scene = load_scene("ti6al4v_preheating_bed", duration=duration)
    scene["packing"] = {"kind": "powder_bed", "method": "roll", "lateral_size": 5e-4, "height": 4e-4,
                        "diameter_range": [45e-6, 105e-6], "seed": 0}
    scene.pop("mechanics")  # the pour's material: a rolled bed needs none
    return scene


@pytest.mark.slow
def test_a_kinetic_fit_through_a_bed_preheat_recovers_the_law_from_its_k_star(tmp_path):
    """The preheating bed scene end to end at reduced size (issue: a 1e4 bed in notebooks/calibrate_preheat.ipynb):
    its k*(t) at five times of the first 1.9 s of the ramp, the last equal to `sintercond run`'s history at the
    end (the same adaptive run, other intervals: to its tolerance); synthetic data made with the scene's law,
    fitted from ln A + 0.5 and Q - 4 kJ/mol by Levenberg-Marquardt (forward mode through the adaptive loop)."""
    scene = small_preheating_bed(1.9)
    k_star, model = preheat_conductivity_model(scene, 5)
    law = model.params.sintering
    truth = {"log_A": jnp.asarray(math.log(float(law["A"]))), "Q": jnp.asarray(float(law["activation_energy"]))}
    observed, failed = jax.jit(k_star)(truth)
    assert not bool(failed) and np.all(np.diff(np.asarray(observed)) > 0)

    run_scene = copy.deepcopy(scene)
    run_scene["run"]["integrator"] = "implicit"
    runner.run_scene(run_scene, tmp_path, progress=False, pictures=False)
    history = runner.read_history(tmp_path)
    assert history["time"][-1] == pytest.approx(1.9, rel=1e-12)
    # the same adaptive run in other intervals (the run's output clock): measured 5e-7 apart
    assert history["k_star_W_mK"][-1] == pytest.approx(float(observed[-1]), rel=1e-5)

    start = {"log_A": float(truth["log_A"]) + 0.5, "Q": float(truth["Q"]) - 4.0}
    fit = least_squares(lambda theta, _: k_star(theta), None, observed, start, method="levenberg_marquardt",
                        relative=True, max_steps=30, invalid=True)
    assert fit.params["log_A"] == pytest.approx(float(truth["log_A"]), abs=1e-3)
    assert fit.params["Q"] == pytest.approx(float(truth["Q"]), abs=1e-2)
