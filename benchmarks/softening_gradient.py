"""Gradient of the softening fit's loss through the coupled thermo-mechanical scan: time and memory, and fit times.

Usage: python benchmarks/softening_gradient.py [--lateral-size 0.008] [--height 0.006] [--settle-time 0.3]
                                              [--steps 1000 10000 100000] [--no-fits] [--section NAME] [--no-friction]
                                              [--variants forward "gradient checkpointed" ...]

A bed (fitting.softening.bed_experiment: powder_bed piled, settled by the coupled
simulation with friction (without it under --no-friction: Mindlin's law off throughout, to see
what that law costs each variant), then heated by its floor at 700 K; float64), read
every steps/100 steps (3 probe temperatures and the mean height); loss = weighted
sum of squared residuals against the nominal readings shifted by one sigma.
Variants, each in its own process so that its peak memory is its own:

* forward: the readings alone (jit).
* gradient checkpointed: value and d/d(log E0, log theta*, log rate) by JAX's reverse
  mode through `sintercond.simulate.rollout` as the experiment runs it (jax.checkpoint
  around segments of ~sqrt(steps) steps, each recomputed once on the way back, and
  around every step: `SofteningExperiment.step_checkpoint`, the states of a segment
  kept and each step run once more on the way back instead of storing its intermediates).
* gradient plain: no checkpoints at all (every step's intermediates kept): compiled
  for XLA's memory estimate, run only below --max-gb.
* gradient forward mode: the same value and gradient by forward mode (`jax.jvp` of the
  loss along the 3 unit vectors of the logs, batched by `jax.vmap`: what `jax.jacfwd` does,
  one pass with 3 tangents); no checkpoints needed, memory O(1) in the steps. Extra
  information: the issue-12 target is on reverse mode through the checkpointed segments.

All compiled with ``mechanics.COMPILER_OPTIONS`` (as ``rollout.advance`` compiles a mechanical chunk).
Times: the variant and the forward program in the same process (best of alternating runs when
they take under 20 s; one run each beyond).
Memory: XLA's buffer assignment of the compiled program (temporaries + arguments + outputs)
and the process's peak RSS growth over its state before the run.
Then the fits: Levenberg-Marquardt (forward-mode Jacobians) on the bed and on Example 5.1,
Adam (reverse mode, 150 steps at most, then Gauss-Newton polish) on Example 5.1: their optimiser
steps and wall time (first call, compile included, and a second call).
Prints the tables and rewrites its section of benchmarks/RESULTS.md.
"""

import argparse
import dataclasses
import json
import os
import pathlib
import pickle
import resource
import shlex
import subprocess
import sys
import tempfile
import time

import numpy as np

VARIANTS = ("forward", "gradient checkpointed", "gradient plain", "gradient forward mode")
SIGMA = (0.5, 0.5, 0.5, 2e-8)


def build(path, lateral_size, height, settle_time=0.3, friction=True):
    from fitting import softening as sf

    t0 = time.perf_counter()
    ex = sf.bed_experiment(lateral_size=lateral_size, height=height, t_end=0.01, save_every=10,
                           settle_time=settle_time, friction=friction)
    state = ex.state
    with open(path, "wb") as f:
        pickle.dump({"lateral_size": lateral_size, "height": height, "settle_time": settle_time,
                     "friction": friction,
                     "seconds": time.perf_counter() - t0,
                     "n": int(state.particles.radii.shape[0]), "dt": float(state.dt)}, f)
    return ex


def experiment(meta, steps):
    """The bed rebuilt (same seed: the same packing and settling) and read every steps/100 steps."""
    from fitting import softening as sf

    dt = meta["dt"]
    return sf.bed_experiment(lateral_size=meta["lateral_size"], height=meta["height"], t_end=steps * dt,
                             save_every=max(1, steps // 100), settle_time=meta["settle_time"],
                             friction=meta["friction"])


def run_one(path, variant, steps, max_gb):
    import jax
    import jax.numpy as jnp

    from sintercond.sim import mechanics

    with open(path, "rb") as f:
        meta = pickle.load(f)
    ex = experiment(meta, steps)
    if variant == "gradient plain":
        ex = dataclasses.replace(ex, step_checkpoint=False)
    names = ("E0", "theta_star", "rate")
    nominal = ex.nominal()
    logs0 = jnp.log(jnp.asarray([nominal[k] for k in names]))
    target = ex.readings(nominal) + np.asarray(SIGMA)
    weights = 1.0 / jnp.asarray(SIGMA)

    def loss(logs, checkpoint=True):
        params = ex.params_with(dict(zip(names, jnp.exp(logs))))
        saved = ex.run(params, checkpoint=checkpoint)[1]
        return 0.5 * jnp.sum(((saved - target) * weights) ** 2)

    def forward_mode(logs):
        """``(loss, gradient)`` by forward mode: one pass with a tangent per log (``jax.jacfwd``'s batching)."""
        basis = jnp.eye(logs.shape[0], dtype=logs.dtype)
        return jax.vmap(lambda tangent: jax.jvp(loss, (logs,), (tangent,)), out_axes=(None, 0))(basis)

    forward = jax.jit(loss)
    if variant == "forward":
        fn = forward
    elif variant == "gradient checkpointed":
        fn = jax.jit(jax.value_and_grad(loss))
    elif variant == "gradient forward mode":
        fn = jax.jit(forward_mode)
    else:
        fn = jax.jit(jax.value_and_grad(lambda logs: loss(logs, checkpoint=False)))
    options = mechanics.compiler_options(ex.sim.physics)  # the same XLA options for every variant
    compiled = fn.lower(logs0).compile(compiler_options=options)
    mem = compiled.memory_analysis()
    xla_bytes = mem.temp_size_in_bytes + mem.argument_size_in_bytes + mem.output_size_in_bytes
    out = {"xla_gb": xla_bytes / 1e9, "seconds": None, "rss_gb": None, "ratio": None}
    if xla_bytes > max_gb * 1e9:
        return out
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    result = jax.block_until_ready(compiled(logs0))
    best = time.perf_counter() - t0
    out["rss_gb"] = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) * 1024 / 1e9
    fwd = forward.lower(logs0).compile(compiler_options=options)
    if variant == "forward":
        fwd = compiled
    else:
        jax.block_until_ready(fwd(logs0))
    t0 = time.perf_counter()
    jax.block_until_ready(fwd(logs0))
    best_forward = time.perf_counter() - t0
    if best < 20.0:  # short runs: the best of alternating repeats (this VM's speed drifts)
        for _ in range(2):
            t0 = time.perf_counter()
            jax.block_until_ready(compiled(logs0))
            best = min(best, time.perf_counter() - t0)
            t0 = time.perf_counter()
            jax.block_until_ready(fwd(logs0))
            best_forward = min(best_forward, time.perf_counter() - t0)
    out["seconds"], out["forward_seconds"], out["ratio"] = best, best_forward, best / best_forward
    if variant != "forward":
        out["grad"] = [float(g) for g in result[1]]
    return out


def fits(path, bed_steps):
    """Optimiser steps and wall time of the fits (first call compiles; the second reuses the program)."""
    from fitting import softening as sf

    with open(path, "rb") as f:
        meta = pickle.load(f)
    rows = []
    start = {"E0": 1.3e6, "theta_star": 450.0, "rate": 0.7}
    bed = experiment(meta, bed_steps)
    ex = sf.example_5_1_experiment(t_end=1.5, save_every=2500, initial_temperature=380.0)
    lm = ("levenberg_marquardt", {"loss_tol": 1e-9, "max_steps": 100})
    adam = ("adam", {"learning_rate": 0.02, "max_steps": 150})
    cases = [(f"bed, {meta['n']} particles, {bed_steps:,} steps", bed, SIGMA, (lm,)),
             (f"Example 5.1 from 380 K, {ex.n_steps:,} steps", ex, (0.5, 2e-9), (lm, adam))]
    for label, experiment_, sigma, methods in cases:
        truth = experiment_.nominal()
        _, data = sf.synthetic_data(experiment_, truth, sigma, seed=0)
        for method, options in methods:
            times = []
            for _ in range(2):
                t0 = time.perf_counter()
                fit = sf.fit_softening(experiment_, data, sigma, start=start, method=method, **options)
                times.append(time.perf_counter() - t0)
                if times[0] > 120.0:  # long: the second call is not timed
                    times.append(float("nan"))
                    break
            error = max(abs(fit.values[k] / truth[k] - 1) / (fit.stderr[k] / fit.values[k]) for k in fit.names)
            rows.append([label, method, f"{fit.fit.steps}{'' if fit.fit.converged else ' (cap, not converged)'}",
                         f"{times[0]:.1f}",
                         f"{times[1]:.1f}" if times[1] == times[1] else "not timed",
                         f"{error:.2f}"])
            print(rows[-1], flush=True)
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--lateral-size", type=float, default=0.008)
    parser.add_argument("--height", type=float, default=0.006)
    parser.add_argument("--settle-time", type=float, default=0.3,
                        help="s of settling allowed (a 20 x 20 x 12 mm bed of ~770 spheres needs more than 0.3)")
    parser.add_argument("--steps", type=int, nargs="+", default=[1000, 10_000, 100_000])
    parser.add_argument("--fit-steps", type=int, default=3800)
    parser.add_argument("--max-gb", type=float, default=8.0)
    parser.add_argument("--no-fits", action="store_true", help="time the gradient only (a large bed's fits take long)")
    parser.add_argument("--no-friction", action="store_true",
                        help="frictionless bed (settled and heated without Mindlin's law): what the friction law "
                             "costs in each variant")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS,
                        help="variants to time (default: all)")
    parser.add_argument("--section", default="softening_gradient",
                        help="RESULTS.md section to rewrite (another name keeps the default bed's section)")
    parser.add_argument("--one", nargs=3, help=argparse.SUPPRESS)
    parser.add_argument("--fits", nargs=1, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(run_one(args.one[0], args.one[1], int(args.one[2]), args.max_gb)))
        return
    if args.fits:
        print(json.dumps(fits(args.fits[0], args.fit_steps)))
        return

    from _common import markdown_table, write_section
    from thermal_step import load_line

    load_start = os.getloadavg()[0]
    fit_rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "bed.pkl"
        build(path, args.lateral_size, args.height, args.settle_time, friction=not args.no_friction)
        with open(path, "rb") as f:
            meta = pickle.load(f)
        rows, notes = [], []
        for steps in args.steps:
            grads = {}
            for variant in args.variants:
                proc = subprocess.run([sys.executable, __file__, "--one", str(path), variant, str(steps),
                                       "--max-gb", str(args.max_gb)], capture_output=True, text=True)
                if proc.returncode:
                    print(proc.stderr[-3000:], file=sys.stderr)
                    raise SystemExit(f"{variant} at {steps} steps failed")
                r = json.loads(proc.stdout.strip().splitlines()[-1])
                if r.get("grad"):
                    grads[variant] = np.asarray(r["grad"])
                rows.append([f"{steps:,}", variant, f"{r['seconds']:.3f}" if r["seconds"] else "not run",
                             f"{r['ratio']:.2f}x" if r["ratio"] else "-", f"{r['xla_gb']:.4f}",
                             f"{r['rss_gb']:.3f}" if r["rss_gb"] is not None else "-"])
                print(rows[-1], flush=True)
            if "gradient checkpointed" in grads and "gradient forward mode" in grads:
                reverse, forward_mode = grads["gradient checkpointed"], grads["gradient forward mode"]
                notes.append(f"{steps:,} steps: {np.max(np.abs(forward_mode - reverse) / np.abs(reverse)):.1e}")
        if not args.no_fits:
            proc = subprocess.run([sys.executable, __file__, "--fits", str(path), "--fit-steps",
                                   str(args.fit_steps)], capture_output=True, text=True)
            if proc.returncode:
                print(proc.stderr[-3000:], file=sys.stderr)
                raise SystemExit("the fits failed")
            fit_rows = json.loads(proc.stdout.strip().splitlines()[-1])
    header = ["steps", "variant", "seconds", "/ forward (same process)", "XLA memory GB", "peak RSS growth GB"]
    fit_header = ["data", "method", "optimiser steps", "seconds (first call, compile incl.)", "seconds (second call)",
                  "max |error| / stderr"]
    body = (f"Bed of {meta['n']:,} particles (powder_bed in a {1e3 * args.lateral_size:g} mm box, "
            f"{1e3 * args.height:g} mm high, settled by the coupled simulation; built and settled in "
            f"{meta['seconds']:.0f} s), "
            f"{'friction and softening on' if meta['friction'] else 'softening on, no friction'}, "
            f"dt = {meta['dt']:.3g} s, float64; loss on "
            f"3 probe temperatures and the mean height read every steps/100 steps; gradient in the logs of "
            f"E0, theta*, rate.\n\n" + markdown_table(header, rows))
    if any(row[2] == "not run" for row in rows):
        body += f"\n\nNot run: XLA's estimate above {args.max_gb:g} GB."
    if notes:
        body += ("\n\nForward mode (extra information; the target is on reverse mode): the largest relative "
                 "difference of its gradient from the checkpointed reverse mode's, " + "; ".join(notes) + ".")
    if fit_rows:
        body += ("\n\nFits (start E0 1.3 MPa, theta* 450 K, rate 0.7; truth 1 MPa, 400 K, 1; synthetic noise "
                 "0.5 K, 20 nm on the bed, 2 nm on the overlap):\n\n" + markdown_table(fit_header, fit_rows))
    body += ("\n\nThe ratios come from alternating runs in one process. " + load_line(load_start))
    print(body)
    write_section(args.section, "python benchmarks/softening_gradient.py " + shlex.join(sys.argv[1:]), body)


if __name__ == "__main__":
    main()
