"""Powder-bed build (`packing.powder_bed`, method "relax"), phase by phase, with the bed's quality figures.

Usage: python benchmarks/bed_build.py [--beds 3k 10k] [--seed 1] [--json FILE]

Each bed is built in a fresh process (so each first call pays its compilations, as a user's would):
'deposit' is ``deposit_spheres``; 'pair list' the host pair-list builds inside ``settle.relax_under_gravity``
(count); 'dynamics' the compiled relax chunks (count, steps); 'figures' ``_bed`` (coordination, surface height);
'total' the whole ``powder_bed`` call. Quality: packing fraction, mean coordination, isolated spheres, mean surface
height over the asked height, residual force over weight, largest overlap. No RESULTS.md section exists for beds:
the figures go to stdout (and ``--json``).
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


def child(name, seed):
    """Build one bed in this process; print its figures as one JSON line."""
    import numpy as np

    from sintercond import packing, settle

    lateral, height, diameters = BEDS[name]
    log = {}
    for module, fn in ((packing, "deposit_spheres"), (settle, "_pair_list"), (settle, "_damped_chunk"), (packing, "_bed")):
        _timed(module, fn, log)
    start = time.perf_counter()
    bed = packing.powder_bed(lateral, height, diameters, seed=seed, max_particles=200_000)
    total = time.perf_counter() - start
    out = {"bed": name, "n": len(bed.radii), "total_s": round(total, 2),
           **{f"{k}_{q}": round(v, 2) if q == "seconds" else v for k, e in log.items() for q, v in e.items()},
           "packing_fraction": bed.packing_fraction, "coordination": bed.coordination, "isolated": bed.isolated,
           "height_ratio": bed.height / height, "residual_force": bed.residual_force, "max_overlap": bed.max_overlap}
    out["centres_digest"] = float(np.sum(bed.centres * np.arange(1, 4)))
    print(json.dumps(out))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--beds", nargs="+", default=["3k", "10k"], choices=sorted(BEDS))
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", help="also write the rows to this file")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child, args.seed)
    rows = []
    for name in args.beds:
        run = subprocess.run([sys.executable, __file__, "--child", name, "--seed", str(args.seed)],
                             capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
        if run.returncode:
            print(run.stderr[-3000:], file=sys.stderr)
            raise SystemExit(f"bed {name} failed")
        rows.append(json.loads(run.stdout.strip().splitlines()[-1]))
        print(json.dumps(rows[-1]), flush=True)
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
