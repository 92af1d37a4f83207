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
from _common import best_time, command_line, markdown_table, random_pairs, reference_neck_radius, write_section

from sintercond.neck import neck_radius

ITERATIONS = (0, 1, 2, 3, 4, 5, 6, None)


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
        "over up to 25 repeats or 10 s.\n\n" + table + "\n\n"
        + "\n".join(f"- {name}: every pair within {'1e-14' if name == 'float64' else '1e-6'} after {k} iterations"
                    for name, k in converged_at.items())
    )
    write_section("neck_convergence", command_line(), body)


if __name__ == "__main__":
    main()
