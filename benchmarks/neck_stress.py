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
from _common import command_line, markdown_table, new_figure, number, reference_neck_radius, save_figure, write_section

from sintercond.laws.neck import max_overlap, neck_radius

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


def plot(rows):
    """Max and median relative error per regime and dtype (log bars); NaN/inf counts written beside them."""
    fig = new_figure(8.5, 4.4)
    ax = fig.subplots()
    regimes = list(dict.fromkeys(r[0] for r in rows))
    y = np.arange(len(regimes))[::-1]
    for k, dtype in enumerate(("float64", "float32")):
        mine = {r[0]: r for r in rows if r[1] == dtype}
        worst = [max(number(mine[g][2]), 1e-17) if mine[g][2] != "n/a" else np.nan for g in regimes]
        offset = 0.2 - 0.4 * k
        ax.barh(y + offset, worst, height=0.38, color=f"C{k}", label=f"{dtype}: max rel. error (0 drawn at 1e-17)")
        for yy, g, w in zip(y + offset, regimes, worst):
            bad = int(mine[g][4]) + int(mine[g][5])
            ax.annotate(f" NaN/inf: {bad}" if np.isfinite(w) else " n/a (h rounds to 0)", (w if np.isfinite(w) else 1e-17, yy),
                        va="center", fontsize=6)
    ax.set_yticks(y, [g.replace(": ", ":\n", 1) for g in regimes], fontsize=7)
    ax.set(xscale="log", xlabel="max relative error of a against the 80-bit reference [-]",
           title="neck_radius under stress (20,000 pairs per regime)")
    ax.set_xlim(1e-17, 1e-2)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2)
    return save_figure("neck_stress", fig, "Neck solve under stress: max relative error per regime, float64 and float32")


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
        + "\n\n" + plot(rows)
    )
    write_section("neck_stress", command_line(), body)


if __name__ == "__main__":
    main()
