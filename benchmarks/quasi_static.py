"""Sintering with the mechanics at sintering time scales: quasi-static mechanics at the real modulus against the
inertial step, softened and not.

The built-in scene ``ti6al4v_preheating_bed`` (a 398-particle Ti6Al4V bed poured by the DEM and settled at the run's modulus,
necks growing by grain-boundary diffusion) run with the mechanics on (``physics.mechanics = true``,
``sintering.shrinkage = "many_body"``) by the ``sintercond run`` command, each case in its own process:

- ``quasi_static``: ``mechanics.quasi_static = true`` at 110 GPa, on the scene's 9.5 s preheating ramp, and the
  same for its first 0.05 s;
- ``inertial_soft``: the inertial step with the modulus softened to 1e7 Pa (the pour too, ``packing.soft_modulus
  = 1e6``), 0.05 s: what a coupled sintering run took before (the ramp needs the mechanics quasi-static, so its
  plate stays at 845 K);
- ``inertial_real``: the inertial step at 110 GPa, 1 ms.

Reported: the step ``dt`` and the steps each run took, the wall time of the whole process (pour, network, compile,
run, outputs) and of its run phase (``summary.json``'s ``wall_s``), the run phase per simulated second, and at the
end the mean neck ratio, the shrinkages and the drop of the mean surface height. The step count of a 9.5 s run is ``9.5 / dt``.

Usage: ``python benchmarks/quasi_static.py [--work DIR] [--write] [--cases NAME ...]``
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _common import sintercond_process  # noqa: E402

SCENE = "ti6al4v_preheating_bed"
LATERAL_SIZE = 500e-6  # m, the scene's

CASES = {  # name: (duration s, young_modulus Pa, quasi_static, keeps [preheating])
    "quasi_static": (9.5, 110e9, True, True),
    "quasi_static_short": (0.05, 110e9, True, True),
    "inertial_soft": (0.05, 1e7, False, False),
    "inertial_real": (0.001, 110e9, False, False),
}


CONCLUSIONS = (
    "Quasi-static mechanics steps at the thermal limit: 171 times fewer steps than the inertial step softened to "
    "1e7 Pa and 7,060 times fewer than at 110 GPa. The whole 9.5 s preheat of this 398-particle bed with the "
    "mechanics takes two minutes (117.9 and 140.0 s whole process in two runs, 2026-12-07); "
    "softened and inertial it would take some 6.5 hours of run phase (2,482 s per simulated second). The softened "
    "bed's 0.05 s are mostly its re-settling at the new modulus (height shrinkage 1.2 %, 22 times the quasi-static "
    "run's 0.055 % from sintering), and the inertial run at 110 GPa is stopped by the motion guard within 2,000 "
    "steps (contacts approaching at 0.76 m/s, beyond the 0.05 m/s its step was sized for). No peer (LAMMPS, "
    "LIGGGHTS, Yade, MercuryDPM) has a quasi-static sintering mode: they step the inertial DEM (MercuryDPM's sinter "
    "species at its elastic step), so the inertial rows are what they would take.")


def scene_text(duration: float, modulus: float, quasi_static: bool, preheating: bool) -> str:
    """The built-in scene with the mechanics on, many-body shrinkage, the given modulus and duration."""
    from importlib.resources import files

    text = files("sintercond.data").joinpath("scenes", f"{SCENE}.toml").read_text()
    for needed in ("young_modulus = 110e9", "soft_modulus = 1e7", "[preheating]", "[sintering]", "duration = 9.5"):
        if needed not in text:
            raise SystemExit(f"{SCENE}: expected {needed!r} in it")
    text = text.replace("young_modulus = 110e9", f"young_modulus = {modulus!r}\nquasi_static = "
                                                   f"{'true' if quasi_static else 'false'}")
    if modulus < 1e8:
        text = text.replace("soft_modulus = 1e7", "soft_modulus = 1e6")
    if not preheating:
        start = text.index("[preheating]")
        text = text[:start] + text[text.index("\n\n", start) + 2:]
    text = text.replace("[sintering]", '[sintering]\nshrinkage = "many_body"')
    if not quasi_static:  # the inertial bed re-settles: its floor layer lifts off and k*'s box has no floor face
        text = text.replace("k_star_axis = 2\n", "")
    text = text.rstrip().removesuffix("duration = 9.5") + f"duration = {duration!r}\n"
    return "[physics]\nmechanics = true\n\n" + text


def run(name: str, work: Path) -> dict:
    """Run one case in a new process; its summary, the process's wall time and its log's step line."""
    work.mkdir(parents=True, exist_ok=True)
    path, out = work / f"{name}.toml", work / name
    path.write_text(scene_text(*CASES[name]))
    argv = ["run", str(path), "--out", str(out), "--no-progress", "--no-pictures"]
    done, wall = sintercond_process(argv)
    (work / f"{name}.log").write_text(done.stdout + done.stderr)
    (work / f"{name}.wall.json").write_text(json.dumps(wall))
    return read(name, work)


def read(name: str, work: Path) -> dict:
    """A case's last run in ``work``: its summary, wall time, and if it stopped, the reason and its step."""
    wall = json.loads((work / f"{name}.wall.json").read_text())
    summary = work / name / "summary.json"
    if summary.is_file():
        return {"summary": json.loads(summary.read_text()), "wall": wall}
    log = (work / f"{name}.log").read_text()
    errors = [line for line in log.splitlines() if "error:" in line]
    step = re.search(r"dt ([0-9.e+-]+) s, ", log)
    if not errors or step is None:
        raise SystemExit(f"the {name} run failed:\n{log[-3000:]}")
    return {"stopped": errors[-1].split("error: ", 1)[1], "dt": float(step.group(1)), "wall": wall}


def surface_drop(out: Path) -> float:
    """The relative drop of the bed's mean surface height (:func:`sintercond.beds.packing.surface_height`) from the
    start of a run to its last checkpoint."""
    from sintercond.beds import packing

    saved, radii = np.load(out / "checkpoint.npz"), np.load(out / "packing.npz")["radii"]
    start, end = (packing.surface_height(saved[key], radii, LATERAL_SIZE)
                  for key in (".sintering.start_positions", ".particles.positions"))
    return 1.0 - end / start


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/sintercond_quasi_static"))
    parser.add_argument("--write", action="store_true", help="write the section of benchmarks/RESULTS.md")
    parser.add_argument("--cases", nargs="*", default=list(CASES), choices=list(CASES),
                        help="run these cases only (the others' rows are read from their last run in --work)")
    args = parser.parse_args(argv)
    rows = []
    for name, (duration, modulus, quasi, _) in CASES.items():
        result = run(name, args.work) if name in args.cases else read(name, args.work)
        if "stopped" in result:
            row = [name, f"{modulus:.3g}", "inertial", f"{duration:g}", f"{result['dt']:.3g}",
                   f"stopped: {result['stopped']}", f"{9.5 / result['dt']:,.0f}", f"{result['wall']:.1f}"]
            rows.append(row + [""] * 6)
            print(" | ".join(row), flush=True)
            continue
        s = result["summary"]
        surface = surface_drop(args.work / name)
        per_second = s["wall_s"] / s["simulated_s"]
        row = [name, f"{modulus:.3g}", "quasi-static" if quasi else "inertial", f"{duration:g}", f"{s['dt_s']:.3g}",
               f"{s['steps']:,}", f"{9.5 / s['dt_s']:,.0f}", f"{result['wall']:.1f}", f"{s['wall_s']:.1f}",
               f"{per_second:,.1f}", f"{s['mean_neck_ratio']:.4f}", f"{s['height_shrinkage']:.2e}",
               f"{s['volume_shrinkage']:.2e}", f"{surface:.2e}"]
        rows.append(row)
        print(" | ".join(row), flush=True)
    if args.write:
        sys.path.insert(0, str(Path(__file__).parent))
        from _common import markdown_table, write_section

        header = ["case", "E (Pa)", "motion", "simulated (s)", "dt (s)", "steps", "steps for 9.5 s",
                  "process (s)", "run phase (s)", "run phase per simulated s", "mean neck ratio",
                  "height shrinkage", "volume shrinkage", "surface height drop"]
        body = ("## Sintering with the mechanics: quasi-static at 110 GPa against the inertial step\n\n"
                "The built-in `ti6al4v_preheating_bed` (398 particles poured by the DEM and settled at the run's "
                "modulus, "
                "grain-boundary necks) with `physics.mechanics = true` and `sintering.shrinkage = \"many_body\"`, "
                "each case one `sintercond run` in its own process: quasi-static at 110 GPa on the scene's 9.5 s "
                "ramp and on its first 0.05 s; inertial with the modulus softened to 1e7 Pa (what a coupled "
                "sintering run took before; the ramp needs quasi-static mechanics, so its plate stays at 845 K, and "
                "k* is not measured: the soft bed lifts off its floor), 0.05 s; inertial at 110 GPa, 1 ms. Process: "
                "the whole command (pour, network, compile, run, outputs); run phase: `summary.json` `wall_s`. "
                "Steps for 9.5 s: `9.5 / dt`. Height and volume shrinkage: the bed's best-fit homogeneous "
                "deformation (`history.csv`); surface height drop: of its mean surface height "
                "(`packing.surface_height`).\n\n" + markdown_table(header, rows) + "\n\n" + CONCLUSIONS)
        write_section("quasi_static", "python benchmarks/quasi_static.py --write", body)


if __name__ == "__main__":
    main()
