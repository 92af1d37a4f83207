"""Gradient of a probe-history loss through the thermal scan: time and peak memory against the forward run.

Usage: python benchmarks/inverse_gradient.py [--particles 100000] [--steps 1000 10000 100000]

A flash experiment (fitting.inverse.flash_experiment) on a sintered simple-cubic
lattice, float64, 8 probes read every 10 steps; loss = sum of squared readings.
Variants, each in its own process so that its peak memory is its own:

* forward: the readings alone (jit).
* adjoint: value and d/d(kappa, c) by fitting.inverse's checkpointed discrete
  adjoint (states every ~sqrt(steps) steps, each segment recomputed once).
* autodiff checkpointed: JAX's own reverse mode through `sintercond.simulate.rollout`
  (jax.checkpoint around segments of ~sqrt(steps) steps; the explicit table step's
  derivative is written out, `thermal._conduction_update`: its transpose is the same
  gather as the forward, it keeps L T per step, and the conductivity and capacity enter
  through the rates s / C and 1 / C formed once per rollout, whose cotangents it
  accumulates per particle).
* autodiff plain: the same rollout without checkpoints (every step's residuals kept).
* reference adjoint (with --reference-adjoint FILE): the `_adjoint_readings` of another version of
  fitting/inverse.py (e.g. `git show REV:fitting/inverse.py > /tmp/old_inverse.py`), to compare adjoints.

Times: the best of alternating runs of the variant and the forward program in the same process
(the VM's speed drifts by up to 2x over minutes, so ratios between processes are unreliable).
Memory: XLA's buffer assignment of the compiled program (temporaries plus
arguments and outputs, what the program needs whatever else the process
holds) and the process's peak RSS growth over its state before the run.
Variants whose XLA estimate exceeds --max-gb are compiled but not run.
Prints the table and rewrites its section of benchmarks/RESULTS.md.
"""

import argparse
import json
import os
import pathlib
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

VARIANTS = ("forward", "adjoint", "autodiff plain", "autodiff checkpointed", "reference adjoint")


def build(path, particles):
    from fitting import inverse

    side = round(particles ** (1 / 3))
    d = 1e-4
    grid = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3) * d * 0.97
    radii = np.full(len(grid), d / 2)
    ex = inverse.flash_experiment(grid, radii, 4430.0, n_steps=10, save_every=10, n_probes=8, kappa_max=20.0,
                                  specific_heat_min=500.0)
    np.savez(path, neighbors=np.asarray(ex.table.neighbors), conductance=np.asarray(ex.table.conductance),
             mass=np.asarray(ex.mass), power=np.asarray(ex.power), dt=ex.dt, probes=np.asarray(ex.probes))
    return len(radii)


def _reference_readings(path):
    """``_adjoint_readings`` of the fitting/inverse.py version stored at ``path``."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("reference_inverse", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module._adjoint_readings


def run_one(path, variant, steps, max_gb, reference=None):
    import jax
    import jax.numpy as jnp

    from fitting import inverse
    from sintercond import simulate
    from sintercond.contacts.network import ContactTable

    data = np.load(path)
    table = ContactTable(jnp.asarray(data["neighbors"]), jnp.asarray(data["conductance"]))
    dt = float(data["dt"])
    ex = inverse.ProbeExperiment(table=table, mass=jnp.asarray(data["mass"]),
                                 initial=jnp.full(len(data["mass"]), 300.0), power=jnp.asarray(data["power"]),
                                 pulse_duration=0.1 * steps * dt, dt=dt, n_steps=steps, save_every=10,
                                 probes=jnp.asarray(data["probes"]))

    def unchecked(kappa, c):
        n_readings = steps // 10
        return simulate.rollout(ex._sim, ex.initial_state(), ex.params(kappa, c), n_readings * 10,
                                simulate.SaveAt(10, simulate.probe_temperatures(ex.probes)), checkpoint=False)[1]

    loss = jax.jit(lambda k, c: jnp.sum(ex.temperatures(k, c) ** 2))
    if variant == "forward":
        fn = loss
    elif variant == "adjoint":
        fn = jax.jit(jax.value_and_grad(lambda k, c: jnp.sum(ex.temperatures(k, c) ** 2), argnums=(0, 1)))
    elif variant == "reference adjoint":
        readings = _reference_readings(reference)
        fn = jax.jit(jax.value_and_grad(lambda k, c: jnp.sum(readings(ex, k, c) ** 2), argnums=(0, 1)))
    elif variant == "autodiff plain":
        fn = jax.jit(jax.value_and_grad(lambda k, c: jnp.sum(unchecked(k, c) ** 2), argnums=(0, 1)))
    else:
        fn = jax.jit(jax.value_and_grad(lambda k, c: jnp.sum(ex.temperatures(k, c, "autodiff") ** 2),
                                        argnums=(0, 1)))
    args = (jnp.asarray(7.0), jnp.asarray(560.0))
    compiled = fn.lower(*args).compile()
    mem = compiled.memory_analysis()
    xla_bytes = mem.temp_size_in_bytes + mem.argument_size_in_bytes + mem.output_size_in_bytes
    out = {"xla_gb": xla_bytes / 1e9, "seconds": None, "rss_gb": None, "value": None, "ratio": None}
    if xla_bytes > max_gb * 1e9:
        return out
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    result = jax.block_until_ready(compiled(*args))
    best = time.perf_counter() - t0
    out["rss_gb"] = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) * 1024 / 1e9
    # the forward run timed in the same process, alternating with the variant (this VM's speed drifts)
    forward = loss.lower(*args).compile()
    jax.block_until_ready(forward(*args))
    best_forward = np.inf
    repeats = 5 if best < 5.0 else 2
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(forward(*args))
        best_forward = min(best_forward, time.perf_counter() - t0)
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        best = min(best, time.perf_counter() - t0)
    out["seconds"], out["forward_seconds"] = best, best_forward
    out["ratio"] = best / best_forward
    value = result if variant == "forward" else result[0]
    out["value"] = float(value)
    if variant != "forward":
        out["grad"] = [float(g) for g in result[1]]
    return out


def plot(rows, name="inverse_gradient"):
    """Gradient cost against the number of steps: seconds of each variant, and its ratio to the forward run."""
    from _common import new_figure, number, save_figure

    fig = new_figure(10, 3.8)
    seconds_ax, ratio_ax = fig.subplots(1, 2)
    for k, variant in enumerate(dict.fromkeys(r[1] for r in rows)):
        done = [r for r in rows if r[1] == variant and r[2][:1].isdigit()]
        steps = [number(r[0]) for r in done]
        seconds_ax.plot(steps, [number(r[2]) for r in done], "o-", color=f"C{k}", label=variant)
        ratios = [(s, number(r[3])) for s, r in zip(steps, done) if r[3][:1].isdigit()]
        if ratios:
            ratio_ax.plot(*zip(*ratios), "o-", color=f"C{k}", label=variant)
    seconds_ax.set(xscale="log", yscale="log", xlabel="time steps [-]", ylabel="wall time [s]",
                   title="forward run and gradient")
    ratio_ax.set(xscale="log", xlabel="time steps [-]", ylabel="gradient time / forward time [-]",
                 title="gradient cost relative to the forward run")
    for ax in (seconds_ax, ratio_ax):
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    return save_figure(name, fig, "Gradient cost against time steps: adjoint and JAX reverse mode")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--particles", type=int, default=100_000)
    parser.add_argument("--steps", type=int, nargs="+", default=[1000, 10_000, 100_000])
    parser.add_argument("--max-gb", type=float, default=40.0)
    parser.add_argument("--max-checkpointed-steps", type=int, default=100_000,
                        help="skip 'autodiff checkpointed' beyond this many steps")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS[:4]), choices=VARIANTS)
    parser.add_argument("--reference-adjoint", help="a version of fitting/inverse.py whose adjoint runs as "
                        "'reference adjoint'")
    parser.add_argument("--section", default="inverse_gradient", help="RESULTS.md section (and figure) to write")
    parser.add_argument("--one", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(run_one(args.one[0], args.one[1], int(args.one[2]), args.max_gb, args.reference_adjoint)))
        return

    from _common import markdown_table, write_section
    from thermal_step import load_line

    load_start = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "experiment.npz"
        n = build(path, args.particles)
        rows, results = [], {}
        for steps in args.steps:
            for variant in ["forward"] + [v for v in args.variants if v != "forward"]:
                if variant == "autodiff checkpointed" and steps > args.max_checkpointed_steps:
                    rows.append([f"{steps:,}", variant, "not run (time)", "-", "-", "-", "-"])
                    continue
                reference = ["--reference-adjoint", args.reference_adjoint] if args.reference_adjoint else []
                proc = subprocess.run([sys.executable, __file__, "--one", str(path), variant, str(steps),
                                       "--max-gb", str(args.max_gb)] + reference, capture_output=True, text=True)
                if proc.returncode:
                    print(proc.stderr[-3000:], file=sys.stderr)
                    raise SystemExit(f"{variant} at {steps} steps failed")
                r = json.loads(proc.stdout.strip().splitlines()[-1])
                results[(steps, variant)] = r
                ratio = f"{r['ratio']:.2f}x" if r["ratio"] else "-"
                grad = results[(steps, "adjoint")].get("grad") if variant != "forward" else None
                agree = "-"
                if variant != "adjoint" and r.get("grad") and grad:
                    agree = f"{max(abs(a / b - 1) for a, b in zip(r['grad'], grad)):.1e}"
                rows.append([f"{steps:,}", variant, f"{r['seconds']:.3f}" if r["seconds"] else "not run",
                             ratio, f"{r['xla_gb']:.3f}", f"{r['rss_gb']:.2f}" if r["rss_gb"] is not None else "-",
                             agree])
                print(rows[-1], flush=True)
    header = ["steps", "variant", "seconds", "/ forward (same process, best of alternating runs)", "XLA memory GB",
              "peak RSS growth GB",
              "grad rel. diff to adjoint"]
    body = (f"{n:,} particles (sintered SC lattice, 6 contacts each), float64, 8 probes read every 10 steps, "
            f"loss = sum of squared readings, gradient d/d(kappa, c).\n\n" + markdown_table(header, rows) +
            f"\n\nNot run: XLA's estimate above {args.max_gb:g} GB.\n\n" + load_line(load_start) + "\n\n" +
            plot(rows, args.section))
    print(body)
    write_section(args.section, "python benchmarks/inverse_gradient.py " + " ".join(sys.argv[1:]), body)


if __name__ == "__main__":
    main()
