"""The many-body sintering balance: conjugate-gradient iterations per neck update, before and after.

Usage: python benchmarks/balance_iterations.py [--sizes 10648,97336] [--updates 20] [--no-write]

The simple cubic lattice of ``benchmarks/sintering_step.py`` (40 um Ti6Al4V spheres, a temperature ramp of
845-1273 K across it, the bottom layer held on a plate), sintering with ``shrinkage = "many_body"`` every 10
steps of 0.2 ms. Each variant runs ``--updates`` neck updates in one jitted rollout and records each update's
iterations (``NeckState.balance_iterations``) and the rollout's wall time (best of 3, after a compile):

* ``block Jacobi, recent start`` (the library): each particle's 3x3 block inverted, the solve started from the
  Galerkin projection on the last four updates' balances (``Sintering(recent_start=True)``, the default);
* ``block Jacobi, from rest``: the same preconditioner, no start (``recent_start=False``);
* ``diagonal, from rest``: each particle's dashpot sum as the preconditioner, from rest (the iterations of the solve
  as it was before; :func:`jax.scipy.sparse.linalg.cg` takes the same);
* ``as before``: the same, its forces scattered from the pairs instead of gathered on the table's rows: the solve
  as it was before (the obvious alternative), in the library's counted conjugate gradients (the diagonal as a
  3x3 block), not jax.scipy's cg, which takes the same iterations.

Every variant but the last gathers the forces on the table's rows.

The first update has no recent displacements: the table gives the first update's iterations and the mean over the
others. The largest relative difference of the final necks from the library's shows that every variant solves the
same balance to its tolerance (1e-8); the displacements (relative to the largest) agree to it where the
preconditioner is the library's (its blocks' norm chooses the free motions), and differ by the free motions
(rigid and floppy: the simple cubic lattice of central contacts has rows that slide) where it is the diagonal.
"""

import argparse
import contextlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import command_line, markdown_table, write_section
from sintering_step import KINETICS, lattice

from sintercond import simulate
from sintercond.sim import neck_growth
from sintercond.state import particle_state

jax.config.update("jax_enable_x64", True)

EVERY = 10
DT = 2e-4


def _diagonal_blocks(pairs, normal, weights, movable):
    """Each particle's dashpot sum times the identity (the solve's preconditioner before the block one)."""
    n = movable.shape[0]
    trace = jnp.zeros(n, weights.dtype).at[pairs[:, 0]].add(weights).at[pairs[:, 1]].add(weights)
    scale = jnp.where(movable & (trace[:, None] > 0), trace[:, None], 1.0)
    blocks = scale[:, :, None] * jnp.eye(3, dtype=weights.dtype)
    return blocks, jnp.linalg.inv(blocks)


@contextlib.contextmanager
def variant(name):
    """The library's balance with its preconditioner swapped for the variant's (the start: :func:`model`)."""
    saved = neck_growth.balance_blocks, neck_growth.balance_displacements
    if name in ("diagonal, from rest", "as before"):
        neck_growth.balance_blocks = _diagonal_blocks
    if name == "as before":  # the table (the last argument) left out: the forces scattered from the pairs
        balance = saved[1]
        neck_growth.balance_displacements = lambda *args: balance(*args[:-1])
    try:
        yield
    finally:
        neck_growth.balance_blocks, neck_growth.balance_displacements = saved


def model(n, recent_start=True):
    centres, radii, temperature = lattice(n)
    particles = particle_state(centres, radii, temperature, 4430.0)
    physics = simulate.Physics.create(law="rojek", conductance="lifted",
                                      sintering=neck_growth.Sintering(every=EVERY, shrinkage="many_body",
                                                                      recent_start=recent_start))
    contacts = simulate.lifted_contacts(physics, centres, radii)
    supports = np.zeros((len(radii), 3), bool)
    supports[:, 2] = centres[:, 2] == centres[:, 2].min()
    necks = neck_growth.neck_state(contacts, particles.temperature, supports=supports, positions=centres)
    state = simulate.init_state(particles, contacts, DT, sintering=necks)
    params = simulate.Params(conductivity=[7.0], specific_heat=[560.0], sintering=dict(KINETICS))
    return simulate.simulator(physics), state, params


def measure(name, n, updates):
    sim, state, params = model(n, recent_start=name == "block Jacobi, recent start")
    with variant(name):
        run = jax.jit(lambda s, p: simulate.rollout(
            sim, s, p, updates * EVERY, simulate.SaveAt(EVERY, lambda s: s.sintering.balance_iterations),
            checkpoint=False))
        end, iterations = jax.block_until_ready(run(state, params))
        seconds = []
        for _ in range(3):
            start = time.perf_counter()
            jax.block_until_ready(run(state, params))
            seconds.append(time.perf_counter() - start)
    neck_growth.check_stable(end)
    return (np.asarray(iterations), seconds, np.asarray(end.contacts.neck),
            np.asarray(end.particles.positions - state.particles.positions))


def main(argv=None):
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", default="10648,97336")
    parser.add_argument("--updates", type=int, default=20)
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args(argv)
    names = ("block Jacobi, recent start", "block Jacobi, from rest", "diagonal, from rest", "as before")
    rows = []
    for n in map(int, args.sizes.split(",")):
        results = {name: measure(name, n, args.updates) for name in names}
        necks, moved = results[names[0]][2:]
        before = results[names[-1]][0][1:].mean()
        for name, (iterations, seconds, neck, displacement) in results.items():
            rows.append([f"{n:,}", name, int(iterations[0]), f"{iterations[1:].mean():.1f}",
                         f"{before / iterations[1:].mean():.1f}", f"{min(seconds) / args.updates * 1e3:.0f}",
                         f"{max(seconds) / args.updates * 1e3:.0f}", f"{np.abs(neck / necks - 1).max():.1e}",
                         f"{np.abs(displacement - moved).max() / np.abs(moved).max():.1e}"])
            print(rows[-1], flush=True)
    header = ["particles", "solve", "iterations, first update", "iterations per later update",
              "fewer than before", "ms per update (best of 3)", "(worst)",
              "necks against the library's", "displacements against the library's"]
    table = markdown_table(header, rows)
    print(table)
    if not args.no_write:
        body = ("## Many-body balance: iterations per neck update\n\n"
                f"The simple cubic lattice of `sintering_step` (845-1273 K ramp, bottom layer held), "
                f"`shrinkage = \"many_body\"` every {EVERY} steps of {DT * 1e3:g} ms, {args.updates} updates in one "
                "jitted rollout (each update's 10 conduction steps included in the time). Tolerance 1e-8 (relative "
                "residual) for every solve. The necks agree to the tolerance. The block Jacobi solves, started from "
                "the recent balances or from rest, leave out the same free motions (those of least sum_i u_i^T B_i "
                "u_i): their displacements agree to the tolerance; the diagonal preconditioner's differ by the free "
                "motions of its own norm (rigid, and the rows of the lattice that slide). Every variant but "
                "`as before` gathers the forces on the table's rows; `as before` scatters them from the pairs, as the "
                "solve did before (the same iterations as `diagonal, from rest`).\n\n" + table)
        write_section("balance_iterations", command_line(), body)


if __name__ == "__main__":
    sys.exit(main())
