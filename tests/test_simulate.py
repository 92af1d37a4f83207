"""The one simulator: table and lifted conductances agree, gradients through rollout equal finite differences."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fitting.core import Positive, least_squares
from sintercond import simulate
from sintercond.contacts import network
from sintercond.simulate import simulate_table
from sintercond.sim import steady
from sintercond.laws.conductance import rojek_pair_conductance
from sintercond.state import ParticleState

A, R = 1.0e-4, 0.53e-4


def _packing(n=5, seed=0):
    rng = np.random.default_rng(seed)
    g = np.arange(n) * A
    centres = np.array(np.meshgrid(g, g, g[:3], indexing="ij")).reshape(3, -1).T
    centres = centres + rng.uniform(-0.02, 0.02, centres.shape) * A
    radii = R * (1 + rng.uniform(-0.02, 0.02, len(centres)))
    return centres, radii


def _setup(conductance, materials=1, walls=False, physics_extra=None):
    centres, radii = _packing()
    n = len(radii)
    material = (np.arange(n) % materials).astype(np.int32)
    mass = 4 / 3 * np.pi * radii**3 * 4430.0
    held = centres[:, 0] < 0.5 * A
    t0 = np.where(held, 900.0, 300.0)
    particles = ParticleState(jnp.asarray(centres), jnp.asarray(radii), jnp.asarray(t0), jnp.asarray(mass),
                              jnp.asarray(material), jnp.asarray(held), jnp.asarray(t0))
    physics = simulate.Physics.create(conductance=conductance, held=True, pulse=True, **(physics_extra or {}))
    wall_pen = radii - np.abs(centres[:, 0] - (centres[:, 0].max() + 0.97 * R))
    if conductance == "table":
        table = network.contact_table(centres, radii, 1.0)
        k_w = network.wall_conductance(centres, radii, 1.0, 0, centres[:, 0].max() + 0.97 * R) if walls else None
        contacts = simulate.table_contacts(table, k_w, None if k_w is None else np.full(n, 250.0))
    else:
        contacts = simulate.lifted_contacts(physics, centres, radii, [(wall_pen, 250.0)] if walls else ())
    physics = dataclasses.replace(physics, conduction=dataclasses.replace(physics.conduction,
                                                                          conducting_walls=int(walls)))
    power = np.where(centres[:, 1] < 0.5 * A, 2e-3, 0.0)
    params = simulate.Params(conductivity=jnp.full(materials, 7.0), specific_heat=jnp.full(materials, 560.0),
                             pulse=simulate.PulseParams(jnp.asarray(power), jnp.asarray(2e-3)))
    state = simulate.init_state(particles, contacts, 1.0)
    sim = simulate.simulator(physics)
    dt = 0.5 * float(simulate.thermal_time_step(sim, state, params))
    return sim, simulate.init_state(particles, contacts, dt), params, centres, radii


PROBES = jnp.asarray([10, 40, 60])


def _readings(sim, state, params, n_steps=120, every=10, checkpoint=True):
    saveat = simulate.SaveAt(every, simulate.probe_temperatures(PROBES))
    return simulate.rollout(sim, state, params, n_steps, saveat, checkpoint)[1]


@pytest.mark.slow
@pytest.mark.parametrize("walls", [False, True])
def test_table_and_lifted_give_the_same_numbers_and_gradients(walls):
    table = _setup("table", walls=walls)
    lifted = _setup("lifted", walls=walls)
    np.testing.assert_allclose(float(table[1].dt), float(lifted[1].dt), rtol=1e-13)
    state = dataclasses.replace(lifted[1], dt=table[1].dt)
    a, b = _readings(*table[:3]), _readings(lifted[0], state, lifted[2])
    np.testing.assert_allclose(a, b, rtol=1e-13)
    assert float(jnp.max(a)) > 300.5  # the pulse and the held face heat the probes

    def loss(sim, st):
        return lambda p: jnp.sum(_readings(sim, st, p) ** 2)

    ga = jax.grad(loss(table[0], table[1]))(table[2])
    gb = jax.grad(loss(lifted[0], state))(lifted[2])
    for name in ("conductivity", "specific_heat"):
        np.testing.assert_allclose(getattr(ga, name), getattr(gb, name), rtol=1e-10)


def _central_difference(f, x, rel=1e-6):
    h = rel * abs(x)
    return (f(x + h) - f(x - h)) / (2 * h)


@pytest.mark.slow
def test_gradients_through_rollout_equal_central_differences():
    sim, state, params, *_ = _setup("lifted", materials=2, walls=True)
    params = dataclasses.replace(params, law={"slope": jnp.asarray(1.064), "contact_resistance": jnp.asarray(50.0)})

    def loss(p):
        return jnp.sum(jnp.sin(_readings(sim, state, p) / 50.0))

    grad = jax.jit(jax.grad(loss))(params)
    value = jax.jit(loss)
    checks = [
        ("slope", lambda x: dataclasses.replace(params, law={**params.law, "slope": x}), params.law["slope"],
         grad.law["slope"]),
        ("contact_resistance", lambda x: dataclasses.replace(params, law={**params.law, "contact_resistance": x}),
         params.law["contact_resistance"], grad.law["contact_resistance"]),
        ("conductivity[1]", lambda x: dataclasses.replace(params, conductivity=params.conductivity.at[1].set(x)),
         params.conductivity[1], grad.conductivity[1]),
        ("specific_heat[0]", lambda x: dataclasses.replace(params, specific_heat=params.specific_heat.at[0].set(x)),
         params.specific_heat[0], grad.specific_heat[0]),
        ("pulse duration", lambda x: dataclasses.replace(params, pulse=simulate.PulseParams(params.pulse.power, x)),
         params.pulse.duration, grad.pulse.duration),
    ]
    for name, with_x, x, g in checks:
        fd = _central_difference(lambda v: float(value(with_x(jnp.asarray(v)))), float(x))
        if name == "pulse duration":
            assert float(g) == 0.0  # a step function of time: zero almost everywhere
            continue
        assert float(g) == pytest.approx(fd, rel=1e-6), name
    # forward mode and the unchecked scan agree with the checkpointed reverse mode
    tangent = jax.tree.map(jnp.zeros_like, params)
    tangent = dataclasses.replace(tangent, law={**tangent.law, "slope": jnp.asarray(1.0)})
    _, jvp = jax.jvp(loss, (params,), (tangent,))
    assert float(jvp) == pytest.approx(float(grad.law["slope"]), rel=1e-12)
    plain = jax.grad(lambda p: jnp.sum(jnp.sin(_readings(sim, state, p, checkpoint=False) / 50.0)))(params)
    np.testing.assert_allclose(plain.law["slope"], grad.law["slope"], rtol=1e-12)


def test_table_step_derivatives_equal_central_differences():
    """The table path's written derivative of the explicit step (thermal.explicit_update with a network):
    reverse mode through the checkpointed rollout equals central differences in the conductivity, the
    specific heat, the pulse power and the initial field (held particles, a conducting wall), and forward
    mode (jacfwd, which batches the linear_call) equals reverse mode."""
    sim, state, params, *_ = _setup("table", walls=True)
    direction = jnp.linspace(0.5, 1.5, state.particles.temperature.shape[0])

    def loss(kappa, c, power_scale, shift):
        p = dataclasses.replace(params, conductivity=kappa[None], specific_heat=c[None],
                                pulse=simulate.PulseParams(power_scale * params.pulse.power, params.pulse.duration))
        particles = dataclasses.replace(state.particles, temperature=state.particles.temperature + shift * direction)
        return jnp.sum(jnp.sin(_readings(sim, dataclasses.replace(state, particles=particles), p) / 50.0))

    x = tuple(jnp.asarray(v) for v in (7.0, 560.0, 1.0, 1.0))
    grads = jax.jit(jax.grad(loss, argnums=(0, 1, 2, 3)))(*x)
    value = jax.jit(loss)
    for k, name in enumerate(("conductivity", "specific heat", "pulse power", "initial field")):
        def along(v, k=k):
            return float(value(*x[:k], jnp.asarray(v), *x[k + 1:]))

        assert float(grads[k]) == pytest.approx(_central_difference(along, float(x[k])), rel=1e-6), name
    forward = jax.jit(jax.jacfwd(loss, argnums=(0, 1, 2, 3)))(*x)
    for g, f in zip(grads, forward):
        assert float(f) == pytest.approx(float(g), rel=1e-10)


def test_rollout_checks_its_arguments():
    sim, state, params, *_ = _setup("table")
    with pytest.raises(ValueError, match=r"n_steps \(10\) must be a multiple of saveat.every \(3\)"):
        simulate.rollout(sim, state, params, 10, simulate.SaveAt(3))
    with pytest.raises(ValueError, match="Conduction.integrator must be one of"):
        simulate.Physics.create(integrator="rk4")
    with pytest.raises(ValueError, match="Physics.contacts='dynamic' needs conduction.conductance='lifted'"):
        simulate.Physics.create(contacts="dynamic")
    with pytest.raises(ValueError, match=r"Params.law of law 'rojek' must be among"):
        simulate.rollout(simulate.simulator(simulate.Physics.create(conductance="lifted")), state,
                         dataclasses.replace(params, law={"slop": 1.0}), 10, simulate.SaveAt(10))


def test_segments_do_not_change_the_numbers():
    """Checkpointed segments (sqrt(n) steps) and save groups give the plain scan's numbers bit for bit."""
    sim, state, params, *_ = _setup("table")
    for n_steps, every in ((120, 10), (97, 1), (100, 50), (64, 4)):
        a = _readings(sim, state, params, n_steps, every, checkpoint=True)
        b = _readings(sim, state, params, n_steps, every, checkpoint=False)
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_heat_is_conserved_by_the_lifted_network():
    sim, state, params, *_ = _setup("lifted", materials=2)
    physics = dataclasses.replace(sim.physics, conduction=dataclasses.replace(sim.physics.conduction, held=False),
                                  sources=dataclasses.replace(sim.physics.sources, pulse=False))
    sim = simulate.simulator(physics)
    final, _ = simulate.rollout(sim, state, params, 200, simulate.SaveAt(200))
    capacity = np.asarray(state.particles.mass) * 560.0
    assert float(np.sum(capacity * final.particles.temperature)) == pytest.approx(
        float(np.sum(capacity * state.particles.temperature)), rel=1e-13)


@pytest.mark.slow
def test_rojek_slope_recovered_by_gradient_descent_through_a_transient_dem():
    """The slope of Rojek's law (not only kappa) is identifiable from probe histories when kappa is known:
    a sintered packing held hot on one face, probes on the far side; truth s = 1.064 with 0.02 K noise."""
    sim, state, params, *_ = _setup("lifted")
    true = dataclasses.replace(params, law={"slope": jnp.asarray(1.064)})
    readings = _readings(sim, state, true, 200, 10)
    noise = 0.02
    noisy = readings + noise * jax.random.normal(jax.random.PRNGKey(3), readings.shape, readings.dtype)

    def model(p, _):
        return _readings(sim, state, dataclasses.replace(params, law={"slope": p["slope"]}), 200, 10)

    fit = least_squares(model, None, noisy, {"slope": 0.8}, {"slope": Positive()},
                        weights=jnp.full(noisy.shape, 1 / noise), method="levenberg_marquardt")
    slope, stderr = float(fit.params["slope"]), float(fit.stderr["slope"])
    assert abs(slope - 1.064) < 4 * stderr and stderr < 0.01
    # the network's pair conductance is Rojek's with that slope (the lift is the law)
    k = rojek_pair_conductance(R, R, 2 * R - A, 7.0, slope=slope) / rojek_pair_conductance(R, R, 2 * R - A, 7.0)
    assert float(k) == pytest.approx(slope / 1.064, rel=1e-12)


def test_thermal_simulate_is_the_rollout():
    """The table convenience wrapper runs the simulator: same numbers as the simulator on the same table."""
    sim, state, params, centres, radii = _setup("table")
    table = network.contact_table(centres, radii, 7.0)
    capacity = state.particles.mass * 560.0
    power = params.pulse.power
    source = _Pulse(power)
    final, _ = simulate_table(state.particles.temperature, table, capacity, float(state.dt), 100, 100,
                                state.particles.fixed, state.particles.fixed_temperature, source=source)
    via_sim, _ = simulate.rollout(sim, state, params, 100, simulate.SaveAt(100))
    np.testing.assert_allclose(final, via_sim.particles.temperature, rtol=1e-13)


@dataclasses.dataclass(frozen=True, eq=False)
class _Pulse:
    power: object

    def __call__(self, temperature, t):
        return jnp.where(t < 2e-3, self.power, 0.0)


@pytest.mark.slow
@pytest.mark.parametrize("coupling", ["none", "sphere"])
def test_steady_state_conductivity_is_differentiable(coupling):
    """k* is linear in kappa (both networks: the halves and the surface Green function both scale as 1/kappa); the
    isolated network's is linear in Rojek's slope too (exact for any packing without contact resistance), the
    coupled one's is not (its Green-function part does not scale with the slope) and its slope derivative equals
    central differences; the contact-resistance derivative equals central differences (implicit CG
    derivative)."""
    centres, radii = _packing()
    kw = {"axis": 0, "coupling": coupling}
    k_star = steady.steady_state_conductivity(centres, radii, 7.0, **kw)
    d_kappa = jax.grad(lambda k: steady.steady_state_conductivity(centres, radii, k, **kw))(7.0)
    assert float(d_kappa) == pytest.approx(float(k_star) / 7.0, rel=1e-9)

    def with_slope(s):
        return steady.steady_state_conductivity(centres, radii, 7.0, params={"slope": s}, **kw)

    d_slope = jax.grad(with_slope)(1.064)
    if coupling == "none":
        assert float(d_slope) == pytest.approx(float(k_star) / 1.064, rel=1e-9)
    else:
        assert float(d_slope) == pytest.approx(_central_difference(lambda s: float(with_slope(s)), 1.064), rel=1e-6)
        assert abs(float(d_slope) / (float(k_star) / 1.064) - 1.0) > 1e-3  # not linear in the slope

    def with_resistance(r):
        return steady.steady_state_conductivity(centres, radii, 7.0, params={"contact_resistance": r}, **kw)

    g = jax.grad(with_resistance)(200.0)
    fd = _central_difference(lambda r: float(with_resistance(r)), 200.0)
    assert float(g) == pytest.approx(fd, rel=1e-6) and float(g) < 0


def test_lifted_two_material_pair_is_the_series_of_its_halves():
    """Mutation 'lift two materials' (the lift used the first particle's conductivity for both halves)
    survived: no lifted network had two materials with a closed-form check. Rojek Eqs. 8-9, 43: halves
    s kappa_k pi a in series, s pi a kappa_1 kappa_2 / (kappa_1 + kappa_2), whatever the numbering."""
    centres = np.array([[0.0, 0.0, 0.0], [A, 0.0, 0.0]])
    radii = np.full(2, R)
    physics = simulate.Physics.create(conductance="lifted")
    contacts = simulate.lifted_contacts(physics, centres, radii)
    kappa = jnp.array([7.0, 390.0])
    for material in ([0, 1], [1, 0]):
        particles = ParticleState(jnp.asarray(centres), jnp.asarray(radii), jnp.full(2, 300.0), jnp.ones(2),
                                  jnp.asarray(material, jnp.int32), jnp.zeros(2, bool), jnp.full(2, 300.0))
        prep = simulate.simulator(physics).prepare_fn(simulate.init_state(particles, contacts, 1.0),
                                                       simulate.Params(kappa, jnp.ones(2)))
        k = np.asarray(prep.conductance)
        expected = float(rojek_pair_conductance(R, R, 2 * R - A, 7.0, kappa_j=390.0))
        assert k[0][np.asarray(contacts.neighbors)[0] == 1][0] == pytest.approx(expected, rel=1e-14)
        assert k[1][np.asarray(contacts.neighbors)[1] == 0][0] == pytest.approx(expected, rel=1e-14)
