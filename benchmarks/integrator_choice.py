"""What ``run.integrator = "auto"`` picks for each built-in scene, and what the other choice would cost.

Each built-in scene without inertial mechanics (``implicit`` is refused with it, and ``auto`` is explicit there) is
run by the ``sintercond run`` command in its own process twice: ``run.integrator = "explicit"`` (Euler at 0.9 of
the step bound) and ``"implicit"`` (the adaptive TR-BDF2 of :mod:`sintercond.sim.adaptive`, ``run.rtol`` /
``run.atol`` at their defaults, the same output clock); under a beam also explicitly at a hundredth of the step,
for the explicit run's own time error. Reported: the whole process's wall time (packing, network,
compile, run, outputs), the explicit steps, the adaptive steps accepted and rejected, the final largest and mean
temperature and mean neck ratio of the implicit run against the explicit one, and what ``auto`` picks
(:func:`sintercond.scene.integrator.scene_integrator`, then :func:`sintercond.scene.integrator.auto_by_steps` on
the explicit run's step count) with its reason. One run of each (the machine's spread: ``time_scales`` in
RESULTS.md).

Usage: ``python benchmarks/integrator_choice.py [--scenes a,b,...] [--work DIR] [--no-write]``
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from _common import command_line, markdown_table, write_section

from sintercond.scene.integrator import AUTO_IMPLICIT_STEPS, auto_by_steps, scene_integrator
from sintercond.scene.validate import builtin_scenes, load_scene


def run(name: str, integrator: str, work: Path, dt=None) -> tuple[float, dict]:
    """``(seconds, summary)`` of one ``sintercond run`` of the built-in scene ``name`` (``"default"``: the default
    scene) with ``run.integrator``, and ``run.dt`` if given."""
    raw = load_scene(None if name == "default" else name)
    raw["run"]["integrator"] = integrator
    if dt is not None:
        raw["run"]["dt"] = dt
        raw["run"].pop("output_every", None)
        raw["run"].pop("checkpoint_every", None)
    folder = work / f"{name}_{integrator}{'' if dt is None else '_fine'}"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "scene.json").write_text(json.dumps(raw))
    script = ("import json, sys; from sintercond.run import run_scene; from sintercond.scene.validate import "
              "validate_scene; run_scene(validate_scene(json.load(open(sys.argv[1]))), sys.argv[2], progress=False, "
              "pictures=False)")
    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", script, str(folder / "scene.json"), str(folder / "out")], check=True,
                   capture_output=True)
    seconds = time.perf_counter() - start
    return seconds, json.loads((folder / "out" / "summary.json").read_text())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scenes", default=None, help="comma-separated built-in scenes (default: all)")
    parser.add_argument("--work", default="/tmp/integrator_choice")
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args(argv)
    names = args.scenes.split(",") if args.scenes else ["default"] + sorted(builtin_scenes())
    rows = []
    for name in names:
        scene = load_scene(None if name == "default" else name)
        if scene.get("physics", {}).get("mechanics", False):
            rows.append([f"`{name}`", "explicit (inertial mechanics)", "", "", "", "", "", "", "", ""])
            print(rows[-1], flush=True)
            continue
        (explicit_s, explicit), (implicit_s, implicit) = (run(name, kind, Path(args.work))
                                                          for kind in ("explicit", "implicit"))
        picked, why = auto_by_steps(scene, *scene_integrator(scene), explicit["steps"])
        reason = why.split(": ", 1)[1].split(":")[0].split(" (")[0]
        fine = ""
        if scene.get("beam") is not None:  # the explicit run's own time error: the same run at a hundredth of its step
            fine = f"{run(name, 'explicit', Path(args.work), explicit['dt_s'] / 100)[1]['T_max_K'] - explicit['T_max_K']:+.3g}"
        necks = ""
        if "mean_neck_ratio" in explicit:
            necks = f"{implicit['mean_neck_ratio'] / explicit['mean_neck_ratio'] - 1:.1e}"
        rows.append([f"`{name}`", f"{picked} ({reason})", f"{explicit_s:.1f}", f"{implicit_s:.1f}",
                     f"{explicit['steps']:,}", f"{implicit['implicit_steps']:,} + {implicit['rejected_steps']:,}",
                     f"{implicit['T_max_K'] - explicit['T_max_K']:+.3g}",
                     f"{implicit['T_mean_K'] - explicit['T_mean_K']:+.3g}", necks, fine])
        print(rows[-1], flush=True)
    header = ["scene", "auto picks", "explicit, process (s)", "implicit, process (s)", "explicit steps",
              "adaptive steps (accepted + rejected)", "T_max implicit - explicit (K)", "T_mean (K)",
              "mean neck ratio (relative)", "T_max at a 100x shorter explicit step - explicit (K; beams)"]
    table = markdown_table(header, rows)
    print(table)
    if not args.no_write:
        body = ("## Integrator choice: what `run.integrator = \"auto\"` picks for the built-in scenes\n\n"
                "Each built-in scene without inertial mechanics run by `sintercond run` in its own process with "
                "`run.integrator = \"explicit\"` and `\"implicit\"` (adaptive TR-BDF2, rtol 1e-5, atol 1e-3 K), "
                "the whole process timed (packing, network, compile, run, outputs), one run each. `auto` picks "
                "the implicit integrator where the run has no inertial mechanics, coupled necks or scanning beam "
                f"and the explicit run takes at least {AUTO_IMPLICIT_STEPS:,} steps. Where a beam scans, the "
                "adaptive step follows its spot and rejects most of its tries; where the explicit run is short, "
                "compiling the adaptive step costs more than it saves. The differences are the final state's; "
                "under a beam the explicit run's own time error is shown by the same run at a hundredth of its "
                "step (the last column).\n\n" + table)
        write_section("integrator_choice", command_line(), body)
    return 0


if __name__ == "__main__":
    sys.exit(main())
