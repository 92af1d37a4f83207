"""Numerical stress table for neck_radius: extreme ratios, tiny and near-maximal overlaps, float32.

Usage: python benchmarks/neck_stress.py

For each regime, 20,000 random pairs: the maximum relative error of a against
the extended-precision bisection reference (float32: of its rounded inputs),
and the NaN/inf count in a and in its gradient with respect to (r_i, r_j, h).
Prints the table and rewrites its section of benchmarks/RESULTS.md.
"""

import jax
import jax.numpy as jnp
import numpy as np
from _common import command_line, markdown_table, reference_neck_radius, write_section

from sintercond.neck import max_overlap, neck_radius

N = 20_000

# (regime, log10 ratio range of r_j / r_i, fraction of max_overlap range, log-spaced fraction?)
REGIMES = (
    ("typical: ratio 1/3..3, h in (0, h_max]", (-0.48, 0.48), (0.0, 1.0), False),
    ("equal radii", (0.0, 0.0), (0.0, 1.0), False),
    ("nearly equal: |ratio - 1| < 1e-9", (-4e-10, 4e-10), (0.0, 1.0), False),
    ("extreme ratio 1e2..1e3 (both ways)", (2.0, 3.0), (0.0, 1.0), False),
    ("tiny overlap: h/h_max in 1e-12..1e-6", (-3.0, 3.0), (-12.0, -6.0), True),
    ("very tiny overlap: h/h_max in 1e-300..1e-100", (-3.0, 3.0), (-300.0, -100.0), True),
    ("near max: 1 - h/h_max in 1e-12..1e-4", (-3.0, 3.0), (-12.0, -4.0), "near"),
    ("exactly h = max_overlap", (-3.0, 3.0), None, False),
)


def regime_inputs(ratio_range, frac_range, log_frac, seed):
    rng = np.random.default_rng(seed)
    r_i = np.exp(rng.uniform(np.log(1e-3), np.log(1e3), N))
    log_ratio = rng.uniform(*ratio_range, N) * rng.choice([-1.0, 1.0], N)
    r_j = r_i * 10.0**log_ratio
    h_max = np.asarray(max_overlap(r_i, r_j))
    if frac_range is None:
        frac = np.ones(N)
    elif log_frac == "near":
        frac = 1.0 - 10.0 ** rng.uniform(*frac_range, N)
    elif log_frac:
        frac = 10.0 ** rng.uniform(*frac_range, N)
    else:
        frac = rng.uniform(*frac_range, N)
    return r_i, r_j, np.maximum(frac * h_max, np.finfo(np.float64).tiny)


def main():
    value_and_grad = jax.jit(jax.vmap(jax.value_and_grad(neck_radius, argnums=(0, 1, 2))))
    rows = []
    for k, (name, ratio_range, frac_range, log_frac) in enumerate(REGIMES):
        r_i, r_j, h = regime_inputs(ratio_range, frac_range, log_frac, seed=k)
        for dtype in (jnp.float64, jnp.float32):
            x = [jnp.asarray(v, dtype) for v in (r_i, r_j, h)]
            x64 = [np.asarray(v, np.float64) for v in x]
            usable = x64[2] > 0  # float32 rounds the tiniest overlaps to 0 (no contact)
            a, grads = value_and_grad(*x)
            a = np.asarray(a, np.float64)
            ref = reference_neck_radius(*(v[usable] for v in x64))
            err = np.abs(a[usable] - ref) / ref
            bad_value = int(np.sum(~np.isfinite(a)))
            bad_grad = int(sum(np.sum(~np.isfinite(np.asarray(g))) for g in grads))
            rows.append((name, jnp.dtype(dtype).name, f"{err.max():.1e}" if err.size else "n/a",
                         f"{np.median(err):.1e}" if err.size else "n/a", bad_value, bad_grad,
                         int(np.sum(~usable))))
            print(*rows[-1], sep="\t", flush=True)
    body = (
        "## Neck solve: numerical stress\n\n"
        f"{N:,} random pairs per regime (radii log-uniform in [1e-3, 1e3]); relative error of a against "
        "the extended-precision bisection reference; NaN/inf counts over a and its three partial derivatives. "
        "'h -> 0 in float32' counts overlaps that round to 0 in float32 (no contact: a = 0, excluded from "
        "the error).\n\n"
        + markdown_table(("regime", "dtype", "max rel. error", "median rel. error", "NaN/inf in a",
                          "NaN/inf in gradient", "h -> 0 in float32"), rows)
    )
    write_section("neck_stress", command_line(), body)


if __name__ == "__main__":
    main()
