"""Powder-bed build (`packing.powder_bed`): rolled (the default) against relaxed, phase by phase, with quality.

Usage: python benchmarks/bed_build.py [--beds 3k 10k 10k-r5 100k] [--relax 3k] [--seed 1] [--json FILE] [--no-write]

Each bed is built in a fresh process (so each first call pays its compilations, as a user's would). Rolled
(``method="roll"``): 'deposit' is ``rolling.roll_deposit`` (arcs rolled); relaxed (``method="relax"``, the beds
named by ``--relax``): 'deposit' is the ballistic ``deposit_spheres``, 'pair list' the host pair-list builds inside
``settle.relax_under_gravity`` (count), 'dynamics' its compiled chunks (steps); 'figures' is ``_bed`` (coordination,
surface height) for both; 'total' the whole ``powder_bed`` call. Quality: packing fraction, mean coordination,
isolated spheres, mean surface height over the asked height, largest overlap. Writes the ``bed_build`` section of
RESULTS.md unless ``--no-write``.
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the checkout this script lives in, not an installed sintercond

# name: (lateral size, height, diameter range) in m
BEDS = {
    "3k": (0.5e-3, 0.4e-3, (20e-6, 60e-6)),  # the 3,290-sphere bed of issue 27
    "10k": (0.9e-3, 0.4e-3, (20e-6, 60e-6)),  # 10,658 spheres
    "10k-r5": (1.2e-3, 0.4e-3, (20e-6, 100e-6)),  # 10,231 spheres, diameter ratio 5
    "30k": (1.6e-3, 0.4e-3, (20e-6, 60e-6)),  # 33,686 spheres
    "100k": (2.8e-3, 0.4e-3, (20e-6, 60e-6)),  # 103,150 spheres
}


def _timed(module, name, log):
    """Wrap ``module.name`` to add its wall time (results ready) and call count to ``log[name]``."""
    import jax

    inner = getattr(module, name, None)
    if inner is None:
        return

    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        out = jax.block_until_ready(inner(*args, **kwargs))
        entry = log.setdefault(name, {"seconds": 0.0, "calls": 0})
        entry["seconds"] += time.perf_counter() - start
        entry["calls"] += 1
        if name == "_damped_chunk":  # steps is the last argument; a redone chunk counts too
            entry["steps"] = entry.get("steps", 0) + int(args[-1])
        return out

    setattr(module, name, wrapper)


def child(name, seed, method):
    """Build one bed in this process; print its figures as one JSON line."""
    import numpy as np

    from sintercond.beds import packing, rolling, settle

    lateral, height, diameters = BEDS[name]
    log = {}
    for module, fn in ((packing, "deposit_spheres"), (settle, "_pair_list"), (settle, "_damped_chunk"), (packing, "_bed")):
        _timed(module, fn, log)
    _timed(rolling, "roll_deposit", log)
    start = time.perf_counter()
    bed = packing.powder_bed(lateral, height, diameters, seed=seed, max_particles=200_000, method=method)
    total = time.perf_counter() - start
    out = {"bed": name, "method": method, "n": len(bed.radii), "total_s": round(total, 2),
           **{f"{k}_{q}": round(v, 2) if q == "seconds" else v for k, e in log.items() for q, v in e.items()},
           "packing_fraction": bed.packing_fraction, "coordination": bed.coordination, "isolated": bed.isolated,
           "height_ratio": bed.height / height, "residual_force": bed.residual_force, "max_overlap": bed.max_overlap}
    if bed.roll is not None:
        out["arcs"] = bed.roll.arcs
    out["centres_digest"] = float(np.sum(bed.centres * np.arange(1, 4)))
    print(json.dumps(out))


def _row(r):
    """A RESULTS.md row: bed, method, spheres, phases, total, quality."""
    lateral, height, diameters = BEDS[r["bed"]]
    if r["method"] == "roll":
        phases = f"rolling {r['roll_deposit_seconds']:.1f} ({r['arcs']:,} arcs), figures {r['_bed_seconds']:.1f}"
    else:
        phases = (f"deposit {r['deposit_spheres_seconds']:.1f}, pair lists {r['_pair_list_seconds']:.1f} "
                  f"({r['_pair_list_calls']}), dynamics {r['_damped_chunk_seconds']:.1f} "
                  f"({r['_damped_chunk_steps']:,} steps), figures {r['_bed_seconds']:.1f}")
    box = f"{lateral * 1e3:g} mm box, {diameters[0] * 1e6:g}-{diameters[1] * 1e6:g} um"
    return [f"{r['bed']} ({box})", r["method"], f"{r['n']:,}", phases, f"{r['total_s']:.1f}",
            f"{r['packing_fraction']:.3f}", f"{r['coordination']:.2f}", r["isolated"], f"{r['height_ratio']:.3f}",
            f"{r['max_overlap']:.2g}"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--beds", nargs="+", default=["3k", "10k", "10k-r5", "100k"], choices=sorted(BEDS),
                        help="beds built rolled")
    parser.add_argument("--relax", nargs="*", default=["3k"], choices=sorted(BEDS), help="beds also built relaxed")
    parser.add_argument("--no-write", action="store_true", help="leave RESULTS.md alone")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", help="also write the rows to this file")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--method", default="roll", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child, args.seed, args.method)
    rows = []
    jobs = [(name, "roll") for name in args.beds] + [(name, "relax") for name in args.relax]
    for name, method in jobs:
        run = subprocess.run([sys.executable, __file__, "--child", name, "--seed", str(args.seed), "--method", method],
                             capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
        if run.returncode:
            print(run.stderr[-3000:], file=sys.stderr)
            raise SystemExit(f"bed {name} ({method}) failed")
        rows.append(json.loads(run.stdout.strip().splitlines()[-1]))
        print(json.dumps(rows[-1]), flush=True)
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(rows, indent=1))
    if not args.no_write:
        from _common import command_line, markdown_table, write_section

        body = ("## Powder beds: rolled against relaxed\n\n"
                "`packing.powder_bed` in a fresh process each (seconds, one run): rolled (`method=\"roll\"`, "
                "the default) and relaxed (`\"relax\"`). Height ratio: mean surface height over the asked height.\n\n"
                + markdown_table(["bed", "method", "spheres", "phases (s)", "total (s)", "packing fraction",
                                  "coordination", "isolated", "height ratio", "largest overlap"],
                                 [_row(r) for r in rows]))
        write_section("bed_build", command_line(), body)


if __name__ == "__main__":
    main()
