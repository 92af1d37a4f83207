"""Run time against error of neck_radius: Newton iterations x {float32, float64}.

Usage: python benchmarks/neck_convergence.py [--pairs N]

Error is the relative error of a against a bracketing reference (bisection
of Rojek Eq. 27 in extended precision, <1e-15), over random pairs with
radius ratios up to 1e3 either way and h uniform in (0, max_overlap]. Time is
per pair for the jitted, batched call. Prints the table and rewrites its
section of benchmarks/RESULTS.md.
"""

import argparse
import functools

import jax
import jax.numpy as jnp
import numpy as np
from _common import (
    best_time,
    command_line,
    markdown_table,
    new_figure,
    number,
    random_pairs,
    reference_neck_radius,
    save_figure,
    write_section,
)

from sintercond.laws.neck import neck_radius

ITERATIONS = (0, 1, 2, 3, 4, 5, 6, None)


def plot(rows):
    """Time per pair against max and median error, one curve per dtype, points labelled by iterations."""
    fig = new_figure()
    ax = fig.subplots()
    for k, dtype in enumerate(("float64", "float32")):
        mine = [r for r in rows if r[0] == dtype]
        ns = [number(r[5]) for r in mine]
        worst = [max(number(r[2]), 1e-17) for r in mine]
        ax.plot(ns, worst, "o-", color=f"C{k}", label=f"{dtype}: max rel. error")
        ax.plot(ns, [max(number(r[3]), 1e-17) for r in mine], "s:", color=f"C{k}", ms=4,
                label=f"{dtype}: median rel. error (0 drawn at 1e-17)")
        for r, x, y in zip(mine, ns, worst):
            ax.annotate(r[1].split(" ")[0].replace("converged", "while"), (x, y), textcoords="offset points",
                        xytext=(4, 4), fontsize=7, color=f"C{k}")
    ax.set(xscale="log", yscale="log", xlabel="time per pair [ns] (batched, jitted)",
           ylabel="relative error of a [-]", title="neck_radius: Newton iterations (labels) against error")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return save_figure("neck_convergence", fig, "Neck solve: time per pair against error, per Newton iteration count")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--pairs", type=int, default=1_000_000)
    args = parser.parse_args()
    n = args.pairs
    r_i, r_j, h = random_pairs(n, seed=0)
    rows, converged_at = [], {}
    for dtype in (jnp.float64, jnp.float32):
        inputs = [jnp.asarray(x, dtype) for x in (r_i, r_j, h)]
        ref = reference_neck_radius(*(np.asarray(x, np.float64) for x in inputs))
        for iterations in ITERATIONS:
            fn = jax.jit(functools.partial(neck_radius, iterations=iterations))
            a = np.asarray(fn(*inputs), np.float64)
            err = np.abs(a - ref) / ref
            seconds = best_time(fn, *inputs)
            label = "converged (while_loop)" if iterations is None else str(iterations)
            if iterations == 5:
                label += " (default)"
            target = 1e-14 if dtype == jnp.float64 else 1e-6
            if iterations is not None and err.max() <= target:
                converged_at.setdefault(jnp.dtype(dtype).name, iterations)
            rows.append((jnp.dtype(dtype).name, label, f"{err.max():.1e}", f"{np.median(err):.1e}",
                         f"{np.mean(err > target):.1e}", f"{seconds / n * 1e9:.1f}"))
            print(*rows[-1], sep="\t", flush=True)
    table = markdown_table(
        ("dtype", "Newton iterations", "max rel. error", "median rel. error",
         "fraction > 1e-14 (f64) / 1e-6 (f32)", "ns / pair"), rows
    )
    body = (
        "## Neck solve: run time against error\n\n"
        f"{n:,} random pairs (radius ratio log-uniform up to 1e3 either way, h uniform in (0, max_overlap]); "
        "reference: bisection of Rojek Eq. 27 in 80-bit precision. Iteration 0 is Coble's start clipped to "
        "min(r_i, r_j). Float32 errors are against the reference for the float32-rounded inputs; its floor is "
        "float32 round-off (eps 1.2e-7). Times exclude compilation (a warm-up call first) and are the minimum "
        "over up to 25 repeats or 10 s.\n\n" + table + "\n\n" + plot(rows) + "\n\n"
        + "\n".join(f"- {name}: every pair within {'1e-14' if name == 'float64' else '1e-6'} after {k} iterations"
                    for name, k in converged_at.items())
    )
    write_section("neck_convergence", command_line(), body)


if __name__ == "__main__":
    main()
