"""Moving and sliding walls, the step they need, and the run-time guards of the coupled step (issue 28).

References: angular momentum about the contact point (a sphere dropped on a belt moving at U ends rolling at
2U/7, whatever the friction or the spring), Hertz's static overlap under the weight (a floor rising at w carries
the sphere at w on that overlap), the collision-sized step of sintercond.laws.forces at the wall's speed, the
distances the wall and the beam's spot travel per step, and the energy a resting or colliding system has.
"""

import copy
import dataclasses
import math

import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import examples, rollout
from sintercond.sim import guards, mechanics
from sintercond import run as runner
from sintercond.scene import BEAM_STEP_FRACTION, WALL_STEP_FRACTION, SceneError, validate_scene
from sintercond.laws.walls import PlaneWall
from test_mechanics import E0, MASS, NU, G, R, _params, _run, _scene

DELTA = examples.static_overlap(MASS * G, R, E0, NU)  # Hertz overlap under the weight (m)


def test_a_sphere_on_a_moving_belt_ends_rolling_at_two_sevenths_of_the_belt_speed():
    """Friction acts at the contact point, so the angular momentum about it, m v r + I omega, stays 0: when the
    slip stops (v - r omega = U) the centre moves at U / (1 + m r^2 / I) = 2U/7 and spins at -5U/(7r). Slip ends
    at U / (3.5 mu g); 20 times that, the Mindlin spring's transient has died out."""
    belt, mu, dt = 0.01, 0.3, 2e-5
    floor = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), velocity=(belt, 0.0, 0.0))
    sim, state, params = _scene([[0.0, 0.0, R - DELTA]], [[0.0, 0.0, 0.0]], dt, _params(mu=mu), walls=(floor,),
                                friction=True, wall_friction=True)
    n = round(20 * belt / (3.5 * mu * G) / dt)
    _, saved = _run(sim, state, params, n, n, lambda s: jnp.concatenate([s.mechanics.velocity[0],
                                                                         s.mechanics.spin[0]]))
    v = np.asarray(saved[-1])
    assert v[0] == pytest.approx(2 * belt / 7, rel=1e-10)
    assert v[4] * R == pytest.approx(-5 * belt / 7, rel=1e-10)
    assert abs(v[1]) + abs(v[3]) + abs(v[5]) < 1e-15  # no motion across the belt


def test_a_rising_floor_carries_the_sphere_at_its_speed_on_the_static_overlap():
    """A floor moving up at w under a resting sphere: once the critically damped contact has settled, the
    sphere moves at w, on Hertz's overlap of its weight measured from the moving plane."""
    w = 1e-3
    floor = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), velocity=(0.0, 0.0, w))
    sim, state, params = _scene([[0.0, 0.0, R - DELTA]], [[0.0, 0.0, 0.0]], 2e-5, _params(), walls=(floor,))
    _, saved = _run(sim, state, params, 5000, 1000, lambda s: jnp.stack(
        [s.mechanics.velocity[0, 2], s.particles.positions[0, 2] - w * s.time]))
    velocity, height = np.asarray(saved[1:]).T  # from 0.02 s on
    np.testing.assert_allclose(velocity, w, rtol=1e-9)
    np.testing.assert_allclose(R - height, DELTA, rtol=1e-9)


def _resting(**extra):
    """One sphere resting on an insulated floor, with mechanics (a scene)."""
    scene = {
        "packing": {"kind": "spheres", "centres": [[2e-3, 2e-3, 1e-3]], "radii": 1e-3},
        "material": {"density": 3000.0, "specific_heat": 100.0, "conductivity": 60.0},
        "conduction": {"law": "conductivity", "neck_model": "hertz"},
        "initial": {"temperature": 300.0},
        "walls": [{"axis": 2, "side": "min", "mode": "insulated", "penetration": 0.0}],
        "physics": {"mechanics": True},
        "mechanics": {"young_modulus": 1e6, "poisson_ratio": 0.3},
        "run": {"duration": 2e-3, "output_every": 10, "checkpoint_every": 100, "formats": ["vtp"]},
    }
    for section, values in extra.items():
        scene[section].update(values) if isinstance(values, dict) else scene.__setitem__(section, values)
    return validate_scene(scene)


def test_a_scene_walls_velocity_reaches_the_wall():
    """walls[k].velocity was validated and then dropped: the built wall stood still."""
    scene = _resting(walls=[{"axis": 2, "side": "min", "mode": "insulated", "penetration": 0.0,
                             "velocity": [1e-3, 0.0, 2e-3]}])
    model = runner.build_model(scene)
    assert model.physics.mechanics.walls[0].velocity == (1e-3, 0.0, 2e-3)


def test_the_automatic_step_covers_a_moving_wall():
    """A floor rising at 0.5 m/s: the mechanical step is sized for physics.impact_velocity plus the wall's normal
    speed, and the wall moves at most WALL_STEP_FRACTION of the smallest radius per step."""
    speed = 0.5
    two = {"kind": "spheres", "centres": [[2e-3, 2e-3, 1e-3], [6e-3, 2e-3, 0.5e-3]], "radii": [1e-3, 0.5e-3]}
    scene = _resting(packing=two, walls=[{"axis": 2, "side": "min", "mode": "insulated", "penetration": 0.0,
                                          "velocity": [0.3, 0.0, speed]}])  # the sliding part sizes nothing
    model = runner.build_model(scene)
    assert model.sized_speed == pytest.approx(0.05 + speed, rel=1e-15)
    alone = runner.build_model(_resting(packing=two))
    particles, neighbors = alone.state.particles, alone.state.contacts.neighbors
    expected = float(mechanics.mechanical_time_step(model.physics.mechanics, particles, neighbors,
                                                model.params.mechanics, 0.05 + speed))
    assert model.limits["mechanical"] == pytest.approx(expected, rel=1e-12)
    assert model.limits["mechanical"] < alone.limits["mechanical"]
    assert model.limits["wall"] == pytest.approx(WALL_STEP_FRACTION * 0.5e-3 / speed, rel=1e-12)  # the smaller
    assert model.dt * speed <= WALL_STEP_FRACTION * 0.5e-3 and model.dt <= model.limits["mechanical"]


def test_a_fixed_step_a_wall_outruns_is_refused_naming_the_wall():
    scene = _resting(walls=[{"axis": 2, "side": "min", "mode": "insulated", "penetration": 0.0,
                             "velocity": [0.0, 0.0, 1000.0]}], run={"dt": 1e-6, "duration": 1e-5})
    with pytest.raises(SceneError, match=r"run\.dt: dt = 1e-06 s exceeds .*walls\[0\]\.velocity"):
        runner.build_model(scene)


def test_a_receding_wall_sizes_nothing():
    """A floor moving away from the packing meets nothing faster than the particles themselves."""
    scene = _resting(walls=[{"axis": 2, "side": "min", "mode": "insulated", "penetration": 0.0,
                             "velocity": [0.0, 0.0, -1000.0]}])
    model = runner.build_model(scene)
    assert model.sized_speed == 0.05 and "wall" not in model.limits


def test_the_beam_spot_moves_at_most_a_fraction_of_its_radius_per_step():
    spot, speed = 1e-4, 2.0
    base = {"packing": {"kind": "simple_cubic", "counts": [4, 2, 2], "spacing": 1e-4, "radius": 0.52e-4},
            "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.6},
            "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0},
            "beam": {"intensity": 2e8, "attenuation": 2e4, "spot_radius": spot, "absorptance": 0.7, "speed": speed,
                     "path": [[0.0, 1e-4], [3e-4, 1e-4]]},
            "run": {"duration": 1e-4, "dt": "auto", "output_every": 5, "checkpoint_every": 10, "formats": ["vtp"]}}
    model = runner.build_model(validate_scene(copy.deepcopy(base)))
    assert model.limits["beam"] == pytest.approx(BEAM_STEP_FRACTION * spot / speed, rel=1e-15)
    assert model.dt * speed <= BEAM_STEP_FRACTION * spot
    stationary = copy.deepcopy(base)
    stationary["beam"]["path"] = [[1e-4, 1e-4]]  # a spot that does not move sizes nothing
    assert "beam" not in runner.build_model(validate_scene(stationary)).limits
    base["run"]["dt"] = 2 * BEAM_STEP_FRACTION * spot / speed
    with pytest.raises(SceneError, match=r"run\.dt: .* exceeds .*beam\.speed = 2 m/s.*beam\.spot_radius"):
        runner.build_model(validate_scene(base))


# --------------------------------------------------------------------------
# run-time guards


def test_an_approach_speed_the_step_was_not_sized_for_stops_the_run(tmp_path):
    """physics.impact_velocity = 1e-9 m/s sized a step far too long for the sphere falling onto the floor (issue
    28: the bed reached 3,196 m/s with exit code 0). The first output sees the sphere approach the floor faster
    than the sizing speed, and the run stops naming the key."""
    scene = _resting(physics={"mechanics": True, "impact_velocity": 1e-9})
    with pytest.raises(guards.UnstableStep, match=r"particle 0 and wall 0 approach at .* m/s, above the 1e-09 m/s "
                                                  r"the time step was sized for: raise physics\.impact_velocity"):
        runner.run_scene(scene, tmp_path / "out", progress=False)


def test_a_wall_driven_through_a_soft_sphere_stops_the_run(tmp_path):
    """Issue 28: a floor rising at 1,000 m/s (an allowed value) under a 1 MPa sphere. The step is sized for that
    speed now, but no Hertz contact can stop the sphere within its radius: the run stops once an overlap passes
    half the radius, naming the wall, instead of reporting a sphere the wall has gone through."""
    scene = _resting(walls=[{"axis": 2, "side": "min", "mode": "insulated", "penetration": 0.0,
                             "velocity": [0.0, 0.0, 1000.0]}], run={"duration": 2e-6, "checkpoint_every": 10})
    with pytest.raises(guards.UnstableStep, match=r"the overlap of particle 0 and wall 0 reached .* the contact "
                                                  r"is crushed; slow the walls .*walls\[k\]\.velocity"):
        runner.run_scene(scene, tmp_path / "out", progress=False)


def test_a_sized_run_passes_the_guards(tmp_path):
    """The same sphere with the default sizing speed settles on the floor: no guard fires, and it ends on
    Hertz's overlap of its weight."""
    scene = _resting(run={"duration": 0.05, "output_every": 500, "checkpoint_every": 500})
    runner.run_scene(scene, tmp_path / "out", progress=False)
    history = runner.read_history(tmp_path / "out")
    weight = 3000.0 * 4 / 3 * math.pi * 1e-9 * G
    assert history["max_overlap_m"][-1] == pytest.approx(examples.static_overlap(weight, 1e-3, 1e6, 0.3), rel=1e-3)


def test_the_guard_counts_the_walls_own_speed():
    """A floor rising at 0.2 m/s under a resting sphere: the sphere approaches the wall at 0.2 m/s although it
    is at rest, above a sizing speed of 0.1 m/s."""
    floor = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), velocity=(0.0, 0.0, 0.2))
    sim, state, params = _scene([[0.0, 0.0, R + 1e-4 * R]], [[0.0, 0.0, 0.0]], 1e-6, _params(), walls=(floor,),
                                gravity=(0.0, 0.0, 0.0))
    with pytest.raises(guards.UnstableStep, match=r"particle 0 and wall 0 approach at 0\.19\d* m/s, above the 0\.1"):
        rollout.advance(sim, state, params, 10, 10, check=guards.motion_guard(sim, state, params, 0.1, "v_rel"))


def test_the_energy_balance_counts_gravitys_work():
    """A sphere thrown up at 0.5 m/s trades its kinetic energy for height: with gravity's work in the balance no
    guard fires, and at the top (t = v/g) the kinetic energy is gone while the energy is unchanged."""
    v0 = 0.5
    sim, state, params = _scene([[0.0, 0.0, 0.0]], [[0.0, 0.0, v0]], 1e-5, _params(), gravity=(0.0, 0.0, -G))
    check = guards.motion_guard(sim, state, params, 1.0, "v_rel")
    end, _ = rollout.advance(sim, state, params, round(v0 / G / 1e-5), 500, check=check)
    start, top = guards.motion_figures(sim.physics, state, params), guards.motion_figures(sim.physics, end, params)
    assert top.kinetic < 1e-6 * start.kinetic
    assert top.gravity_potential - start.gravity_potential == pytest.approx(start.kinetic, rel=1e-3)  # O(g dt / v)


def _two_spheres(velocity, dt, overlap=0.0):
    """Two spheres on the x axis without gravity, ``overlap`` (m) deep, the first moving at ``velocity``."""
    sim, state, params = _scene([[0.0, 0.0, 0.0], [2 * R - overlap, 0.0, 0.0]], [[velocity, 0.0, 0.0], [0.0] * 3],
                                dt, _params(xi_con=0.0), gravity=(0.0, 0.0, 0.0))
    return sim, state, params


def test_the_guard_names_the_pair_that_approaches_too_fast():
    sim, state, params = _two_spheres(0.2, 1e-6)
    check = guards.motion_guard(sim, state, params, 0.1, "v_rel")
    with pytest.raises(guards.UnstableStep, match=r"particles 0 and 1 approach at 0\.2 m/s, above the 0\.1 m/s"):
        rollout.advance(sim, state, params, 10, 10, check=check)
    check = guards.motion_guard(sim, state, params, 0.25, "v_rel")
    rollout.advance(sim, state, params, 10, 10, check=check)  # sized for it: no complaint


def test_the_energy_guard_stops_an_unstable_step_and_passes_a_stable_one():
    """Two spheres pressed 1 % of a radius together and released, undamped, without gravity: a stable step keeps
    their kinetic plus elastic energy (symplectic Euler: bounded error); a step 5 times the stability limit of
    that overlap lets it grow, and the guard stops the run (sized for any approach speed, it is the energy that
    tells)."""
    overlap = 0.01 * R
    sim, state, params = _two_spheres(0.0, 1.0, overlap)
    r_star, m_star = R / 2, MASS / 2
    e_star = E0 / (2 * (1 - NU**2))
    omega = math.sqrt(2 * e_star * math.sqrt(r_star * overlap) / m_star)  # Hertz tangent stiffness over m*
    stable = dataclasses.replace(state, dt=jnp.asarray(0.1 / omega))
    check = guards.motion_guard(sim, stable, params, 1e3, "v_rel")
    end, _ = rollout.advance(sim, stable, params, 2000, 100, check=check)
    figures = guards.motion_figures(sim.physics, end, params)
    start = guards.motion_figures(sim.physics, stable, params)
    assert start.elastic > 0 and figures.kinetic + figures.elastic == pytest.approx(start.elastic, rel=0.05)
    unstable = dataclasses.replace(state, dt=jnp.asarray(10.0 / omega))  # omega dt = 10 > 2
    check = guards.motion_guard(sim, unstable, params, 1e3, "v_rel")
    with pytest.raises(guards.UnstableStep, match=r"exceeds what the start .* can supply: the time step is unstable"):
        rollout.advance(sim, unstable, params, 200, 20, check=check)


def test_hertz_elastic_energy_is_the_integral_of_the_elastic_force():
    from scipy.integrate import quad

    from sintercond.laws import forces

    r_star, e_star = 3e-4, 2e9
    for delta in (1e-9, 1e-7, 1e-5):
        work, _ = quad(lambda d: float(forces.hertz_normal_force(d, 0.0, r_star, 1.0, e_star, 0.0)), 0.0, delta,
                       epsabs=0.0, epsrel=1e-12)
        assert float(forces.hertz_elastic_energy(delta, r_star, e_star)) == pytest.approx(work, rel=1e-10)
    assert float(forces.hertz_elastic_energy(-1e-6, r_star, e_star)) == 0.0
