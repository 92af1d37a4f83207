"""Time and peak memory of steady_state_conductivity for 1e5 and 1e6 particles, on both networks.

Usage: python benchmarks/effective_large.py [--sizes 100000 1000000]

Each size and network runs in a fresh subprocess (so its peak RSS is its own): jittered
sintered SC packing, Morton-ordered, Rojek law, k* along x from one CG solve, with the
necks coupled through their spheres (the default) and on the isolated pipe network.
The exact answer for the unjittered lattice is K_pair / a on both; the jitter moves
it by a few per cent. Prints the table and rewrites its section of
benchmarks/RESULTS.md.
"""

import argparse
import json
import subprocess
import sys

from _common import markdown_table, new_figure, number, save_figure, write_section

CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, "benchmarks")
import numpy as np
from thermal_step import jittered_packing
from sintercond.contacts import network
from sintercond.sim import thermal
from sintercond.sim import steady
from sintercond.laws.conductance import rojek_pair_conductance
n = int(sys.argv[1])
t0 = time.perf_counter()
centres, radii = jittered_packing(n)
order = network.morton_order(centres)
k = steady.steady_state_conductivity(centres[order], radii[order], 7.0, axis=0, tol=1e-10, coupling=sys.argv[2])
elapsed = time.perf_counter() - t0
k_lattice = float(rojek_pair_conductance(0.53e-4, 0.53e-4, 0.06e-4, 7.0)) / 1e-4
print(json.dumps({"n": len(radii), "seconds": elapsed, "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
                  "k_star": k, "k_lattice": k_lattice}))
"""


def plot(rows):
    """Time and peak memory of k* against the particle count."""
    fig = new_figure(6.4, 3.8)
    ax = fig.subplots()
    for coupling, style in (("sphere", "-"), ("none", ":")):
        mine = [r for r in rows if r[1] == coupling]
        n = [number(r[0]) for r in mine]
        ax.plot(n, [number(r[2]) for r in mine], "o" + style, label=f"time [s], coupling {coupling}")
        ax.plot(n, [number(r[3]) for r in mine], "s" + style, label=f"peak RSS [GB], coupling {coupling}")
    ax.set(xscale="log", yscale="log", xlabel="particles [-]", ylabel="time [s], peak memory [GB]",
           title="Effective conductivity k* end to end")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return save_figure("effective_large", fig, "Effective conductivity of large packings: time and memory")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="+", default=[100_000, 1_000_000])
    args = parser.parse_args()
    rows = []
    seconds = {}
    for n in args.sizes:
        for coupling in ("sphere", "none"):
            out = subprocess.run([sys.executable, "-c", CHILD, str(n), coupling], capture_output=True, text=True,
                                 check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            seconds[n, coupling] = r["seconds"]
            ratio = f"{seconds[n, 'sphere'] / r['seconds']:.1f}" if coupling == "none" else ""
            rows.append((f"{r['n']:,}", coupling, f"{r['seconds']:.1f}", f"{r['peak_gb']:.1f}", f"{r['k_star']:.4g}",
                         f"{r['k_lattice']:.4g}", ratio))
            print(*rows[-1], sep="\t", flush=True)
    body = (
        "## Effective conductivity of large packings: time and memory\n\n"
        "`steady_state_conductivity` end to end (packing build, Morton order, jax-md contact search, conductances, "
        "one CG solve to 1e-10), fresh process per size and network: `sphere`, the necks coupled through their "
        "spheres (the default), and `none`, the isolated pipe network; targets: 1e5 particles under 10 s, 1e6 "
        "under 5 min and 8 GB on this 2-core, 24 GB machine. The packing is a jittered simple-cubic lattice (six "
        "near-opposite necks a sphere), where the two networks nearly agree.\n\n"
        + markdown_table(("particles", "coupling", "time (s)", "peak RSS (GB)", "k* (W/(m K))",
                          "K_pair/a, unjittered", "coupled / isolated time"), rows)
        + "\n\n" + plot(rows)
    )
    write_section("effective_large", "python benchmarks/effective_large.py", body)


if __name__ == "__main__":
    main()
