"""Run time against error for Dryden & Zok's sigma(alpha).

Usage: python benchmarks/dryden_zok.py

* sintercond's graded-panel Nystrom with product integration of the log and
  |xi| parts of the kernel (sintercond.laws.dryden_zok), node counts 16-192: max
  error over 40 alphas in (0, pi/2] against a 320-node solution (whose own
  spread is measured against 256- and 384-node solutions), and time per sigma
  (jitted, after a warm-up call: one alpha per call, and a batch of 40 by vmap;
  minimum over up to 25 repeats or 10 s).
* A plain midpoint Nystrom on N equal cells of [0, alpha] (the paper used
  60), the log-singular diagonal cell integrated exactly and everything else
  by the midpoint rule, in NumPy: it converges only like O(h). Time: minimum
  of up to 25 repeats or 10 s after a warm-up call.
Prints the table and rewrites its section of benchmarks/RESULTS.md.
"""

import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import best_time, command_line, markdown_table, new_figure, number, save_figure, write_section

from sintercond.laws import dryden_zok as dz

ALPHAS = np.pi / 2 * np.linspace(0.025, 1.0, 40)


def midpoint_sigma(alpha, n):
    """Plain midpoint Nystrom for Eq. 24 on n equal cells."""
    h = alpha / n
    t = (np.arange(n) + 0.5) * h
    diff = t[:, None] - t[None, :]
    direct = np.where(np.eye(n, dtype=bool), 0.0, np.asarray(dz.kernel(np.where(diff == 0, 1.0, diff))))
    # diagonal cell: K ~ (1/2) ln|x| + C(0) with C(0) = 1/2 - ln(2)/2; int over |x| < h/2 exactly
    diagonal = 0.5 * h * (np.log(h / 2) - 1) + h * (0.5 - 0.5 * np.log(2.0))
    matrix = h * direct + np.diag(np.full(n, diagonal)) + h * np.asarray(dz.kernel(t[:, None] + t[None, :]))
    j = np.linalg.solve(np.eye(n) - matrix / np.pi, np.cos(1.5 * t))
    return 6 / np.pi * h * np.sum(j * np.cos(1.5 * t))


def plot(rows):
    """Max error against time per sigma: sintercond's graded panels (single call and batched) and plain midpoint."""
    fig = new_figure()
    ax = fig.subplots()
    ours = [r for r in rows if r[0].startswith("sintercond")]
    plain = [r for r in rows if not r[0].startswith("sintercond")]
    curves = [(ours, 3, "o-", "sintercond, graded panels: one alpha per call"),
              (ours, 4, "s--", "sintercond, graded panels: per alpha in a batch of 40"),
              (plain, 3, "^-", "plain midpoint Nystrom (NumPy)")]
    for k, (mine, column, style, label) in enumerate(curves):
        times, errors = [number(r[column]) for r in mine], [max(number(r[2]), 1e-17) for r in mine]
        ax.plot(times, errors, style, color=f"C{k}", label=label)
        for r, x, y in zip(mine, times, errors):
            if column == 3:
                ax.annotate(str(r[1]), (x, y), textcoords="offset points", xytext=(4, 3), fontsize=7, color=f"C{k}")
    ax.set(xscale="log", yscale="log", xlabel="time per σ [ms]", ylabel="max |σ − σ_ref| over 40 α [-]",
           title="Dryden–Zok σ(α): node count (labels) against error")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return save_figure("dryden_zok", fig, "Dryden-Zok sigma: time per sigma against error, per node count")


def main():
    reference = np.asarray(dz.dryden_zok_sigma(ALPHAS, nodes=320))
    spread = max(np.max(np.abs(np.asarray(dz.dryden_zok_sigma(ALPHAS, nodes=n)) - reference)) for n in (256, 384))
    print(f"reference (320 nodes) against 256 and 384 nodes: {spread:.1e}")
    rows = []
    for nodes in (16, 32, 48, 64, 80, 96, 128, 192):
        t0 = time.perf_counter()
        dz._mesh(nodes)
        build = time.perf_counter() - t0
        err = np.max(np.abs(np.asarray(dz.dryden_zok_sigma(ALPHAS, nodes)) - reference))
        single = jax.jit(lambda a, n=nodes: dz.dryden_zok_sigma(a, n))
        batch = jax.jit(lambda a, n=nodes: dz.dryden_zok_sigma(a, n))
        t_single = best_time(single, jnp.asarray(0.7))
        t_batch = best_time(batch, jnp.asarray(ALPHAS)) / len(ALPHAS)
        rows.append(("sintercond (graded panels, product integration)", nodes, f"{err:.1e}",
                     f"{t_single * 1e3:.3f}", f"{t_batch * 1e3:.3f}", f"{build:.2f}"))
        print(*rows[-1], sep="\t", flush=True)
    for n in (60, 120, 240, 480, 960):
        sigmas = np.array([midpoint_sigma(a, n) for a in ALPHAS])
        elapsed = best_time(midpoint_sigma, 0.7, n)
        rows.append(("plain midpoint (NumPy)", n, f"{np.max(np.abs(sigmas - reference)):.1e}",
                     f"{elapsed * 1e3:.3f}", "", ""))
        print(*rows[-1], sep="\t", flush=True)
    body = (
        "## Dryden-Zok sigma(alpha): run time against error\n\n"
        "Max |sigma - sigma_ref| over 40 alphas in (0, pi/2], reference = 320 nodes (it differs from the 256- "
        f"and 384-node solutions by at most {spread:.1e}, computed in this run). Time per sigma, compilation "
        "excluded (a warm-up call first), minimum over up to 25 repeats or 10 s: one jitted call with a single "
        "alpha, and per alpha in a vmapped batch of 40; 'mesh build' is the one-off NumPy precomputation of the "
        "product weights (cached per node count).\n\n"
        + markdown_table(("method", "nodes", "max error", "ms / sigma (single)", "ms / sigma (batch of 40)",
                          "mesh build (s)"), rows)
        + "\n\n" + plot(rows)
    )
    write_section("dryden_zok", command_line(), body)


if __name__ == "__main__":
    main()
