"""The physics spec in sub-specs (issue 24): ``Physics(conduction=, contacts=, motion=, sources=, mechanics=, sintering=)``.

The nested spec and the normalising constructor ``Physics.create`` (flat keywords) give one spec and one compiled
step; specs that mean the same step compare and hash equal; the classes validate and never rewrite themselves.
(Against the flat spec this replaced, the step's jaxpr was compared for the default scene, Examples 5.1 and 5.4,
``examples.example_5_1`` and the softening bed: identical; the note of that change says how.)
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import simulate
from sintercond.sim import mechanics
from sintercond.state import particle_state
from sintercond.laws.walls import PlaneWall

R = 1e-4


def _two_spheres():
    x = np.asarray([[0.0, 0.0, R], [1.9 * R, 0.0, R]])
    return x, particle_state(x, R, np.asarray([300.0, 500.0]), 4430.0)


def _jaxpr(physics):
    """The jaxpr of one step of ``physics`` on two touching spheres (static lifted or dynamic contacts)."""
    x, particles = _two_spheres()
    params = simulate.Params(conductivity=jnp.asarray([7.0]), specific_heat=jnp.asarray([560.0]),
                             radiation=simulate.RadiationParams(300.0, 0.4) if physics.sources.radiation else None)
    if physics.contacts == "static":
        contacts, fns = simulate.lifted_contacts(physics, x, particles.radii), None
        state = simulate.init_state(particles, contacts, 1e-6)
    else:
        contacts, fns = simulate.dynamic_contacts(x, particles.radii, 0.1 * R)
        motion = None
        if physics.mechanics is not None:
            motion = mechanics.mechanical_state(physics.mechanics, x, contacts)
            params = dataclasses.replace(params, mechanics=mechanics.MechanicalParams(E0=1e9, nu=0.3, mu=0.3, mu_r=0.1))
        state = simulate.init_state(particles, contacts, 1e-7, mechanics=motion)
    return str(jax.make_jaxpr(simulate.simulator(physics, fns).step_fn)(state, params))


FLOOR = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), "conducting", 400.0)

CASES = [
    ("thermal lifted", dict(law="rojek", conductance="lifted", held=True),
     simulate.Physics(conduction=simulate.Conduction(law="rojek", conductance="lifted", held=True))),
    ("radiation", dict(law="batchelor_obrien", neck_model="intersection", conductance="lifted", radiation=True),
     simulate.Physics(conduction=simulate.Conduction(law="batchelor_obrien", neck_model="intersection",
                                                     conductance="lifted"),
                      sources=simulate.Sources(radiation=True))),
    ("mechanics", dict(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                       mechanics=True, walls=[FLOOR], friction=True, rolling=True, softening=True),
     simulate.Physics(conduction=simulate.Conduction(law="conductivity", neck_model="hertz", conductance="lifted"),
                      contacts="dynamic",
                      mechanics=simulate.Mechanics(walls=(FLOOR,), friction=True, rolling=True, softening=True))),
]


@pytest.mark.parametrize("flat,nested", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_flat_keywords_and_the_nested_spec_are_one_spec_and_one_program(flat, nested):
    made = simulate.Physics.create(**flat)
    assert made == nested and hash(made) == hash(nested)
    assert _jaxpr(made) == _jaxpr(nested)


def test_specs_that_mean_the_same_step_compare_equal():
    """Sequences and NumPy booleans are normalised; ``wall_friction``/``wall_rolling`` say nothing without the
    pairs' law, so ``create`` sets them True there (the step it compiles does not read them)."""
    base = dict(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic", mechanics=True)
    a = simulate.Physics.create(**base, walls=[PlaneWall([0, 0, 0], [0, 0, 1])], gravity=[0, 0, -9.81],
                                wall_friction=False, wall_rolling=np.bool_(False), softening=np.bool_(True))
    b = simulate.Physics.create(**base, walls=(PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),), softening=True)
    assert a == b and hash(a) == hash(b)
    assert a.mechanics.wall_friction is True and a.mechanics.gravity == (0.0, 0.0, -9.81)
    # with friction on, the flag matters and is kept
    c = simulate.Physics.create(**base, friction=True, wall_friction=False)
    assert c.mechanics.wall_friction is False and c != simulate.Physics.create(**base, friction=True)
    assert _jaxpr(c) != _jaxpr(simulate.Physics.create(**base, friction=True))


def test_the_spec_classes_validate_and_never_rewrite():
    spec = simulate.Mechanics(walls=(FLOOR,), friction=False, wall_friction=False)
    assert spec.wall_friction is False  # kept as written: only create() normalises
    with pytest.raises(ValueError, match=r"Mechanics\.walls must be a tuple of PlaneWall; got list"):
        simulate.Mechanics(walls=[FLOOR])
    with pytest.raises(ValueError, match=r"Mechanics\.gravity must be a tuple of 3 finite floats"):
        simulate.Mechanics(gravity=(0, 0, -10))
    with pytest.raises(ValueError, match=r"Mechanics\.walls\[0\]: point, normal and velocity must be tuples"):
        simulate.Mechanics(walls=(PlaneWall([0.0, 0.0, 0.0], (0.0, 0.0, 1.0)),))
    with pytest.raises(ValueError, match=r"Mechanics\.friction must be True or False"):
        simulate.Mechanics(friction=1)
    with pytest.raises(ValueError, match=r"Physics\.mechanics must be a sintercond\.sim\.mechanics\.Mechanics or None"):
        simulate.Physics(mechanics=True)
    with pytest.raises(ValueError, match=r"Physics\.conduction must be a Conduction"):
        simulate.Physics(conduction="rojek")
    with pytest.raises(ValueError, match=r"Physics\.sintering must be a sintercond\.sim\.neck_growth\.Sintering or None"):
        simulate.Physics(sintering="grain_boundary")
    with pytest.raises(ValueError, match=r"Sources\.beam must be one of"):
        simulate.Sources(beam="electron")
    with pytest.raises(ValueError, match=r"Physics\.mechanics needs conduction\.conductance='lifted'"):
        simulate.Physics(contacts="dynamic", mechanics=simulate.Mechanics())
    with pytest.raises(ValueError, match=r"friction belong to the mechanical step"):
        simulate.Physics.create(friction=True)


def test_a_sub_spec_that_is_off_is_not_traced():
    """The same thermal step with and without sources that are all off: one program, no source term traced."""
    plain = simulate.Physics(conduction=simulate.Conduction(conductance="lifted"))
    off = simulate.Physics(conduction=simulate.Conduction(conductance="lifted"), sources=simulate.Sources())
    assert plain == off and _jaxpr(plain) == _jaxpr(off)
    hot = dataclasses.replace(plain, sources=simulate.Sources(radiation=True))
    assert "pow" not in _jaxpr(plain) and _jaxpr(hot) != _jaxpr(plain)


def test_a_source_without_its_parameters_is_refused_naming_both():
    x, particles = _two_spheres()
    physics = simulate.Physics(conduction=simulate.Conduction(conductance="lifted"),
                               sources=simulate.Sources(radiation=True))
    state = simulate.init_state(particles, simulate.lifted_contacts(physics, x, particles.radii), 1e-6)
    params = simulate.Params(conductivity=jnp.asarray([7.0]), specific_heat=jnp.asarray([560.0]))
    with pytest.raises(ValueError, match=r"Physics\.sources\.radiation is on but Params\.radiation is None"):
        simulate.rollout(simulate.simulator(physics), state, params, 2)
