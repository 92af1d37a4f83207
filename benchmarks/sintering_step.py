"""Sintering in the simulator: the cost of a step with growing necks, and the error of updating them every N steps.

Usage: python benchmarks/sintering_step.py [--sizes 10648,97336] [--steps 100] [--no-write]

* Step cost: 100 steps of a simple cubic lattice of 40 um Ti6Al4V spheres (a small initial overlap, so necks
  exist), jitted ``rollout``, on the same state: conduction with a table (the fast thermal path), conduction
  with lifted conductances (the law applied once per rollout), and sintering with the necks grown every step
  and every 10 steps (the grain-boundary law; the conductance law applied to the grown necks at every step),
  and every 10 steps with many-body shrinkage (the force balance solved by conjugate gradients at each update,
  the particles moved; on the lattice, whose contacts can all approach freely, it costs its solve's iterations).
  The same with the elastic mechanics on (dynamic contacts, the necks on the half pair list): the coupled step
  without sintering, and with the necks grown every 10 steps, independently and many-body.
  The obvious alternative to the in-scan update, a host loop that grows the necks between jitted conduction
  chunks, pays a dispatch and a copy per update and cannot be differentiated through: not timed.
* Error against N: the neck of each contact of a pulsed three-sphere chain (the test's history, far from
  isothermal) after 0.24 s, updated every N steps, against N = 1 at the same thermal step.

Prints the tables and rewrites the ``sintering_step`` section of benchmarks/RESULTS.md.
"""

import argparse
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
from _common import best_time, command_line, markdown_table, write_section

from sintercond import simulate
from sintercond.sim import neck_growth
from sintercond.state import particle_state

KINETICS = {"A": 1.2e-20, "activation_energy": 37.0}  # docs/laws.md: about Rizza & Galati's 80-58.6 couple
FAST = {"A": 1e-16, "activation_energy": 100.0}  # the tests' chain: necks of a few um in a fraction of a second


def lattice(n, dtype=np.float64):
    side = round(n ** (1 / 3))
    r, spacing = 40e-6, 79.6e-6
    grid = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1).reshape(-1, 3)
    centres = (grid * spacing + r).astype(dtype)
    radii = np.full(len(centres), r, dtype)
    temperature = np.linspace(845.0, 1273.0, len(centres)).astype(dtype)
    return centres, radii, temperature


def models(n):
    centres, radii, temperature = lattice(n)
    particles = particle_state(centres, radii, temperature, 4430.0)
    out = {}
    specs = {
        "conduction, table": simulate.Physics.create(law="rojek"),
        "conduction, lifted": simulate.Physics.create(law="rojek", conductance="lifted"),
        "sintering, every step": simulate.Physics.create(law="rojek", conductance="lifted",
                                                         sintering=neck_growth.Sintering(every=1)),
        "sintering, every 10 steps": simulate.Physics.create(law="rojek", conductance="lifted",
                                                             sintering=neck_growth.Sintering(every=10)),
        "sintering, every 10 steps, many-body": simulate.Physics.create(
            law="rojek", conductance="lifted", sintering=neck_growth.Sintering(every=10, shrinkage="many_body")),
    }
    for name, physics in specs.items():
        if physics.conduction.conductance == "table":
            from sintercond.contacts.network import contact_table
            contacts = simulate.table_contacts(contact_table(centres, radii, 1.0, "rojek"))
        else:
            contacts = simulate.lifted_contacts(physics, centres, radii)
        supports = None
        if physics.sintering is not None and physics.sintering.shrinkage == "many_body":
            supports = np.zeros((len(radii), 3), bool)
            supports[:, 2] = centres[:, 2] == centres[:, 2].min()  # the bottom layer on a plate
        necks = None if physics.sintering is None else neck_growth.neck_state(
            contacts, particles.temperature, supports=supports, positions=None if supports is None else centres)
        state = simulate.init_state(particles, contacts, 2e-4, sintering=necks)
        params = simulate.Params(conductivity=[7.0], specific_heat=[560.0],
                                 sintering=None if necks is None else dict(KINETICS))
        out[name] = (simulate.simulator(physics), state, params)
    return out


def coupled_models(n):
    """The coupled thermo-mechanical step on the same lattice (its small overlaps taken as necks, so nothing is
    loaded and 100 steps of 10 ns move nothing): without sintering, and with necks on the half pair list grown
    every 10 steps, independently and many-body (the bottom layer held)."""
    from sintercond.sim import mechanics

    centres, radii, temperature = lattice(n)
    particles = particle_state(centres, radii, temperature, 4430.0)
    out = {}
    for name, spec in (("coupled (mechanics)", None),
                       ("coupled, sintering every 10 steps", neck_growth.Sintering(every=10)),
                       ("coupled, sintering every 10 steps, many-body",
                        neck_growth.Sintering(every=10, shrinkage="many_body"))):
        physics = simulate.Physics.create(law="rojek", neck_model="volume_conserving", conductance="lifted",
                                          contacts="dynamic", mechanics=True, gravity=(0.0, 0.0, 0.0),
                                          sintering=spec)
        contacts, fns = simulate.dynamic_contacts(centres, radii, 4e-6)
        motion = mechanics.mechanical_state(physics.mechanics, centres, contacts)
        necks = None
        if spec is not None:
            motion = neck_growth.with_pair_necks(motion, contacts, centres, radii, "overlap")
            supports = None
            if spec.shrinkage == "many_body":
                supports = np.zeros((len(radii), 3), bool)
                supports[:, 2] = centres[:, 2] == centres[:, 2].min()
            necks = neck_growth.neck_state(contacts, particles.temperature, supports=supports, positions=centres)
        state = simulate.init_state(particles, contacts, 1e-8, mechanics=motion, sintering=necks)
        mp = mechanics.MechanicalParams(E0=110e9, nu=0.34, xi_con=1.0, xi_fric=1.0, xi_rol=0.0, mu=0.0, mu_r=0.0,
                                        theta_star=1000.0, rate=1.0, E_min=0.0)
        params = simulate.Params(conductivity=[7.0], specific_heat=[560.0], mechanics=mp,
                                 sintering=None if spec is None else dict(KINETICS))
        out[name] = (simulate.simulator(physics, fns), state, params)
    return out


def step_costs(sizes, steps):
    rows = []
    for n in sizes:
        base = None
        for name, (sim, state, params) in {**models(n), **coupled_models(n)}.items():
            run = jax.jit(lambda s, p, sim=sim: simulate.rollout(sim, s, p, steps, simulate.SaveAt(steps, lambda s: ()),
                                                                 checkpoint=False)[0])
            seconds = best_time(run, state, params, repeats=5, max_seconds=20.0)
            base = seconds if base is None else base
            rows.append([f"{len(state.particles.radii):,}", name, f"{seconds * 1e3 / steps:.3g}", f"{seconds / base:.1f}"])
    return rows


def chain_necks(spec):
    """The two necks (m) of the pulsed three-sphere chain (tests/test_neck_growth.py) after 240 steps of 1 ms."""
    radii = np.array([40e-6, 30e-6, 35e-6])
    x = np.zeros((3, 3))
    x[1:, 0] = np.cumsum(radii[:-1] + radii[1:])
    pulse = simulate.PulseParams(power=jnp.array([2e-3, 0.0, 0.0]), duration=0.15)
    particles = particle_state(x, radii, np.array([1000.0, 1100.0, 1050.0]), 4430.0)
    physics = simulate.Physics.create(law="rojek", conductance="lifted", pulse=True, sintering=spec)
    contacts = simulate.lifted_contacts(physics, x, radii)
    state = simulate.init_state(particles, contacts, 1e-3, sintering=neck_growth.neck_state(contacts,
                                                                                          particles.temperature))
    params = simulate.Params(conductivity=[7.0], specific_heat=[560.0], sintering=dict(FAST), pulse=pulse)
    sim = simulate.simulator(physics)
    end, _ = jax.jit(lambda s, p: simulate.rollout(sim, s, p, 240))(state, params)
    return np.asarray(end.contacts.table_neck[[0, 1], [0, 1]])


def every_error():
    """Rows of the error against N (every) and against the integration's nodes and Newton steps."""
    reference = chain_necks(neck_growth.Sintering(every=1, quadrature_nodes=8, newton_iterations=4))
    rows = []
    for every in (1, 2, 5, 10, 20, 40):
        for nodes, newton in ((4, 2), (3, 1), (2, 1)):
            if every != 1 and (nodes, newton) != (4, 2):
                continue
            a = chain_necks(neck_growth.Sintering(every=every, quadrature_nodes=nodes, newton_iterations=newton))
            error = np.max(np.abs(a / reference - 1))
            rows.append([every, f"{nodes}, {newton}", f"{error:.1e}"])
    return rows


def scene_time(runs):
    """The whole process of ``sintercond run ti6al4v_preheating_bed`` (build, compile, 9.5 s of preheating,
    outputs), as built in and with ``sintering.shrinkage = "many_body"``: wall seconds of each run and the steps
    it took."""
    import json
    import subprocess
    import sys
    import tempfile
    import time

    builtin = pathlib.Path(__file__).resolve().parents[1] / "sintercond" / "data" / "scenes"

    lines = []
    for shrinkage in ("independent", "many_body"):
        times = []
        for _ in range(runs):
            with tempfile.TemporaryDirectory() as out:
                scene = pathlib.Path(out) / "scene.toml"
                text = (builtin / "ti6al4v_preheating_bed.toml").read_text()
                scene.write_text(text.replace('law = "grain_boundary"\n',
                                              f'law = "grain_boundary"\nshrinkage = "{shrinkage}"\n', 1))
                start = time.perf_counter()
                subprocess.run([sys.executable, "-m", "sintercond.cli", "run", str(scene), "--out", out + "/run",
                                "--no-progress"], check=True, capture_output=True)
                times.append(time.perf_counter() - start)
                summary = json.loads((pathlib.Path(out) / "run" / "summary.json").read_text())
        lines.append(f"{shrinkage}: " + ", ".join(f"{t:.1f} s" for t in times)
                     + f" (stepping {summary['wall_s']:.1f} s of the last; final shrinkage {summary['shrinkage']:.6g})")
    return (f"The whole process of `sintercond run ti6al4v_preheating_bed` ({summary['particles']} particles, "
            f"{summary['steps']:,} steps to 9.5 s, outputs and pictures) with sintering.shrinkage = "
            + "; ".join(lines) + ".")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10648,97336")
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--scene-runs", type=int, default=2, help="whole-process runs of the preheating scene")
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    cost = markdown_table(["particles", "step", "ms per step", "/ table step"],
                          step_costs([int(s) for s in args.sizes.split(",")], args.steps))
    error = markdown_table(["N", "nodes, Newton steps", "largest relative error"], every_error())
    whole = scene_time(args.scene_runs) if args.scene_runs else ""
    print(cost, "\n\n", error, "\n\n", whole)
    if not args.no_write:
        write_section("sintering_step", command_line(), "## Sintering step: cost against conduction, error against N\n\n"
                      f"{args.steps} steps of a simple cubic lattice, jitted, minimum of 5. Sintering: necks grown "
                      "per update (4 nodes, 2 Newton steps), the conductance law at every step; many-body: the "
                      "balance solved per update by preconditioned CG (tol 1e-8), the bottom layer held. Coupled: "
                      "the thermo-mechanical step (dynamic contacts, Hertz, dt 10 ns), the necks on its half pair "
                      "list.\n\n"
                      + cost + "\n\nError of a pulsed three-sphere chain's necks after 0.24 s (dt 1 ms), updated "
                      "every N steps, against N = 1 with 8 nodes and 4 Newton steps:\n\n" + error + "\n\n" + whole)


if __name__ == "__main__":
    main()
