"""A soft pour carried to a real material's stiffness (issue 27: a DEM pour at 110 GPa that finishes).

References: Hertz's static overlap of a sphere on a plane under its weight (closed form); the homogeneity of the
Hertz-Mindlin laws (every force unchanged when the overlaps and springs scale by (E_soft / E)^(2/3)); the floor's
Hertz reactions against the bed's weight; brute-force overlaps of the moved positions.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sintercond import scene
from sintercond.beds import packing, rolling, settle
from sintercond.scene import SceneError

TI = settle.DemMaterial(density=4430.0, E=110e9, nu=0.34, mu=0.3, mu_r=0.05, mu_wall=0.3, mu_r_wall=0.05)
SOFT = 1e7  # Pa
BOX = 300e-6  # m


def _hertz_floor_overlap(weight, radius, material):
    """(3 W / (4 E* sqrt(r)))^(2/3), E* = E / (1 - nu^2): a sphere resting on a rigid plane (Remark 1)."""
    return (3.0 * weight / (4.0 * material.E / (1.0 - material.nu**2) * math.sqrt(radius))) ** (2.0 / 3.0)


def test_a_sphere_on_the_floor_stiffens_to_hertz_overlap():
    r = 40e-6
    weight = 4.0 / 3.0 * math.pi * r**3 * TI.density * settle.GRAVITY
    walls = settle.box_walls(BOX)[:1]
    start = np.array([[BOX / 2, BOX / 2, r]])
    soft = settle.dem_settle(start, [r], walls, dataclasses.replace(TI, E=SOFT), force_tol=1e-4, check_every=200)
    assert r - soft.centres[0, 2] == pytest.approx(_hertz_floor_overlap(weight, r, soft.material), rel=1e-3)
    stiff = settle.stiffen(soft, TI, force_tol=1e-4, check_every=200)
    assert r - stiff.centres[0, 2] == pytest.approx(_hertz_floor_overlap(weight, r, TI), rel=1e-3)
    report = stiff.report
    assert report.soft_modulus == SOFT and report.soft_steps == soft.report.steps and report.steps >= 200
    assert report.dt < soft.report.dt / 10  # the stiff step
    assert stiff.material == TI


@pytest.fixture(scope="module")
def soft_bed():
    rng = np.random.default_rng(3)
    radii = packing.sample_diameters(40, 45e-6, 105e-6, rng) / 2
    centres, _ = rolling.roll_deposit(radii, BOX, rng, overlap=0.0)
    return settle.dem_settle(centres, radii, settle.box_walls(BOX), dataclasses.replace(TI, E=SOFT), check_every=2000,
                             v_rel=math.sqrt(2.0 * settle.GRAVITY * 2.0 * float(np.mean(radii))))


def _net_forces(settled, state, material):
    """``[n, 3]`` net forces (N) at ``state`` from one probe step at ``material``'s parameters."""
    with jax.enable_x64(True):
        params = dataclasses.replace(settled.params, mechanics=material.mechanical_params())
        state = dataclasses.replace(state, dt=jnp.asarray(1e-9))
        probe = settled.sim.step_fn(state, params)
        return np.asarray(state.particles.mass[:, None] * (probe.mechanics.velocity - state.mechanics.velocity)
                          / state.dt)


def test_scaled_overlaps_and_springs_keep_every_force(soft_bed):
    # Hertz-Mindlin homogeneity: the stiffened state feels the soft state's forces, to the moved normals' order
    ratio = (SOFT / TI.E) ** (2.0 / 3.0)
    state = soft_bed.state
    with jax.enable_x64(True):
        rest = dataclasses.replace(state.mechanics, velocity=0 * state.mechanics.velocity,
                                   spin=0 * state.mechanics.spin)
        state = dataclasses.replace(state, mechanics=rest)
        x, residual = settle.stiffened_positions(state.particles.positions, state.particles.radii,
                                                 state.contacts.pairs.pairs, soft_bed.sim.physics.mechanics.walls, ratio)
        scaled = dataclasses.replace(rest, spring=rest.spring * ratio, rolling=rest.rolling * ratio,
                                     wall_spring=rest.wall_spring * ratio, wall_rolling=rest.wall_rolling * ratio)
        moved = dataclasses.replace(state, mechanics=scaled,
                                    particles=dataclasses.replace(state.particles, positions=jnp.asarray(x)))
        unscaled = dataclasses.replace(moved, mechanics=rest)
    assert residual < 1e-6
    weight = np.asarray(state.particles.mass) * settle.GRAVITY
    # at rest: a settled bed's last creep leaves some load on its dashpots, which stopping it removes
    before = _net_forces(soft_bed, state, soft_bed.material)
    after = _net_forces(soft_bed, moved, TI)
    error = np.max(np.linalg.norm(after - before, axis=1) / weight)
    assert error < 0.25
    # the springs carry their share: without scaling them the same positions are far from balance
    unscaled_error = np.max(np.linalg.norm(_net_forces(soft_bed, unscaled, TI) - before, axis=1) / weight)
    assert unscaled_error > 10 * error


def test_stiffened_positions_reach_their_overlaps_and_touch_nothing_new(soft_bed):
    ratio = (SOFT / TI.E) ** (2.0 / 3.0)
    x0, r = np.asarray(soft_bed.state.particles.positions), np.asarray(soft_bed.state.particles.radii)
    walls = soft_bed.sim.physics.mechanics.walls
    x, _ = settle.stiffened_positions(x0, r, soft_bed.state.contacts.pairs.pairs, walls, ratio)
    i, j = np.triu_indices(len(r), 1)  # brute force over every pair
    h0 = r[i] + r[j] - np.linalg.norm(x0[i] - x0[j], axis=1)
    h = r[i] + r[j] - np.linalg.norm(x[i] - x[j], axis=1)
    touching = h0 > 0
    assert touching.sum() > len(r)
    np.testing.assert_allclose(h[touching], ratio * h0[touching], rtol=1e-6, atol=1e-6 * ratio * h0.max())
    assert np.all(h[~touching] <= 1e-6 * ratio * h0.max())
    for w in walls:
        p0, p = np.asarray(w.penetration(x0, r)), np.asarray(w.penetration(x, r))
        np.testing.assert_allclose(p[p0 > 0], ratio * p0[p0 > 0], rtol=1e-6)
        assert np.all(p[p0 <= 0] <= 1e-6 * ratio * h0.max())


@pytest.mark.slow
def test_a_110_gpa_pour_finishes_and_its_floor_carries_the_weight(soft_bed):
    bed = settle.stiffen(soft_bed, TI, check_every=2000)
    report = bed.report
    assert report.kinetic_ratio < settle.KINETIC_TOL and report.force_ratio < settle.FORCE_TOL
    assert report.steps * report.dt == pytest.approx(report.time)
    c, r = bed.centres, np.asarray(bed.state.particles.radii)
    # the overlaps of 110 GPa: a micrometre's thousandths, not the soft bed's tenths
    ratio = (SOFT / TI.E) ** (2.0 / 3.0)
    assert report.max_overlap == pytest.approx(ratio * soft_bed.report.max_overlap, rel=0.2)
    assert report.max_overlap < 1e-4
    weight = np.sum(4.0 / 3.0 * np.pi * r**3 * TI.density) * settle.GRAVITY
    floor, *sides = settle.box_walls(BOX)
    h = np.maximum(np.asarray(floor.penetration(c, r)), 0.0)
    reaction = np.sum(4.0 / 3.0 * TI.E / (1 - TI.nu**2) * np.sqrt(r) * h**1.5)
    side_normal = sum(np.sum(4.0 / 3.0 * TI.E / (1 - TI.nu**2) * np.sqrt(r)
                             * np.maximum(np.asarray(w.penetration(c, r)), 0.0) ** 1.5) for w in sides)
    # the side walls rub: they carry at most mu times their normal load
    assert weight - TI.mu_wall * side_normal - settle.FORCE_TOL * weight <= reaction <= weight * (1 + settle.FORCE_TOL)


def test_a_pour_through_packing_takes_the_soft_modulus():
    radii = np.full(3, 40e-6)
    bed = packing.pour(radii, BOX, TI, seed=0, start="rolled", soft_modulus=SOFT, check_every=500)
    assert bed.settle.soft_modulus == SOFT
    summary = bed.summary()
    assert summary["settle_soft_modulus_Pa"] == SOFT and summary["settle_soft_steps"] > 0
    assert bed.settle.max_overlap < 1e-4


def test_bad_soft_pours_are_refused_before_compiling():
    radii, start = np.full(2, 40e-6), np.array([[50e-6, 50e-6, 40e-6], [150e-6, 50e-6, 40e-6]])
    walls = settle.box_walls(BOX)
    for bad in (TI.E, 2 * TI.E, 0.0, -1.0, True, "soft"):
        with pytest.raises(packing.PackingError, match=r"soft_modulus must be a number in \(0, E = 1.1e\+11\) Pa"):
            settle.dem_settle(start, radii, walls, TI, soft_modulus=bad)
    with pytest.raises(packing.PackingError, match=r"soft_modulus needs softening=False"):
        settle.dem_settle(start, radii, walls, TI, softening=True, soft_modulus=SOFT)
    fake = settle.DemSettled(start, None, None, None, None, None, dataclasses.replace(TI, E=SOFT, mu=0.1))
    with pytest.raises(packing.PackingError, match=r"stiffen takes the DemMaterial of the soft settle with a larger E"):
        settle.stiffen(fake, TI)


POURED = {"kind": "poured", "particles": 20, "radius_mean": 35e-6, "radius_std": 5e-6, "lateral_size": BOX}


def _scene(packing_table, mechanics=True):
    s = {"packing": packing_table, "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 7.0},
         "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0},
         "run": {"duration": 1e-3, "output_every": 5, "checkpoint_every": 10}}
    if mechanics:
        s["mechanics"] = {"young_modulus": 110e9, "poisson_ratio": 0.34, "friction": 0.3}
    return s


def test_scene_soft_modulus_is_checked():
    ok = scene.validate_scene(_scene({**POURED, "soft_modulus": 1e7}))
    assert ok["packing"]["soft_modulus"] == 1e7
    with pytest.raises(SceneError, match=r"packing.soft_modulus must be below mechanics.young_modulus = 1.1e\+11 Pa"):
        scene.validate_scene(_scene({**POURED, "soft_modulus": 2e11}))
    with pytest.raises(SceneError, match=r"packing.soft_modulus applies to a poured packing only"):
        scene.validate_scene(_scene({"kind": "powder_bed", "lateral_size": 1e-3, "height": 3e-4,
                                     "diameter_range": [45e-6, 105e-6], "soft_modulus": 1e7}, mechanics=False))
    with pytest.raises(SceneError, match=r"soft_modulus"):
        scene.validate_scene(_scene({**POURED, "soft_modulus": 0.0}))


def test_a_dem_powder_bed_takes_where_its_pour_starts_and_the_build_passes_it(monkeypatch):
    bed = {"kind": "powder_bed", "lateral_size": 1e-3, "height": 3e-4, "diameter_range": [45e-6, 105e-6],
           "method": "dem", "start": "rolled", "soft_modulus": 1e7}
    assert scene.validate_scene(_scene(bed))["packing"]["start"] == "rolled"
    with pytest.raises(SceneError, match=r"packing.start is where a DEM pour starts from"):
        scene.validate_scene(_scene({k: v for k, v in bed.items() if k not in ("method", "soft_modulus")},
                                    mechanics=False))
    with pytest.raises(SceneError, match=r"packing.start must be one of"):
        scene.validate_scene(_scene({**bed, "start": "poured"}))
    seen = {}

    def fake_powder_bed(*args, **kwargs):
        seen.update(kwargs)
        raise RuntimeError("stop here")

    from sintercond.beds import packing
    from sintercond.scene import build

    monkeypatch.setattr(packing, "powder_bed", fake_powder_bed)
    with pytest.raises(RuntimeError, match="stop here"):
        build.build_model(scene.validate_scene(_scene(bed)))
    assert seen["start"] == "rolled" and seen["soft_modulus"] == 1e7 and seen["method"] == "dem"
