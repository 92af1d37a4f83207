"""Time to a result: explicit vs implicit vs steady solver; and what skipping unused physics saves.

Usage: python benchmarks/thermal_solvers.py [--side 20]

Packing: jittered sintered SC lattice (side^3 particles, Morton-ordered),
faces x = min held at 1000 K and x = max at 300 K, float64.

1. Steady field to 1e-6 of the 700 K span: CG steady solve, explicit Euler at
   0.9x the stable step, backward Euler at 100x it (chunks of steps until the
   max error against a tight steady solve is below the target).
2. Per-step cost of the static step (conductances precomputed once) against
   the general step that recomputes every neck and conductance from the
   positions each step (what a moving packing needs), same network.
Prints the tables and rewrites its section of benchmarks/RESULTS.md.
"""

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import best_time, markdown_table, write_section
from thermal_step import jittered_packing

from sintercond import network, thermal
from sintercond.conductance import pair_conductance


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--side", type=int, default=20)
    args = parser.parse_args()
    centres, radii = jittered_packing(args.side**3)
    order = network.morton_order(centres)
    centres, radii = centres[order], radii[order]
    table = network.contact_table(centres, radii, 7.0)
    n = len(radii)
    capacity = jnp.asarray(4 / 3 * np.pi * radii**3 * 4430 * 560)
    x = centres[:, 0]
    hot, cold = jnp.asarray(x < x.min() + 0.1e-4), jnp.asarray(x > x.max() - 0.1e-4)
    fixed = hot | cold
    held = jnp.where(hot, 1000.0, 300.0)
    start = jnp.where(fixed, held, 300.0)
    reference = thermal.steady_state(table, fixed, held, tol=1e-15)
    target = 1e-6 * 700.0
    limit = float(thermal.stable_time_step(capacity, table))

    rows = []
    steady = jax.jit(lambda: thermal.steady_state(table, fixed, held, tol=1e-10))
    t_steady = best_time(steady, repeats=5)
    rows.append(("steady state (CG)", "-", "1 solve", f"{float(jnp.max(jnp.abs(steady() - reference))):.1e}",
                 f"{t_steady:.3f}"))
    for name, method, dt, chunk in (("explicit Euler", "explicit", 0.9 * limit, 2000),
                                    ("backward Euler (CG)", "implicit", 100 * limit, 20)):
        advance = jax.jit(lambda t, dt=dt, method=method, chunk=chunk: thermal.simulate(
            t, table, capacity, dt, n_steps=chunk, save_every=chunk, fixed_mask=fixed, fixed_temperature=held,
            method=method)[0])
        jax.block_until_ready(advance(start))  # compile
        t, steps, t0 = start, 0, time.perf_counter()
        while float(jnp.max(jnp.abs(t - reference))) > target and steps < 2_000_000:
            t = advance(t)
            steps += chunk
        elapsed = time.perf_counter() - t0
        rows.append((name, f"{dt / limit:.1f}x stable", f"{steps:,} steps",
                     f"{float(jnp.max(jnp.abs(t - reference))):.1e}", f"{elapsed:.3f}"))
        print(*rows[-1], sep="\t", flush=True)

    # skip what the scene does not need: precomputed conductances vs recomputed from positions
    nbr = table.neighbors
    real = nbr != jnp.arange(n)[:, None]
    positions = jnp.asarray(centres)
    r = jnp.asarray(radii)
    dt = 0.9 * limit

    def general_step(temperature, positions):
        d = jnp.linalg.norm(positions[:, None, :] - positions[nbr], axis=-1)
        h = jnp.where(real, r[:, None] + r[nbr] - d, -1.0)
        k = jnp.where(real, pair_conductance("rojek", r[:, None], r[nbr], jnp.maximum(h, -1.0), 7.0), 0.0)
        inflow = jnp.sum(k * (temperature[nbr] - temperature[:, None]), axis=1)
        return temperature + dt * inflow / capacity

    steps = 100
    velocity = jnp.zeros_like(positions)  # a runtime zero: positions are a loop carry, nothing can be hoisted

    def general_loop(t, v):
        def body(_, carry):
            temperature, pos = carry
            return general_step(temperature, pos), pos + dt * v
        return jax.lax.fori_loop(0, steps, body, (t, positions))[0]

    general = jax.jit(lambda t: general_loop(t, velocity))
    static = jax.jit(lambda t: thermal.simulate(t, table, capacity, dt, n_steps=steps, save_every=steps)[0])
    np.testing.assert_allclose(np.asarray(general(start)), np.asarray(static(start)), rtol=1e-12)
    general = jax.jit(general_loop)
    t_general = best_time(general, start, velocity)
    t_static = best_time(static, start)
    skip_rows = [("static: conductances once, one gather-sum per step", f"{t_static / steps * 1e6:.1f}"),
                 ("general: necks and conductances from positions every step", f"{t_general / steps * 1e6:.1f}")]
    body = (
        "## Thermal solvers: time to a steady field, and skipping unused physics\n\n"
        f"Jittered sintered SC lattice, {n:,} particles, faces held at 1000 K and 300 K; target max error "
        f"{target:.1e} K (1e-6 of the span) against a tight steady solve.\n\n"
        + markdown_table(("solver", "step", "work", "max error (K)", "time (s)"), rows)
        + "\n\nPer-step cost on the same network (float64):\n\n"
        + markdown_table(("step", "us / step"), skip_rows)
        + f"\n\nSpeed-up of the static step: {t_general / t_static:.1f}x.\n"
    )
    print(body)
    write_section("thermal_solvers", "python benchmarks/thermal_solvers.py", body)


if __name__ == "__main__":
    main()
