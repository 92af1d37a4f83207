"""Command-line entry point.

* ``sintercond run [scene.toml | NAME] [--out DIR] [--duration S]`` runs a
  scene file or a built-in example scene by name (the built-in default scene
  without either): progress bar, VTK/LAMMPS outputs, ``history.csv``,
  checkpoints, a summary table. ``--duration`` replaces ``run.duration``.
  ``sintercond run --resume DIR`` continues an interrupted run.
* ``sintercond scenes`` lists the built-in example scenes.
* ``sintercond effective scene.toml [--axis k] [--coupling sphere|none]``: the
  steady-state effective conductivity of the scene's packing (necks coupled
  through their sphere by default).
* ``sintercond demo`` (also the default with no arguments) prints the neck
  radii and pair conductances of the cases of Rojek et al. (2022).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from sintercond._cache import cache_by_default, enable_compilation_cache

# (r_i, r_j, h) in mm: the unequal pairs of Rojek et al. 2022, Sects. 4.3 and 6,
# and the equal-size overlaps h/r of their Figs. 13-14.
ROJEK_CASES_MM = (
    (1.0, 3.0, 0.2),
    (1.0, 3.0, 0.06),
    (1.0, 1.0, 0.02),
    (1.0, 1.0, 0.08),
    (1.0, 1.0, 0.2),
    (1.0, 1.0, 0.4),
)
COPPER_CONDUCTIVITY = 394.0  # W/(m K), Rojek et al. 2022, Sect. 5


def neck_table(cases_mm=ROJEK_CASES_MM, kappa=COPPER_CONDUCTIVITY) -> str:
    """The demo table as text: neck radii (mm) and conductances (W/K) per case."""
    from sintercond.laws import conductance, neck

    r_i, r_j, h = (np.array(col, dtype=np.float64) for col in zip(*cases_mm))
    neck.validate_neck_inputs(r_i, r_j, h)
    m = 1e-3  # mm -> m
    columns = {
        "r_i": r_i,
        "r_j": r_j,
        "h": h,
        "h_max": neck.max_overlap(r_i, r_j),
        "a_coble": neck.coble_radius(r_i, r_j, h),
        "a_volume": neck.neck_radius(r_i, r_j, h),
        "a_lens": neck.intersection_radius(r_i, r_j, h),
        "a_hertz": neck.hertz_radius(r_i, r_j, h),
    }
    laws = ("rojek", "argento_bouvard", "batchelor_obrien", "conductivity")
    for law in laws:
        columns[f"K_{law}"] = conductance.pair_conductance(law, r_i * m, r_j * m, h * m, kappa)
    header = "  ".join(f"{name:>{_width(name)}}" for name in columns)
    lines = [
        f"Rojek et al. (2022) neck cases, copper kappa = {kappa:g} W/(m K); lengths in mm, conductances K in W/K",
        header,
        "-" * len(header),
    ]
    for row in zip(*(np.asarray(v) for v in columns.values())):
        lines.append("  ".join(f"{value:>{_width(name)}.6f}" for name, value in zip(columns, row)))
    lines += [
        "",
        "a_volume: volume-conserving cylindrical neck (Eqs. 19-20, 27); a_coble: Eqs. 11-12;",
        "a_lens: sphere intersection circle (Quintana-Ruiz Eqs. 33-34); a_hertz: sqrt(r* h).",
        "K_rojek: 1.064 kappa pi a halves in series (Eqs. 9, 43); K_argento_bouvard: slope 1/0.899;",
        "K_batchelor_obrien: 2 kappa a; K_conductivity: kappa pi a_lens^2 / d (Quintana-Ruiz Eq. 32).",
    ]
    return "\n".join(lines)


def _width(name: str) -> int:
    return max(len(name), 10)


def entry():
    """The ``sintercond`` command: :func:`main`, then a quick exit.

    Once the command is done (its files closed, its output flushed), the ``atexit`` handlers run and the
    process ends with ``os._exit``: Python's own shutdown would then spend about 0.3 s unloading jaxlib's
    native libraries (measured after every handler had run, on a 97k-particle ``sintercond run`` taking 2.4 s
    in all), time the user waits for and nothing else needs. :func:`main` itself, as tests call it, returns.
    """
    import atexit
    import os

    try:
        code = main()
    except SystemExit as done:  # argparse's exits and parser.exit: their code, printed message already out
        code = done.code if isinstance(done.code, int) else (0 if done.code is None else 1)
        if done.code is not None and not isinstance(done.code, int):
            print(done.code, file=sys.stderr)
    sys.stdout.flush()
    sys.stderr.flush()
    atexit._run_exitfuncs()  # what the interpreter would run first (logging's flush, JAX's own handlers)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code or 0)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="sintercond",
        description="Differentiable heat conduction through sintered particles.",
    )
    sub = parser.add_subparsers(dest="command")
    demo = sub.add_parser("demo", help="print neck radii and pair conductances of the Rojek et al. (2022) cases")
    demo.add_argument("--kappa", type=float, default=COPPER_CONDUCTIVITY,
                      help="conductivity in W/(m K), > 0 (default: copper, 394)")
    run = sub.add_parser("run", help="run a scene file (default: the built-in scene)")
    run.add_argument("scene", nargs="?", default=None,
                     help="scene TOML file, or the name of a built-in scene (`sintercond scenes` lists them; "
                          "default: the built-in default scene)")
    run.add_argument("--out", default="sintercond-out", help="output directory (default: sintercond-out)")
    run.add_argument("--duration", type=float, default=None, metavar="S",
                     help="simulated time in s, replacing the scene's run.duration (with --resume: extend the run to it)")
    run.add_argument("--resume", metavar="DIR", default=None, help="continue the run in DIR from its checkpoint")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.add_argument("--no-pictures", action="store_true", help="skip final_state.png and history.png")
    sub.add_parser("scenes", help="list the built-in example scenes (run one with `sintercond run NAME`)")
    effective = sub.add_parser("effective", help="steady-state effective conductivity of a scene's packing")
    effective.add_argument("scene", nargs="?", default=None, help="scene TOML file (default: built-in default scene)")
    effective.add_argument("--axis", type=int, default=2, choices=(0, 1, 2), help="heat-flow axis (default 2, z)")
    effective.add_argument("--out", default=None, metavar="DIR", help="also write the steady field to DIR/steady.vtp")
    effective.add_argument("--coupling", default="sphere", choices=("sphere", "none"),
                           help="the conductance network: necks coupled through their sphere (default), or each "
                                "neck's pair law alone on its sphere, the isolated pipe network")
    args = parser.parse_args(argv)
    if cache_by_default():
        enable_compilation_cache()  # a second run of the same scene compiles nothing
    if args.command in ("run", "effective"):
        return _scene_command(parser, args)
    if args.command == "scenes":
        return _list_scenes()
    kappa = getattr(args, "kappa", COPPER_CONDUCTIVITY)
    if not (np.isfinite(kappa) and kappa > 0):
        parser.error(f"--kappa must be finite and > 0 W/(m K); got {kappa}")
    print(neck_table(kappa=kappa))
    return 0


def _scene_command(parser, args) -> int:
    """``run`` and ``effective``: a clean one-line error (exit 2 for bad input, 1 for a failed run), no traceback."""
    from sintercond.scene import SceneError

    try:
        return _effective(args) if args.command == "effective" else _run(args)
    except SceneError as err:
        parser.exit(2, f"sintercond: error: {err}\n")
    except ValueError as err:  # raised while building the packing or network from a valid scene
        parser.exit(2, f"sintercond: error: the scene cannot be built: {err}\n")
    except MemoryError:
        parser.exit(1, "sintercond: error: out of memory while building or running the scene; make [packing] "
                       "smaller (docs/scenes.md, Limits)\n")
    except FloatingPointError as err:
        parser.exit(1, f"sintercond: error: the run left the physical range: {err}\n")
    except OSError as err:
        parser.exit(1, f"sintercond: error: {err.strerror or err}: {err.filename or ''}\n")
    except KeyboardInterrupt:
        parser.exit(130, "sintercond: interrupted; `sintercond run --resume DIR` continues from the last checkpoint\n")


def _list_scenes() -> int:
    from sintercond.scene import builtin_scenes

    scenes = builtin_scenes()
    width = max(len(name) for name in scenes)
    print("built-in example scenes (run one with `sintercond run NAME [--duration S]`):")
    for name, description in scenes.items():
        print(f"  {name:<{width}}  {description}")
    return 0


def _run(args) -> int:
    from sintercond import run as runner
    from sintercond.scene import load_scene

    if args.resume is not None:
        _, summary = runner.resume(args.resume, progress=not args.no_progress, pictures=not args.no_pictures,
                                   duration=args.duration)
        out = args.resume
    else:
        scene = load_scene(args.scene, duration=args.duration)
        _, summary = runner.run_scene(scene, args.out, progress=not args.no_progress, pictures=not args.no_pictures)
        out = args.out
    print(runner.summary_table(summary))
    print(f"outputs in {out}/ ({runner.written_outputs(out)})")
    return 0


def effective_box(scene, bed, centres=None, radii=None, axis=2):
    """The box ``k*`` is measured in, chosen from the scene (:func:`sintercond.beds.packing.measurement_box`, as a
    sintering run's history measures it): ``None`` for a lattice (its cell, see steady). A powder bed's box is
    its container: the side walls laterally, and from the floor to the bed's mean surface height vertically (the
    rough top above it is cut off). Any other packing (listed, poured, read from a file): the bounding box of its
    particles' surfaces (for a packing pressed against container walls, the container, whose cross-section is
    ``A``), its two faces along ``axis`` moved half a mean radius inward, so that each face layer (every particle
    whose surface comes within half a mean radius of the outermost) is held. The particles reaching a face of the
    box along the axis are held (hot at ``lo``, cold at ``hi``).
    """
    from sintercond.beds.packing import measurement_box

    kind = scene["packing"]["kind"]
    if kind == "powder_bed":
        return measurement_box(bed.centres, bed.radii, axis, bed_size=float(bed.container[1][0]))
    return measurement_box(centres, radii, axis, lattice=kind == "simple_cubic")


def _effective(args) -> int:
    from sintercond.beds import packing
    from sintercond.sim import steady
    from sintercond.scene import load_scene
    from sintercond.scene.build import build_packing

    scene = load_scene(args.scene)
    bed = None
    if scene["packing"]["kind"] in ("powder_bed", "simple_cubic"):
        bed = packing.from_scene(scene["packing"])
        centres, radii = bed.centres, bed.radii
    else:
        centres, radii, _ = build_packing(scene)
    box = effective_box(scene, bed, centres, radii, args.axis)
    c = scene["conduction"]
    kappa = scene["material"]["conductivity"]
    k_star, temperature, outside = steady.steady_state_conductivity(
        centres, radii, kappa, axis=args.axis, law=c["law"], params=c.get("params"), neck_model=c.get("neck_model"),
        box=box, field=True, coupling=args.coupling, beyond_domain="isolated", domain=True)
    if box is None:
        where = "the lattice cell"
    elif bed is not None:
        where = f"the container cut at the mean surface height, {box[1][0]:.4g} x {box[1][1]:.4g} x {box[1][2]:.4g} m"
    else:
        size = (centres + radii[:, None]).max(axis=0) - (centres - radii[:, None]).min(axis=0)
        where = (f"the packing's bounding box ({size[0]:.4g} x {size[1]:.4g} x {size[2]:.4g} m), each face layer "
                 "(within half a mean radius of the outermost particle) held")
    isolated = int(np.count_nonzero(np.isnan(np.asarray(temperature))))
    print(f"effective conductivity along axis {args.axis}: {k_star:.6g} W/(m K) "
          f"({len(radii)} particles, solid conductivity {kappa:g} W/(m K), k*/k = {k_star / kappa:.4g})")
    print(f"k* = Q L / (A dT): particles reaching the two faces of {where} along axis {args.axis} held at "
          "dT apart, Q the steady heat flow, L the distance of the mean centre planes of the two held sets, "
          "A the box cross-section")
    if args.coupling == "sphere":
        beyond = int(np.count_nonzero(np.asarray(outside)))
        print("network: necks that share a sphere coupled through its surface (--coupling none: the isolated pipe "
              "network)" + (f"; {beyond} particles have two necks closer than their discs' half-widths: they keep "
                            "the pair law's halves (isolated necks)" if beyond else ""))
    else:
        print("network: each neck's pair law alone on its sphere (the isolated pipe network)")
    if isolated:
        print(f"{isolated} particles are joined to neither held face by any chain of contacts: they carry no heat "
              "(no temperature in the field: NaN, and isolated = 1)")
    if args.out is not None:
        from pathlib import Path

        from sintercond.output.io import write_pvd, write_vtp

        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        t = np.asarray(temperature)
        write_vtp(out / "steady.vtp", centres, radii, t, 0, 0.0, {"isolated": np.isnan(t).astype(np.int64)})
        write_pvd(out / "steady.pvd", [(0.0, "steady.vtp")])
        print(f"the steady field (T = 1 on the hot face, 0 on the cold one) in {out}/steady.vtp (steady.pvd)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
