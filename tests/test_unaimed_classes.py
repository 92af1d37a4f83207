"""Classes of bugs that independently written mutants slipped past (issue 43, item 14): each test checks a class
against an independent reference, not the planted line.

- packing files: scaled dump coordinates in a box away from the origin, diameter columns in both table readers;
- the mechanical step estimate's reduced radius and mass, against the closed-form Hertz limit of a pair of unequal
  spheres;
- which steps a rollout saves, and over which particles the mean temperature averages, against a constant-power
  closed form for every combination of save interval, segment length and checkpointing.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import simulate
from sintercond.beds import packing_files
from sintercond.sim import mechanics
from sintercond.state import ParticleState


def _dump(rows, box, columns="id type xs ys zs radius"):
    lines = ["ITEM: TIMESTEP", "0", "ITEM: NUMBER OF ATOMS", str(len(rows)), "ITEM: BOX BOUNDS ff ff ff"]
    lines += [f"{lo!r} {hi!r}" for lo, hi in box]
    lines += [f"ITEM: ATOMS {columns}"] + [" ".join(repr(float(v)) if k > 1 else str(int(v)) for k, v in enumerate(row))
                                           for row in rows]
    return "\n".join(lines) + "\n"


def test_scaled_dump_coordinates_are_read_in_a_box_away_from_the_origin(tmp_path):
    """x = lo + s (hi - lo) on each axis: a box [10, 14] x [-3, -1] x [100, 108] shifts and scales differently per
    axis, so reading s as x, using one axis's box for all, or leaving out lo all fail."""
    box = [(10.0, 14.0), (-3.0, -1.0), (100.0, 108.0)]
    scaled = np.array([[0.25, 0.5, 0.125], [0.75, 0.25, 0.875], [0.5, 1.0, 0.0]])
    rows = [[k + 1, 1, *s, 0.1 + 0.05 * k] for k, s in enumerate(scaled)]
    path = tmp_path / "scaled.dump"
    path.write_text(_dump(rows, box))
    centres, radii = packing_files.read_packing(path, "lammps_dump")
    lo, hi = np.array(box).T
    np.testing.assert_allclose(centres, lo + scaled * (hi - lo), rtol=0, atol=1e-12)
    np.testing.assert_allclose(radii, [0.1, 0.15, 0.2], rtol=0, atol=1e-15)


@pytest.mark.parametrize("separator", [",", " "])
@pytest.mark.parametrize("name", ["d", "diameter"])
@pytest.mark.parametrize("uniform", [True, False], ids=["fast path", "row by row"])
def test_a_diameter_column_gives_radii_of_half_of_it(tmp_path, separator, name, uniform):
    """Both readers of a table (NumPy's over uniform rows, the row-by-row one where a row differs: here a trailing
    comment) halve a diameter column wherever it stands, and leave the other columns alone."""
    diameters = [2e-5, 5e-5, 8e-5]
    header = separator.join(["z", name, "x", "y"])
    body = [separator.join(repr(v) for v in (3e-4 * k, d, 1e-4 * k, -2e-4 * k)) for k, d in enumerate(diameters)]
    if not uniform:
        body[1] += "  # a comment: not a uniform table"
    path = tmp_path / "bed.csv"
    path.write_text("\n".join([header, *body]) + "\n")
    centres, radii = packing_files.read_packing(path, "table")
    np.testing.assert_array_equal(radii, np.array(diameters) / 2)
    k = np.arange(3)
    np.testing.assert_array_equal(centres, np.stack([1e-4 * k, -2e-4 * k, 3e-4 * k], axis=1))


def test_the_mechanical_step_of_unequal_spheres_uses_their_reduced_radius_and_mass():
    """Undamped, frictionless: the stable step at overlap delta is 2 / omega with omega^2 = 2 E* sqrt(r* delta) / m*
    (Quintana-Ruiz & Campello 2020, Eq. 2 differentiated; symplectic Euler's limit), r* = r_i r_j / (r_i + r_j),
    m* = m_i m_j / (m_i + m_j), E* = E / (2 (1 - nu^2)) for one material."""
    r = np.array([1e-3, 3e-3])
    rho, e0, nu, delta = np.array([2000.0, 7000.0]), 1e7, 0.25, 2e-6
    mass = 4 / 3 * np.pi * r**3 * rho
    x = np.array([[0.0, 0.0, 0.0], [r.sum() - delta, 0.0, 0.0]])
    particles = ParticleState(jnp.asarray(x), jnp.asarray(r), jnp.full(2, 300.0), jnp.asarray(mass),
                              jnp.zeros(2, jnp.int32), jnp.zeros(2, bool), jnp.full(2, 300.0))
    spec = mechanics.Mechanics.create(gravity=(0.0, 0.0, 0.0))
    params = mechanics.MechanicalParams(E0=jnp.asarray(e0), nu=jnp.asarray(nu), xi_con=jnp.asarray(0.0))
    contacts, _ = simulate.dynamic_contacts(x, r, 0.1 * r.min())
    limit = float(mechanics.mechanical_time_step(spec, particles, contacts.neighbors, params, 1e-9, delta=delta,
                                                 fraction=1e9, safety=1.0))
    r_star, m_star = r.prod() / r.sum(), mass.prod() / mass.sum()
    omega = math.sqrt(2 * e0 / (2 * (1 - nu**2)) * math.sqrt(r_star * delta) / m_star)
    assert limit == pytest.approx(2 / omega, rel=1e-12)


def _heated_pair(held):
    """Two unconnected particles of capacities 2 and 6 J/K, 1 W into the first, 3 W into the second (until 1e9 s):
    each warms at 0.5 K/s exactly under explicit Euler. The second is held at 400 K when ``held``."""
    t0 = np.array([300.0, 400.0])
    mass = np.array([2.0, 6.0])
    particles = ParticleState(jnp.zeros((2, 3)), jnp.ones(2), jnp.asarray(t0), jnp.asarray(mass),
                              jnp.zeros(2, jnp.int32), jnp.asarray([False, held]), jnp.asarray(t0))
    table = np.array([[0], [1]], np.int32)  # each its own padding: no contact
    contacts = simulate.TableContacts(neighbors=jnp.asarray(table), conductance=jnp.zeros((2, 1)))
    physics = simulate.Physics.create(held=held, pulse=True)
    params = simulate.Params(conductivity=jnp.ones(1), specific_heat=jnp.ones(1),
                             pulse=simulate.PulseParams(jnp.asarray([1.0, 3.0]), jnp.asarray(1e9)))
    return simulate.simulator(physics), simulate.init_state(particles, contacts, 0.1), params


@pytest.mark.parametrize("n_steps, every", [(12, 1), (12, 3), (12, 4), (35, 7), (36, 12), (17, 17)])
@pytest.mark.parametrize("checkpoint", [True, False])
def test_each_save_is_the_state_after_its_interval_and_the_mean_weighs_the_free_particles(n_steps, every, checkpoint):
    """Save k (from 0) is the state after (k + 1) * every steps: T = T0 + 0.5 K/s (k + 1) every dt. The mean
    temperature is mass-weighted over the free particles; with none held, over all."""
    for held in (False, True):
        sim, state, params = _heated_pair(held)
        probes = simulate.rollout(sim, state, params, n_steps, simulate.SaveAt(every, None), checkpoint)[1]
        means = simulate.rollout(sim, state, params, n_steps, simulate.SaveAt(every, simulate.mean_temperature),
                                 checkpoint)[1]
        t = 0.1 * every * np.arange(1, n_steps // every + 1)
        first, second = 300.0 + 0.5 * t, (np.full_like(t, 400.0) if held else 400.0 + 0.5 * t)
        np.testing.assert_allclose(np.asarray(probes), np.stack([first, second], axis=1), rtol=1e-13)
        expected = first if held else (2.0 * first + 6.0 * second) / 8.0
        np.testing.assert_allclose(np.asarray(means), expected, rtol=1e-13)


def _hot_pair(temperature, softening=True):
    """Two spheres (1 mm, 2 mm) overlapping 5 um at rest at ``temperature``, E0 = 1e8 Pa, E_min = 2e6 Pa,
    theta* = 400 K."""
    r, delta = np.array([1e-3, 2e-3]), 5e-6
    x = np.array([[0.0, 0.0, 0.0], [r.sum() - delta, 0.0, 0.0]])
    particles = ParticleState(jnp.asarray(x), jnp.asarray(r), jnp.full(2, float(temperature)),
                              jnp.asarray(4 / 3 * np.pi * r**3 * 3000.0), jnp.zeros(2, jnp.int32),
                              jnp.zeros(2, bool), jnp.full(2, float(temperature)))
    physics = simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                      mechanics=True, gravity=(0.0, 0.0, 0.0), softening=softening)
    contacts, _ = simulate.dynamic_contacts(x, r, 0.1 * r.min())
    state = simulate.init_state(particles, contacts, 1e-7, mechanics=mechanics.mechanical_state(physics.mechanics, x,
                                                                                                contacts))
    f = lambda v: jnp.asarray(float(v))  # noqa: E731
    params = simulate.Params(conductivity=jnp.ones(1), specific_heat=jnp.ones(1), mechanics=mechanics.MechanicalParams(
        E0=f(1e8), nu=f(0.3), xi_con=f(0.5), theta_star=f(400.0), rate=f(1.0), E_min=f(2e6)))
    return physics, state, params, r.prod() / r.sum(), delta


@pytest.mark.parametrize("temperature", [300.0, 600.0, 5000.0])
def test_the_coupled_step_pushes_with_the_softened_modulus_and_its_floor(temperature):
    """Hertz at rest: |F| = 4/3 E* sqrt(r*) delta^(3/2), E* = E / (2 (1 - nu^2)), E = max(E_min, E0 exp(min(0,
    1 - T/theta*))) (Quintana-Ruiz & Campello 2020, Eqs. 2 and 42): E0 below theta*, the exponential above it, the
    floor far above it."""
    physics, state, params, r_star, delta = _hot_pair(temperature)
    _, force = simulate.contact_forces(physics, state, params)
    modulus = max(2e6, 1e8 * math.exp(min(0.0, 1.0 - temperature / 400.0)))
    expected = 4 / 3 * modulus / (2 * (1 - 0.3**2)) * math.sqrt(r_star) * delta**1.5
    assert float(jnp.linalg.norm(force[0])) == pytest.approx(expected, rel=1e-12)


def test_wall_friction_without_friction_between_the_particles_reaches_the_walls_only():
    """A scene with mechanics.friction = 0 and wall_friction = 0.3: the step's friction is on (walls rub), the pairs'
    coefficient 0, the walls' 0.3; rolling stays off."""
    from sintercond.scene import build, validate_scene

    scene = validate_scene({
        "packing": {"kind": "spheres", "centres": [[0.0, 0.0, 1e-3], [2e-3, 0.0, 1e-3]], "radii": 1e-3},
        "material": {"density": 3000.0, "specific_heat": 100.0, "conductivity": 60.0},
        "conduction": {"law": "conductivity", "neck_model": "hertz"}, "initial": {"temperature": 300.0},
        "walls": [{"axis": 2, "side": "min", "mode": "insulated", "penetration": 0.0}],
        "physics": {"mechanics": True},
        "mechanics": {"young_modulus": 1e6, "poisson_ratio": 0.3, "friction": 0.0, "wall_friction": 0.3},
        "run": {"duration": 1e-4, "output_every": 1, "checkpoint_every": 1}})
    model = build.build_model(scene)
    spec, mp = model.physics.mechanics, model.params.mechanics
    assert spec.friction and spec.wall_friction and not spec.rolling
    assert float(mp.mu) == 0.0 and float(mp.mu_wall) == 0.3


@pytest.mark.parametrize("every", [1, 3, 4])
def test_the_necks_grow_at_the_end_of_each_interval_by_the_whole_interval(every):
    """Two touching 40 um spheres at a uniform 1150 K (nothing conducts): after n steps of dt the neck is the law
    tier's (:func:`sintercond.laws.sintering.grow_neck`, from a point contact) after ``floor(n / every) * every * dt``:
    it grows at the end of each interval, by all of it, and not between."""
    import jax

    from sintercond.laws import sintering
    from sintercond.scene import build, validate_scene

    kinetics = {"A": 1.2e-18, "activation_energy": 37.0}
    scene = validate_scene({
        "packing": {"kind": "spheres", "centres": [[0.0, 0.0, 0.0], [80e-6, 0.0, 0.0]], "radii": 40e-6},
        "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 7.0},
        "conduction": {"law": "rojek", "neck_model": "volume_conserving"}, "initial": {"temperature": 1150.0},
        "sintering": {"every": every, "params": kinetics},
        "run": {"duration": 1e-3, "dt": 1e-4, "output_every": 1, "checkpoint_every": 1}})
    model = build.build_model(scene)
    step, state, dt = jax.jit(model.sim.step_fn), model.state, float(model.state.dt)
    for n in range(1, 9):
        state = step(state, model.params)
        grown = n // every * every * dt
        expected = 0.0 if grown == 0 else float(sintering.grow_neck("grain_boundary", 0.0, 40e-6, 40e-6, [1150.0],
                                                                     [grown], kinetics)[0])
        # 6e-10 apart here (the law tier's Newton inversion); a step more or less of growth moves it by over 2 %
        assert float(jnp.max(state.contacts.table_neck[0])) == pytest.approx(expected, rel=1e-8, abs=1e-18), n


def test_the_wall_columns_of_the_history_count_each_walls_heat_in_closed_form(tmp_path):
    """A 2 x 2 x 3 simple cubic block at 300 K, its floor held at 900 K (a held wall) and its top facing a
    conducting wall at 500 K. At the start (the history's first row) the held floor layer is at 900 K and the rest
    at 300 K: the floor's column reads 4 K_pair (900 - 300) (the four columns' first contacts, Rojek's K of the
    overlap) and the top wall's sum K_w (500 - 300) over its four particles (the wall law at their penetration,
    :func:`sintercond.laws.walls.wall_conductance`)."""
    from sintercond import run as runner
    from sintercond.laws import walls
    from sintercond.laws.conductance import rojek_pair_conductance
    from sintercond.scene import validate_scene

    r, a, kappa = 40e-6, 78e-6, 7.0
    scene = validate_scene({
        "packing": {"kind": "simple_cubic", "counts": [2, 2, 3], "spacing": a, "radius": r},
        "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": kappa},
        "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0},
        "walls": [{"axis": 2, "side": "min", "mode": "held", "temperature": 900.0},
                  {"axis": 2, "side": "max", "mode": "conducting", "temperature": 500.0, "penetration": 0.05}],
        "run": {"duration": 1e-4, "dt": 1e-4, "output_every": 1, "checkpoint_every": 1}})
    runner.run_scene(scene, tmp_path / "out", progress=False, pictures=False)
    history = runner.read_history(tmp_path / "out")
    k_pair = float(rojek_pair_conductance(r, r, 2 * r - a, kappa))
    k_wall = float(walls.wall_conductance("rojek", r, 0.05 * r, kappa))
    assert history["heat_wall0_W"][0] == pytest.approx(4 * k_pair * 600.0, rel=1e-12)
    assert history["heat_wall1_W"][0] == pytest.approx(4 * k_wall * 200.0, rel=1e-12)
    assert 0 < history["heat_wall0_W"][-1] < history["heat_wall0_W"][0]  # the next layer has warmed


@pytest.mark.parametrize("kill_after, checkpoint_every", [(3, 2), (4, 4), (5, 3)])
def test_a_resumed_run_writes_the_history_of_an_uninterrupted_one(tmp_path, kill_after, checkpoint_every):
    """Killed after some output chunks and resumed from its last checkpoint, a run's history.csv is the
    uninterrupted run's, row for row (no row of the checkpoint's step lost or written twice, none after it kept)."""
    from sintercond import run as runner
    from sintercond.scene import validate_scene

    scene = validate_scene({
        "packing": {"kind": "simple_cubic", "counts": [2, 2, 3], "spacing": 78e-6, "radius": 40e-6},
        "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 7.0},
        "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0},
        "walls": [{"axis": 2, "side": "min", "mode": "held", "temperature": 900.0}],
        "run": {"duration": 1e-3, "dt": 1e-4, "output_every": 1, "checkpoint_every": checkpoint_every}})
    runner.run_scene(scene, tmp_path / "whole", progress=False, pictures=False)
    runner.run_scene(scene, tmp_path / "cut", progress=False, pictures=False, stop_after_chunks=kill_after)
    runner.resume(tmp_path / "cut", progress=False, pictures=False)
    whole = (tmp_path / "whole" / "history.csv").read_text().splitlines()
    assert (tmp_path / "cut" / "history.csv").read_text().splitlines() == whole
    assert len(whole) == 1 + 11  # the header, step 0 and each of the 10 steps


@pytest.mark.parametrize("dihedral", [120.0, 150.0])
def test_a_hot_neck_on_the_table_stops_at_its_cap_and_stays(dihedral):
    """Fast kinetics at 1400 K: the grain-boundary neck of two 40 um spheres reaches the equilibrium neck
    r sin(psi/2) (Coble's dihedral-angle limit) within a few steps and never passes it."""
    import jax

    from sintercond.scene import build, validate_scene

    scene = validate_scene({
        "packing": {"kind": "spheres", "centres": [[0.0, 0.0, 0.0], [80e-6, 0.0, 0.0]], "radii": 40e-6},
        "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 7.0},
        "conduction": {"law": "rojek", "neck_model": "volume_conserving"}, "initial": {"temperature": 1400.0},
        "sintering": {"every": 1, "params": {"A": 1e-6, "activation_energy": 1.0, "dihedral_angle": dihedral}},
        "run": {"duration": 1e-3, "dt": 1e-4, "output_every": 1, "checkpoint_every": 1}})
    model = build.build_model(scene)
    step, state = jax.jit(model.sim.step_fn), model.state
    cap = 40e-6 * math.sin(math.radians(dihedral) / 2)
    necks = []
    for _ in range(6):
        state = step(state, model.params)
        necks.append(float(jnp.max(state.contacts.table_neck[0])))
    assert max(necks) <= cap * (1 + 1e-12)
    assert necks[-1] == pytest.approx(cap, rel=1e-12)


def _twisting_pair(projection, spin):
    """Two 1 mm spheres touching along x (5 um overlap), no gravity, friction off, rolling resistance on; sphere 0
    spins at ``spin`` (rad/s)."""
    r, delta = 1e-3, 5e-6
    x = np.array([[0.0, 0.0, 0.0], [2 * r - delta, 0.0, 0.0]])
    particles = ParticleState(jnp.asarray(x), jnp.full(2, r), jnp.full(2, 300.0),
                              jnp.full(2, 4 / 3 * np.pi * r**3 * 3000.0), jnp.zeros(2, jnp.int32), jnp.zeros(2, bool),
                              jnp.full(2, 300.0))
    physics = simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                      mechanics=True, gravity=(0.0, 0.0, 0.0), rolling=True,
                                      rolling_projection=projection)
    contacts, fns = simulate.dynamic_contacts(x, particles.radii, 0.1 * r)
    motion = mechanics.mechanical_state(physics.mechanics, x, contacts, spin=np.array([spin, [0.0, 0.0, 0.0]]))
    f = lambda v: jnp.asarray(float(v))  # noqa: E731
    params = simulate.Params(conductivity=jnp.ones(1), specific_heat=jnp.ones(1), mechanics=mechanics.MechanicalParams(
        E0=f(1e6), nu=f(0.3), xi_con=f(0.5), xi_rol=f(0.3), mu_r=f(0.5)))
    return simulate.simulator(physics, fns), simulate.init_state(particles, contacts, 1e-6, mechanics=motion), params


def test_the_coupled_step_rolls_on_the_tangential_spin_only_with_the_projection():
    """A pure twist (spin about the contact normal) meets no rolling resistance with ``rolling_projection`` (the
    rolling part of the relative spin, ``omega - (omega . n) n``, is zero: LAMMPS' ``rolling sds``), and is resisted
    without it (the paper's literal law, erratum 5); a spin about a tangent is resisted the same by both at the first
    step (its rate is all rolling and the spring starts at zero)."""
    twist, roll = [5.0, 0.0, 0.0], [0.0, 0.0, 5.0]
    end = {}
    for projection in (True, False):
        for name, spin in (("twist", twist), ("roll", roll)):
            sim, state, params = _twisting_pair(projection, spin)
            end[projection, name] = simulate.rollout(sim, state, params, 1)[0].mechanics.spin
    np.testing.assert_array_equal(np.asarray(end[True, "twist"]), np.array([twist, [0.0, 0.0, 0.0]]))
    assert float(end[False, "twist"][0, 0]) < 5.0 and float(end[False, "twist"][1, 0]) > 0.0
    np.testing.assert_allclose(np.asarray(end[True, "roll"]), np.asarray(end[False, "roll"]), rtol=1e-12, atol=0)
    assert float(end[True, "roll"][0, 2]) < 5.0


def test_a_settled_sphere_rests_on_hertz_s_overlap_and_the_report_says_so():
    """One sphere (r = 3 mm, Example 5.3's material) dropped 0.2 mm onto the floor settles to Hertz's overlap of its
    weight, delta = (3 m g / (4 E* sqrt(r)))^(2/3), E* = E / (1 - nu^2); the report's figures are that state's: the
    largest overlap over the radius, the kinetic and force ratios below the thresholds they met, the time steps * dt."""
    from sintercond.beds import settle

    r, material = 3e-3, settle.DemMaterial()
    centres = np.array([[0.01, 0.01, r + 2e-4]])
    floor = [w for w in settle.box_walls(0.02) if w.normal[2] == 1.0]
    settled = settle.dem_settle(centres, np.array([r]), floor, material, check_every=500)
    report = settled.report
    mass = material.density * 4 / 3 * math.pi * r**3
    delta = (3 * mass * 9.81 / (4 * material.E / (1 - material.nu**2) * math.sqrt(r))) ** (2 / 3)
    assert r - float(settled.centres[0, 2]) == pytest.approx(delta, rel=1e-3)
    assert report.max_overlap == pytest.approx(delta / r, rel=1e-3)
    assert report.kinetic_ratio < report.kinetic_tol and report.force_ratio < report.force_tol
    assert report.time == pytest.approx(report.steps * report.dt, rel=1e-12)
    # the reported net force of the settled state: Hertz (Eq. 2) less its dashpot 2 xi sqrt(k m) v (Eq. 6, k the
    # tangent stiffness 2 E* sqrt(r delta)) at the state's overlap and speed, less the weight, over the weight
    z, v = float(settled.state.particles.positions[0, 2]), float(settled.state.mechanics.velocity[0, 2])
    e_star, overlap = material.E / (1 - material.nu**2), r - z
    hertz = 4 / 3 * e_star * math.sqrt(r) * overlap**1.5
    dashpot = 2 * material.xi_con * math.sqrt(2 * e_star * math.sqrt(r * overlap) * mass) * v
    assert report.force_ratio == pytest.approx(abs(hertz - dashpot - mass * 9.81) / (mass * 9.81), rel=1e-9)
