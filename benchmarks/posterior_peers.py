"""Posteriors per simulator run: NUTS from the least-squares optimum (fitting.posterior) against GrainLearning.

Usage: python benchmarks/posterior_peers.py [--repeats 5] [--glvenv /tmp/glvenv] [--gl-samples 20] [--gl-iterations 10]

The problem (the same data and prior for both): six necks of Rizza & Galati's 80-80 couple along their Eq. 6
ramp (0.5, 2.5, 4.5, 6.5, 8.5, 9.5 s), synthetic: the grain-boundary law (``sintercond.laws.sintering.grow_neck``)
at a known truth (``log_rate_ref``, ``Q``) plus Gaussian noise of known sd 0.1 um (one fixed realisation); the
prior uniform on the box ``log_rate_ref`` in truth -+ 3, ``Q`` in (1, 200) kJ/mol.

* sintercond: :func:`fitting.sintering.kinetics_posterior` (Levenberg-Marquardt start, then 4 NUTS chains of 100
  warmup and 150 draws). A simulator evaluation is one ``grow_neck`` run with its derivatives (a value and a
  forward-mode Jacobian in the fit, a value and a reverse-mode gradient per leapfrog step): the count is
  ``PosteriorResult.evaluations``. "To ESS 400": the fit and warmup, plus the draws scaled to an effective
  sample size of 400 for the worse-mixed parameter.
* The cheap path: the Laplace approximation at the least-squares optimum (the fit's runs only), 90 % intervals
  optimum -+ 1.645 sd; the NUTS run says how far it is from the posterior (Laplace sd / posterior sd).
* GrainLearning 2.0.5 (PyPI; its own virtual environment, since it pins numpy < 2): the iterative Bayesian
  filter (Halton start over the prior box, Gaussian-mixture resampling, ``ess_target`` 0.3), ``--gl-samples``
  runs per iteration, each a plain ``grow_neck`` run computed by this process (the child sends parameters over a
  pipe). Its posterior after each iteration is its weighted ensemble; a 90 % interval is a weighted quantile.

Also the flash experiment's ``kappa`` (:func:`fitting.inverse.conductivity_posterior`) on a 4x4x4 lattice: the
evaluations (adjoint gradients) to ESS 400. Spread: over ``--repeats`` seeds (NUTS seeds; GrainLearning's
``random_state``). Prints the tables and rewrites the ``posterior_peers`` section of benchmarks/RESULTS.md.
"""

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import time
import warnings

import numpy as np

TIMES_IDX = [0, 2, 4, 6, 8, 9]
NOISE_UM = 0.1


def _gl_child():
    """Run GrainLearning in its own environment: parameters out on stdout, simulated necks in on stdin."""
    from contextlib import redirect_stdout

    from grainlearning import BayesianCalibration
    from grainlearning.dynamic_systems import DynamicSystem

    config = json.loads(sys.stdin.readline())
    out = sys.stdout

    def run_sim(calib):
        out.write(json.dumps({"params": calib.system.param_data.tolist()}) + "\n")
        out.flush()
        necks = np.asarray(json.loads(sys.stdin.readline())["necks"])
        calib.system.set_sim_data(necks[:, None, :])

    quiet = redirect_stdout(sys.stderr)  # GrainLearning prints its progress: stdout is the pipe
    quiet.__enter__()
    calib = BayesianCalibration.from_dict({
        "num_iter": config["iterations"], "callback": run_sim, "save_fig": -1,
        "system": {"system_type": DynamicSystem, "param_names": ["log_rate_ref", "activation_energy"],
                   "param_min": config["low"], "param_max": config["high"], "num_samples": config["samples"],
                   "obs_data": [config["necks"]], "ctrl_data": config["times"], "obs_names": ["neck"],
                   "sim_name": "kinetics"},
        "inference": {"Bayes_filter": {"ess_target": 0.3},
                      "sampling": {"max_num_components": 2, "random_state": config["seed"],
                                   "covariance_type": "full"}},
    })
    iterations = []
    for _ in range(config["iterations"]):
        stop = calib.run_one_iteration()
        iterations.append({"params": calib.system.param_data.tolist(),
                           "weights": np.asarray(calib.inference.posterior).tolist()})
        if stop:
            break
    quiet.__exit__(None, None, None)
    out.write(json.dumps({"done": iterations}) + "\n")
    out.flush()


def weighted_interval(values, weights, level=0.9):
    order = np.argsort(values)
    cdf = np.cumsum(weights[order]) / np.sum(weights)
    lo = values[order][np.searchsorted(cdf, (1 - level) / 2)]
    hi = values[order][min(np.searchsorted(cdf, (1 + level) / 2), len(values) - 1)]
    return lo, hi


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--glvenv", default="/tmp/glvenv")
    parser.add_argument("--gl-samples", type=int, default=20)
    parser.add_argument("--gl-iterations", type=int, default=10)
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()

    import jax
    import jax.numpy as jnp
    from _common import command_line, markdown_table, write_section

    from fitting import inverse
    from fitting import sintering as fs
    from fitting.posterior import Uniform

    full = fs.neck_series("80-80")
    index = np.array(TIMES_IDX)
    series = dataclasses.replace(full, interval=full.interval[index], couple=full.couple[index],
                                 times=full.times[index], necks_um=full.necks_um[index])
    warnings.simplefilter("ignore", fs.IdentifiabilityWarning)
    best = fs.fit_kinetics(full)
    truth = np.array([round(best.fit.params["log_rate_ref"], 2), 50.0])
    _, data = fs.synthetic_series(series, "grain_boundary", dict(zip(("log_rate_ref", "activation_energy"), truth)),
                                  NOISE_UM, seed=1)
    low, high = [truth[0] - 3.0, 1.0], [truth[0] + 3.0, 200.0]
    priors = {"log_rate_ref": Uniform(low[0], high[0]), "activation_energy": Uniform(low[1], high[1])}
    start = {"log_rate_ref": float(truth[0]) + 0.5, "activation_energy": 100.0}

    ours, laplace = [], []
    for seed in range(args.repeats):
        t0 = time.perf_counter()
        kp = fs.kinetics_posterior(data, priors=priors, sigma=NOISE_UM, start=start, num_samples=150, num_warmup=100,
                                   seed=seed)
        wall = time.perf_counter() - t0
        post = kp.posterior
        ci = post.interval(0.9)
        ev = post.evaluations
        min_ess = min(post.ess.values())
        to_400 = ev["least_squares"] + ev["warmup"] + ev["sampling"] * 400 / min_ess
        covered = all(ci[n][0] <= t <= ci[n][1] for n, t in zip(post.names, truth))
        widths = [ci[n][1] - ci[n][0] for n in post.names]
        ours.append((to_400, post.total_evaluations, min_ess, covered, *widths, wall,
                     post.laplace_ratio["activation_energy"], post.divergences))
        # the cheap path: the Laplace approximation at the least-squares optimum (its runs: the fit's)
        centre = np.array([post.fit.params[n] for n in post.fit.names])
        half = 1.6448536 * np.sqrt(np.diag(post.laplace_covariance))
        laplace.append((ev["least_squares"], bool(np.all(np.abs(centre - truth) <= half)), *(2 * half)))
        print(f"sintercond seed {seed}: {post.total_evaluations} evaluations, min ESS {min_ess:.0f}, to ESS 400 "
              f"{to_400:.0f}, covered {covered}, widths {widths}, {wall:.1f} s", flush=True)

    # GrainLearning, its model runs computed here
    t_ref, model, _ = fs._setup(data, "grain_boundary", 6.0, 0.0, 150.0, None, None)
    simulate = jax.jit(jax.vmap(lambda p: model({"log_rate_ref": p[0], "activation_energy": p[1]}, data)))
    gl = []
    for seed in range(args.repeats):
        t0 = time.perf_counter()
        child = subprocess.Popen([os.path.join(args.glvenv, "bin", "python"), __file__, "--grainlearning-child"],
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        child.stdin.write(json.dumps({"iterations": args.gl_iterations, "samples": args.gl_samples, "low": low,
                                      "high": high, "necks": data.necks_um.tolist(), "times": data.times.tolist(),
                                      "seed": seed}) + "\n")
        child.stdin.flush()
        runs = 0
        while True:
            message = json.loads(child.stdout.readline())
            if "done" in message:
                break
            params = np.asarray(message["params"])
            runs += len(params)
            necks = np.asarray(simulate(jnp.asarray(params)))
            child.stdin.write(json.dumps({"necks": necks.tolist()}) + "\n")
            child.stdin.flush()
        child.wait()
        wall = time.perf_counter() - t0
        first, per_iteration = None, []
        for k, it in enumerate(message["done"]):
            p, w = np.asarray(it["params"]), np.asarray(it["weights"])
            cis = [weighted_interval(p[:, j], w) for j in range(2)]
            covered = all(lo <= t <= hi for (lo, hi), t in zip(cis, truth))
            ess = 1 / np.sum((w / w.sum()) ** 2)
            per_iteration.append((args.gl_samples * (k + 1), covered, *(hi - lo for lo, hi in cis), ess))
            if covered and first is None:
                first = k
        gl.append((runs, per_iteration, wall))
        print(f"GrainLearning seed {seed}: {runs} runs, per iteration (runs, covered, widths, ESS): "
              f"{[(r, c, round(a, 3), round(b, 2), round(e, 1)) for r, c, a, b, e in per_iteration]}", flush=True)

    # the flash's kappa
    grid = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3)
    d = 1e-4
    experiment = inverse.flash_experiment(grid * d * 0.97, np.full(len(grid), d / 2), 4430.0, n_steps=403,
                                          save_every=10, kappa_max=20.0, specific_heat_min=500.0)
    clean = np.asarray(experiment.temperatures(7.0, 560.0))
    readings = clean + np.random.default_rng(2).normal(0, 0.02, clean.shape)
    flash = []
    for seed in range(args.repeats):
        t0 = time.perf_counter()
        post = inverse.conductivity_posterior(experiment, readings, 560.0, kappa0=3.0, noise=0.02, num_samples=150,
                                              num_warmup=100, seed=seed)
        wall = time.perf_counter() - t0
        ev = post.evaluations
        to_400 = ev["least_squares"] + ev["warmup"] + ev["sampling"] * 400 / post.ess["kappa"]
        ci = post.interval(0.9)["kappa"]
        flash.append((to_400, post.total_evaluations, post.ess["kappa"], ci[0] <= 7.0 <= ci[1], ci[1] - ci[0], wall,
                      post.laplace_ratio["kappa"]))
        print(f"flash seed {seed}: {post.total_evaluations} evaluations, ESS {post.ess['kappa']:.0f}, to 400 "
              f"{to_400:.0f}, interval {ci}, {wall:.1f} s", flush=True)

    def spread(values, fmt="{:.0f}"):
        values = np.asarray(values, float)
        return f"{fmt.format(np.median(values))} ({fmt.format(values.min())}-{fmt.format(values.max())})"

    o = np.array([r[:3] + r[4:] for r in ours], float)
    # GrainLearning's first iteration whose intervals cover the truth and are as tight as the posterior's (no wider
    # than 1.25 x NUTS's median widths)
    tight = 1.25 * np.median(o[:, 3:5], axis=0)
    gl_cover = [next((r for r in it if r[1] and r[2] <= tight[0] and r[3] <= tight[1]), None) for _, it, _ in gl]
    gl_final = [it[-1] for _, it, _ in gl]
    hits = [c for c in gl_cover if c]
    lap = np.array([r[0] for r in laplace], float)
    gl_runs = np.array([r for r, _, _ in gl], float)
    table = markdown_table(
        ["method", "simulator runs", "90 % intervals cover the truth", "width ln-rate", "width Q (kJ/mol)",
         "ESS", "wall s (first seed compiles)"],
        [["sintercond NUTS (fit + warmup + draws to ESS 400)", spread(o[:, 0]),
          f"{sum(r[3] for r in ours)}/{len(ours)} seeds", spread(o[:, 3], "{:.3f}"), spread(o[:, 4], "{:.1f}"),
          spread(o[:, 2]) + " (min over parameters, as run)", spread(o[:, 5], "{:.1f}")],
         ["sintercond NUTS, as run (4 x (100 + 150))", spread(o[:, 1]), "", "", "", "", ""],
         ["sintercond Laplace at the least-squares optimum (Levenberg-Marquardt, value + Jacobian per run)",
          spread(lap), f"{sum(r[1] for r in laplace)}/{len(laplace)} seeds",
          spread([r[2] for r in laplace], "{:.3f}"), spread([r[3] for r in laplace], "{:.1f}"), "(Gaussian)", ""],
         [f"GrainLearning 2.0.5, {args.gl_samples} runs/iteration: first iteration that covers with widths <= 1.25x "
          "NUTS's", spread([c[0] for c in hits]) if hits else f"none ({len(gl)} seeds)",
          f"{len(hits)}/{len(gl)} seeds", spread([c[2] for c in hits], "{:.3f}") if hits else "",
          spread([c[3] for c in hits], "{:.1f}") if hits else "",
          spread([c[4] for c in hits], "{:.1f}") + " (weights)" if hits else "", ""],
         [f"GrainLearning 2.0.5, at its stop ({args.gl_iterations} iterations or sigma_tol)",
          spread(gl_runs), f"{sum(f[1] for f in gl_final)}/{len(gl)} seeds",
          spread([f[2] for f in gl_final], "{:.3f}"), spread([f[3] for f in gl_final], "{:.1f}"),
          spread([f[4] for f in gl_final], "{:.1f}") + " (weights)", spread([w for _, _, w in gl], "{:.1f}")]])
    f = np.array([r[:3] + r[4:] for r in flash], float)
    flash_table = markdown_table(
        ["flash kappa (4x4x4 lattice, 40 readings x 4 probes, noise 0.02 K)", "simulator runs to ESS 400",
         "as run", "ESS", "90 % covers 7.0", "width W/(m K)", "Laplace sd / posterior sd", "wall s"],
        [["NUTS on the adjoint gradient", spread(f[:, 0]), spread(f[:, 1]), spread(f[:, 2]),
          f"{sum(r[3] for r in flash)}/{len(flash)}", spread(f[:, 3], "{:.4f}"), spread(f[:, 5], "{:.3f}"),
          spread(f[:, 4], "{:.1f}")]])
    body = (f"Kinetics (ln-rate at T_ref = {t_ref:.0f} K, Q) from six synthetic necks, truth ({truth[0]}, {truth[1]}), "
            f"noise {NOISE_UM} um known, uniform prior box; median (min-max) over {args.repeats} seeds. A "
            "simulator run is one grow_neck run along the ramp (with its derivatives, for sintercond).\n\n"
            + table + "\n\n"
            f"Runs, GrainLearning at its stop / sintercond: {np.median(gl_runs) / np.median(lap):.1f}x against the "
            f"Laplace path, {np.median(gl_runs) / np.median(o[:, 0]):.3f}x against NUTS to ESS 400 (above 1: "
            "sintercond needs fewer). GrainLearning's ensemble has an ESS of about 10 and its adaptive likelihood "
            "width is not the known noise, so its intervals are not the posterior's. Laplace sd / posterior sd of Q "
            f"(NUTS): {spread(o[:, 6], '{:.2f}')}; divergences: {int(o[:, 7].sum())}.\n\n" + flash_table)
    print(body)
    if not args.no_write:
        write_section("posterior_peers", command_line(), body)


if __name__ == "__main__":
    if "--grainlearning-child" in sys.argv:
        _gl_child()
    else:
        main()
