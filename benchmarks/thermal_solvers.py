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
from _common import best_time, markdown_table, new_figure, number, save_figure, write_section
from thermal_step import jittered_packing

from sintercond.contacts import network
from sintercond.sim import thermal
from sintercond.simulate import simulate_table
from sintercond.sim import steady
from sintercond.laws.conductance import pair_conductance


def plot_transient(transient_rows):
    """Run time against max error for the explicit and implicit integrators, points labelled by dt / stable step."""
    fig = new_figure()
    ax = fig.subplots()
    for k, method in enumerate(("explicit", "implicit")):
        mine = [r for r in transient_rows if r[0] == method]
        times, errors = [number(r[4]) for r in mine], [max(number(r[3]), 1e-17) for r in mine]
        ax.plot(times, errors, "o-", color=f"C{k}", label=f"{method} Euler" + (" (CG per step)" if k else ""))
        for r, x, y in zip(mine, times, errors):
            ax.annotate(f"dt = {r[1]} x stable", (x, y), textcoords="offset points", xytext=(4, 3), fontsize=7)
    ax.set(xscale="log", yscale="log", xlabel="run time to t_end [ms]", ylabel="max error against the exact solution [K]",
           title="Transient conduction: time step and integrator against error")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return save_figure("thermal_solvers", fig, "Transient conduction: run time against error per time step and integrator")


def transient_error_table():
    centres, radii = jittered_packing(10**3)
    table = network.contact_table(centres, radii, 7.0)
    n = len(radii)
    capacity = np.asarray(4 / 3 * np.pi * radii**3 * 4430 * 560)
    x = centres[:, 0]
    hot, cold = x < x.min() + 0.1e-4, x > x.max() - 0.1e-4
    fixed = hot | cold
    held = np.where(hot, 1000.0, 300.0)
    # dense Laplacian, free block, exact solution T_f(t) = T_ss + exp(-C^-1 L_ff t)(T0 - T_ss)
    lap = np.zeros((n, n))
    nbr, k = np.asarray(table.neighbors), np.asarray(table.conductance)
    for i in range(n):
        for jj, kk in zip(nbr[i], k[i]):
            if jj != i:
                lap[i, jj] -= kk
                lap[i, i] += kk
    free = ~fixed
    l_ff = lap[np.ix_(free, free)]
    t_ss = np.linalg.solve(l_ff, -lap[np.ix_(free, fixed)] @ held[fixed])
    c_half = np.sqrt(capacity[free])
    eigval, eigvec = np.linalg.eigh(l_ff / c_half[:, None] / c_half[None, :])
    t0 = np.where(fixed, held, 300.0)
    t_end = 3.0 / eigval[0]

    def exact(t):
        coefficient = eigvec.T @ (c_half * (t0[free] - t_ss))
        return t_ss + (eigvec @ (np.exp(-eigval * t) * coefficient)) / c_half

    reference = exact(t_end)
    limit = float(thermal.table_time_step(jnp.asarray(capacity), table))
    rows = []
    for method, factors in (("explicit", (0.1, 0.3, 0.9)), ("implicit", (1.0, 10.0, 100.0))):
        for factor in factors:
            steps = max(1, int(round(t_end / (factor * limit))))
            dt = t_end / steps
            run = jax.jit(lambda t, dt=dt, steps=steps, method=method: simulate_table(
                t, table, jnp.asarray(capacity), dt, n_steps=steps, save_every=steps,
                fixed_mask=jnp.asarray(fixed), fixed_temperature=jnp.asarray(held), method=method)[0])
            result = np.asarray(run(jnp.asarray(t0)))
            seconds = best_time(run, jnp.asarray(t0), repeats=5)
            rows.append((method, f"{dt / limit:.2f}", f"{steps:,}", f"{np.max(np.abs(result[free] - reference)):.1e}",
                         f"{seconds * 1e3:.1f}"))
            print(*rows[-1], sep="\t", flush=True)
    return rows


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
    reference = steady.steady_state(table, fixed, held, tol=1e-15)
    target = 1e-6 * 700.0
    limit = float(thermal.table_time_step(capacity, table))

    rows = []
    solve = jax.jit(lambda: steady.steady_state(table, fixed, held, tol=1e-10))
    t_steady = best_time(solve, repeats=5)
    rows.append(("steady state (CG)", "-", "1 solve", f"{float(jnp.max(jnp.abs(solve() - reference))):.1e}",
                 f"{t_steady:.3f}"))
    for name, method, dt, chunk in (("explicit Euler", "explicit", 0.9 * limit, 2000),
                                    ("backward Euler (CG)", "implicit", 100 * limit, 20)):
        advance = jax.jit(lambda t, dt=dt, method=method, chunk=chunk: simulate_table(
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
    static = jax.jit(lambda t: simulate_table(t, table, capacity, dt, n_steps=steps, save_every=steps)[0])
    np.testing.assert_allclose(np.asarray(general(start)), np.asarray(static(start)), rtol=1e-12)
    general = jax.jit(general_loop)
    t_general = best_time(general, start, velocity)
    t_static = best_time(static, start)
    skip_rows = [("static: conductances once, one gather-sum per step", f"{t_static / steps * 1e6:.1f}"),
                 ("general: necks and conductances from positions every step", f"{t_general / steps * 1e6:.1f}")]
    transient_rows = transient_error_table()
    body = (
        "## Thermal solvers: time to a steady field, and skipping unused physics\n\n"
        f"Jittered sintered SC lattice, {n:,} particles, faces held at 1000 K and 300 K; target max error "
        f"{target:.1e} K (1e-6 of the span) against a tight steady solve.\n\n"
        + markdown_table(("solver", "step", "work", "max error (K)", "time (s)"), rows)
        + "\n\nPer-step cost on the same network (float64):\n\n"
        + markdown_table(("step", "us / step"), skip_rows)
        + f"\n\nSpeed-up of the static step: {t_general / t_static:.1f}x.\n\n"
        "Transient accuracy against the exact solution (eigen-decomposition of the 10^3-particle network, "
        "faces held, t_end = 3 slowest decay times): step size against max error and time.\n\n"
        + markdown_table(("integrator", "dt / stable step", "steps", "max error (K)", "time (ms)"), transient_rows)
        + "\n\n" + plot_transient(transient_rows)
    )
    print(body)
    write_section("thermal_solvers", "python benchmarks/thermal_solvers.py", body)


if __name__ == "__main__":
    main()
