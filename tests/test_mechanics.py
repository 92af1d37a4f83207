"""The coupled thermo-mechanical step against independent references.

References: Hertz's static overlap under the weight, the quasi-static overlap
under the softened modulus (Eq. 42), momentum conservation, the energy of an
undamped Hertz collision, the restitution relation of the delta^(1/4)-damped
Hertz contact (as in tests/test_forces.py), Coulomb's limit on an incline and
the rolling acceleration 5/7 g sin(a) of a solid sphere, central differences.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import examples, simulate
from sintercond.sim import mechanics
from sintercond.state import particle_state
from sintercond.laws.walls import PlaneWall
from _helpers import contact_loads, forced_rebuild

R, RHO, E0, NU, G = 1e-3, 3000.0, 1e6, 0.3, 9.81
MASS = 4.0 / 3.0 * math.pi * R**3 * RHO


def _f64(x):
    return jnp.asarray(float(x), jnp.float64)


def _params(**mech):
    base = dict(E0=E0, nu=NU, xi_con=1.0, xi_fric=1.0, xi_rol=0.0, mu=0.0, mu_r=0.0, theta_star=400.0, rate=1.0,
                E_min=0.0)
    base.update(mech)
    return simulate.Params(conductivity=jnp.asarray([60.0]), specific_heat=jnp.asarray([100.0]),
                           mechanics=mechanics.MechanicalParams(**{k: _f64(v) for k, v in base.items()}))


def _scene(positions, velocity, dt, params, skin=0.1 * R, **physics):
    positions = np.asarray(positions, np.float64)
    particles = particle_state(positions, R, 300.0, RHO)
    phys = simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                   mechanics=True, **physics)
    contacts, fns = simulate.dynamic_contacts(positions, particles.radii, skin, capacity_multiplier=3.0)
    motion = mechanics.mechanical_state(phys.mechanics, positions, contacts, velocity=velocity)
    return simulate.simulator(phys, fns), simulate.init_state(particles, contacts, dt, mechanics=motion), params


def _run(sim, state, params, n_steps, every, fn):
    return jax.jit(lambda s, p: simulate.rollout(sim, s, p, n_steps, simulate.SaveAt(every, fn), checkpoint=False))(
        state, params)


def _overlap(s):
    return s.particles.radii[0] - s.particles.positions[0, 2]


# --------------------------------------------------------------------------
# Example 5.1


@pytest.mark.slow
def test_example_5_1_settles_on_the_weight_and_hertz_overlap():
    sim, state, params, _ = examples.example_5_1(softening=False)
    final, saved = _run(sim, state, params, 10000, 100, lambda s: jnp.stack([_overlap(s), s.mechanics.velocity[0, 2]]))
    delta = examples.static_overlap(MASS * G, R, E0, NU)
    assert float(saved[-1, 0]) == pytest.approx(delta, rel=1e-9)  # 0.2 s: critically damped long before
    assert abs(float(saved[-1, 1])) < 1e-12
    loads = _loads(sim, final, params)
    assert float(loads.wall_normal_force[0, 0]) == pytest.approx(MASS * G, rel=1e-6)  # 1.233e-4 N
    assert MASS * G == pytest.approx(1.233e-4, rel=1e-3)
    assert float(loads.force[0, 2]) == pytest.approx(0.0, abs=1e-6 * MASS * G)


def _loads(sim, state, params):
    p, mp = state.particles, params.mechanics
    geometry = mechanics.pair_geometry(p.positions, p.radii, state.contacts.pairs.pairs)
    modulus = mechanics.particle_modulus(sim.physics.mechanics, mp, p.temperature, p.material)
    nu = jnp.broadcast_to(mp.nu, p.radii.shape)
    return contact_loads(sim.physics.mechanics, mp, geometry, p.positions, p.radii, p.mass, modulus, nu,
                                   state.mechanics, state.time, state.dt)


@pytest.mark.slow
def test_softened_overlap_follows_the_quasi_static_oracle():
    sim, state, params, _ = examples.example_5_1(softening=True)
    # start above the onset so that the modulus changes from the first contact on
    state = dataclasses.replace(state, particles=dataclasses.replace(state.particles,
                                                                     temperature=jnp.asarray([450.0])))
    _, saved = _run(sim, state, params, 25000, 500, lambda s: jnp.stack([_overlap(s), s.particles.temperature[0]]))
    saved = np.asarray(saved)[2:]  # settled after 20 ms
    modulus = E0 * np.exp(np.minimum(0.0, 1.0 - saved[:, 1] / 400.0))
    oracle = np.array([examples.static_overlap(MASS * G, R, e, NU) for e in modulus])
    np.testing.assert_allclose(saved[:, 0], oracle, rtol=2e-4)  # lag ~ (heating rate / contact frequency)
    assert saved[-1, 0] > 1.05 * saved[0, 0]  # it did soften
    assert saved[-1, 1] > saved[0, 1] + 25  # and heat


@pytest.mark.slow
def test_example_5_1_softening_grows_the_contact_and_heats_faster():
    every = 1000  # 0.02 s
    obs = lambda s: jnp.stack([s.particles.temperature[0], _overlap(s)])  # noqa: E731
    runs = {}
    for softening in (False, True):
        sim, state, params, n = examples.example_5_1(softening=softening, t_end=40.0)
        runs[softening] = np.asarray(_run(sim, state, params, n, every, obs)[1])
    t = (np.arange(len(runs[True])) + 1) * every * 2e-5
    # contact area pi r delta at the end, softened over unsoftened (the paper: about 63 %)
    gain = runs[True][-1, 1] / runs[False][-1, 1] - 1
    assert gain == pytest.approx((math.exp(-0.75)) ** (-2.0 / 3.0) - 1, rel=1e-3)  # E(700 K) = E0 e^(-3/4)
    assert 0.6 < gain < 0.7
    # equilibrium: within 1 K of the floor
    t_eq = {s: t[np.argmax(700.0 - runs[s][:, 0] < 1.0)] for s in runs}
    assert t_eq[True] < t_eq[False]
    assert runs[True][-1, 0] == pytest.approx(700.0, abs=1e-3)
    assert np.all(runs[True][:, 0] >= runs[False][:, 0] - 1e-9)


def test_time_step_above_the_limit_is_refused():
    with pytest.raises(ValueError, match="exceeds the mechanical time step"):
        examples.example_5_1(dt=1e-3)


def test_mechanics_spec_is_validated():
    with pytest.raises(ValueError, match="contacts='dynamic'"):
        simulate.Physics.create(mechanics=True, conductance="lifted")
    with pytest.raises(ValueError, match="mechanical walls"):
        simulate.Physics.create(walls=(PlaneWall((0, 0, 0), (0, 0, 1)),))
    wall = PlaneWall([0, 0, 0], [0, 0, 1])
    physics = simulate.Physics.create(mechanics=True, contacts="dynamic", conductance="lifted", walls=(wall,))
    hash(physics)  # lists turned into tuples


# --------------------------------------------------------------------------
# two spheres head-on


def _head_on(xi, dt, n_steps, v0=0.1):
    sim, state, params = _scene([[0, 0, 0], [2 * R + 1e-6, 0, 0]], [[v0, 0, 0], [-v0, 0, 0]], dt,
                                _params(xi_con=xi), gravity=(0.0, 0.0, 0.0))

    def obs(s):
        v = s.mechanics.velocity
        return jnp.concatenate([jnp.sum(s.particles.mass[:, None] * v, axis=0), v[:, 0]])

    return _run(sim, state, params, n_steps, 10, obs)[1]


@pytest.mark.slow
def test_head_on_momentum_energy_and_restitution():
    dt = 1e-6
    # momentum: zero to round-off at every step
    saved = np.asarray(_head_on(0.3, dt, 3000))
    assert np.max(np.abs(saved[:, :3])) < 1e-15 * MASS * 0.1 * 10
    # energy without damping: the collision returns the kinetic energy up to O(dt^2)
    errors = []
    for h in (2 * dt, dt):
        v = np.asarray(_head_on(0.0, h, int(round(3e-3 / h))))[-1, 3:]
        errors.append(abs(v[1] / 0.1 - 1.0))
    assert errors[1] < 1e-4
    assert errors[1] < errors[0] / 3  # second order
    # restitution with damping against the relation of the delta^(1/4)-damped Hertz contact
    for xi in (0.1, 0.3):
        v = np.asarray(_head_on(xi, dt, 3000))[-1, 3:]
        beta = xi * math.sqrt(6.0 / 5.0)
        e = math.exp(-math.pi * beta / math.sqrt(1.0 - beta**2))
        assert (v[1] - v[0]) / 0.2 == pytest.approx(e, rel=2e-3)
        assert v[1] / 0.1 < 1.0  # energy decays


@pytest.mark.slow
def test_springs_follow_their_pairs_through_rebuilds():
    # 0 and 1 slide on each other (loaded springs); 2 arrives and hits 0: the table changes under them
    positions = [[0, 0, 0], [2 * R - 2e-6, 0, 0], [-2 * R - 3e-5, 1e-4, 0]]
    velocity = [[0, 0.05, 0.01], [0, -0.05, 0], [0.05, 0, 0]]
    runs = []
    for skin in (1e-3 * R, 0.5 * R):  # rebuilt at almost every step / never
        sim, state, params = _scene(positions, velocity, 1e-6, _params(mu=0.3, mu_r=0.1, xi_rol=0.3), skin=skin,
                                    gravity=(0.0, 0.0, 0.0), friction=True, rolling=True)
        final, saved = _run(sim, state, params, 2000, 100, lambda s: s.mechanics.spin)
        runs.append((final, np.asarray(saved)))
    (a, spin_a), (b, spin_b) = runs
    assert not bool(a.overflow) and not bool(b.overflow)
    assert np.max(np.abs(spin_a[:, 2])) > 1.0  # friction and the collision spun them
    np.testing.assert_allclose(spin_a, spin_b, rtol=1e-9, atol=1e-9 * np.max(np.abs(spin_b)))
    np.testing.assert_allclose(a.particles.positions, b.particles.positions, rtol=1e-12)


# --------------------------------------------------------------------------
# friction on an incline


def _incline(angle_deg, mu, mu_r, rolling=True, n_steps=5000):
    a = math.radians(angle_deg)
    normal = (-math.sin(a), 0.0, math.cos(a))
    wall = PlaneWall((0.0, 0.0, 0.0), normal)
    sim, state, params = _scene([np.asarray(normal) * R], None, 2e-5, _params(mu=mu, mu_r=mu_r, xi_rol=0.3),
                                walls=(wall,), friction=True, rolling=rolling)
    down = np.array([-math.cos(a), 0.0, -math.sin(a)])  # along the slope, downhill

    def obs(s):
        return jnp.stack([jnp.sum(s.particles.positions[0] * down), jnp.sum(s.mechanics.velocity[0] * down)])

    return np.asarray(_run(sim, state, params, n_steps, 100, obs)[1]), a


@pytest.mark.slow
def test_friction_holds_a_sphere_on_an_incline():
    saved, a = _incline(20.0, mu=0.5, mu_r=0.5)
    assert math.tan(a) < 0.5
    assert np.max(np.abs(saved[:, 0])) < 1e-6  # the springs' give only (~f_t / k_t)
    assert abs(saved[-1, 1]) < 1e-9


@pytest.mark.slow
def test_beyond_the_friction_angle_it_slides_with_coulombs_acceleration():
    saved, a = _incline(20.0, mu=0.2, mu_r=0.5)
    assert math.tan(a) > 0.2
    accel = (saved[-1, 1] - saved[-11, 1]) / (10 * 100 * 2e-5)
    assert accel == pytest.approx(G * (math.sin(a) - 0.2 * math.cos(a)), rel=1e-3)


def test_without_rolling_resistance_it_rolls_at_five_sevenths():
    saved, a = _incline(20.0, mu=0.5, mu_r=0.0, rolling=False)
    accel = (saved[-1, 1] - saved[-11, 1]) / (10 * 100 * 2e-5)
    assert accel == pytest.approx(5.0 / 7.0 * G * math.sin(a), rel=1e-3)


@pytest.mark.slow
def test_frictionless_walls_skip_their_laws_exactly():
    """``Physics(wall_friction=False, wall_rolling=False)``: the same run, bit for bit, as the walls' tangential and
    rolling laws evaluated at mu_wall = mu_r_wall = 0 (zero force and torque there: a spring may load, capped at
    zero force, and never act), no wall springs kept; a sphere on a
    frictionless incline slides at g sin(a); nonzero wall coefficients with the flags off are refused."""
    floor, side = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), PlaneWall((-R, 0.0, 0.0), (1.0, 0.0, 0.0))
    x = [[0.0, 0.0, R - 2e-6], [2 * R - 3e-6, 1e-4, R + 1e-5], [R, 2e-4, 2.8 * R]]
    v = [[0.01, 0.02, -0.01], [-0.01, 0.0, 0.0], [0.0, -0.01, -0.02]]
    params = _params(mu=0.3, mu_r=0.1, xi_rol=0.3, mu_wall=0.0, mu_r_wall=0.0)
    states = []
    for flags in (True, False):
        sim, state, _ = _scene(x, v, 1e-6, params, walls=(floor, side), friction=True, rolling=True,
                               wall_friction=flags, wall_rolling=flags)
        states.append(_run(sim, state, params, 400, 400, lambda s: s.particles.positions)[0])
    dense, skipped = states
    assert skipped.mechanics.wall_spring is None and skipped.mechanics.wall_rolling is None
    for name in ("positions", "temperature"):
        np.testing.assert_array_equal(getattr(dense.particles, name), getattr(skipped.particles, name))
    for name in ("velocity", "spin", "spring", "rolling"):
        np.testing.assert_array_equal(getattr(dense.mechanics, name), getattr(skipped.mechanics, name))
    assert float(jnp.max(jnp.abs(skipped.mechanics.spring))) > 0  # the pairs still rub

    a = math.radians(20.0)
    normal = (-math.sin(a), 0.0, math.cos(a))
    down = jnp.asarray([-math.cos(a), 0.0, -math.sin(a)])
    slope = _params(mu=0.5, mu_wall=0.0)
    sim, state, _ = _scene([np.asarray(normal) * R], None, 2e-5, slope, walls=(PlaneWall((0.0, 0.0, 0.0), normal),),
                           friction=True, wall_friction=False)
    end, speed = _run(sim, state, slope, 5000, 100, lambda s: jnp.sum(s.mechanics.velocity[0] * down))
    speed = np.asarray(speed)
    assert (speed[-1] - speed[-11]) / (10 * 100 * 2e-5) == pytest.approx(G * math.sin(a), rel=1e-3)
    assert float(jnp.max(jnp.abs(end.mechanics.spin))) == 0.0  # no torque: it slides without turning

    with pytest.raises(ValueError, match="mu_wall"):
        simulate.rollout(sim, state, _params(mu=0.5), 1)  # mu_wall None falls back to mu = 0.5
    with pytest.raises(ValueError, match="wall_rolling"):
        simulate.Physics.create(mechanics=True, contacts="dynamic", conductance="lifted", rolling=True,
                                wall_rolling="no")


# --------------------------------------------------------------------------
# jit, rollout, gradients


@pytest.mark.slow
def test_jit_equals_eager_with_every_law_on():
    wall = PlaneWall((0.0, 0.0, -R + 2e-6), (0.0, 0.0, 1.0), "conducting", 700.0)
    sim, state, params = _scene([[0, 0, 0], [2 * R - 3e-6, 1e-4, 0]], [[0.01, 0.02, -0.01], [-0.01, 0.0, 0.0]],
                                1e-6, _params(mu=0.3, mu_r=0.1, xi_rol=0.3), walls=(wall,), friction=True,
                                rolling=True, softening=True)
    eager, jitted = state, state
    step = jax.jit(sim.step_fn)
    for _ in range(5):
        eager, jitted = sim.step_fn(eager, params), step(jitted, params)
    for a, b in zip(jax.tree.leaves(eager), jax.tree.leaves(jitted)):
        a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)  # XLA may fuse differently: round-off only
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * float(np.max(np.abs(a), initial=0.0)))
    assert float(jnp.max(jnp.abs(eager.mechanics.spring))) > 0  # the springs were loaded
    assert float(eager.particles.temperature[0]) > 300.0  # the wall heats


@pytest.mark.slow
def test_gradient_through_rollout_equals_central_differences():
    sim, state, params, _ = examples.example_5_1(softening=True)
    state = dataclasses.replace(state, particles=dataclasses.replace(state.particles,
                                                                     temperature=jnp.asarray([420.0])))

    def observe(p, checkpoint=True):
        final, saved = simulate.rollout(sim, state, p, 400, simulate.SaveAt(100, lambda s: jnp.stack(
            [s.particles.temperature[0], _overlap(s)])), checkpoint=checkpoint)
        return saved[-1]

    def with_e0(x):
        return dataclasses.replace(params, mechanics=dataclasses.replace(params.mechanics, E0=x))

    # both readings' gradients from one reverse-mode program (a row each), their differences from one plain run
    grads = np.asarray(jax.jit(jax.jacrev(lambda x: observe(with_e0(x))))(params.mechanics.E0))
    value = jax.jit(lambda x: observe(with_e0(x), checkpoint=False))
    h = 1e-6 * E0
    fds = (np.asarray(value(_f64(E0 + h))) - np.asarray(value(_f64(E0 - h)))) / (2 * h)
    for which in (0, 1):
        grad, fd = float(grads[which]), float(fds[which])
        assert grad != 0.0
        assert grad == pytest.approx(fd, rel=1e-6), which


# --------------------------------------------------------------------------
# the half pair list: rebuilds, reallocations, conservation


def _stack(mu=0.5):
    """Sphere 0 in the groove of spheres 1 and 2 on the floor, gravity tilted 10 degrees: friction holds the pile."""
    a = math.radians(10.0)
    gravity = (G * math.sin(a), 0.0, -G * math.cos(a))
    floor = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    return _scene([[0, 0, R + math.sqrt(3.0) * R], [-R, 0, R], [R, 0, R]], None, 2e-5,
                  _params(mu=mu, mu_r=0.5, xi_rol=0.3), walls=(floor,), gravity=gravity, friction=True, rolling=True)


@pytest.mark.slow
def test_a_sphere_held_by_friction_continues_bit_for_bit_through_aforced_rebuild():
    sim, state, params = _stack()
    run = jax.jit(lambda s, p: simulate.rollout(sim, s, p, 2500, simulate.SaveAt(2500, lambda s: ()),
                                                checkpoint=False)[0])
    settled = run(state, params)  # 0.05 s: held, the pair's springs loaded
    spring = np.asarray(settled.mechanics.spring[0])
    assert np.asarray(settled.contacts.pairs.pairs)[0].tolist() == [0, 1]
    assert np.linalg.norm(spring) > 1e-9  # ~ m g sin(a) / k_t
    through = run(forced_rebuild(settled), params)
    assert np.all(np.isfinite(np.asarray(through.contacts.neighbor_list.reference_position)))  # it did rebuild
    kept = run(settled, params)
    for a, b in zip(jax.tree.leaves(through.mechanics), jax.tree.leaves(kept.mechanics)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(np.asarray(through.particles.positions), np.asarray(kept.particles.positions))
    drift = np.asarray(kept.particles.positions - settled.particles.positions)
    assert np.max(np.abs(drift)) < 1e-9  # held: it does not move
    # control: a rebuild that forgets the springs lets the top sphere lurch down the slope
    forgot = forced_rebuild(dataclasses.replace(settled, mechanics=dataclasses.replace(
        settled.mechanics, spring=jnp.zeros_like(settled.mechanics.spring))))
    lurch = np.asarray(run(forgot, params).particles.positions - settled.particles.positions)
    assert np.abs(lurch[0, 0]) > 100 * np.max(np.abs(drift))


@pytest.mark.slow
def test_tight_lists_redone_after_overflow_equal_roomy_ones_springs_included():
    from sintercond.rollout import advance

    # 0 and 1 slide on each other (loaded springs); 2 arrives at ~600 steps and hits 0: the lists must grow
    positions = [[0, 0, 0], [2 * R - 2e-6, 0, 0], [-2 * R - 3e-5, 1e-4, 0]]
    velocity = [[0, 0.05, 0.01], [0, -0.05, 0], [0.05, 0, 0]]
    runs = {}
    for name, multiplier in (("tight", 1.0), ("roomy", 4.0)):
        positions_ = np.asarray(positions, np.float64)
        particles = particle_state(positions_, R, 300.0, RHO)
        phys = simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                       mechanics=True, gravity=(0.0, 0.0, 0.0), friction=True, rolling=True)
        contacts, fns = simulate.dynamic_contacts(positions_, particles.radii, 0.01 * R, multiplier)
        motion = mechanics.mechanical_state(phys.mechanics, positions_, contacts, velocity=velocity)
        state = simulate.init_state(particles, contacts, 1e-6, mechanics=motion)
        sim = simulate.simulator(phys, fns)
        final, report = advance(sim, state, _params(mu=0.3, mu_r=0.1, xi_rol=0.3), 1500, 100,
                                reallocate=simulate.reallocate_neighbors(fns))
        runs[name] = (contacts.pairs.capacity, final, report)
    (cap0, tight, report), (_, roomy, report_roomy) = runs["tight"], runs["roomy"]
    assert cap0 == 1 and tight.contacts.pairs.capacity > 1 and report.reallocations >= 1
    assert report_roomy.reallocations == 0

    def by_pair(s):
        pairs = np.asarray(s.contacts.pairs.pairs).tolist()
        return {tuple(p): (np.asarray(s.mechanics.spring[k]), np.asarray(s.mechanics.rolling[k]))
                for k, p in enumerate(pairs) if p[0] < p[1]}

    springs_tight, springs_roomy = by_pair(tight), by_pair(roomy)
    assert {(0, 1), (0, 2)} <= set(springs_roomy)
    assert np.linalg.norm(springs_roomy[(0, 1)][0]) > 0 and np.linalg.norm(springs_roomy[(0, 2)][0]) > 0
    # round-off, not bitwise: XLA's CPU loops over arrays of different lengths (the capacities) round
    # differently (the forced-rebuild test above shows bit-for-bit at equal capacity)
    close = lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.max(np.abs(b)))  # noqa: E731
    for p in set(springs_tight) | set(springs_roomy):
        for a, b in zip(springs_tight.get(p, (np.zeros(3),) * 2), springs_roomy.get(p, (np.zeros(3),) * 2)):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.linalg.norm(springs_roomy[(0, 1)][0]))
    close(tight.particles.positions, roomy.particles.positions)
    close(tight.mechanics.velocity, roomy.mechanics.velocity)
    close(tight.mechanics.spin, roomy.mechanics.spin)


@pytest.mark.slow
def test_momentum_of_a_colliding_cloud_is_conserved_to_round_off_float32_forces_close():
    rng = np.random.default_rng(12)
    grid = np.array(np.meshgrid(*[np.arange(3)] * 3, indexing="ij")).reshape(3, -1).T * 2.05 * R
    positions = grid + rng.uniform(-0.03, 0.03, grid.shape) * R
    velocity = rng.normal(0.0, 0.05, grid.shape)
    p0 = np.sum(MASS * velocity, axis=0)
    scale = MASS * np.sum(np.abs(velocity))
    finals = {}
    for force_dtype in (None, "float32"):  # the laws in float64, then in float32 with float64 positions
        sim, state, params = _scene(positions, velocity, 1e-6, _params(mu=0.3, mu_r=0.1, xi_rol=0.3),
                                    gravity=(0.0, 0.0, 0.0), friction=True, rolling=True, force_dtype=force_dtype)
        final, saved = _run(sim, state, params, 3000, 100,
                            lambda s: jnp.sum(s.particles.mass[:, None] * s.mechanics.velocity, axis=0))
        # per-pair forces summed in float64 to both ends: momentum to float64 round-off either way
        assert np.max(np.abs(np.asarray(saved) - p0)) < 1e-13 * scale
        finals[force_dtype] = final
    ref, f32 = finals[None], finals["float32"]
    touching = mechanics.pair_geometry(ref.particles.positions, ref.particles.radii, ref.contacts.pairs.pairs).touching
    assert int(jnp.sum(touching)) >= 3  # they collided
    assert f32.particles.positions.dtype == jnp.float64 and f32.mechanics.velocity.dtype == jnp.float64
    assert f32.mechanics.spring.dtype == jnp.float32
    # float32 laws: velocities within 1e-5 of the float64 run's largest, positions within 1e-6 R (measured
    # 2.4e-6 and 1.9e-7 R after 3000 steps of collisions)
    v = np.asarray(ref.mechanics.velocity)
    np.testing.assert_allclose(np.asarray(f32.mechanics.velocity), v, atol=1e-5 * np.max(np.abs(v)))
    np.testing.assert_allclose(np.asarray(f32.particles.positions), np.asarray(ref.particles.positions), atol=1e-6 * R)
    with pytest.raises(ValueError, match="Mechanics.force_dtype must be None, 'float32' or 'float64'"):
        simulate.Physics.create(mechanics=True, contacts="dynamic", conductance="lifted", force_dtype="float16")


@pytest.mark.slow
def test_pair_pass_by_blocks_equals_one_pass(monkeypatch):
    from sintercond.contacts import pair_list

    rng = np.random.default_rng(4)
    grid = np.array(np.meshgrid(*[np.arange(3)] * 3, indexing="ij")).reshape(3, -1).T * 2.02 * R
    positions = grid + rng.uniform(-0.03, 0.03, grid.shape) * R + [0.0, 0.0, R]
    velocity = rng.normal(0.0, 0.05, grid.shape)
    wall = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), "conducting", 700.0)
    scene = lambda: _scene(positions, velocity, 1e-6, _params(mu=0.3, mu_r=0.1, xi_rol=0.3),  # noqa: E731
                           walls=(wall,), friction=True, rolling=True)
    summary = lambda s: (s.particles.positions, s.mechanics.velocity, s.mechanics.spin, s.particles.temperature)  # noqa: E731
    sim, state, params = scene()
    one_pass = _run(sim, state, params, 150, 150, summary)[0]
    monkeypatch.setattr(pair_list, "PAIR_BLOCK", 8)
    monkeypatch.setattr(pair_list, "PAIR_BLOCKS_FROM", 2)
    sim_b, rounded, _ = scene()  # capacity allocated in whole blocks
    assert rounded.contacts.pairs.capacity % 8 == 0 and rounded.contacts.pairs.capacity >= 16
    blocked = _run(sim_b, rounded, params, 150, 150, summary)[0]
    assert int(jnp.sum(mechanics.pair_geometry(blocked.particles.positions, blocked.particles.radii,
                                               blocked.contacts.pairs.pairs).touching)) >= 10
    for a, b in zip(summary(blocked), summary(one_pass)):  # the same arithmetic per pair: round-off at most
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13 * float(np.max(np.abs(b))))
    pairs = lambda s: {tuple(p): k for k, p in enumerate(np.asarray(s.contacts.pairs.pairs).tolist())  # noqa: E731
                       if p[0] < p[1]}
    ours, theirs = pairs(blocked), pairs(one_pass)
    assert ours.keys() == theirs.keys()
    for p, k in ours.items():
        np.testing.assert_allclose(blocked.mechanics.spring[k], one_pass.mechanics.spring[theirs[p]],
                                   rtol=1e-13, atol=1e-13 * float(jnp.max(jnp.abs(one_pass.mechanics.spring))))
    assert float(jnp.max(one_pass.particles.temperature)) > 300.0  # the wall heated the bottom layer
