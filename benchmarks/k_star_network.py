"""k* of powder beds on the coupled network (the default) against the isolated pipe network: what the user waits for.

Usage: python benchmarks/k_star_network.py [--repeats 2] [--work /tmp/k_star_network] [--write]

Each case is one ``sintercond`` command in its own process (_common.sintercond_process), run ``--repeats`` times per
network, alternating the networks so that the machine's drift falls on both:

- ``sintercond run ti6al4v_preheating_bed``: the built-in 398-particle bed on its 9.5 s preheat (integrator auto),
  a k* row at every output, with ``sintering.k_star_coupling = "sphere"`` and ``"none"``;
- ``sintercond effective`` of a rolled bed of about 14,000 particles (2.5 mm wide, 0.6 mm high, 45-105 um, the
  preheating bed's powder) with ``--coupling sphere`` and ``none``.

Reports the whole process's wall time (min / max over the repeats), the k* each network gives (the run: its last
history row; both runs' rows are the same packing and necks) and, for the run, the most particles kept at their pair
laws' halves (``k_star_uncoupled``). No peer computes coupled necks: the isolated rows are the peers' network.
"""

import argparse
import csv
import json
import re
from importlib.resources import files
from pathlib import Path

from _common import markdown_table, sintercond_process, write_section

BED = "ti6al4v_preheating_bed"
ROLLED = """[packing]
kind = "powder_bed"
method = "roll"
lateral_size = 2.5e-3
height = 6e-4
diameter_range = [45e-6, 105e-6]
seed = 0

[material]
density = 4430.0
specific_heat = 560.0
conductivity = 7.0

[conduction]
law = "rojek"

[initial]
temperature = 300.0

[run]
duration = 1e-3
"""


def preheat_scene(coupling: str) -> str:
    text = files("sintercond.data").joinpath("scenes", f"{BED}.toml").read_text()
    if "[sintering]" not in text:
        raise SystemExit(f"{BED}: expected a [sintering] section")
    return text.replace("[sintering]", f'[sintering]\nk_star_coupling = "{coupling}"', 1)


def run_preheat(coupling: str, work: Path, k: int) -> dict:
    path, out = work / f"preheat_{coupling}.toml", work / f"preheat_{coupling}_{k}"
    path.write_text(preheat_scene(coupling))
    done, wall = sintercond_process(["run", str(path), "--out", str(out), "--no-progress", "--no-pictures"])
    if done.returncode:
        raise SystemExit(f"the preheat with k_star_coupling {coupling} failed:\n{(done.stdout + done.stderr)[-3000:]}")
    with open(out / "history.csv") as f:
        rows = list(csv.DictReader(f))
    summary = json.loads((out / "summary.json").read_text())
    return {"wall": wall, "k_star": float(rows[-1]["k_star_W_mK"]), "outputs": len(rows),
            "uncoupled": max(int(r["k_star_uncoupled"]) for r in rows), "run_phase": summary["wall_s"]}


def run_effective(coupling: str, work: Path) -> dict:
    path = work / "rolled.toml"
    path.write_text(ROLLED)
    done, wall = sintercond_process(["effective", str(path), "--coupling", coupling])
    if done.returncode:
        raise SystemExit(f"effective --coupling {coupling} failed:\n{(done.stdout + done.stderr)[-3000:]}")
    found = re.search(r"along axis \d: ([0-9.e+-]+) W/\(m K\) \((\d+) particles", done.stdout)
    return {"wall": wall, "k_star": float(found.group(1)), "particles": int(found.group(2))}


def spread(values) -> str:
    return f"{min(values):.1f} / {max(values):.1f}"


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--work", type=Path, default=Path("/tmp/k_star_network"))
    parser.add_argument("--write", action="store_true", help="rewrite the k_star_network section of RESULTS.md")
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    preheat = {"sphere": [], "none": []}
    effective = {"sphere": [], "none": []}
    for k in range(args.repeats):
        for coupling in ("sphere", "none"):
            preheat[coupling].append(run_preheat(coupling, args.work, k))
            print("preheat", coupling, preheat[coupling][-1], flush=True)
            effective[coupling].append(run_effective(coupling, args.work))
            print("effective", coupling, effective[coupling][-1], flush=True)
    rows = []
    for coupling in ("sphere", "none"):
        p, e = preheat[coupling], effective[coupling]
        rows.append((f"`sintercond run {BED}` (398 particles, {p[0]['outputs']} k* rows)", coupling,
                     spread([r["wall"] for r in p]), spread([r["run_phase"] for r in p]), f"{p[0]['k_star']:.5g}",
                     str(p[0]["uncoupled"])))
    for coupling in ("sphere", "none"):
        e = effective[coupling]
        rows.append((f"`sintercond effective` rolled bed ({e[0]['particles']:,} particles)", coupling,
                     spread([r["wall"] for r in e]), "", f"{e[0]['k_star']:.5g}", ""))
    ratio_run = min(r["wall"] for r in preheat["sphere"]) / min(r["wall"] for r in preheat["none"])
    ratio_eff = min(r["wall"] for r in effective["sphere"]) / min(r["wall"] for r in effective["none"])
    k_run = preheat["sphere"][0]["k_star"] / preheat["none"][0]["k_star"] - 1
    k_eff = effective["sphere"][0]["k_star"] / effective["none"][0]["k_star"] - 1
    body = (
        "## k* on the coupled network against the isolated one: whole processes\n\n"
        "The network k* is measured on (`sintering.k_star_coupling`, `sintercond effective --coupling`): `sphere`, "
        "the necks that share a sphere coupled through its surface (the default), `none`, the isolated pipe network "
        "(the peers'). Each command in its own process, the networks alternated, "
        f"{args.repeats} runs each (min / max of the whole process, s; run phase: `summary.json` `wall_s`). "
        "The preheat's k* is its last history row (9.5 s); uncoupled: the most particles any row kept at their pair "
        "laws' halves (two necks' discs overlapping).\n\n"
        + markdown_table(("command", "network", "whole process (s)", "run phase (s)", "k* (W/(m K))",
                          "uncoupled particles"), rows)
        + f"\n\nCoupled / isolated, fastest runs: preheat {ratio_run:.2f}x, effective {ratio_eff:.2f}x; k* coupled "
        f"against isolated: preheat {100 * k_run:+.1f} %, rolled bed {100 * k_eff:+.1f} %."
    )
    print(body)
    if args.write:
        write_section("k_star_network", "python benchmarks/k_star_network.py --write", body)


if __name__ == "__main__":
    main()
