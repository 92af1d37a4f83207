"""Bad input at the Python API boundary (simulate.rollout, rollout.advance) is refused before anything compiles,
with the field and its allowed range named: the same rules as the scene validator (issue 28's misuse list)."""

import dataclasses
import math

import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import rollout, simulate
from sintercond.sim import mechanics
from sintercond.state import particle_state

R, RHO = 1e-3, 3000.0


def _mechanical(positions=((0.0, 0.0, 1.2e-3), (0.0, 0.0, 3.3e-3)), **mech):
    base = dict(E0=1e6, nu=0.3, xi_con=1.0, xi_fric=1.0, xi_rol=0.0, mu=0.3, mu_r=0.0, theta_star=400.0, rate=1.0,
                E_min=0.0)
    base.update(mech)
    params = simulate.Params(conductivity=jnp.asarray([60.0]), specific_heat=jnp.asarray([100.0]),
                             mechanics=mechanics.MechanicalParams(**{k: jnp.asarray(v, jnp.float64)
                                                                     for k, v in base.items()}))
    positions = np.asarray(positions, np.float64)
    particles = particle_state(positions, R, 300.0, RHO)
    physics = simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                      mechanics=True, friction=True)
    contacts, fns = simulate.dynamic_contacts(positions, particles.radii, 0.1 * R, capacity_multiplier=3.0)
    state = simulate.init_state(particles, contacts, 1e-5,
                                mechanics=mechanics.mechanical_state(physics.mechanics, positions, contacts))
    return simulate.simulator(physics, fns), state, params


def _with(params, **changes):
    return dataclasses.replace(params, mechanics=dataclasses.replace(
        params.mechanics, **{k: jnp.asarray(v, jnp.float64) for k, v in changes.items()}))


MISUSE = [  # (what, change to (state, params), the words the message must hold)
    ("E0 = 0", lambda s, p: (s, _with(p, E0=0.0)), "MechanicalParams.E0 must be finite and in [1, 1e+13] Pa"),
    ("E0 < 0", lambda s, p: (s, _with(p, E0=-1e6)), "MechanicalParams.E0"),
    ("E0 NaN", lambda s, p: (s, _with(p, E0=math.nan)), "MechanicalParams.E0"),
    ("nu = 0.7", lambda s, p: (s, _with(p, nu=0.7)), "MechanicalParams.nu must be finite and in [0, 0.5]"),
    ("nu = 1", lambda s, p: (s, _with(p, nu=1.0)), "MechanicalParams.nu"),
    ("nu = -1", lambda s, p: (s, _with(p, nu=-1.0)), "MechanicalParams.nu"),
    ("negative friction", lambda s, p: (s, _with(p, mu=-0.1)), "MechanicalParams.mu must be"),
    ("negative damping", lambda s, p: (s, _with(p, xi_con=-1.0)), "MechanicalParams.xi_con"),
    ("theta* of 0 K", lambda s, p: (s, _with(p, theta_star=0.0)), "MechanicalParams.theta_star"),
    ("floor above E0", lambda s, p: (s, _with(p, E_min=2e6)), "MechanicalParams.E_min (2e+06 Pa) must not exceed"),
    ("E0 for 3 materials of 1", lambda s, p: (s, _with(p, E0=[1e6, 1e6, 1e6])),
     "MechanicalParams.E0 must be a scalar or one per material (1,)"),
    ("per-pair friction", lambda s, p: (s, _with(p, mu=[0.3, 0.3])), "MechanicalParams.mu must be a scalar"),
    ("negative step", lambda s, p: (dataclasses.replace(s, dt=jnp.asarray(-1e-5)), p), "SimState.dt"),
    ("NaN step", lambda s, p: (dataclasses.replace(s, dt=jnp.asarray(math.nan)), p), "SimState.dt"),
    ("NaN velocity", lambda s, p: (dataclasses.replace(s, mechanics=dataclasses.replace(
        s.mechanics, velocity=s.mechanics.velocity.at[1, 0].set(jnp.nan))), p),
     "MechanicalState.velocity must be finite; particle 1"),
    ("negative conductivity", lambda s, p: (s, dataclasses.replace(p, conductivity=jnp.asarray([-60.0]))),
     "Params.conductivity (W/(m K))"),
    ("mismatched materials", lambda s, p: (s, dataclasses.replace(p, conductivity=jnp.asarray([60.0, 20.0]))),
     "must be [n_materials] each"),
    ("no mechanical params", lambda s, p: (s, dataclasses.replace(p, mechanics=None)), "needs Params.mechanics"),
]


@pytest.mark.parametrize("what, change, words", MISUSE, ids=[m[0] for m in MISUSE])
def test_misuse_is_refused_naming_the_field(what, change, words):
    sim, state, params = _mechanical()
    bad_state, bad_params = change(state, params)
    with pytest.raises(ValueError) as rolled:
        simulate.rollout(sim, bad_state, bad_params, 10)
    with pytest.raises(ValueError) as advanced:
        rollout.advance(sim, bad_state, bad_params, 10, 10)
    for err in (rolled, advanced):
        assert words in str(err.value), str(err.value)


def test_the_valid_start_runs():
    sim, state, params = _mechanical()
    simulate.validate_inputs(sim, state, params)  # the misuse cases above differ from this in one field
    final, _ = rollout.advance(sim, state, params, 20, 10)
    assert int(final.step) == 20 and bool(jnp.all(jnp.isfinite(final.particles.positions)))


def test_coincident_and_deeply_overlapping_spheres_are_named():
    sim, state, params = _mechanical(positions=((0.0, 0.0, 2e-3), (0.0, 0.0, 2e-3)))
    with pytest.raises(ValueError, match="particles 0 and 1 are at the same centre"):
        rollout.advance(sim, state, params, 10, 10)
    sim, state, params = _mechanical(positions=((0.0, 0.0, 2e-3), (0.0, 0.0, 2.2e-3)))  # 0.2 r apart: 1.8 r deep
    with pytest.raises(ValueError, match=r"particles 0 and 1 are overlapping by 1.8 of the smaller radius"):
        simulate.rollout(sim, state, params, 10)
    sim, state, params = _mechanical(positions=((0.0, 0.0, 2e-3), (0.0, 0.0, 3.9e-3)))  # 0.1 r: a contact, allowed
    simulate.validate_inputs(sim, state, params)


def test_traced_inputs_are_left_to_the_caller():
    import jax

    sim, state, params = _mechanical()
    bad = _with(params, nu=0.7)
    # under jit nothing is concrete: no host check (and no error), as documented
    jax.eval_shape(lambda p: simulate.rollout(sim, state, p, 10)[0].particles.positions, bad)


def test_float32_positions_that_cannot_resolve_the_overlaps_warn():
    """A stiff settled bed in float32 positions loses touching pairs to round-off (issue 28: 61 of 96): the start
    warns, naming the remedy; float64 positions, or overlaps of many float32 steps, do not."""
    import warnings

    a = (1.0, 1.0, 1.0)
    shallow = (1.0, 1.0, 1.0 + 2 * R - 2e-8)  # 20 nm overlap at 1 m from the origin: float32 steps there are 60 nm
    sim, state, params = _mechanical(positions=(a, shallow))
    as32 = dataclasses.replace(state, particles=dataclasses.replace(
        state.particles, positions=state.particles.positions.astype(jnp.float32)))
    with pytest.warns(simulate.PrecisionWarning, match="force_dtype='float32'"):
        simulate.validate_inputs(sim, as32, params)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate.validate_inputs(sim, state, params)  # float64 positions
        deep = (1.0, 1.0, 1.0 + 1.9 * R)  # 0.1 r: about 1,700 float32 steps
        sim, state, params = _mechanical(positions=(a, deep))
        simulate.validate_inputs(sim, dataclasses.replace(state, particles=dataclasses.replace(
            state.particles, positions=state.particles.positions.astype(jnp.float32))), params)
