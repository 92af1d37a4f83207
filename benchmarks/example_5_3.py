"""Example 5.3 of Quintana-Ruiz & Campello (2020): pour, settle, heat, k* with and without softening.

Pours ``--n`` spheres (radii N(3 mm, 0.667 mm) truncated at 3 sigma) into an
open box of side ``--lateral-size`` with the DEM (:func:`sintercond.beds.packing.pour`),
heats it from the x walls (1000 K / 300 K) for 350 s and reads k* three ways
(MECHANICS.md erratum 9), then the softened variant (theta* = 300 K) as a
quasi-static fixed point (:func:`sintercond.examples.example_5_3`). Writes the
``example_5_3`` section of RESULTS.md.

    python benchmarks/example_5_3.py --n 10000
"""

import argparse
import time

from _common import command_line, markdown_table, write_section

from sintercond import examples

PAPER = {"k_unsoftened": 6.2, "k_softened": 7.4, "phi": 0.54, "hs_upper": 44.6}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=10_000)
    parser.add_argument("--lateral-size", type=float, default=0.1)
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument("--start", default="relaxed")
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    start = time.perf_counter()
    ex = examples.example_5_3(n=args.n, lateral_size=args.lateral_size, iterations=args.iterations,
                              start=args.start)
    total = time.perf_counter() - start
    bed, s = ex.packing, ex.packing.settle
    rows = []
    for name, est, b, packed in (("unsoftened", ex.unsoftened, ex.bounds, bed),
                                 ("softened, theta* = 300 K", ex.softened, ex.softened_bounds, ex.softened_packing)):
        rows.append([name, f"{packed.packing_fraction:.4f}", f"{packed.height * 1e3:.2f}", f"{est.k_steady:.4g}",
                     f"{est.k_wall:.4g}", f"{est.k_paper:.4g}",
                     f"{PAPER['k_unsoftened'] if name == 'unsoftened' else PAPER['k_softened']}",
                     f"{b[0]:.3g} - {b[1]:.4g}", f"{est.heat_hot:.4g}", f"{est.stored:.4g}",
                     f"{est.steady_change:.2e}"])
    table = markdown_table(["bed", "packing fraction", "bed height (mm)", "k* steady (W/(m K))",
                            "k* hot wall at 350 s", "k* paper's formula", "paper", "HS bounds", "heat in, hot wall (J)",
                            "stored (J)", "|P_hot + P_cold| / P_hot"], rows)
    note = ("Figures taken while other jobs shared the 2 cores (load average ~10): the run times are several "
            "times those of a quiet machine. ")
    settle = note + (f"Settle ({args.start} start): {s.steps} DEM steps of {s.dt:.3g} s ({s.time:.3g} s simulated), "
              f"kinetic energy {s.kinetic_ratio:.2g} of sum m g r (threshold {s.kinetic_tol:g}), largest net force "
              f"{s.force_ratio:.2g} of a weight (threshold {s.force_tol:g}), largest overlap {s.max_overlap:.3g} r, "
              f"{s.wall_seconds:.0f} s. Softened re-settles: k* steady after each pass "
              f"{', '.join(f'{k:.4g}' for k in ex.iterations)}. Run time: "
              + ", ".join(f"{k} {v:.0f} s" for k, v in ex.seconds.items()) + f", total {total:.0f} s.")
    print(table)
    print(settle)
    if not args.no_write:
        name = "example_5_3" if args.n == 10_000 else f"example_5_3_n{args.n}"
        write_section(name, command_line(), "## Example 5.3: poured bed, k* with and without softening\n\n"
                      f"{args.n} spheres in an open box of side {args.lateral_size} m. " + settle + "\n\n" + table)


if __name__ == "__main__":
    main()
