"""Slow physics at its own time scale: the ti6al4v preheating bed run explicit against ``run.integrator = "auto"``.

The built-in scene ``ti6al4v_preheating_bed`` (a poured 398-particle Ti6Al4V bed on a plate held on the 9.5 s
preheating ramp, necks growing by grain-boundary diffusion, no mechanics in the run) is run twice by the
``sintercond run`` command, each in its own process: once with ``run.integrator = "explicit"`` (Euler at 0.9 of
the explicit limit on the necks at the cap) and once with ``"auto"`` (resolved to the adaptive TR-BDF2 of
:mod:`sintercond.sim.adaptive`, ``run.rtol`` / ``run.atol`` at their defaults). Both runs keep the same output grid
(the auto run's ``dt`` is the explicit one, its output clock), so their LAMMPS frames and ``history.csv`` rows
compare at the same times: the largest particle temperature difference, and the relative differences of the mean
neck ratio and of k* (along z), at the outputs nearest 1, 5 and 9.5 s. Reported: the steps each took (the
explicit run's steps; the adaptive run's accepted and rejected steps), the wall time of the whole process (pour,
network, compile, run, outputs) and of its run phase (``summary.json``'s ``wall_s``: compile and stepping, with
the outputs written between chunks). The pour is the same in both (the seed; the benchmark checks the packings
are identical).

Usage: ``python benchmarks/time_scales.py [--work DIR] [--write] [--lateral-size M] [--no-in-process]``
(``--lateral-size 2.5e-3``: a rolled bed of about 1e4 particles, the section ``time_scales_wide``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _common import sintercond_process  # noqa: E402

SCENE = "ti6al4v_preheating_bed"
TIMES = (1.0, 5.0, 9.5)


LATERAL_SIZE = "lateral_size = 500e-6"


DEM_POUR = ('method = "dem"', 'start = "rolled"', "soft_modulus = 1e7")


def scene_text(integrator: str, lateral_size: float | None = None, rtol: float | None = None) -> str:
    """The built-in scene with ``run.integrator`` and LAMMPS frames (per-particle temperatures as text); with
    ``lateral_size`` (m) a wider bed of the same height (about 400 particles per 0.25 mm^2 of plate), rolled
    (``packing.method = "roll"``: the spheres rest on their supports at point contacts) instead of poured by the
    DEM, whose settling at 110 GPa takes longer than the whole preheat at 1e4 particles (killed after 15 min)."""
    from importlib.resources import files

    text = files("sintercond.data").joinpath("scenes", f"{SCENE}.toml").read_text()
    if not text.rstrip().endswith("duration = 9.5") or not all(key in text for key in (LATERAL_SIZE, *DEM_POUR)):
        raise SystemExit(f"{SCENE}: expected its [run] table last, {LATERAL_SIZE!r} and {DEM_POUR}")
    if lateral_size is not None:
        text = text.replace(LATERAL_SIZE, f"lateral_size = {lateral_size!r}")
        lines = [line for line in text.splitlines() if not line.lstrip().startswith(DEM_POUR[1:])]
        text = "\n".join('method = "roll"' if line.startswith(DEM_POUR[0]) else line for line in lines)
        start = text.index("[mechanics]")  # the pour's contact material: a rolled bed has none
        text = text[:start] + text[text.index("\n\n", start) + 2:]
    tolerance = "" if rtol is None else f"rtol = {rtol!r}\n"
    return text.rstrip() + f'\nintegrator = "{integrator}"\nformats = ["lammps"]\n' + tolerance


def run(integrator: str, work: Path, lateral_size: float | None = None, rtol: float | None = None) -> dict:
    """Run the scene in a new process; returns its summary, the process's wall time and the run folder."""
    work.mkdir(parents=True, exist_ok=True)
    path, out = work / f"{integrator}.toml", work / integrator
    path.write_text(scene_text(integrator, lateral_size, rtol if integrator == "auto" else None))
    argv = ["run", str(path), "--out", str(out), "--no-progress", "--no-pictures"]
    done, wall = sintercond_process(argv)
    (work / f"{integrator}.log").write_text(done.stdout + done.stderr)
    if done.returncode:
        raise SystemExit(f"the {integrator} run failed:\n{done.stderr[-3000:]}")
    summary = json.loads((out / "summary.json").read_text())
    return {"summary": summary, "wall": wall, "out": out,
            "log": [line for line in done.stderr.splitlines() if "integrator" in line or "compiled" in line]}


def frames(path: Path) -> dict[int, np.ndarray]:
    """``{step: temperatures [n]}`` of a LAMMPS dump (ordered by particle id)."""
    out, lines, k = {}, path.read_text().splitlines(), 0
    while k < len(lines):
        if lines[k] == "ITEM: TIMESTEP":
            step, n = int(lines[k + 1]), int(lines[k + 3])
            header = lines[k + 8].split()[2:]
            rows = np.array([row.split() for row in lines[k + 9:k + 9 + n]], float)
            out[step] = rows[np.argsort(rows[:, 0]), header.index("temperature")]
            k += 9 + n
        else:
            k += 1
    return out


def history(path: Path) -> dict[int, dict]:
    lines = path.read_text().splitlines()
    names = lines[0].split(",")
    return {int(float(row.split(",")[0])): dict(zip(names, map(float, row.split(",")))) for row in lines[1:]}


def face_layers(out: Path, lateral_size: float) -> str:
    """How many particles hold k*'s two faces (the powder bed's box, :func:`sintercond.beds.packing.bed_box`)."""
    from sintercond.beds.packing import bed_box

    packed = np.load(out / "packing.npz")
    centres, radii = packed["centres"], packed["radii"]
    lo, hi = bed_box(centres, radii, lateral_size)
    bottom, top = int(np.sum(centres[:, 2] - radii <= lo[2])), int(np.sum(centres[:, 2] + radii >= hi[2]))
    return (f"k*'s face layers: {bottom} particles on the floor, {top} reaching above the mean surface "
            f"({1e6 * hi[2]:.0f} um)")


def in_process(work: Path) -> dict:
    """Compile-and-step and step-only seconds of each integrator in this process, on the runs' packing without
    outputs: ``advance`` twice (the second reuses the compiled chunk)."""
    from sintercond.scene import load_scene
    from sintercond.scene.build import build_model
    from sintercond.sim import rollout

    packed = np.load(work / "auto" / "packing.npz")
    times = {}
    for name in ("auto", "explicit"):
        model = build_model(load_scene(work / f"{name}.toml"), packed["centres"], packed["radii"])
        runs = []
        for _ in range(2):
            start = time.perf_counter()
            rollout.advance(model.sim, model.state, model.params, model.n_steps, model.output_every)
            runs.append(time.perf_counter() - start)
        times[name] = runs
    return times


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", default="/tmp/sintercond_time_scales", help="run folders (default %(default)s)")
    parser.add_argument("--write", action="store_true", help="write the section of benchmarks/RESULTS.md")
    parser.add_argument("--lateral-size", type=float, default=None,
                        help="the bed's lateral size (m; the scene's 500e-6 by default: 398 particles); 2.5e-3 pours "
                             "about 1e4 particles, written to the section time_scales_wide")
    parser.add_argument("--no-in-process", action="store_true", help="skip the in-process compile and step timings")
    parser.add_argument("--rtol", type=float, default=None,
                        help="run.rtol of the auto run (the default's 1e-5 if not given); written to the section "
                             "time_scales_rtol (time_scales_wide_rtol with --lateral-size)")
    args = parser.parse_args(argv)
    work = Path(args.work)
    runs = {name: run(name, work, args.lateral_size, args.rtol) for name in ("auto", "explicit")}
    ex, im = runs["explicit"], runs["auto"]
    same_packing = all(np.array_equal(np.load(ex["out"] / "packing.npz")[k], np.load(im["out"] / "packing.npz")[k])
                       for k in ("centres", "radii"))
    te, ti = frames(ex["out"] / "dump.lammpstrj"), frames(im["out"] / "dump.lammpstrj")
    he, hi = history(ex["out"] / "history.csv"), history(im["out"] / "history.csv")
    rows = []
    for t in TIMES:
        step = min(he, key=lambda s: abs(he[s]["time_s"] - t))
        rows.append((f"{he[step]['time_s']:.4g}", f"{np.max(np.abs(te[step] - ti[step])):.3g}",
                     f"{100 * abs(hi[step]['mean_neck_ratio'] / he[step]['mean_neck_ratio'] - 1):.2g}",
                     f"{100 * abs(hi[step]['k_star_W_mK'] / he[step]['k_star_W_mK'] - 1):.2g}",
                     f"{he[step]['T_mean_K']:.2f}", f"{he[step]['mean_neck_ratio']:.4f}",
                     f"{he[step]['k_star_W_mK']:.4g}"))
    s_e, s_i = ex["summary"], im["summary"]
    lines = [f"packings identical: {same_packing}; {s_e['particles']} particles, {s_e['contacts']} contacts; "
             f"{face_layers(ex['out'], args.lateral_size or 500e-6)}",
             f"explicit: {s_e['steps']:,} steps of {s_e['dt_s']:.3g} s; process {ex['wall']:.1f} s, run phase "
             f"{s_e['wall_s']:.1f} s, of which outputs {s_e['outputs_s']:.1f} s, compile and stepping "
             f"{s_e['wall_s'] - s_e['outputs_s']:.1f} s",
             f"auto ({s_i['integrator']}): {s_i['implicit_steps']:,} accepted + {s_i['rejected_steps']:,} rejected "
             f"adaptive steps; process {im['wall']:.1f} s, run phase {s_i['wall_s']:.1f} s, of which outputs "
             f"{s_i['outputs_s']:.1f} s, compile and stepping {s_i['wall_s'] - s_i['outputs_s']:.1f} s",
             *ex["log"], *im["log"]]
    timed = {} if args.no_in_process else in_process(work)
    lines[3:3] = [f"in one process, no outputs: {name} compile + stepping {first:.1f} s, stepping alone (compiled) "
                  f"{second:.1f} s" for name, (first, second) in timed.items()]
    header = ("t (s)", "max abs dT (K)", "mean neck ratio diff (%)", "k* diff (%)", "T mean (K, explicit)",
              "mean neck ratio (explicit)", "k* (W/(m K), explicit)")
    print("\n".join(lines))
    print("\n".join(" | ".join(r) for r in [header] + rows))
    if args.write:
        sys.path.insert(0, str(Path(__file__).parent))
        from _common import command_line, markdown_table, write_section

        wide = args.lateral_size is not None
        title = (f"a bed {args.lateral_size * 1e3:g} mm wide ({s_e['particles']:,} particles)" if wide
                 else "the ti6al4v preheat")
        body = (f"## Time scales: {title}, explicit against auto (adaptive TR-BDF2)\n\n"
                + ("`packing.lateral_size` widened and the bed rolled (`packing.method = \"roll\"`: point contacts, "
                   "the necks born at them) instead of poured by the DEM (its settling at 110 GPa outlasts the whole "
                   "preheat at this size), everything else as the scene. " if wide else "") +
                "The built-in `ti6al4v_preheating_bed` (9.5 s preheating ramp, sintering necks) run by `sintercond "
                "run` in its own process with `run.integrator = \"explicit\"` and `\"auto\"` (implicit here: no "
                f"mechanics in the run; rtol {args.rtol or 1e-5:g}, atol 1e-3 K), the same pour and output grid. "
                "Differences of the auto run from the explicit one at the outputs nearest 1, 5, 9.5 s. Process: "
                "the whole command (pour, network, compile, run, outputs); run phase: `summary.json` `wall_s` "
                "(compile, stepping and the outputs between chunks: frames, history rows with a k* steady solve "
                "each, checkpoints; `outputs_s`).\n\n"
                + "\n".join(f"- {line}" for line in lines[:5]) + "\n\n" + markdown_table(header, rows))
        if wide:
            body += ("\n\nThe auto run is faster than the explicit one here, but short of the issue's goal (1 min for "
                     "the whole process at 1e4): its steps cost some 0.1 s each (two stages of two fixed-point "
                     "iterations, each a conjugate-gradient solve and a neck growth, and an error solve).")
            if args.rtol is not None:
                body = body.replace("## Time scales: ", f"## Time scales at run.rtol = {args.rtol:g}: ", 1)
                body += (f" At run.rtol = {args.rtol:g} the adaptive run takes {s_i['implicit_steps']:,} + "
                         f"{s_i['rejected_steps']:,} steps and {im['wall']:.1f} s for the whole process (of which the "
                         f"run phase {s_i['wall_s']:.1f} s, outputs {s_i['outputs_s']:.1f} s), its errors against the "
                         "explicit run in the table: a looser tolerance is the lever on the 1-minute goal where the "
                         "issue's 0.5 K and 0.5 % allow it.")
            write_section("time_scales_wide" if args.rtol is None else "time_scales_wide_rtol", command_line(), body)
            return
        body += ("\n\nThe adaptive run takes some 200 times fewer steps, each of them two implicit stages (conjugate "
                "gradients, two fixed-point iterations with the necks) and an error solve. At 398 particles the "
                "whole command takes the same time either way (three runs on one machine, 2026-12-06: explicit "
                "33.5-38.0 s, auto 36.4-38.5 s; compiled stepping alone 6.7-8.2 s against 3.1-4.3 s): the pour and "
                "the network are most of both runs, and the adaptive step compiles longer. The outputs were 42-46 s "
                "of each run until their k* steady solve was compiled instead of dispatched op by op (0.25 s to "
                "3.6 ms a row, measured on a 10 x 10 x 4 simple cubic block of 400 spheres with grown necks). "
                "Compile times depend on JAX's persistent compilation cache (a cached explicit chunk compiles in "
                "about 2 s, a new one in about 8 s).")
        if args.rtol is not None:
            body = body.replace("## Time scales: ", f"## Time scales at run.rtol = {args.rtol:g}: ", 1)
        write_section("time_scales" if args.rtol is None else "time_scales_rtol", command_line(), body)


if __name__ == "__main__":
    main()
