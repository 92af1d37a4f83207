"""Cost of the coupled neck network (issue 40) in the steady k* solve, against the isolated network.

Usage: PYTHONPATH=. python benchmarks/coupling_cost.py [--sizes 1000 10000]
       PYTHONPATH=. python benchmarks/coupling_cost.py --cells     (the docs/laws.md table: cells vs full field)
       PYTHONPATH=. python benchmarks/coupling_cost.py --transient [--sizes 10000]   (the explicit step)
       PYTHONPATH=. python benchmarks/coupling_cost.py --outputs [--sizes 100000]   (k* rows along a run)

Beds: rolled random beds (``sintercond.beds.packing.powder_bed``, diameters 60-120, seed 0) of about the given
number of spheres, densified by 4 % about the origin (sintered necks, 5-6 contacts a sphere), k* along z
between the face layers (``face_layer_box``). Per coupling: the first call (host setup, compile, solve), the
second (host setup and solve on the compiled program), the conjugate-gradient iterations (counted through a
callback in the mat-vec), and for ``"sphere"`` the memory of the per-sphere blocks (the constant geometric
``[n, m, m]`` block and ``C_s``, float64, both counted at the table's width m: an upper bound, since ``C_s`` is
stored packed by row width). Prints a table; writes nothing.

``--transient``: the explicit step on the same beds, insulated, from a random field (300-400 K), at 0.9 of each
network's stable step: the milliseconds a step of a compiled 200-step rollout takes (after a warm-up call, best of
3), the stable steps, and for ``"sphere"`` the memory of the per-sphere blocks ``C_s`` (packed by row width, what
a step streams twice). The coupled step takes ``NECK_SWEEPS`` (1) conjugate-gradient sweeps on the neck balance a
step (sintercond.sim.terms.coupling).

``--outputs``: what a run's history pays per k* row on a static bed whose necks grow: k* from
``steady_state_network_conductivity`` (the path of ``observe.sintered_conductivity``) on the same bed with its
necks scaled by 1.0, 1.1, 1.2 (Rojek's law at unit conductivity), each network in turn; the first call builds
(and, coupled, caches) the geometry and compiles, the later ones reuse them.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import jax
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT))

from sintercond.sim import steady, thermal  # noqa: E402
from sintercond.contacts.network import contact_pairs  # noqa: E402
from sintercond.beds.packing import powder_bed  # noqa: E402

MATVECS = [0]


def _counting_cg(cg):
    """``cg`` whose mat-vec bumps :data:`MATVECS` (one call for the initial residual, then one per iteration)."""
    def counted(matvec, b, **kwargs):
        def a(x):
            jax.debug.callback(lambda: MATVECS.__setitem__(0, MATVECS[0] + 1))
            return matvec(x)
        return cg(a, b, **kwargs)
    return counted


def bed(n_target, seed=0):
    """A rolled bed of about ``n_target`` spheres (diameters 60-120), densified by 4 %."""
    height = 400.0
    lateral = float(np.sqrt(n_target / 187.0 * 500.0**2))  # 187 spheres in 500 x 500 x 400
    b = powder_bed(lateral, height, (60.0, 120.0), seed=seed, max_particles=4 * n_target)
    return 0.96 * np.asarray(b.centres), np.asarray(b.radii)


def time_bed(n_target):
    centres, radii = bed(n_target)
    box = steady.face_layer_box(centres, radii, 2)
    pairs = contact_pairs(centres, radii)
    width = int(np.bincount(np.concatenate([pairs.i, pairs.j]), minlength=len(radii)).max())
    rows = []
    for coupling in ("none", "sphere"):
        times, k = [], None
        for _ in range(2):
            MATVECS[0] = 0
            t0 = time.perf_counter()
            k = steady.steady_state_conductivity(centres, radii, 1.0, axis=2, box=box, tol=1e-10, coupling=coupling)
            times.append(time.perf_counter() - t0)
        iterations = MATVECS[0] - 1
        blocks_mb = 2 * len(radii) * width * width * 8 / 1e6 if coupling == "sphere" else 0.0
        rows.append((len(radii), 2 * len(pairs.i) / len(radii), width, coupling, times[0], times[1], iterations,
                     blocks_mb, k))
    return rows


def time_outputs(n_target):
    """Rows ``(n, row, coupling, seconds, k*)`` of three k* rows of a static bed with growing necks."""
    from sintercond.laws.neck import neck_radius

    centres, radii = bed(n_target)
    box = steady.face_layer_box(centres, radii, 2)
    pairs = contact_pairs(centres, radii)
    start = np.asarray(neck_radius(pairs.r_i, pairs.r_j, pairs.overlap))
    rows = []
    for k, scale in enumerate((1.0, 1.1, 1.2)):
        a = scale * start
        conductance = 1.064 * np.pi * a / 2  # Rojek's linear law, unit conductivity, equal halves in series
        for coupling in ("sphere", "none"):
            t0 = time.perf_counter()
            value = steady.steady_state_network_conductivity(centres, radii, pairs, conductance, axis=2, box=box,
                                                             coupling=coupling, kappa=1.0, neck_radii=a,
                                                             beyond_domain="isolated")
            rows.append((len(radii), k, coupling, time.perf_counter() - t0, float(value)))
    return rows


def cells_table():
    """Coupled and isolated k*/kappa of the reference cells through the public solver, against the full field."""
    import csv

    from fullfield import lattice_block, rizza_block
    from fullfield_cells import RIZZA_NECKS

    with open(ROOT / "tests" / "data" / "fullfield_cells.csv") as f:
        ref = {(r["structure"], r["a_over_r"]): r for r in csv.DictReader(x for x in f if not x.startswith("#"))}
    print("| cell | a/r | full field | isolated | coupled | isolated / full | coupled / full | "
          "coupled / full / SC ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for ar in ("0.16", "0.22", "0.3", "0.4"):
        sc = float(ref["SC", ar]["ratio"])
        for kind in ("SC", "BCC", "FCC"):
            centres, radii, _, kw = lattice_block(kind, float(ar))
            iso = steady.steady_state_conductivity(centres, radii, 1.0, coupling="none", **kw)
            cpl = steady.steady_state_conductivity(centres, radii, 1.0, coupling="sphere", **kw)
            full = float(ref[kind, ar]["fullfield"])
            print(f"| {kind} | {ar} | {full:.4f} | {iso:.4f} | {cpl:.4f} | {iso / full:.3f} | {cpl / full:.3f} | "
                  f"{cpl / full / sc:.3f} |")
    for t, (a1, a2) in RIZZA_NECKS.items():
        centres, radii, _, kw = rizza_block(a1, a2)
        iso = steady.steady_state_conductivity(centres, radii, 1.0, coupling="none", **kw)
        cpl = steady.steady_state_conductivity(centres, radii, 1.0, coupling="sphere", **kw)
        row = next(r for (s, _), r in ref.items() if s == f"BCC_RG_{t}s")
        full = float(row["fullfield"])
        print(f"| R&G BCC {t} s | {a1 / 40:.3f} | {full:.4f} | {iso:.4f} | {cpl:.4f} | {iso / full:.3f} | "
              f"{cpl / full:.3f} | |")


def time_transient(n_target, steps=200):
    """Rows ``(n, coupling, ms per step, stable step (s), block memory (MiB))`` of the explicit step on a bed."""
    from sintercond import simulate
    from sintercond.sim import rollout as rollouts
    from sintercond.sim.stability import thermal_time_step
    from sintercond.state import particle_state

    centres, radii = bed(n_target)
    temperature = 300.0 + 100.0 * np.random.default_rng(0).random(len(radii))
    params = simulate.Params(jax.numpy.array([1.0]), jax.numpy.array([1.0]))
    rows = []
    for coupling in ("none", "sphere"):
        physics = simulate.Physics.create(conductance="lifted", coupling=coupling)
        contacts = simulate.lifted_contacts(physics, centres, radii)
        sim = simulate.simulator(physics)
        state = simulate.init_state(particle_state(centres, radii, temperature, 1.0), contacts, 1.0)
        limit = float(thermal_time_step(sim, state, params))
        state = simulate.init_state(particle_state(centres, radii, temperature, 1.0), contacts, 0.9 * limit)
        run = jax.jit(lambda st, p, sim=sim: rollouts.rollout(sim, st, p, steps)[0])
        jax.block_until_ready(run(state, params))
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            jax.block_until_ready(run(state, params))
            best = min(best, time.perf_counter() - t0)
        memory = float("nan")
        if coupling == "sphere":
            blocks = sim.prepare_fn(state, params).neck_blocks.blocks
            memory = sum(c.nbytes for c in blocks) / 2**20  # C_s, packed
        rows.append((len(radii), coupling, 1e3 * best / steps, limit, memory))
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--cells", action="store_true")
    parser.add_argument("--transient", action="store_true")
    parser.add_argument("--outputs", action="store_true")
    args = parser.parse_args()
    if args.transient:
        print("| n | coupling | ms per step | stable step (s) | block memory (MiB) |")
        print("|---|---|---|---|---|")
        for n in args.sizes:
            for r in time_transient(n):
                print(f"| {r[0]} | {r[1]} | {r[2]:.3f} | {r[3]:.4g} | {r[4]:.1f} |", flush=True)
        return
    if args.outputs:
        print("| n | k* row | coupling | seconds | k* |")
        print("|---|---|---|---|---|")
        for n in args.sizes:
            for r in time_outputs(n):
                print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.3f} | {r[4]:.6g} |", flush=True)
        return
    if args.cells:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        cells_table()
        return
    thermal.cg = _counting_cg(thermal.cg)  # the steady solves run sintercond.sim.thermal.held_solve
    print("| n | contacts/sphere | width m | coupling | first call (s) | second call (s) | CG iterations | "
          "blocks (MB) | k* |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in args.sizes:
        for r in time_bed(n):
            print(f"| {r[0]} | {r[1]:.2f} | {r[2]} | {r[3]} | {r[4]:.2f} | {r[5]:.2f} | {r[6]} | {r[7]:.1f} | "
                  f"{r[8]:.5g} |", flush=True)


if __name__ == "__main__":
    main()
