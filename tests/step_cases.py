"""The step of every physics combination on small packings: the cases that pin the simulator's behaviour while it
is reshaped (issue 39).

Each case builds ``(sim, state, params)`` (through a scene where a scene can say it, else through the Python API),
takes :data:`STEPS` jitted steps and returns the arrays the step changes. ``tests/test_pinned_step.py`` compares
them with ``tests/data/pinned_steps.npz``, written by this file at the commit before a refactor::

    python tests/step_cases.py            # rewrite tests/data/pinned_steps.npz from this checkout

A refactor that keeps behaviour leaves every array equal to round-off; a change of behaviour rewrites the file in
its own commit, saying why.
"""

from __future__ import annotations

import dataclasses
import pathlib
import sys

import jax
import jax.numpy as jnp
import numpy as np

from sintercond import simulate
from sintercond.sim import mechanics
from sintercond.sim.neck_growth import Sintering
from sintercond.scene import validate_scene
from sintercond.scene.build import build_model
from sintercond.state import ParticleState
from sintercond.laws.walls import PlaneWall

STEPS = 12
PINNED = pathlib.Path(__file__).resolve().parent / "data" / "pinned_steps.npz"

R, SPACING = 40e-6, 78e-6  # sintered simple cubic: overlaps of 2 um


def _scene(**sections):
    base = {
        "packing": {"kind": "simple_cubic", "counts": [3, 3, 3], "spacing": SPACING, "radius": R},
        "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 7.0},
        "conduction": {"law": "rojek"},
        "initial": {"temperature": 300.0},
        "walls": [{"axis": 2, "side": "min", "mode": "held", "temperature": 900.0}],
        "run": {"duration": 1e-3, "output_every": 1, "checkpoint_every": 1},
    }
    for name, value in sections.items():
        if value is None:
            base.pop(name, None)
        elif isinstance(value, dict) and isinstance(base.get(name), dict):
            base[name] = {**base[name], **value}
        else:
            base[name] = value
    return base


BEAM = {"intensity": 1e9, "attenuation": 2e4, "spot_radius": 60e-6, "absorptance": 0.7, "speed": 0.5,
        "path": [[0.0, 0.0], [160e-6, 160e-6]]}
NOZZLE = {"kind": "nozzle", "intensity": 1e9, "max_depth": 100e-6, "spot_radius": 60e-6, "absorptance": 0.7,
          "speed": 0.5, "path": [[0.0, 0.0], [160e-6, 160e-6]]}
TABLE_C = [[200.0, 500.0], [600.0, 560.0], [1200.0, 700.0]]
TABLE_K = [[200.0, 5.0], [600.0, 7.0], [1200.0, 12.0]]
KINETICS = {"A": 1.2e-18, "activation_energy": 37.0}

SCENES = {
    "table_held": _scene(),
    "table_beam_radiation": _scene(beam=BEAM, radiation={"environment_temperature": 300.0, "emissivity": 0.4}),
    "table_nozzle_convection": _scene(beam=NOZZLE, convection={"environment_temperature": 350.0,
                                                                "environment_conductivity": 0.03}),
    "lifted_resistance": _scene(conduction={"law": "rojek", "params": {"contact_resistance": 1e3}}),
    "conducting_walls": _scene(walls=[{"axis": 2, "side": "min", "mode": "conducting", "temperature": 900.0},
                                      {"axis": 0, "side": "max", "mode": "conducting", "temperature": 250.0}]),
    "conducting_walls_lifted": _scene(conduction={"law": "rojek", "params": {"contact_resistance": 1e2}},
                                      walls=[{"axis": 2, "side": "min", "mode": "conducting", "temperature": 900.0}]),
    "specific_heat_table": _scene(material={"specific_heat_table": TABLE_C}, beam=BEAM),
    "conductivity_table": _scene(material={"conductivity_table": TABLE_K},
                                 walls=[{"axis": 2, "side": "min", "mode": "conducting", "temperature": 900.0}]),
    "sintering": _scene(conduction={"law": "rojek", "neck_model": "volume_conserving"},
                        packing={"spacing": 80e-6}, sintering={"every": 3, "params": KINETICS},
                        initial={"temperature": 1100.0}, walls=[{"axis": 2, "side": "min", "mode": "held",
                                                                  "temperature": 1273.0}]),
    "sintering_every_step": _scene(conduction={"law": "rojek", "neck_model": "volume_conserving"},
                                   packing={"spacing": 80e-6}, sintering={"every": 1, "params": KINETICS},
                                   initial={"temperature": 1100.0}),
    "sintering_many_body": _scene(conduction={"law": "rojek", "neck_model": "volume_conserving"},
                                  packing={"spacing": 80e-6},
                                  sintering={"every": 2, "params": KINETICS, "shrinkage": "many_body"},
                                  initial={"temperature": 1100.0}),
    "preheating": _scene(conduction={"law": "rojek", "neck_model": "volume_conserving"}, packing={"spacing": 80e-6},
                         sintering={"every": 2, "params": KINETICS}, initial={"temperature": 845.0},
                         preheating={"end_temperature": 1273.0, "duration": 2e-4, "steps": 5}),
    "mechanics": _scene(conduction={"law": "conductivity", "neck_model": "hertz"},
                        physics={"mechanics": True, "gravity": [0.0, 0.0, -9.81]},
                        mechanics={"young_modulus": 1e8, "poisson_ratio": 0.3, "friction": 0.3,
                                   "rolling_friction": 0.1, "rolling_damping": 0.2},
                        softening={"onset_temperature": 500.0}, beam=BEAM,
                        walls=[{"axis": 2, "side": "min", "mode": "conducting", "temperature": 900.0},
                               {"axis": 0, "side": "max", "mode": "insulated"}]),
    "mechanics_sintering": _scene(conduction={"law": "rojek", "neck_model": "volume_conserving"},
                                  packing={"spacing": 80e-6}, physics={"mechanics": True},
                                  mechanics={"young_modulus": 1e8, "poisson_ratio": 0.3},
                                  sintering={"every": 2, "params": KINETICS, "shrinkage": "many_body",
                                             "start_necks": "point"},
                                  initial={"temperature": 1100.0}),
}


def _scene_case(raw):
    model = build_model(validate_scene(raw))
    return model.sim, model.state, model.params


def _api_packing():
    rng = np.random.default_rng(0)
    g = np.arange(3) * 1e-4
    centres = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    centres = centres + rng.uniform(-0.02, 0.02, centres.shape) * 1e-4
    radii = 0.53e-4 * (1 + rng.uniform(-0.02, 0.02, len(centres)))
    return centres, radii


def _api_case(conductance, integrator="explicit", pulse=True, motion=False, materials=1):
    """Held particles, a pulse, conducting walls and two materials through the Python API (no scene key)."""
    centres, radii = _api_packing()
    n = len(radii)
    material = (np.arange(n) % materials).astype(np.int32)
    mass = 4 / 3 * np.pi * radii**3 * 4430.0
    held = centres[:, 0] < 0.5e-4
    t0 = np.where(held, 900.0, 300.0)
    particles = ParticleState(jnp.asarray(centres), jnp.asarray(radii), jnp.asarray(t0), jnp.asarray(mass),
                              jnp.asarray(material), jnp.asarray(held), jnp.asarray(t0))
    x_wall = centres[:, 0].max() + 0.97 * radii.max()
    wall_pen = radii - np.abs(centres[:, 0] - x_wall)
    power = np.where(centres[:, 1] < 0.5e-4, 2e-3, 0.0)
    params = simulate.Params(conductivity=jnp.full(materials, 7.0), specific_heat=jnp.full(materials, 560.0),
                             pulse=simulate.PulseParams(jnp.asarray(power), jnp.asarray(2e-3)) if pulse else None)
    if motion:  # the top layer moves down by 2 % of a radius over the steps taken, at half the static stable step
        static = simulate.Physics.create(conductance="lifted", held=True, pulse=pulse)
        contacts = simulate.lifted_contacts(static, centres, radii)
        dt = 0.5 * float(simulate.thermal_time_step(simulate.simulator(static), simulate.init_state(
            particles, contacts, 1.0), params))
        velocity = np.zeros_like(centres)
        velocity[:, 2] = np.where(centres[:, 2] > 1.5e-4, -0.02 * radii.max() / (STEPS * dt), 0.0)
        move = _Squeeze(jnp.asarray(centres), jnp.asarray(velocity))
        physics = simulate.Physics.create(conductance="lifted", contacts="dynamic", held=True, pulse=pulse, motion=move)
        contacts, fns = simulate.dynamic_contacts(centres, radii, 0.2 * radii.max())
        sim = simulate.simulator(physics, fns)
        return sim, simulate.init_state(particles, contacts, dt), params
    physics = simulate.Physics.create(conductance=conductance, held=True, pulse=pulse, integrator=integrator,
                                      conducting_walls=1)
    if conductance == "table":
        from sintercond.contacts import network
        table = network.contact_table(centres, radii, 1.0)
        k_w = network.wall_conductance(centres, radii, 1.0, 0, x_wall)
        contacts = simulate.table_contacts(table, k_w, np.full(n, 250.0))
    else:
        contacts = simulate.lifted_contacts(physics, centres, radii, [(wall_pen, 250.0)])
    sim = simulate.simulator(physics)
    dt = 0.5 * float(simulate.thermal_time_step(sim, simulate.init_state(particles, contacts, 1.0), params))
    return sim, simulate.init_state(particles, contacts, dt * (20.0 if integrator == "implicit" else 1.0)), params


@dataclasses.dataclass(frozen=True, eq=False)
class _Squeeze:
    """Prescribed motion: the upper layers move down at a constant speed (m, s)."""

    start: jax.Array
    velocity: jax.Array

    def __call__(self, t):
        return self.start + t * self.velocity


def _mechanics_api_case():
    """Two spheres on a conducting floor with friction, rolling and every coefficient of the Python API."""
    r = 1e-3
    x = np.array([[0.0, 0.0, r * 0.999], [2 * r * 0.999, 0.0, r * 1.05]])
    particles = ParticleState(jnp.asarray(x), jnp.full(2, r), jnp.asarray([300.0, 600.0]),
                                       jnp.full(2, 4 / 3 * np.pi * r**3 * 3000.0), jnp.zeros(2, jnp.int32),
                                       jnp.zeros(2, bool), jnp.asarray([300.0, 600.0]))
    floor = PlaneWall(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), mode="conducting", temperature=700.0)
    physics = simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                      mechanics=True, walls=[floor], friction=True, rolling=True, softening=True,
                                      wall_friction=True, wall_rolling=True)
    contacts, fns = simulate.dynamic_contacts(x, particles.radii, 0.1 * r, capacity_multiplier=3.0)
    velocity = np.array([[0.01, 0.0, -0.02], [-0.01, 0.005, -0.03]])
    motion = mechanics.mechanical_state(physics.mechanics, x, contacts, velocity=velocity)
    f = lambda v: jnp.asarray(float(v), jnp.float64)  # noqa: E731
    mp = mechanics.MechanicalParams(E0=f(1e6), nu=f(0.3), xi_con=f(0.5), xi_fric=f(0.5), xi_rol=f(0.2), mu=f(0.4),
                                    mu_r=f(0.1), theta_star=f(400.0), rate=f(1.0), E_min=f(1e5), mu_wall=f(0.3),
                                    mu_r_wall=f(0.05))
    params = simulate.Params(conductivity=jnp.asarray([60.0]), specific_heat=jnp.asarray([100.0]), mechanics=mp)
    return simulate.simulator(physics, fns), simulate.init_state(particles, contacts, 2e-6, mechanics=motion), params


API_CASES = {
    "api_table_pulse_walls": lambda: _api_case("table"),
    "api_lifted_two_materials": lambda: _api_case("lifted", materials=2),
    "api_implicit_table": lambda: _api_case("table", integrator="implicit", pulse=False),
    "api_implicit_lifted": lambda: _api_case("lifted", integrator="implicit", pulse=False),
    "api_prescribed_motion": lambda: _api_case("lifted", motion=True),
    "api_mechanics_every_law": _mechanics_api_case,
}

CASES = sorted(SCENES) + sorted(API_CASES)


def build(name):
    """``(sim, state, params)`` of case ``name``."""
    return _scene_case(SCENES[name]) if name in SCENES else API_CASES[name]()


ROUND_OFF = 1e-11
"""Relative tolerance of a case's pinned arrays (of each array's scale): another machine's or XLA's fusion order
changes last digits, which a dozen explicit steps amplify by far less."""


def tolerance(name) -> float:
    """Relative tolerance of case ``name``: :data:`ROUND_OFF`, or where the step solves the many-body balance by
    conjugate gradients, that solve's own relative residual (``Sintering.balance_tol``): a last-digit difference
    moves where the iterations stop, anywhere within the residual they stop at."""
    raw = SCENES.get(name, {})
    if raw.get("sintering", {}).get("shrinkage") == "many_body":
        return max(ROUND_OFF, raw["sintering"].get("balance_tol", Sintering().balance_tol))
    return ROUND_OFF


def outputs(name) -> dict[str, np.ndarray]:
    """The arrays the step changes after :data:`STEPS` steps of case ``name``, and the heat power at the start."""
    sim, state, params = build(name)
    step = jax.jit(sim.step_fn)
    power = jax.jit(lambda s, p: sim.heat_power_fn(s, sim.prepare_fn(s, p)))(state, params) \
        if sim.physics.mechanics is None else None
    for _ in range(STEPS):
        state = step(state, params)
    out = {"temperature": state.particles.temperature, "positions": state.particles.positions}
    if power is not None:
        out["power"] = power
    if state.sintering is not None:
        out["unstable"] = state.sintering.unstable
    if sim.physics.sintering is not None and sim.physics.mechanics is None:
        out["neck"] = state.contacts.table_neck
    if state.mechanics is not None:
        out |= {"velocity": state.mechanics.velocity, "spin": state.mechanics.spin}
        if sim.physics.sintering is not None:
            out["neck"] = state.mechanics.neck
    return {k: np.asarray(v) for k, v in out.items()}


def write():
    arrays = {f"{name}/{key}": value for name in CASES for key, value in outputs(name).items()}
    PINNED.parent.mkdir(exist_ok=True)
    np.savez_compressed(PINNED, **arrays)
    print(f"{len(CASES)} cases, {len(arrays)} arrays -> {PINNED}")


if __name__ == "__main__":
    sys.exit(write())
