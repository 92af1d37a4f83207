"""Example 5.1 of Quintana-Ruiz & Campello (2020) over the paper's 40 s, with and without softening.

Prints the settled contact force and overlap against m g and Hertz, the
contact-area gain from softening, the temperature at 8 s (absolute and rise
above 300 K), and the equilibrium times at several tolerances (the paper does
not state its own; it reports ~12 s with softening, ~18 s without).

    python benchmarks/example_5_1.py
"""

import math
import time

import jax
import jax.numpy as jnp
import numpy as np

from sintercond import examples, simulate

EVERY = 500  # saves every 0.01 s


def main():
    obs = lambda s: jnp.stack([s.particles.temperature[0], s.particles.radii[0] - s.particles.positions[0, 2]])  # noqa: E731
    runs = {}
    for softening in (False, True):
        sim, state, params, n = examples.example_5_1(softening=softening)
        start = time.perf_counter()
        saved = jax.jit(lambda s, p: simulate.rollout(sim, s, p, n, simulate.SaveAt(EVERY, obs), checkpoint=False))(
            state, params)[1]
        runs[softening] = np.asarray(saved)
        print(f"softening={softening}: {n} steps in {time.perf_counter() - start:.1f} s (compile included)")
    m = float(state.particles.mass[0])
    weight = m * 9.81
    t = (np.arange(len(runs[True])) + 1) * EVERY * 2e-5
    r, nu = 1e-3, 0.3
    for softening, run in runs.items():
        delta, temp = run[-1, 1], run[-1, 0]
        e = 1e6 * math.exp(min(0.0, 1 - temp / 400)) if softening else 1e6
        force = 4 / 3 * math.sqrt(r) * e / (1 - nu**2) * delta**1.5
        print(f"softening={softening}: final T {temp:.4f} K, overlap {delta:.6e} m "
              f"(Hertz under m g: {examples.static_overlap(weight, r, e, nu):.6e}), contact force {force:.6e} N "
              f"(m g = {weight:.6e} N)")
    print(f"contact area gain pi r delta, softened / not - 1: {runs[True][-1, 1] / runs[False][-1, 1] - 1:.4f}")
    k8 = int(np.argmin(np.abs(t - 8.0)))
    a, b = runs[True][k8, 0], runs[False][k8, 0]
    print(f"T(8 s): {a:.2f} K softened, {b:.2f} K not: +{a / b - 1:.2%} absolute, +{(a - 300) / (b - 300) - 1:.2%} on the rise")
    for tol in (4.0, 2.0, 1.0, 0.1):
        eq = {s: t[np.argmax(700.0 - runs[s][:, 0] < tol)] for s in runs}
        print(f"equilibrium (within {tol} K of 700 K): {eq[True]:.2f} s softened, {eq[False]:.2f} s not")


if __name__ == "__main__":
    main()
