"""Necks that grow with the elastic mechanics on: the necks live on the dynamic half pair list.

References: the law tier (:func:`sintercond.laws.sintering.grow_neck`, itself tested against closed forms) along each
contact's recorded temperature history; Hertz's static overlaps of a stack under its weight (Quintana-Ruiz &
Campello 2020, Eq. 2) with the closed-form approach of a chain on a support; conservation of heat; rebuilds and
reallocations against a list that never rebuilds and a brute-force contact search; central differences.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import rollout, simulate
from sintercond.laws import sintering
from sintercond.sim import mechanics, neck_growth
from sintercond.state import particle_state
from sintercond.laws.walls import PlaneWall
from _helpers import forced_rebuild

DENSITY, HEAT, KAPPA = 4430.0, 560.0, 7.0  # Ti6Al4V
KINETICS = {"A": 1e-13, "activation_energy": 100.0}  # necks of some um in a few ms at 1000-1200 K
E0, NU, G = 1e8, 0.3, 9.81  # a soft modulus: a step of 1e-7 s resolves the contacts
R = 40e-6
# runs that are never differentiated in reverse mode use rollout(checkpoint=False): one plain scan. The checkpointed
# segments (for reverse mode) split a run into scans of two lengths, two copies of the coupled step to compile.


def mechanical_params(**kw):
    base = dict(E0=E0, nu=NU, xi_con=1.0, xi_fric=1.0, xi_rol=0.0, mu=0.0, mu_r=0.0, theta_star=400.0, rate=1.0,
                E_min=0.0)
    base.update(kw)
    return mechanics.MechanicalParams(**{k: jnp.asarray(float(v), jnp.float64) for k, v in base.items()})


def coupled(x, radii, temperature, shrinkage="many_body", start="overlap", every=1, dt=1e-6, gravity=(0.0, 0.0, 0.0),
            walls=(), supports=None, skin=0.1 * R, multiplier=2.0, kinetics=KINETICS, quasi_static=False, e0=E0):
    """A coupled sintering run's ``(sim, state, params, neighbor_fns)``."""
    x, radii = np.asarray(x, np.float64), np.asarray(radii, np.float64)
    temperature = np.broadcast_to(np.asarray(temperature, np.float64), radii.shape)
    physics = simulate.Physics.create(law="rojek", neck_model="volume_conserving", conductance="lifted",
                                      contacts="dynamic", mechanics=True, gravity=gravity, walls=walls, quasi_static=quasi_static,
                                      sintering=neck_growth.Sintering(every=every, shrinkage=shrinkage,
                                                                      balance_tol=1e-12))
    particles = particle_state(x, radii, temperature, DENSITY)
    contacts, fns = simulate.dynamic_contacts(x, radii, skin, capacity_multiplier=multiplier)
    motion = neck_growth.with_pair_necks(mechanics.mechanical_state(physics.mechanics, x, contacts), contacts, x,
                                         radii, start)
    if shrinkage == "many_body" and supports is None:
        supports = np.zeros((len(radii), 3), bool)
    necks = neck_growth.neck_state(contacts, particles.temperature, supports=supports, positions=x)
    state = simulate.init_state(particles, contacts, dt, mechanics=motion, sintering=necks)
    params = simulate.Params(conductivity=[KAPPA], specific_heat=[HEAT], sintering=dict(kinetics),
                             mechanics=mechanical_params(E0=e0))
    return simulate.simulator(physics, fns), state, params, fns


def free_pair(shrinkage, every=1):
    radii = np.array([40e-6, 30e-6])
    x = np.array([[0.0, 0.0, 0.0], [70e-6 - 1e-8, 0.0, 0.0]])  # a 10 nm overlap, taken as a sintered neck
    return coupled(x, radii, [1000.0, 1200.0], shrinkage, every=every)


def by_pair(state, values):
    pairs = np.asarray(state.contacts.pairs.pairs)
    return {tuple(int(v) for v in p): float(values[k]) for k, p in enumerate(pairs) if p[0] < p[1]}


@pytest.mark.slow
@pytest.mark.parametrize("shrinkage, every", [("independent", 1), ("many_body", 4)])
def test_one_contact_grows_as_the_law_tier_does_along_its_own_temperature_history(shrinkage, every):
    sim, state, params, _ = free_pair(shrinkage, every)
    simulate.validate_inputs(sim, state, params)
    n_steps = 2000
    end, temperature = jax.jit(lambda s, p: simulate.rollout(sim, s, p, n_steps, checkpoint=False))(state, params)
    temperature = np.concatenate([np.asarray(state.particles.temperature)[None], np.asarray(temperature)])
    pair = 0.5 * (temperature[:, 0] + temperature[:, 1])
    history = 0.5 * (pair[0:-every:every] + pair[every::every])  # each growth interval's trapezoid
    spec = sim.physics.sintering
    a0 = float(state.mechanics.neck[0])
    assert a0 > 0  # the start overlap as a neck
    expected = float(sintering.grow_neck("grain_boundary", a0, 40e-6, 30e-6, history,
                                         np.full(len(history), every * float(state.dt)), KINETICS,
                                         quadrature_nodes=spec.quadrature_nodes,
                                         newton_iterations=spec.newton_iterations)[-1])
    assert expected > 5 * a0 and np.ptp(temperature[:, 0]) > 30.0  # grown, along a history that is not isothermal
    np.testing.assert_allclose(float(end.mechanics.neck[0]), expected, rtol=1e-12)
    h = float(sintering.neck_overlap(expected, 40e-6, 30e-6))
    np.testing.assert_allclose(float(end.mechanics.neck_overlap[0]), h, rtol=1e-12)
    distance = float(np.linalg.norm(np.diff(np.asarray(end.particles.positions), axis=0)))
    stats = neck_growth.neck_statistics(end)
    if shrinkage == "many_body":  # the pair approached by its neck's approach, without an elastic load
        np.testing.assert_allclose(70e-6 - distance, h, rtol=1e-9)
        np.testing.assert_allclose(float(stats["shrinkage"]), (h - 1e-8) / 70e-6, rtol=1e-9)
    else:  # positions stay: nothing loads the pair
        assert distance == pytest.approx(70e-6 - 1e-8, rel=1e-15) and float(stats["shrinkage"]) == 0.0
    assert float(np.max(np.abs(np.asarray(end.mechanics.velocity)))) < 1e-12
    np.testing.assert_allclose(float(stats["max_neck_ratio"]), expected / 30e-6, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(neck_growth.particle_neck_ratio(end)), expected / 30e-6, rtol=1e-12)


def stack(shrinkage="many_body", quasi_static=False, e0=E0, dt=1e-7):
    """Three equal spheres stacked on a floor at Hertz's overlaps under their weight, at rest, isothermal."""
    mass = 4.0 / 3.0 * math.pi * R**3 * DENSITY
    e_pair, e_wall = e0 / (2 * (1 - NU**2)), e0 / (1 - NU**2)

    def hertz(force, e_star, r_star):  # Eq. 2 at rest: f = (4/3) sqrt(r*) E* delta^(3/2)
        return (3 * force / (4 * e_star * math.sqrt(r_star))) ** (2 / 3)

    overlaps = [hertz(3 * mass * G, e_wall, R), hertz(2 * mass * G, e_pair, R / 2), hertz(mass * G, e_pair, R / 2)]
    z = np.cumsum([R - overlaps[0], 2 * R - overlaps[1], 2 * R - overlaps[2]])
    x = np.stack([np.zeros(3), np.zeros(3), z], axis=1)
    supports = np.zeros((3, 3), bool)
    supports[0, 2] = True  # on the floor
    floor = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    return coupled(x, np.full(3, R), 1200.0, shrinkage, start="point", every=10, dt=dt, gravity=(0.0, 0.0, -G),
                   walls=(floor,), supports=supports, quasi_static=quasi_static, e0=e0), overlaps


@pytest.mark.slow
def test_a_stack_under_its_weight_shrinks_onto_its_support_and_keeps_hertz_s_overlaps():
    (sim, state, params, _), overlaps = stack()
    n_steps = 4000
    end = jax.jit(lambda s, p: simulate.rollout(sim, s, p, n_steps, checkpoint=False)[0])(state, params)
    spec = sim.physics.sintering
    expected = float(sintering.grow_neck("grain_boundary", 0.0, R, R, [1200.0] * (n_steps // 10),
                                         [10 * float(state.dt)] * (n_steps // 10), KINETICS,
                                         quadrature_nodes=spec.quadrature_nodes,
                                         newton_iterations=spec.newton_iterations)[-1])
    h = float(sintering.neck_overlap(expected, R, R))
    assert h > 100 * overlaps[1]  # the sintering approach dwarfs the elastic overlaps
    necks = by_pair(end, end.mechanics.neck)
    assert set(necks) == {(0, 1), (1, 2)}
    for value in necks.values():
        np.testing.assert_allclose(value, expected, rtol=1e-12)
    # a chain on its support closes up contact by contact: each sphere down by the approaches below it
    z0, z = np.asarray(state.particles.positions)[:, 2], np.asarray(end.particles.positions)[:, 2]
    np.testing.assert_allclose(z0 - z, [0.0, h, 2 * h], rtol=1e-6, atol=1e-3 * overlaps[2])
    # and the elastic overlaps under the weight are Hertz's still: the sintering moved the spheres without loading
    elastic = [R - z[0], 2 * R - (z[1] - z[0]) - h, 2 * R - (z[2] - z[1]) - h]
    np.testing.assert_allclose(elastic, overlaps, rtol=1e-3)
    assert float(np.max(np.abs(np.asarray(end.mechanics.velocity)))) < 1e-6
    assert not bool(end.sintering.unbalanced) and not bool(end.sintering.unstable)


@pytest.mark.slow
def test_a_quasi_static_stack_at_the_real_modulus_closes_as_the_law_tier_says_at_the_thermal_step():
    # Ti6Al4V's 110 GPa: the inertial step would be ~1e-8 s; without inertia the necks' interval is the step
    (sim, state, params, _), overlaps = stack(quasi_static=True, e0=110e9, dt=4e-4)
    n_steps, every = 10, 10
    spec = sim.physics.sintering
    end = jax.jit(lambda s, p: simulate.rollout(sim, s, p, n_steps, checkpoint=False)[0])(state, params)
    expected = float(sintering.grow_neck("grain_boundary", 0.0, R, R, [1200.0], [every * float(state.dt)], KINETICS,
                                         quadrature_nodes=spec.quadrature_nodes,
                                         newton_iterations=spec.newton_iterations)[-1])
    h = float(sintering.neck_overlap(expected, R, R))
    assert h > 1e4 * max(overlaps)  # at the real modulus the weight presses in nothing the necks would notice
    necks = by_pair(end, end.mechanics.neck)
    assert set(necks) == {(0, 1), (1, 2)}
    np.testing.assert_allclose(list(necks.values()), expected, rtol=1e-12)
    z0, z = np.asarray(state.particles.positions)[:, 2], np.asarray(end.particles.positions)[:, 2]
    np.testing.assert_allclose(z0 - z, [0.0, h, 2 * h], rtol=1e-9, atol=1e-9 * h)
    # the elastic overlaps the stack started with (Hertz's under its weight) carry it still: nothing unbalanced
    resultant, _ = simulate.resultant_forces(sim.physics, end, params)
    weight = float(np.asarray(state.particles.mass)[0]) * G
    assert float(np.max(np.abs(np.asarray(resultant)))) < 1e-6 * weight
    assert float(np.max(np.abs(np.asarray(end.mechanics.velocity)))) == 0.0
    assert not bool(end.sintering.unbalanced) and not bool(end.sintering.unstable)


@pytest.mark.slow
def test_an_insulated_coupled_sintering_cluster_conserves_heat_and_its_necks_grow_monotone():
    # a simple cubic cell of eight spheres, overlapping by 1 % of a radius, at four temperatures
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], np.float64)
    x = corners * (2 * R - 0.01 * R)
    temperature = 1000.0 + 100.0 * np.arange(8) % 400
    sim, state, params, _ = coupled(x, np.full(8, R), temperature, every=5, dt=1e-6)
    run = jax.jit(lambda s, p: simulate.rollout(sim, s, p, 400, checkpoint=False)[0])
    capacity = np.asarray(state.particles.mass) * HEAT
    states = [state]
    for _ in range(5):
        states.append(run(states[-1], params))
    heat = [float(np.asarray(s.particles.temperature) @ capacity) for s in states]
    np.testing.assert_allclose(heat, heat[0], rtol=1e-13)
    assert np.ptp(np.asarray(states[-1].particles.temperature)) < 0.9 * np.ptp(temperature)  # heat did flow
    necks = [by_pair(s, s.mechanics.neck) for s in states]
    contacts = {p for p, a in necks[0].items() if a > 0}
    assert len(contacts) == 12  # the cell's edges
    for p in contacts:
        series = np.array([n[p] for n in necks])
        assert np.all(np.isfinite(series)) and np.all(np.diff(series) > 0.0)
    assert min(necks[-1][p] for p in contacts) > 1.5 * max(necks[0][p] for p in contacts)
    assert float(neck_growth.neck_statistics(states[-1])["shrinkage"]) > 0.005
    assert float(np.max(np.abs(np.asarray(states[-1].mechanics.velocity)))) < 1e-12  # no elastic load appeared


@pytest.mark.slow
def test_a_hot_contact_grows_to_the_law_s_cap_and_stays_there():
    fast = {"A": 1e-8, "activation_energy": 100.0}
    radii = np.array([40e-6, 30e-6])
    x = np.array([[0.0, 0.0, 0.0], [70e-6 - 1e-8, 0.0, 0.0]])
    sim, state, params, _ = coupled(x, radii, 1300.0, "independent", every=10, kinetics=fast)
    run = jax.jit(lambda s, p: simulate.rollout(sim, s, p, 500, checkpoint=False)[0])
    first = run(state, params)
    second = run(first, params)
    cap = float(sintering.kinetic_law("grain_boundary").cap(40e-6, 30e-6,
                                                            sintering.law_params("grain_boundary", fast)))
    assert float(first.mechanics.neck[0]) == pytest.approx(cap, rel=1e-12)
    assert float(second.mechanics.neck[0]) == float(first.mechanics.neck[0])
    assert np.isfinite(float(second.mechanics.neck_overlap[0])) and not bool(second.sintering.unstable)


@pytest.mark.slow
def test_necks_follow_their_pairs_through_a_rebuild_bit_for_bit():
    (sim, state, params, _), _ = stack()
    run = jax.jit(lambda s, p: simulate.rollout(sim, s, p, 500, checkpoint=False)[0])
    grown = run(state, params)
    assert min(by_pair(grown, grown.mechanics.neck).values()) > 1e-6
    through, kept = run(forced_rebuild(grown), params), run(grown, params)
    assert np.all(np.isfinite(np.asarray(through.contacts.neighbor_list.reference_position)))  # it did rebuild
    for a, b in zip(jax.tree.leaves((through.mechanics, through.particles)),
                    jax.tree.leaves((kept.mechanics, kept.particles))):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # control: a rebuild that forgets the necks starts them again from point contacts
    forgot = forced_rebuild(dataclasses.replace(grown, mechanics=dataclasses.replace(
        grown.mechanics, neck=jnp.zeros_like(grown.mechanics.neck))))
    restarted = run(forgot, params)
    assert max(by_pair(restarted, restarted.mechanics.neck).values()) < 0.9 * min(
        by_pair(kept, kept.mechanics.neck).values())


def rhombus():
    """Four spheres in a ring of touching pairs (a rhombus of side 2r - 1e-3 r) whose short diagonal is 2 % of a
    radius apart: outside a list of skin 1 % of a radius at the start, in contact once the ring has shrunk."""
    side = 2 * R - 1e-3 * R
    diagonal = 2 * R + 0.02 * R
    half = math.sqrt(side**2 - (diagonal / 2) ** 2)
    return np.array([[-half, 0, 0], [0, -diagonal / 2, 0], [half, 0, 0], [0, diagonal / 2, 0]])


@pytest.mark.slow
def test_a_list_that_overflows_as_the_packing_shrinks_is_reallocated_and_loses_no_contact():
    fast = {"A": 1e-12, "activation_energy": 100.0}
    ends = {}
    for name, multiplier in (("tight", 1.0), ("roomy", 4.0)):
        sim, state, params, fns = coupled(rhombus(), np.full(4, R), 1200.0, every=10, dt=1e-6, skin=0.01 * R,
                                          multiplier=multiplier, kinetics=fast)
        end, report = rollout.advance(sim, state, params, 2000, 100, reallocate=simulate.reallocate_neighbors(fns))
        ends[name] = (state.contacts.pairs.capacity, end, report)
    (start_capacity, tight, report), (_, roomy, roomy_report) = ends["tight"], ends["roomy"]
    assert start_capacity == 4 and report.reallocations >= 1 and roomy_report.reallocations == 0
    # brute force: every pair of spheres that overlap at the end is on the list, with a neck
    x = np.asarray(tight.particles.positions)
    touching = {(i, j) for i in range(4) for j in range(i + 1, 4) if np.linalg.norm(x[i] - x[j]) < 2 * R}
    necks = by_pair(tight, tight.mechanics.neck)
    assert (1, 3) in touching and touching <= set(necks) and all(necks[p] > 0 for p in touching)
    # the diagonal was closed by the shrinkage, at its pace: its overlap became a neck, not an elastic impact
    assert float(np.max(np.abs(np.asarray(tight.mechanics.velocity)))) < 1e-12
    # and the tight run's necks and positions are the roomy run's, to round-off (capacities differ)
    roomy_necks = by_pair(roomy, roomy.mechanics.neck)
    for p in touching:
        np.testing.assert_allclose(necks[p], roomy_necks[p], rtol=1e-12)
    np.testing.assert_allclose(x, np.asarray(roomy.particles.positions), rtol=0, atol=1e-12 * R)


@pytest.mark.slow
def test_gradients_of_a_neck_and_a_probe_temperature_by_the_kinetic_parameters_equal_central_differences():
    sim, state, params, _ = free_pair("many_body", every=5)

    def observe(log_a, q):
        p = dataclasses.replace(params, sintering={"A": jnp.exp(log_a), "activation_energy": q})
        end, _ = simulate.rollout(sim, state, p, 200, checkpoint=False)  # forward mode only: one plain scan
        return jnp.stack([end.mechanics.neck[0] / 1e-6, end.particles.temperature[0]])

    log_a, q = jnp.log(KINETICS["A"]), KINETICS["activation_energy"]
    jac = jax.jit(jax.jacfwd(observe, argnums=(0, 1)))(log_a, q)
    value = jax.jit(observe)
    for k, (x0, h) in enumerate(((log_a, 1e-3), (q, 1e-2))):
        def at(delta, k=k, x0=x0):
            args = [log_a, q]
            args[k] = x0 + delta
            return np.asarray(value(*args))
        central = (4 * (at(h) - at(-h)) / (2 * h) - (at(2 * h) - at(-2 * h)) / (4 * h)) / 3
        assert np.all(np.abs(central) > 0)
        np.testing.assert_allclose(np.asarray(jac[k]), central, rtol=1e-6)


def test_sintering_with_the_mechanics_refuses_what_it_cannot_grow():
    with pytest.raises(ValueError, match="neck_model"):
        simulate.Physics.create(law="rojek", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                mechanics=True, sintering=neck_growth.Sintering())
    sim, state, params, _ = free_pair("independent")
    with pytest.raises(ValueError, match="MechanicalState.neck"):
        simulate.validate_inputs(sim, dataclasses.replace(state, mechanics=dataclasses.replace(
            state.mechanics, neck=None)), params)
    with pytest.raises(ValueError, match=r"MechanicalState.neck must lie in \[0, min"):
        simulate.validate_inputs(sim, dataclasses.replace(state, mechanics=dataclasses.replace(
            state.mechanics, neck=state.mechanics.neck.at[0].set(50e-6))), params)
    with pytest.raises(ValueError, match="activation_energy"):
        simulate.validate_inputs(sim, state, dataclasses.replace(params, sintering={"activation_energy": -1.0}))
    with pytest.raises(ValueError, match="start of the necks"):
        neck_growth.pair_necks(state.contacts, state.particles.positions, state.particles.radii, "sintered")


# --------------------------------------------------------------------------
# in scenes: [sintering] with physics.mechanics

def coupled_cell(duration=0.002, **sintering_keys):
    """A touching 2 x 2 x 3 cell on a held 1273 K floor (touching it) with the soft elastic mechanics and friction, sintering
    many-body from point contacts (the overlaps its weight presses in stay elastic)."""
    from test_sintering_scene import CELL

    scene = {**CELL, "packing": {**CELL["packing"], "counts": [2, 2, 3]}, "physics": {"mechanics": True},
             "walls": [{**CELL["walls"][0], "penetration": 0.0}],  # touching without pushing
             "mechanics": {"young_modulus": 1e6, "poisson_ratio": 0.3, "damping": 1.0, "friction": 0.5,
                           "rolling_friction": 0.1},
             "sintering": {"every": 5, "shrinkage": "many_body", "k_star_axis": 2,
                           "params": {"A": 1e-15, "activation_energy": 37.0}, **sintering_keys},
             "run": {"duration": duration, "output_every": 400, "checkpoint_every": 800, "formats": ["vtp"]}}
    return scene


@pytest.mark.slow
def test_a_coupled_sintering_scene_closes_its_columns_onto_the_floor_and_reports_its_necks(tmp_path):
    import copy

    from sintercond.output import io
    from sintercond import run as runner
    from sintercond.scene import validate_scene

    scene = validate_scene(coupled_cell())
    model = runner.build_model(copy.deepcopy(scene))
    assert model.physics.mechanics is not None and model.physics.sintering.shrinkage == "many_body"
    assert float(np.max(np.asarray(model.state.mechanics.neck))) == 0.0  # point contacts
    _, summary = runner.run_scene(scene, tmp_path, progress=False, pictures=False)
    end = io.load_checkpoint(tmp_path / "checkpoint.npz", model.state)
    x0, x = np.asarray(model.state.particles.positions), np.asarray(end.particles.positions)
    bottom, top = x0[:, 2] == x0[:, 2].min(), x0[:, 2] == x0[:, 2].max()
    # the floor holds the columns on Hertz's overlap under their weight (three spheres each), and nothing more
    weight = 3 * float(np.asarray(end.particles.mass)[0]) * G
    floor = (3 * weight / (4 * (1e6 / (1 - NU**2)) * math.sqrt(R))) ** (2 / 3)
    np.testing.assert_allclose(x0[bottom, 2] - x[bottom, 2], floor, rtol=0.02)
    g = mechanics.pair_geometry(end.particles.positions, end.particles.radii, end.contacts.pairs.pairs,
                                neck_growth.POINT_CONTACT_GAP)
    h = {tuple(int(v) for v in p): float(o) for p, o, t in zip(np.asarray(g.pairs), np.asarray(
        end.mechanics.neck_overlap), np.asarray(g.touching)) if t}
    assert len(h) == 20  # every contact of the cell, horizontal ones too (point contacts at zero overlap)
    # each column of three closes by the approaches of its two vertical contacts and the elastic overlaps under it
    drop = x0[top, 2] - x[top, 2]
    vertical = [v for (i, j), v in h.items() if abs(x0[i, 2] - x0[j, 2]) > R]
    assert np.all(drop >= 2 * min(vertical)) and np.all(drop <= 2 * max(vertical) + 1e-3 * R)
    history = np.genfromtxt(tmp_path / "history.csv", delimiter=",", names=True)
    assert np.all(np.diff(history["mean_neck_ratio"]) > 0) and history["mean_neck_ratio"][-1] > 0.1
    assert np.all(np.diff(history["k_star_W_mK"][1:]) > 0) and history["k_star_W_mK"][-1] > 0
    assert summary["shrinkage"] > 0 and summary["max_neck_ratio"] == pytest.approx(history["max_neck_ratio"][-1])
    frames = sorted((tmp_path / "vtp").glob("*.vtp"))
    assert frames and b"neck_ratio" in frames[-1].read_bytes()


def _cell_run(tmp_path, name, **mechanics_keys):
    import copy

    from sintercond.output import io
    from sintercond import run as runner
    from sintercond.scene import validate_scene

    scene = coupled_cell(duration=1e-4, every=50)
    scene["mechanics"].update(young_modulus=110e9, **mechanics_keys)
    scene["run"].update(dt=1e-8, output_every=10_000, checkpoint_every=10_000)
    scene = validate_scene(scene)
    model = runner.build_model(copy.deepcopy(scene))
    _, summary = runner.run_scene(scene, tmp_path / name, progress=False, pictures=False)
    return model, io.load_checkpoint(tmp_path / name / "checkpoint.npz", model.state), summary


@pytest.mark.slow
def test_quasi_static_sintering_at_the_real_modulus_moves_as_the_inertial_step_less_hertz_s_static_overlaps(tmp_path):
    # the same cell, steps and neck updates at Ti6Al4V's 110 GPa: with inertia (10,000 steps of 1e-8 s, the elastic
    # limit) and without; they differ by the elastic overlaps the weight presses in, which the quasi-static run
    # leaves out: Hertz's (Eq. 2) under the spheres above, 1e-11 m, against necks' approaches of ~1e-6 m
    model, inertial, _ = _cell_run(tmp_path, "inertial")
    _, quasi, summary = _cell_run(tmp_path, "quasi_static", quasi_static=True)
    assert summary["quasi_static"] and summary["mechanical_step_s"] is None and summary["steps"] == 10_000
    x0 = np.asarray(model.state.particles.positions)
    sink = np.asarray(quasi.particles.positions) - np.asarray(inertial.particles.positions)
    mass = float(np.asarray(model.state.particles.mass)[0])
    e_wall, e_pair = 110e9 / (1 - NU**2), 110e9 / (2 * (1 - NU**2))

    def hertz(force, e_star, r_star):
        return (3 * force / (4 * e_star * math.sqrt(r_star))) ** (2 / 3)

    floor = hertz(3 * mass * G, e_wall, R)
    layers = np.cumsum([floor, hertz(2 * mass * G, e_pair, R / 2), hertz(mass * G, e_pair, R / 2)])
    level = np.searchsorted(np.unique(x0[:, 2]), x0[:, 2])
    # the bottom layer sits on the floor by Hertz's overlap; above it the inertial run's first neck update also took
    # the elastic overlap its contacts had reached as neck (a point contact closed by the motion), so each layer's
    # sink holds its elastic overlaps once or twice
    np.testing.assert_allclose(sink[level == 0, 2], floor, rtol=0.02)
    assert np.all(sink[:, 2] >= 0.98 * layers[level]) and np.all(sink[:, 2] <= 2.0 * layers[level])
    np.testing.assert_allclose(sink[:, :2], 0.0, atol=0.05 * floor)
    necks = by_pair(quasi, quasi.mechanics.neck)
    assert min(necks.values()) > 0.15 * R
    approach = float(np.max(np.asarray(quasi.mechanics.neck_overlap)))
    assert float(np.max(np.abs(sink))) < 1e-4 * approach  # what the quasi-static run leaves out, against the necks
    np.testing.assert_allclose(list(necks.values()), list(by_pair(inertial, inertial.mechanics.neck).values()),
                               rtol=1e-7)
    np.testing.assert_allclose(np.asarray(quasi.particles.temperature), np.asarray(inertial.particles.temperature),
                               atol=2e-4)
    assert float(np.max(np.abs(np.asarray(quasi.mechanics.velocity)))) == 0.0


def test_quasi_static_sintering_steps_at_the_thermal_limit_not_the_elastic_one():
    # the built step against the elastic one of today's softened explicit runs (1e7 Pa) and of the real modulus
    import copy

    from sintercond import run as runner
    from sintercond.scene import validate_scene

    def step(**mechanics_keys):
        scene = coupled_cell(duration=0.01)
        scene["mechanics"].update(mechanics_keys)
        return runner.build_model(validate_scene(copy.deepcopy(scene)))

    quasi, soft, real = step(young_modulus=110e9, quasi_static=True), step(young_modulus=1e7), step(young_modulus=110e9)
    assert quasi.dt == pytest.approx(0.01 / 31) and quasi.limits["thermal"] >= quasi.dt
    assert "mechanical" not in quasi.limits and quasi.sized_speed is None
    assert quasi.dt > 100 * soft.dt and quasi.dt > 1e4 * real.dt


@pytest.mark.slow
@pytest.mark.parametrize("quasi_static", [False, True])
def test_a_coupled_sintering_run_killed_mid_way_resumes_bitwise(tmp_path, quasi_static):
    import copy

    from sintercond import run as runner
    from sintercond.scene import validate_scene

    scene = coupled_cell(duration=0.0012)
    if quasi_static:  # at the real modulus, 40 thermal steps with three chunks and two checkpoints
        scene["mechanics"].update(young_modulus=110e9, quasi_static=True)
        scene["run"].update(duration=0.012, output_every=10, checkpoint_every=20)
    scene = validate_scene(scene)
    full, _ = runner.run_scene(copy.deepcopy(scene), tmp_path / "full", progress=False, pictures=False)
    runner.run_scene(copy.deepcopy(scene), tmp_path / "cut", progress=False, pictures=False, stop_after_chunks=2)
    resumed, _ = runner.resume(tmp_path / "cut", progress=False, pictures=False)
    np.testing.assert_array_equal(np.asarray(resumed), np.asarray(full))
    assert (tmp_path / "full" / "history.csv").read_bytes() == (tmp_path / "cut" / "history.csv").read_bytes()
    if quasi_static:  # a run folder whose history has other columns (an earlier version's) is not appended to
        from sintercond.scene import SceneError

        runner.run_scene(copy.deepcopy(scene), tmp_path / "old", progress=False, pictures=False, stop_after_chunks=2)
        history = tmp_path / "old" / "history.csv"
        history.write_text(history.read_text().replace(",height_shrinkage,volume_shrinkage", "", 1))
        before = sorted(p.name for p in (tmp_path / "old").rglob("*"))
        with pytest.raises(SceneError, match="wrote history.csv with the columns"):
            runner.resume(tmp_path / "old", progress=False, pictures=False)
        assert sorted(p.name for p in (tmp_path / "old").rglob("*")) == before


def test_the_start_of_the_necks_is_a_key_of_runs_with_the_mechanics_only():
    from sintercond import run as runner
    from sintercond.scene import SceneError, validate_scene
    from test_sintering_scene import CELL

    model = runner.build_model(validate_scene(coupled_cell(start_necks="overlap")))
    assert model.physics.sintering is not None
    without = {**CELL, "sintering": {**CELL["sintering"], "start_necks": "point"}}
    with pytest.raises(SceneError, match=r"sintering\.start_necks .* without the mechanics"):
        validate_scene(without)
    with pytest.raises(SceneError, match=r"sintering\.start_necks must be one of"):
        validate_scene(coupled_cell(start_necks="sintered"))


@pytest.mark.slow
def test_a_quasi_static_preheating_bed_at_110_gpa_sinters_in_its_container_and_reports_its_shrinkage(tmp_path):
    # the built-in preheating bed (its ramp, its 110 GPa), rolled 0.5 mm wide, with the mechanics quasi-static:
    # the step is the thermal one, the floor holds its layer, the bed shrinks away from its walls and new contacts join
    import copy

    from sintercond.output import io
    from sintercond import run as runner
    from sintercond.beds import packing
    from sintercond.scene import load_scene, validate_scene

    scene = load_scene("ti6al4v_preheating_bed", duration=0.05)
    scene["packing"] = {"kind": "powder_bed", "method": "roll", "lateral_size": 5e-4, "height": 4e-4,
                        "diameter_range": [45e-6, 105e-6], "seed": 0}
    scene["physics"] = {"mechanics": True}
    scene["mechanics"]["quasi_static"] = True
    scene["sintering"]["shrinkage"] = "many_body"
    scene["run"].update(output_every=250)
    scene = validate_scene(scene)
    model = runner.build_model(copy.deepcopy(scene))
    assert model.dt == pytest.approx(0.05 / round(0.05 / (0.9 * model.limits["thermal"]) + 0.5), rel=0.02)
    _, summary = runner.run_scene(scene, tmp_path, progress=False, pictures=False)  # warns if particles escape
    end = io.load_checkpoint(tmp_path / "checkpoint.npz", model.state)
    x0, x = np.asarray(model.state.particles.positions), np.asarray(end.particles.positions)
    held = np.asarray(model.state.sintering.supports)[:, 2]
    assert held.sum() > 10 and np.array_equal(x[held, 2], x0[held, 2])  # the floor's layer stays on it
    assert np.all(x[:, :2] >= x0[:, :2].min(axis=0)) and np.all(x[:, :2] <= x0[:, :2].max(axis=0))
    history = np.genfromtxt(tmp_path / "history.csv", delimiter=",", names=True)
    # the plate's particles follow the ramp (Rizza & Galati's Eq. 6 with its erratum: 845 K + 17.12 K a 0.38 s step)
    np.testing.assert_allclose(history["T_max_K"], 845.0 + 17.12 * np.ceil(history["time_s"] / 0.38), rtol=1e-12)
    assert np.all(history["kinetic_energy_J"] == 0.0) and summary["kinetic_energy_J"] == 0.0
    assert np.all(np.diff(history["contacts"]) >= 0) and history["contacts"][-1] > history["contacts"][0]
    for name in ("mean_neck_ratio", "height_shrinkage", "volume_shrinkage", "k_star_W_mK"):
        assert np.all(np.diff(history[name]) > 0), name
    strain = packing.packing_shrinkage(x0, x)
    assert summary["height_shrinkage"] == pytest.approx(strain["height_shrinkage"], rel=1e-9)
    assert summary["volume_shrinkage"] == pytest.approx(strain["volume_shrinkage"], rel=1e-9)
    assert strain["volume_shrinkage"] > strain["height_shrinkage"] > 0  # the bed shrinks sideways too
    assert 0.2 * (1 - packing.surface_height(x, model.radii, 5e-4) / packing.surface_height(x0, model.radii, 5e-4)) \
        < strain["height_shrinkage"] < 1.0 * strain["volume_shrinkage"]


def test_a_moving_bed_that_lifts_off_its_floor_reports_no_k_star_rather_than_stopping_the_run():
    # an inertial bed can bounce off its floor at an output: no particle then touches the face heat is imposed on
    import dataclasses

    from sintercond import run as runner
    from sintercond.output import observe
    from sintercond.scene import load_scene, validate_scene

    scene = load_scene("ti6al4v_preheating_bed", duration=0.01)
    scene["packing"] = {"kind": "powder_bed", "method": "roll", "lateral_size": 5e-4, "height": 2e-4,
                        "diameter_range": [45e-6, 105e-6], "seed": 0}
    scene["physics"] = {"mechanics": True}
    del scene["preheating"]
    model = runner.build_model(validate_scene(scene))
    state = model.state
    g = mechanics.pair_geometry(state.particles.positions, state.particles.radii, state.contacts.pairs.pairs,
                                neck_growth.POINT_CONTACT_GAP)
    r_i, r_j = state.particles.radii[g.i], state.particles.radii[g.j]
    neck = jnp.where(g.touching, 0.2 * jnp.minimum(r_i, r_j), 0.0)
    state = dataclasses.replace(state, mechanics=dataclasses.replace(
        state.mechanics, neck=neck, neck_overlap=jnp.where(g.touching, sintering.neck_overlap(neck, r_i, r_j), 0.0)))
    assert observe.sintered_conductivity(model, state) > 0
    lifted = dataclasses.replace(state, particles=dataclasses.replace(
        state.particles, positions=state.particles.positions + jnp.array([0.0, 0.0, 1e-7])))
    assert math.isnan(observe.sintered_conductivity(model, lifted))


def test_quasi_static_mechanics_is_refused_where_nothing_would_move_it():
    from sintercond.scene import SceneError, validate_scene

    def scene(sintering=None, walls=None, **mechanics_keys):
        s = coupled_cell()
        s["mechanics"].update({"quasi_static": True, **mechanics_keys})
        if sintering is not None:
            s["sintering"].update(sintering)
        if walls is not None:
            s["walls"] = walls
        return s

    independent = scene({"shrinkage": "independent"})
    with pytest.raises(SceneError, match=r'mechanics\.quasi_static = true .* sintering\.shrinkage = "many_body"'):
        validate_scene(independent)
    no_sintering = scene()
    del no_sintering["sintering"]
    with pytest.raises(SceneError, match=r"mechanics\.quasi_static = true .* \(without sintering nothing would move"):
        validate_scene(no_sintering)
    moving = scene(walls=[{**coupled_cell()["walls"][0], "velocity": [0.0, 0.0, 1e-3]}])
    with pytest.raises(SceneError, match=r"walls\[0\]\.velocity: .* drop mechanics\.quasi_static"):
        validate_scene(moving)
    with pytest.raises(SceneError, match=r"mechanics\.quasi_static must be"):
        validate_scene(scene(quasi_static="yes"))
    with pytest.raises(ValueError, match=r"Mechanics\(quasi_static=True\) .*=Sintering\(shrinkage='many_body'\)"):
        coupled(np.zeros((1, 3)), [R], 1000.0, "independent", quasi_static=True)
    with pytest.raises(ValueError, match=r"Mechanics\.quasi_static must be True or False"):
        mechanics.Mechanics(quasi_static=1)


def test_a_contact_the_shrinkage_closes_in_one_update_takes_its_overlap_as_a_neck_not_an_impact():
    # fast kinetics: the first update closes the ring's short diagonal by some 0.5 um at once, which as an elastic
    # Hertz overlap would throw the ring apart at some 0.7 m/s
    sim, state, params, _ = coupled(rhombus(), np.full(4, R), 1200.0, every=10, dt=1e-6, skin=0.05 * R,
                                    kinetics={"A": 1e-10, "activation_energy": 100.0})
    assert (1, 3) not in {p for p, a in by_pair(state, state.mechanics.neck).items() if a > 0}
    end = jax.jit(lambda s, p: simulate.rollout(sim, s, p, 20, checkpoint=False)[0])(state, params)
    x = np.asarray(end.particles.positions)
    assert np.linalg.norm(x[1] - x[3]) < 2 * R - 0.2e-6  # closed deep
    necks, approaches = by_pair(end, end.mechanics.neck), by_pair(end, end.mechanics.neck_overlap)
    np.testing.assert_allclose(approaches[(1, 3)], 2 * R - np.linalg.norm(x[1] - x[3]), rtol=1e-6)
    assert necks[(1, 3)] > 0
    assert float(np.max(np.abs(np.asarray(end.mechanics.velocity)))) < 1e-12
