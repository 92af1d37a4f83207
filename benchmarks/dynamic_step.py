"""Conduction on moving contacts: time per step with a skinned neighbour list against a rebuild at every step.

Usage: python benchmarks/dynamic_step.py [--sizes 10000] [--steps 200]

A jittered sintered simple-cubic packing (spacing a, radii 0.53 a +- 2 %)
shrinking affinely at a strain rate that moves the outermost particles about
0.2 a over the run (a sintering compact). The simulator with
``Physics(contacts="dynamic", conductance="lifted")``: conductances from the
current overlaps by the Rojek law with the volume-conserving neck at every
step, through the host driver (`sintercond.run.advance`, chunks of 100
steps). Variants: skin 0 (jax-md rebuilds the list at every step: what the
old `moving.py` did) and a skin of 0.1 a (rebuilt once a particle moved
0.05 a). Times exclude compilation (the second run of the same compiled
chunks); the final temperatures of both must agree (no contact lost).
Prints the table and rewrites its section of benchmarks/RESULTS.md.
"""

import argparse
import time

import jax.numpy as jnp
import numpy as np
from _common import markdown_table, write_section
from thermal_step import jittered_packing

from sintercond import simulate
from sintercond.run import advance
from sintercond.state import ParticleState

A = 1e-4  # the lattice spacing of thermal_step.jittered_packing (m)


def run(centres, radii, skin, steps, rate):
    n = len(radii)
    motion = simulate.affine_shrinkage(centres, rate)
    physics = simulate.Physics(conductance="lifted", contacts="dynamic", motion=motion)
    contacts, fns = simulate.dynamic_contacts(centres, radii, skin, capacity_multiplier=1.5)
    t0 = jnp.asarray(np.random.default_rng(2).uniform(300, 1000, n))
    mass = jnp.asarray(4 / 3 * np.pi * radii**3 * 4430.0)
    particles = ParticleState(jnp.asarray(centres), jnp.asarray(radii), t0, mass, jnp.zeros(n, jnp.int32),
                              jnp.zeros(n, bool), t0)
    params = simulate.Params(conductivity=jnp.array([7.0]), specific_heat=jnp.array([560.0]))
    sim = simulate.simulator(physics, fns)
    dt = 2e-6
    state = simulate.init_state(particles, contacts, dt)
    realloc = simulate.reallocate_neighbors(fns)
    advance(sim, state, params, steps, 100, reallocate=realloc)  # compile
    start = time.perf_counter()
    final, report = advance(sim, state, params, steps, 100, reallocate=realloc)
    final.particles.temperature.block_until_ready()
    return (time.perf_counter() - start) / steps, final, report


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000])
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()
    rows = []
    for n in args.sizes:
        centres, radii = jittered_packing(n)
        extent = float(np.ptp(centres[:, 0]))
        rate = 0.2 * A / (0.5 * extent) / (args.steps * 2e-6)
        every, final_every, _ = run(centres, radii, 0.0, args.steps, rate)
        skinned, final_skin, report = run(centres, radii, 0.1 * A, args.steps, rate)
        diff = float(jnp.max(jnp.abs(final_every.particles.temperature - final_skin.particles.temperature)))
        rows.append((f"{len(radii):,}", f"{1e3 * every:.3f}", f"{1e3 * skinned:.3f}", f"{every / skinned:.1f}x",
                     f"{report['reallocations']}", f"{diff:.1e}"))
        print(*rows[-1], sep="\t", flush=True)
    body = (
        f"Jittered sintered SC packing shrinking affinely (outer particles move ~0.2 a in {args.steps} steps), "
        "float64, Rojek law with the volume-conserving neck recomputed from the current overlaps at every step, "
        "host driver with chunks of 100 steps; ms per step excluding compilation.\n\n"
        + markdown_table(("particles", "rebuild every step (skin 0) ms/step", "skin 0.1 a ms/step", "speed-up",
                          "reallocations (skinned)", "max |T_skin - T_every| (K)"), rows)
    )
    print(body)
    write_section("dynamic_step", "python benchmarks/dynamic_step.py " + " ".join(__import__("sys").argv[1:]), body)


if __name__ == "__main__":
    main()
