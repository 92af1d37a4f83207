"""Necks at their own pace (issue 41, part 2): the ti6al4v preheat with fixed and paced neck-update intervals.

Usage: python benchmarks/neck_pace.py [--variants every1 every20 every500 rtol1e-3 rtol1e-2]

The built-in ``ti6al4v_preheating_bed`` (398 particles, 236,471 explicit steps to 9.5 s) run by ``sintercond run`` in
its own process per variant of its ``[sintering]`` table: ``every = 1`` (the reference: the necks grown at every
step), ``every = 20`` (as built in), ``every = 500``, and ``neck_rtol = 1e-3`` / ``1e-2`` with ``every = 500`` as
the longest interval (a longer cap would lower the scene's automatic step through the ramp's bound,
``sintercond.scene.estimate.RAMP_STEP_FRACTION``). Prints, per variant, the whole process's seconds and the last
history row's mean and largest neck ratio, k* and mean temperature with their relative differences from
``every = 1``. Writes nothing.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
import time
from importlib.resources import files
from pathlib import Path

VARIANTS = {"every1": "every = 1", "every20": "every = 20", "every500": "every = 500",
            "rtol1e-3": "every = 500\nneck_rtol = 1e-3", "rtol1e-2": "every = 500\nneck_rtol = 1e-2"}
COLUMNS = ("mean_neck_ratio", "max_neck_ratio", "k_star_W_mK", "T_mean_K")


def run(name: str, work: Path) -> tuple[float, dict]:
    """``(process seconds, last history row)`` of the scene with variant ``name``."""
    text = files("sintercond.data").joinpath("scenes", "ti6al4v_preheating_bed.toml").read_text()
    if text.count("every = 20") != 1:
        raise SystemExit("ti6al4v_preheating_bed: expected sintering.every = 20")
    path = work / f"{name}.toml"
    path.write_text(text.replace("every = 20", VARIANTS[name]))
    argv = ["run", str(path), "--out", str(work / name), "--no-progress", "--no-pictures"]
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", f"from sintercond.cli import main; raise SystemExit(main({argv!r}))"],
                          capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode:
        raise SystemExit(f"{name} failed:\n{done.stderr[-3000:]}")
    with open(work / name / "history.csv") as f:
        last = list(csv.DictReader(f))[-1]
    return wall, {k: float(last[k]) for k in COLUMNS}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    args = parser.parse_args(argv)
    names = ["every1"] + [n for n in args.variants if n != "every1"]
    with tempfile.TemporaryDirectory() as work:
        results = {name: run(name, Path(work)) for name in names}
    reference = results["every1"][1]
    print("| variant | process s | " + " | ".join(COLUMNS) + " | relative differences from every = 1 |")
    print("|---|---|" + "---|" * len(COLUMNS) + "---|")
    for name, (wall, row) in results.items():
        diffs = ", ".join(f"{(row[k] / reference[k] - 1):+.1e}" for k in COLUMNS)
        print(f"| {name} | {wall:.1f} | " + " | ".join(f"{row[k]:.6g}" for k in COLUMNS) + f" | {diffs} |")


if __name__ == "__main__":
    main()
