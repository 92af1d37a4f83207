"""Throughput of neck_radius: pairs per second against NumPy and SciPy, same run.

Usage: python benchmarks/neck_throughput.py [--pairs N] [--brentq-pairs M]

* JAX: ``jax.jit(neck_radius)`` on N random pairs (default 1e6), float64 and
  float32; value, and value plus the gradient with respect to r_i, r_j and h.
* NumPy: the same Newton (reduced Eq. 27, Coble start, 5 steps), vectorised.
* SciPy: ``scipy.optimize.brentq`` on Rojek Eq. 27 per pair, bracketed by
  [lens radius, min(r_i, r_j)] (what a user would write; the lens radius in
  NumPy, so no JAX call and no compilation is timed), on M pairs.
Times: JAX after a warm-up call (compilation excluded), minimum over up to 25
repeats or 10 s (``_common.best_time``); NumPy and brentq minimum of 5 and 3
runs. Errors of a are against a bracketing extended-precision reference; errors
of the gradient against the implicit-function-theorem partials of Eq. 27 at
that reference (``_common.reference_neck_gradient``). Prints the table and
rewrites its section of benchmarks/RESULTS.md.
"""

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import (
    best_time,
    command_line,
    lens_radius,
    markdown_table,
    new_figure,
    number,
    numpy_neck_radius,
    random_pairs,
    reference_neck_gradient,
    reference_neck_radius,
    rojek_residual,
    save_figure,
    write_section,
)
from scipy.optimize import brentq

from sintercond.laws.neck import neck_radius


def _value_and_gradient(r_i, r_j, h):
    a, pullback = jax.vjp(neck_radius, r_i, r_j, h)
    return a, pullback(jnp.ones_like(a))


def brentq_neck_radius(r_i, r_j, h):
    lens = lens_radius(r_i, r_j, h)
    out = np.empty_like(h)
    for k in range(h.size):
        lo, hi = lens[k], min(r_i[k], r_j[k])
        out[k] = brentq(rojek_residual, lo, hi, args=(r_i[k], r_j[k], h[k]), xtol=1e-300, rtol=8.9e-16)
    return out


def plot(rows):
    """Pairs per second of every implementation (bars, log scale), each labelled with its max error."""
    fig = new_figure(7.5, 3.6)
    ax = fig.subplots()
    names = [r[0] for r in rows][::-1]
    rates = [number(r[2]) for r in rows][::-1]
    colours = ["C0" if n.startswith("JAX") else "C1" if n.startswith("NumPy") else "C2" for n in names]
    ax.barh(names, rates, color=colours)
    for k, r in enumerate(rows[::-1]):
        ax.annotate(f" max rel. error {r[3]}", (rates[k], k), va="center", fontsize=7)
    ax.set(xscale="log", xlabel="neck radii per second [pairs/s] (CPU of this machine)",
           title="neck_radius throughput: JAX against NumPy and SciPy brentq")
    ax.set_xlim(min(rates) / 30, max(rates) * 60)
    ax.tick_params(axis="y", labelsize=8)
    return save_figure("neck_throughput", fig, "Neck solve throughput: pairs per second, JAX against NumPy and SciPy")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--pairs", type=int, default=1_000_000)
    parser.add_argument("--brentq-pairs", type=int, default=3_000)
    args = parser.parse_args()
    n, m = args.pairs, args.brentq_pairs
    r_i, r_j, h = random_pairs(n, seed=1)
    ref = reference_neck_radius(r_i, r_j, h)

    def rel_err(a, reference=ref):
        return float(np.max(np.abs(np.asarray(a, np.float64) - reference[: np.size(a)]) / reference[: np.size(a)]))

    def gradient_err(gradient, reference):
        """Max over pairs and the three partials of |g - g_ref| / |g_ref|."""
        return max(rel_err(g, np.asarray(g_ref, np.float64)) for g, g_ref in zip(gradient, reference))

    rows, rate = [], {}

    def record(name, seconds, pairs, err, grad_err=None):
        rate[name] = pairs / seconds
        rows.append([name, f"{seconds / pairs * 1e9:,.1f}", f"{rate[name]:.2e}", f"{err:.1e}",
                     "-" if grad_err is None else f"{grad_err:.1e}"])
        print(*rows[-1], sep="\t", flush=True)

    def best_of(runs, fn, *args):
        best = np.inf
        for _ in range(runs):
            t0 = time.perf_counter()
            out = fn(*args)
            best = min(best, time.perf_counter() - t0)
        return best, out

    for dtype in (jnp.float64, jnp.float32):
        name = jnp.dtype(dtype).name
        x = [jnp.asarray(v, dtype) for v in (r_i, r_j, h)]
        value = jax.jit(neck_radius)
        both = jax.jit(_value_and_gradient)
        inputs = [np.asarray(v, np.float64) for v in x]  # float32: the rounded inputs
        ref_dtype = reference_neck_radius(*inputs) if dtype == jnp.float32 else ref
        grad_ref = reference_neck_gradient(ref_dtype, *inputs)
        record(f"JAX {name}, value", best_time(value, *x), n, rel_err(value(*x), ref_dtype))
        a, gradient = both(*x)
        record(f"JAX {name}, value + gradient", best_time(both, *x), n, rel_err(a, ref_dtype),
               gradient_err(gradient, grad_ref))

    seconds, a_np = best_of(5, numpy_neck_radius, r_i, r_j, h)
    record("NumPy float64, same Newton", seconds, n, rel_err(a_np))

    seconds, a_bq = best_of(3, brentq_neck_radius, r_i[:m], r_j[:m], h[:m])
    record(f"SciPy brentq per pair ({m:,} pairs)", seconds, m, rel_err(a_bq))

    f64 = rate["JAX float64, value"]
    summary = [
        f"float64 value vs NumPy: {f64 / rate['NumPy float64, same Newton']:.1f}x (target >= 6x)",
        f"float64 value vs brentq: {f64 / rate[f'SciPy brentq per pair ({m:,} pairs)']:.0f}x (target >= 1000x)",
        f"float64 value+gradient / value time: {f64 / rate['JAX float64, value + gradient']:.2f} (target <= 1.5)",
        f"float32 / float64 speed: {rate['JAX float32, value'] / f64:.1f}x",
        f"float64 value+gradient vs NumPy value alone: "
        f"{rate['JAX float64, value + gradient'] / rate['NumPy float64, same Newton']:.1f}x",
    ]
    print("\n".join(summary))
    body = (
        "## Neck solve: throughput\n\n"
        f"{n:,} random pairs (radius ratio up to 1e3, h in (0, max_overlap]), jitted batch call; "
        "max relative error of a against the extended-precision bisection reference (float32: of its rounded "
        "inputs), and of each of d a/d(r_i, r_j, h) (by `jax.vjp`) against the implicit-function-theorem "
        "partials of Eq. 27 at that reference. JAX times exclude compilation (a warm-up call first) and are "
        "the minimum over up to 25 repeats or 10 s; NumPy: minimum of 5 runs; brentq: minimum of 3 runs, "
        "no JAX call inside (the bracket's lens radius in NumPy).\n\n"
        + markdown_table(("implementation", "ns / pair", "pairs / s", "max rel. error of a",
                          "max rel. error of the gradient"), rows)
        + "\n\n" + "\n".join(f"- {s}" for s in summary) + "\n\n" + plot(rows)
    )
    write_section("neck_throughput", command_line(), body)


if __name__ == "__main__":
    main()
