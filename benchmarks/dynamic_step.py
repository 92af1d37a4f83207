"""Conduction on moving contacts: time per step with a skinned neighbour list against a rebuild at every step.

Usage: python benchmarks/dynamic_step.py [--sizes 10000] [--steps 200] [--laws rojek batchelor_obrien]
                                         [--before REV]

A jittered sintered simple-cubic packing (spacing a, radii 0.53 a +- 2 %)
shrinking affinely at a strain rate that moves the outermost particles about
0.2 a over the run (a sintering compact). The simulator with
``Physics(contacts="dynamic", conduction=Conduction(conductance="lifted"))``: conductances from the
current overlaps at every step (Rojek's law with the volume-conserving neck,
or Batchelor-O'Brien with the Hertz neck), once per pair of the half pair
list, in jitted chunks of 100 steps compiled once (as `sintercond.rollout.advance`
runs them; best of 3 runs after a warm-up). Variants: skin 0 (jax-md rebuilds the Dense list, and the half list
with it, at every step: what the old `moving.py` did) and a skin of 0.1 a
(rebuilt once a particle moved 0.05 a). Times exclude compilation; the
final temperatures of both must agree (no contact lost).

Share of rebuild + remap in the skinned step: the rebuilds of the skinned
run (counted) times the cost of one (a rebuild-every-step step minus a step
that never rebuilds, the same packing held still), over the skinned run's
time. Pairs per particle: the half list's pairs (within r_i + r_j + skin)
and the Dense list's candidates (within 2 r_max + skin, each pair on both
rows) per particle at the start.

List rebuild: one jitted ``update`` of the skinned list that must rebuild
(its reference positions marked stale), the sorted cell list
(`neighbors.neighbor_list`) and jax-md's own Dense list
(`neighbors.jax_md_neighbor_list`, what the step ran on before) alternated
in this process, compiled ahead, best of 5; both give the same pairs
(checked). Half list + remap: `half_pairs` from the table and the springs'
`remap_half_pairs` ([capacity, 3]), timed the same way.

``--before REV``: the same timings of an earlier revision of the package
(``git archive REV``, this script's timing in a subprocess with that package
on the path), e.g. the Dense both-rows implementation before the half list
(ad65b07).
Prints the table and rewrites its section of benchmarks/RESULTS.md.
"""

import argparse
import dataclasses
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import markdown_table, write_section
from thermal_step import jittered_packing

from sintercond import simulate
from sintercond.contacts import neighbors, pair_list
from sintercond.state import ParticleState

A = 1e-4  # the lattice spacing of thermal_step.jittered_packing (m)
NECKS = {"rojek": None, "batchelor_obrien": "hertz"}


def setup(centres, radii, skin, rate, law):
    n = len(radii)
    physics = simulate.Physics.create(law=law, neck_model=NECKS[law], conductance="lifted", contacts="dynamic",
                                      motion=simulate.affine_shrinkage(centres, rate))
    contacts, fns = simulate.dynamic_contacts(centres, radii, skin, capacity_multiplier=1.5)
    t0 = jnp.asarray(np.random.default_rng(2).uniform(300, 1000, n))
    mass = jnp.asarray(4 / 3 * np.pi * radii**3 * 4430.0)
    particles = ParticleState(jnp.asarray(centres), jnp.asarray(radii), t0, mass, jnp.zeros(n, jnp.int32),
                              jnp.zeros(n, bool), t0)
    params = simulate.Params(conductivity=jnp.array([7.0]), specific_heat=jnp.array([560.0]))
    return simulate.simulator(physics, fns), simulate.init_state(particles, contacts, 2e-6), params, fns


def time_steps(sim, state, params, steps, reallocate, chunk=100, repeats=3):
    """Seconds per step of ``steps`` steps in compiled chunks of ``chunk`` (compiled once, as `rollout.advance` does).

    A run whose lists overflowed is redone from a reallocated start (the lists sized for its end, as the
    host driver does), before timing. Best of ``repeats`` runs after a warm-up (compilation) run;
    returns ``(s/step, final state, start state)``.
    """
    run_chunk = jax.jit(lambda s, p: simulate.rollout(sim, s, p, chunk, simulate.SaveAt(chunk, lambda s: ()),
                                                       checkpoint=False)[0])

    def whole(start):
        s = start
        for _ in range(steps // chunk):
            s = run_chunk(s, params)
        return jax.block_until_ready(s)

    for _ in range(5):
        final = whole(state)
        if not bool(final.overflow):
            break
        state = reallocate(state, final)
    else:
        raise RuntimeError("the neighbour lists keep overflowing: raise capacity_multiplier")
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        whole(state)
        best = min(best, time.perf_counter() - start)
    return best / (steps // chunk * chunk), final, state


def run(centres, radii, skin, steps, rate, law):
    sim, state, params, fns = setup(centres, radii, skin, rate, law)
    return time_steps(sim, state, params, steps, simulate.reallocate_neighbors(fns))


def rebuild_costs(centres, radii, skin, repeats=5):
    """Seconds per list rebuild: ``{"sorted cell list", "jax-md Dense", "half list + remap"}`` (one process)."""
    lo, hi = simulate.list_region(centres, radii)  # simulate.dynamic_contacts' region
    positions, r = jnp.asarray(centres), jnp.asarray(radii)
    runs, tables = {}, {}
    for name, make in (("sorted cell list", neighbors.neighbor_list), ("jax-md Dense", neighbors.jax_md_neighbor_list)):
        fns = make(radii, skin, lo, hi, capacity_multiplier=1.5)
        nbrs = fns.allocate(positions)
        stale = dataclasses.replace(nbrs, reference_position=jnp.full_like(nbrs.reference_position, jnp.inf))
        run = jax.jit(fns.update).lower(positions, stale).compile()
        tables[name] = np.sort(np.asarray(run(positions, stale).idx), axis=1)
        runs[name] = (run, positions, stale)
    if not np.array_equal(*tables.values()):
        raise AssertionError("the sorted cell list and jax-md's list hold different pairs")
    half = pair_list.allocate_half_pairs(tables["sorted cell list"], positions, r, skin, 1.5)

    def half_and_remap(idx, old):
        new = pair_list.half_pairs(idx, positions, r, skin, old.capacity)
        return new, pair_list.remap_half_pairs(old.pairs, new.pairs, jnp.ones((old.capacity, 3)))

    idx = jnp.asarray(tables["sorted cell list"], jnp.int32)
    runs["half list + remap"] = (jax.jit(half_and_remap).lower(idx, half).compile(), idx, half)
    best = dict.fromkeys(runs, float("inf"))
    for _ in range(repeats):
        for name, (run, *args) in runs.items():
            start = time.perf_counter()
            jax.block_until_ready(run(*args))
            best[name] = min(best[name], time.perf_counter() - start)
    return best


def count_rebuilds(centres, radii, skin, steps, rate, law):
    """Rebuilds of the skinned run: changes of the list's reference positions, step by step."""
    sim, state, params, _ = setup(centres, radii, skin, rate, law)
    saveat = simulate.SaveAt(1, lambda s: s.contacts.neighbor_list.reference_position[0])
    _, refs = jax.jit(lambda s, p: simulate.rollout(sim, s, p, steps, saveat, checkpoint=False))(state, params)
    refs = np.concatenate([np.asarray(state.contacts.neighbor_list.reference_position[:1]), np.asarray(refs)])
    return int(np.sum(np.any(refs[1:] != refs[:-1], axis=1)))


def timing_rows(sizes, steps, laws):
    """``(n, law, every, skinned, final_every, final_skin, start)`` per size and law (public API only)."""
    for n in sizes:
        centres, radii = jittered_packing(n)
        extent = float(np.ptp(centres[:, 0]))
        rate = 0.2 * A / (0.5 * extent) / (steps * 2e-6)
        for law in laws:
            every, final_every, _ = run(centres, radii, 0.0, steps, rate, law)
            skinned, final_skin, start = run(centres, radii, 0.1 * A, steps, rate, law)
            still, _, _ = run(centres, radii, 0.1 * A, steps, 0.0, law)  # held still: never rebuilds
            yield len(radii), law, every, skinned, still, final_every, final_skin, start, (centres, radii, rate)


def before(rev, sizes, steps):
    """ms/step (rebuild every step, skinned) of revision ``rev``'s package, timed by this script, per size.

    ``git archive rev`` into a temporary directory, then this script's ``--timing-only`` mode in a
    subprocess with that package first on the path (the API it uses is the same there).
    """
    here = Path(__file__).resolve().parent
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(["git", "-C", str(here.parent), "archive", rev], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        out = subprocess.run([sys.executable, str(here / "dynamic_step.py"), "--timing-only", "--sizes",
                              *map(str, sizes), "--steps", str(steps)], env={**os.environ, "PYTHONPATH": tmp},
                             check=True, capture_output=True, text=True).stdout
    rows = [line.split("\t") for line in out.splitlines() if line.startswith("timing\t")]
    return {int(r[1]): (float(r[3]), float(r[4]), float(r[5])) for r in rows}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--laws", nargs="+", default=["rojek"], choices=sorted(NECKS))
    parser.add_argument("--before", default=None, help="an earlier git revision to time the same way (rojek law)")
    parser.add_argument("--timing-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.timing_only:  # for --before: ms/step with whatever sintercond is on the path
        import sintercond

        print("package", sintercond.__file__, file=sys.stderr)
        for m, law, every, skinned, still, *_ in timing_rows(args.sizes, args.steps, ["rojek"]):
            print("timing", m, law, 1e3 * every, 1e3 * skinned, 1e3 * still, sep="\t", flush=True)
        return
    old = before(args.before, args.sizes, args.steps) if args.before else {}
    rows, costs = [], {}
    for m, law, every, skinned, still, final_every, final_skin, start, (centres, radii, rate) in timing_rows(
            args.sizes, args.steps, args.laws):
        rebuilds = count_rebuilds(centres, radii, 0.1 * A, args.steps, rate, law)
        if m not in costs:
            costs[m] = rebuild_costs(centres, radii, 0.1 * A)
        ours, theirs, half_remap = costs[m].values()
        share = rebuilds * max(every - still, 0.0) / (args.steps * skinned)
        diff = float(jnp.max(jnp.abs(final_every.particles.temperature - final_skin.particles.temperature)))
        half = int(start.contacts.pairs.demand) / m
        dense = int(jnp.sum(start.contacts.neighbors < m)) / m
        was = old.get(m) if law == "rojek" else None
        rows.append((f"{m:,}", law, f"{1e3 * every:.3f}", f"{1e3 * skinned:.3f}", f"{1e3 * still:.3f}",
                     f"{every / skinned:.1f}x",
                     "-" if was is None else f"{was[1]:.3f} / {was[0]:.3f} / {was[2]:.3f}",
                     "-" if was is None else f"{was[1] / (1e3 * skinned):.1f}x / {was[2] / (1e3 * still):.1f}x",
                     "-" if was is None else f"{was[0] / (1e3 * skinned):.1f}x", f"{rebuilds}",
                     f"{100 * share:.1f} %", f"{1e3 * ours:.2f} / {1e3 * theirs:.2f} ({theirs / ours:.1f}x)",
                     f"{1e3 * half_remap:.2f}", f"{half:.2f} / {dense:.2f}", f"{diff:.1e}"))
        print(*rows[-1], sep="\t", flush=True)
    body = (
        f"Jittered sintered SC packing shrinking affinely (outer particles move ~0.2 a in {args.steps} steps), "
        "float64, conductances from the current overlaps at every step, once per pair of the half pair list "
        "(Rojek: volume-conserving neck; Batchelor-O'Brien: Hertz neck), jitted chunks of 100 steps compiled "
        "once; ms per step excluding compilation (best of 3). Held still: the skinned setup without motion "
        "(never rebuilds: the step's own kernels). Before: the same timings of revision "
        f"{args.before or '(not run)'}, skinned / every step / held still. Rebuild share: rebuilds x "
        "(every-step step - held-still step) / skinned run time (the target of issues 9 and 11: < 10 %). List "
        "rebuild: one jitted rebuild of the skinned list, the sorted cell list the step runs on against jax-md's "
        "Dense list (same pairs, checked), alternated in one process, best of 5; half list + remap: the half "
        "pair list built from the table and the springs carried to it, per rebuild. Pairs per particle: half "
        "list (within r_i + r_j + skin) / Dense table (within 2 r_max + skin, both rows). Figures taken while "
        f"other jobs shared the 2 cores (load average {os.getloadavg()[0]:.1f} at the end).\n\n"
        + markdown_table(("particles", "law", "rebuild every step (skin 0) ms/step", "skin 0.1 a ms/step",
                          "held still ms/step", "speed-up (every step / skinned)",
                          "before: skinned / every step / held still ms/step", "vs before: skinned / held still",
                          "before every step / skinned (issue 9 target 10x)", "rebuilds (skinned)",
                          "rebuild + remap share", "list rebuild ms: sorted cell list / jax-md Dense",
                          "half list + remap ms", "pairs per particle (half / Dense)", "max |T_skin - T_every| (K)"),
                         rows)
    )
    print(body)
    write_section("dynamic_step", "python benchmarks/dynamic_step.py " + " ".join(sys.argv[1:]), body)


if __name__ == "__main__":
    main()
