"""Reverse mode through the coupled step with and without the half list's incidence table (issue 12, A/B).

Usage: python benchmarks/incidence_gradient.py bed STEPS REPEATS     (the softening benchmark's 62-sphere bed)
       python benchmarks/incidence_gradient.py block N STEPS REPEATS (coupled_step.py's block, no checkpoints)

``scatter``: ``neighbors.INCIDENCE = False`` (the pair gathers' reverse mode is JAX's scatter-add);
``incidence``: the default (their reverse mode is ``neighbors.incidence_sum``). Both compiled with
``mechanics.compiler_options``, run alternately in one process; prints the min wall and process-CPU times
of the gradient and of the forward, and the values and gradients of both. Writes nothing.
"""

import dataclasses
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from sintercond import mechanics, neighbors, simulate


def bed_loss(steps):
    from fitting import softening as sf

    dt = float(sf.bed_experiment(lateral_size=0.008, height=0.006, t_end=0.01, save_every=10,
                                 settle_time=0.3).state.dt)
    ex = sf.bed_experiment(lateral_size=0.008, height=0.006, t_end=steps * dt, save_every=max(1, steps // 100),
                           settle_time=0.3)
    names = ("E0", "theta_star", "rate")
    nominal = ex.nominal()
    sigma = np.asarray((0.5, 0.5, 0.5, 2e-8))
    target = ex.readings(nominal) + sigma

    def make(state):
        def loss(logs):
            params = ex.params_with(dict(zip(names, jnp.exp(logs))))
            saved = simulate.rollout(ex.sim, state, params, ex.n_steps, simulate.SaveAt(ex.save_every, ex.observe))[1]
            return 0.5 * jnp.sum(((saved - target) / sigma) ** 2)
        return loss

    def setup(flag):
        state = ex.state
        if not flag:
            state = dataclasses.replace(state, contacts=dataclasses.replace(
                state.contacts, pairs=dataclasses.replace(state.contacts.pairs, incidence=None)))
        return make(state), jnp.log(jnp.asarray([nominal[k] for k in names])), ex.sim.physics

    return setup


def block_loss(n, steps):
    sys.path.insert(0, "benchmarks")
    import coupled_step as cs

    centres, radii, temperature = cs.block(n)

    def setup(flag):
        sim, _, state, params, _ = cs.sintercond_setup(centres, radii, temperature, "float64")

        def loss(e0):
            p = dataclasses.replace(params, mechanics=dataclasses.replace(params.mechanics, E0=e0))
            final = simulate.rollout(sim, state, p, steps, simulate.SaveAt(steps, lambda s: ()), checkpoint=False)[0]
            return jnp.mean(final.particles.temperature) + jnp.mean(final.particles.positions[:, 2])
        return loss, params.mechanics.E0, sim.physics

    return setup


def main():
    kind = sys.argv[1]
    setup = bed_loss(int(sys.argv[2])) if kind == "bed" else block_loss(int(sys.argv[2]), int(sys.argv[3]))
    repeats = int(sys.argv[-1])
    runs = {}
    try:
        for name, flag in (("scatter", False), ("incidence", True)):
            neighbors.INCIDENCE = flag  # read when lists are built and when the programs are traced
            loss, x, physics = setup(flag)
            opts = mechanics.compiler_options(physics)
            g = jax.jit(jax.value_and_grad(loss)).lower(x).compile(compiler_options=opts)
            f = jax.jit(loss).lower(x).compile(compiler_options=opts)
            runs[name] = (g, f, x, jax.block_until_ready(g(x)))
    finally:
        neighbors.INCIDENCE = True
    best = {(k, w, c): np.inf for k in runs for w in "gf" for c in ("wall", "cpu")}
    for _ in range(repeats):
        for k, (g, f, x, _) in runs.items():
            for w, fn in (("g", g), ("f", f)):
                t, c = time.perf_counter(), time.process_time()
                jax.block_until_ready(fn(x))
                best[k, w, "wall"] = min(best[k, w, "wall"], time.perf_counter() - t)
                best[k, w, "cpu"] = min(best[k, w, "cpu"], time.process_time() - c)
    for k, run in runs.items():
        print(f"{k}: gradient {best[k, 'g', 'wall']:.3f} s (CPU {best[k, 'g', 'cpu']:.3f}), forward "
              f"{best[k, 'f', 'wall']:.3f} s (CPU {best[k, 'f', 'cpu']:.3f}), ratio "
              f"{best[k, 'g', 'wall'] / best[k, 'f', 'wall']:.2f}; value {float(run[3][0])!r}, gradient "
              f"{np.asarray(run[3][1]).tolist()}")


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main()
