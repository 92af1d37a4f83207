"""Particle-steps per second of the static conduction step: JAX (padded table) against SciPy CSR.

Usage: python benchmarks/thermal_step.py [--sizes 10000 100000 1000000]

A jittered, sintered simple-cubic packing (spacing a, radii 0.53 a +- 2 %,
positions +- 2 % of a; ~6 contacts per particle), float64, explicit Euler
``T += dt / C * (sum_j K_ij T_j - (sum_j K_ij) T_i)``. JAX runs 200 steps in
one ``lax.scan`` (sintercond.simulate.simulate_table); SciPy runs the same update
with a CSR matrix of the same network in a Python loop. Both on the same
particle order: random, then Morton-sorted. Prints the table and rewrites
its section of benchmarks/RESULTS.md.
"""

import argparse
import os
import resource
import time

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from _common import markdown_table, new_figure, number, save_figure, write_section

from sintercond.contacts import network
from sintercond.sim import thermal
from sintercond.simulate import simulate_table

STEPS = 200


def jittered_packing(n, seed=0):
    side = int(round(n ** (1 / 3)))
    a = 1e-4
    rng = np.random.default_rng(seed)
    grid = np.array(np.meshgrid(*[np.arange(side)] * 3, indexing="ij")).reshape(3, -1).T * a
    centres = grid + rng.uniform(-0.02, 0.02, grid.shape) * a
    radii = 0.53 * a * (1 + rng.uniform(-0.02, 0.02, len(grid)))
    return centres, radii


def previous_step_loop(temperature, neighbors, conductance, capacity, dt):
    """The conduction loop as it was before the simulator redesign (commit 43fe49a): the reference."""
    def step(t):
        return t + dt * -jnp.sum(conductance * (t[:, None] - t[neighbors]), axis=1) / capacity

    def chunk(t, _):
        return jax.lax.fori_loop(0, STEPS, lambda m, x: step(x), t), None

    return jax.lax.scan(chunk, temperature, None, length=1)[0]


def best_alternating(functions, argument, repeats):
    """Best wall time of each function, timed alternately (this VM's speed drifts between minutes)."""
    for f in functions:
        jax.block_until_ready(f(argument))
    best = [np.inf] * len(functions)
    for _ in range(repeats):
        for k, f in enumerate(functions):
            s = time.perf_counter()
            jax.block_until_ready(f(argument))
            best[k] = min(best[k], time.perf_counter() - s)
    return best


def load_line(load_start):
    """The machine's 1-minute load average at the start and end of the run (timings are clean only below the core count)."""
    return (f"Load average (1 min) at the start / end of the run: {load_start:.1f} / {os.getloadavg()[0]:.1f} on "
            f"{os.cpu_count()} cores (above the core count other jobs shared the cores: timings not clean).")


def plot(rows):
    """Particle-steps per second against the particle count: JAX and SciPy CSR, random and Morton order."""
    fig = new_figure()
    ax = fig.subplots()
    for k, order in enumerate(("Morton", "random")):
        mine = [r for r in rows if r[1] == order]
        n = [number(r[0]) for r in mine]
        ax.plot(n, [number(r[2]) for r in mine], "o-", color=f"C{k}", label=f"sintercond (JAX), {order} order")
        ax.plot(n, [number(r[3]) for r in mine], "^:", color=f"C{k}", label=f"previous step (43fe49a), {order} order")
        ax.plot(n, [number(r[4]) for r in mine], "s--", color=f"C{k}", label=f"SciPy CSR mat-vec, {order} order")
    ax.set(xscale="log", yscale="log", xlabel="particles [-]", ylabel="throughput [particle-steps/s]",
           title="Conduction step: sintercond against SciPy")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return save_figure("thermal_step", fig, "Conduction step throughput against particle count, JAX and SciPy CSR")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    args = parser.parse_args()
    load_start = os.getloadavg()[0]
    rows = []
    for n in args.sizes:
        centres, radii = jittered_packing(n)
        rng = np.random.default_rng(1)
        for order_name in ("random", "Morton"):
            order = rng.permutation(len(radii)) if order_name == "random" else network.morton_order(centres)
            c, r = centres[order], radii[order]
            t0 = time.perf_counter()
            table = network.contact_table(c, r, 7.0)
            build = time.perf_counter() - t0
            capacity = jnp.asarray(4 / 3 * np.pi * r**3 * 4430 * 560)
            dt = float(thermal.table_time_step(capacity, table))
            temperature = jnp.asarray(np.random.default_rng(2).uniform(300, 1000, len(r)))
            run = jax.jit(lambda t: simulate_table(t, table, capacity, dt, n_steps=STEPS, save_every=STEPS)[0])
            old = jax.jit(lambda t: previous_step_loop(t, table.neighbors, table.conductance, capacity, dt))
            t_jax, t_old = best_alternating((run, old), temperature, repeats=7)
            # SciPy CSR of the same network
            nbr, k = np.asarray(table.neighbors), np.asarray(table.conductance)
            rows_i = np.repeat(np.arange(len(r)), nbr.shape[1])
            matrix = sp.csr_matrix((k.ravel(), (rows_i, nbr.ravel())), shape=(len(r), len(r)))
            matrix.eliminate_zeros()
            degree = np.asarray(matrix.sum(axis=1)).ravel()
            factor = dt / np.asarray(capacity)
            t_np = np.asarray(temperature)

            def scipy_run(t):
                for _ in range(STEPS):
                    t = t + factor * (matrix @ t - degree * t)
                return t

            best = np.inf
            for _ in range(5):
                s = time.perf_counter()
                ref = scipy_run(t_np)
                best = min(best, time.perf_counter() - s)
            err = float(np.max(np.abs(np.asarray(run(temperature)) - ref)))
            peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
            rows.append((f"{len(r):,}", order_name, f"{len(r) * STEPS / t_jax:.2e}", f"{len(r) * STEPS / t_old:.2e}",
                         f"{len(r) * STEPS / best:.2e}", f"{best / t_jax:.2f}", f"{err:.1e}", f"{build:.2f}",
                         f"{peak_gb:.1f}"))
            print(*rows[-1], sep="\t", flush=True)
    body = (
        "## Thermal step: static conduction, particle-steps per second\n\n"
        "Jittered sintered SC packing (~6 contacts per particle), float64 explicit Euler at the stable step, "
        f"{STEPS} steps: JAX `simulate.simulate_table` (on `simulate.rollout`: padded contact table, checkpointed "
        "`lax.scan`) against the previous commit's step (the plain gather-and-sum in `lax.scan` + `fori_loop`, "
        "as `thermal.simulate` had it before the simulator redesign; timed alternately with the new one in the "
        "same process, best of 7 each) and SciPy CSR mat-vec in a Python loop (best of 5), on the same particle "
        "order. 'build' is `contact_table` (vectorised cell list + conductances).\n\n"
        + markdown_table(("particles", "order", "JAX particle-steps/s", "previous step particle-steps/s",
                          "SciPy CSR particle-steps/s", "JAX / SciPy", "max |T_jax - T_scipy| (K)", "build (s)",
                          "peak RSS so far (GB)"), rows)
        + "\n\n" + load_line(load_start) + "\n\n" + plot(rows)
    )
    write_section("thermal_step", "python benchmarks/thermal_step.py", body)


if __name__ == "__main__":
    main()
