"""Scenes with mechanics: the built-in example scenes, `sintercond run` of the coupled step, its outputs and resume.

References are closed forms (Hertz static overlap under the weight, the weight m g itself, the Example 5.1
wall conductance k pi r delta / (r - delta), the restitution-damping conversion) and bitwise equality of an
interrupted-and-resumed run with an uninterrupted one.
"""

import copy
import math

import numpy as np
import pytest

from sintercond import cli, examples
from sintercond.output import io
from sintercond import run as runner
from sintercond.scene import build
from sintercond.scene import SceneError, builtin_scenes, load_scene, restitution_damping_ratio, validate_scene
from _helpers import check_network_of_a_moving_packing

G = 9.81


def _vtp_arrays(path):
    return io.read_vtp(path)


def test_builtin_scenes_are_listed_valid_and_within_limits(capsys):
    assert cli.main(["scenes"]) == 0
    listed = capsys.readouterr().out
    for name in ("quintana2020_5_1", "quintana2020_5_3", "quintana2020_5_4_laser"):
        assert name in listed and name in builtin_scenes()
        scene = load_scene(name)
        assert scene.get("physics", {}).get("mechanics", False) is (name != "quintana2020_5_3")  # 5.3 pours, then heats at rest
    assert load_scene("quintana2020_5_1", duration=0.25)["run"]["duration"] == 0.25


@pytest.mark.slow
def test_the_5_1_scene_builds_examples_example_5_1():
    """The scene file and the Python builder are one model: the same physics spec, parameters and initial state."""

    model = runner.build_model(load_scene("quintana2020_5_1"))
    sim, state, params, n = examples.example_5_1()
    assert model.physics == sim.physics and model.dt == float(state.dt) and model.n_steps == n
    mine, theirs = model.params.mechanics, params.mechanics
    for field in ("E0", "nu", "xi_con", "xi_fric", "xi_rol", "mu", "mu_r", "theta_star", "rate", "E_min"):
        assert float(getattr(mine, field)) == float(getattr(theirs, field)), field
    assert theirs.mu_wall is None and float(mine.mu_wall) == float(mine.mu) == 0.0  # None: the pairs' mu
    np.testing.assert_array_equal(model.state.particles.positions, state.particles.positions)
    np.testing.assert_array_equal(model.state.particles.mass, state.particles.mass)


@pytest.mark.slow
def test_example_5_1_by_name_settles_to_the_closed_forms(tmp_path, capsys):
    """0.5 s of Example 5.1 from the command line: the sphere rests on the floor with the Hertz overlap of its
    weight, the contact force is m g (the paper's 1.23e-4 N), and the heat through the floor is k pi r delta /
    (r - delta) (T_w - T) (MECHANICS.md, Walls)."""
    out = tmp_path / "out"
    assert cli.main(["run", "quintana2020_5_1", "--duration", "0.5", "--out", str(out), "--no-progress"]) == 0
    d = examples.EXAMPLE_5_1
    r = d["radius"]
    weight = d["density"] * 4 / 3 * math.pi * r**3 * G
    assert weight == pytest.approx(1.23e-4, rel=3e-3)  # the paper's figure
    history = runner.read_history(out)
    last = {k: v[-1] for k, v in history.items()}
    assert last["time"] == pytest.approx(0.5, rel=1e-12) and last["T_max_K"] < d["theta_star"]  # not yet softened
    delta = examples.static_overlap(weight, r, d["E0"], d["nu"])
    assert last["max_overlap_m"] == pytest.approx(delta, rel=1e-6)
    assert last["kinetic_energy_J"] < 1e-20 and last["contacts"] == 0 and last["wall_contacts"] == 1
    expected = d["conductivity"] * math.pi * r * last["max_overlap_m"] / (r - last["max_overlap_m"])
    assert last["heat_wall0_W"] == pytest.approx(expected * (d["floor_temperature"] - last["T_mean_K"]), rel=1e-9)
    frame = _vtp_arrays(sorted((out / "vtp").iterdir())[-1])
    np.testing.assert_allclose(frame["force"][0], [0.0, 0.0, weight], rtol=1e-6, atol=1e-12 * weight)
    assert np.max(np.abs(frame["velocity"])) < 1e-9 and frame["coordination"][0] == 0
    assert frame["position"][0, 2] == pytest.approx(r - delta, rel=1e-9)
    assert "mechanical_step_s" in capsys.readouterr().out


PILE = {
    # four spheres 0.05 mm apart on the floor and one above their middle: it drops into the pocket, the spheres
    # gain neighbours and the contact list (2 slots at the start) is reallocated during the run
    "packing": {"kind": "spheres", "centres": [[x, y, 1e-3] for x in (1e-3, 3.05e-3) for y in (1e-3, 3.05e-3)]
                + [[2.025e-3, 2.025e-3, 2.6e-3]], "radii": 1e-3},
    "material": {"density": 3000.0, "specific_heat": 100.0, "conductivity": 60.0},
    "conduction": {"law": "conductivity", "neck_model": "hertz"},
    "initial": {"temperature": 300.0},
    "walls": [{"axis": 2, "side": "min", "mode": "conducting", "temperature": 700.0, "penetration": 0.0},
              {"axis": 0, "side": "min", "mode": "held", "temperature": 500.0, "penetration": 0.0,
               "velocity": [0.0, 1e-3, 0.0]}],
    "physics": {"mechanics": True, "impact_velocity": 0.1},
    "mechanics": {"young_modulus": 1e6, "poisson_ratio": 0.3, "friction": 0.4, "rolling_friction": 0.1,
                  "rolling_damping": 0.2, "restitution": 0.5},
    "softening": {"onset_temperature": 350.0},
    "run": {"duration": 2e-2, "output_every": 100, "checkpoint_every": 200, "formats": ["vtp", "lammps"],
            "contact_network": True},
}


@pytest.mark.slow
def test_mechanics_run_resumes_bitwise_springs_included(tmp_path):
    """Five spheres settling into a pile on a hot floor against a held, sliding side wall, with friction and
    rolling (contact springs on pairs and walls): killed after 9 output chunks, past a reallocation of the contact
    list, and resumed, the run equals the uninterrupted one bit for bit, outputs included."""
    built = runner.build_model(validate_scene(copy.deepcopy(PILE))).state.contacts.neighbors.shape[1]
    full, summary = runner.run_scene(validate_scene(copy.deepcopy(PILE)), tmp_path / "full", progress=False)
    assert summary["steps"] > 900 and summary["final_contacts"] == 4
    check_network_of_a_moving_packing(tmp_path / "full")
    saved = np.load(tmp_path / "full" / "checkpoint.npz")
    springs = [k for k in saved.files if "spring" in k or "rolling" in k]
    assert {".mechanics.velocity", ".mechanics.spin"} <= set(saved.files) and len(springs) == 4
    assert any(np.any(saved[k] != 0) for k in springs)  # the springs are loaded, not trivially zero
    runner.run_scene(validate_scene(copy.deepcopy(PILE)), tmp_path / "cut", progress=False, stop_after_chunks=9)
    cut = np.load(tmp_path / "cut" / "checkpoint.npz")
    # resumed past a reallocation (the checkpoint holds the Dense list's index table once, in the list)
    assert int(cut["step"]) == 800 and cut[".contacts.neighbor_list.idx"].shape[1] > built
    resumed, _ = runner.resume(tmp_path / "cut", progress=False)
    np.testing.assert_array_equal(np.asarray(resumed), np.asarray(full))
    for name in ("history.csv", "dump.lammpstrj"):
        assert (tmp_path / "full" / name).read_text() == (tmp_path / "cut" / name).read_text()
    frames = sorted(p.name for p in (tmp_path / "full" / "vtp").iterdir())
    assert frames == sorted(p.name for p in (tmp_path / "cut" / "vtp").iterdir())
    assert all((tmp_path / "full" / "vtp" / f).read_bytes() == (tmp_path / "cut" / "vtp" / f).read_bytes()
               for f in frames)
    header = (tmp_path / "full" / "dump.lammpstrj").read_text().splitlines()[10]  # after ITEM: TIME, the step, ...
    assert header == "ITEM: ATOMS id radius x y z temperature vx vy vz fx fy fz coordination held material heat_power"


@pytest.mark.slow
def test_user_step_above_the_mechanical_limit_is_refused():
    scene = copy.deepcopy(PILE)
    scene["run"]["dt"] = 1e-3
    with pytest.raises(SceneError, match=r"run\.dt: dt = 0\.001 s exceeds the mechanical time step .* s \(Eq\. 47"):
        runner.build_model(validate_scene(scene))


def test_restitution_gives_the_tsuji_damping_ratio():
    # e = exp(-pi): beta = pi / sqrt(2 pi^2) = 1/sqrt(2), xi = sqrt(5/6) / sqrt(2) = sqrt(5/12)
    assert restitution_damping_ratio(math.exp(-math.pi)) == pytest.approx(math.sqrt(5 / 12), rel=1e-15)
    assert restitution_damping_ratio(1.0) == 0.0
    model_xi = build.mechanical_params(validate_scene(copy.deepcopy(PILE))).xi_con
    assert float(model_xi) == pytest.approx(math.sqrt(5 / 6) * math.log(2) / math.sqrt(math.pi**2 + math.log(2) ** 2))


@pytest.mark.parametrize("mutate,message", [
    (lambda s: s.pop("mechanics"), r"physics\.mechanics = true needs a \[mechanics\] section"),
    (lambda s: s["physics"].update(mechanics=False), r"\[mechanics\] needs physics\.mechanics = true"),
    (lambda s: s["mechanics"].update(damping=1.0), r"give mechanics\.damping or mechanics\.restitution, not both"),
    (lambda s: s["mechanics"].update(poisson_ratio=0.6), r"mechanics\.poisson_ratio must be a number in \[0, 0\.5\]"),
    (lambda s: s["mechanics"].update(restitution=0.0), r"mechanics\.restitution must be a number in \(0, 1\]"),
    (lambda s: s["physics"].update(gravity=[0.0, -9.81]), r"physics\.gravity must be a list of 3 numbers"),
    (lambda s: s["physics"].update(shear="voigt"), r"physics\.shear must be one of \"paper\", \"mindlin\""),
    (lambda s: s["softening"].pop("onset_temperature"), r"missing key softening\.onset_temperature"),
    # issue 28: a floor above the modulus ran (and exploded) before
    (lambda s: s["softening"].update(min_modulus=2 * s["mechanics"]["young_modulus"]),
     r"softening\.min_modulus \(2e\+06 Pa\) must not exceed mechanics\.young_modulus \(1e\+06 Pa\)"),
    (lambda s: s["walls"][1].update(velocity=[0.0, "fast", 0.0]), r"walls\[1\]\.velocity must be a list of 3"),
    (lambda s: s["packing"].update(radii=[1e-3, 1e-3]), r"packing\.radii must be a list of 5 numbers in \[1e-08, 1\]"),
    (lambda s: s["packing"].update(centres=[[0.0, 0.0]]), r"packing\.centres\[0\] must be a list of 3 numbers"),
    (lambda s: s["packing"].update(method="pour"), r"unknown key packing\.method"),  # listed spheres: no method
    (lambda s: s["packing"].update(kindx=s["packing"].pop("kind")), r"unknown key packing\.kindx \(did you mean 'kind'\?\)"),
])
def test_bad_mechanics_scenes_name_the_key(mutate, message):
    scene = copy.deepcopy(PILE)
    mutate(scene)
    with pytest.raises(SceneError, match=message):
        validate_scene(scene)


def test_wall_velocity_needs_mechanics():
    scene = copy.deepcopy(PILE)
    for key in ("physics", "mechanics", "softening"):
        scene.pop(key)
    with pytest.raises(SceneError, match=r"walls\[1\]\.velocity needs physics\.mechanics = true"):
        validate_scene(scene)



def _poured_scene(**packing):
    scene = copy.deepcopy(load_scene("quintana2020_5_3"))
    scene["packing"].update(packing)
    return scene


@pytest.mark.parametrize("mutate,message", [
    (lambda s: s.pop("mechanics"), r"a poured packing .* needs a \[mechanics\] section"),
    (lambda s: s["packing"].update(radius_std=1.5e-3), r"mean - truncation \* std = -0\.0015 must be > 0"),
    (lambda s: s["packing"].update(lateral_size=0.01), r"packing\.lateral_size must be > the largest diameter "
                                                        r"0\.010002 m"),
    (lambda s: s["packing"].update(particles=1), r"packing\.particles must be an integer in \[2, 20000\]"),
    (lambda s: s["packing"].update(start="tipped"), r"packing\.start must be one of \"relaxed\", \"deposit\""),
])
def test_bad_poured_packings_name_the_key(mutate, message):
    scene = _poured_scene()
    mutate(scene)
    with pytest.raises(SceneError, match=message):
        validate_scene(scene)


@pytest.mark.slow
def test_the_5_3_scene_pours_with_its_mechanics_section():
    """The built-in 5.3 scene, shrunk to 12 spheres: the radii are Example 5.3's distribution (the same
    sampler and seed), the pour uses the scene's contact material and meets its settled thresholds, and the
    bed's summary carries the settle report."""
    scene = validate_scene(_poured_scene(particles=12, lateral_size=0.02))
    material = build.dem_material(scene)
    assert (material.E, material.nu, material.mu, material.mu_r, material.mu_wall, material.xi_rol) == \
        (1e6, 0.3, 0.05, 0.2, 0.0, 0.2)
    centres, radii, bed = build.build_packing(scene)
    np.testing.assert_array_equal(np.sort(radii), np.sort(examples.example_5_3_radii(12, np.random.default_rng(0))))
    assert bed["settle_kinetic_ratio"] <= bed["settle_kinetic_tol"] and bed["settle_force_ratio"] <= bed["settle_force_tol"]
    assert np.all(centres[:, :2] - radii[:, None] >= -0.05 * radii[:, None])  # inside the box, up to Hertz overlap
    assert np.all(centres[:, :2] + radii[:, None] <= 0.02 + 0.05 * radii[:, None])


@pytest.mark.slow
def test_a_poured_bed_starts_its_run_with_the_springs_it_settled_with():
    """The run continues the pour (issue 39, part 3): a DEM powder bed (the Ti6Al4V scene's pour, shrunk) run with
    its mechanics in the pour's box starts from the settled state's velocities and the springs of every contact,
    carried pair by pair, so its first net forces are those the DEM settle ended with (the settle's own figure,
    below its threshold); the same bed from unloaded springs starts out of balance (its friction and rolling
    resistance rebuilt from zero)."""
    import dataclasses
    import jax

    raw = copy.deepcopy(load_scene("ti6al4v_preheating_bed"))
    raw["packing"].update(lateral_size=200e-6, height=120e-6)
    for section in ("sintering", "preheating"):
        raw.pop(section)
    raw.update(walls=[], physics={"mechanics": True}, run={"duration": 1e-6, "output_every": 10})
    scene = validate_scene(raw)
    _, _, bed, settled = build._scene_packing(scene)
    model = build.build_model(scene)
    motion, poured = model.state.mechanics, settled.state.mechanics
    np.testing.assert_array_equal(np.asarray(motion.velocity), np.asarray(poured.velocity))
    run_pairs = {tuple(p): k for k, p in enumerate(np.asarray(model.state.contacts.pairs.pairs)) if p[0] < p[1]}
    loaded = 0
    for k, pair in enumerate(np.asarray(settled.state.contacts.pairs.pairs)):
        if pair[0] < pair[1] and np.any(np.asarray(poured.spring[k])):
            np.testing.assert_array_equal(np.asarray(motion.spring[run_pairs[tuple(pair)]]),
                                          np.asarray(poured.spring[k]))
            loaded += 1
    assert loaded > 0

    def force_ratio(state):
        probe = jax.jit(model.sim.step_fn)(state, model.params)
        p = state.particles
        force = np.asarray(p.mass)[:, None] * np.asarray(probe.mechanics.velocity - state.mechanics.velocity) / float(
            state.dt)
        return float(np.max(np.linalg.norm(force, axis=1) / (np.asarray(p.mass) * G)))

    carried = force_ratio(model.state)
    assert carried == pytest.approx(bed["settle_force_ratio"], rel=1e-3) and carried <= bed["settle_force_tol"]
    unloaded = dataclasses.replace(model.state, mechanics=dataclasses.replace(
        motion, **{f: None if getattr(motion, f) is None else 0 * getattr(motion, f)
                   for f in ("velocity", "spin", "spring", "rolling", "wall_spring", "wall_rolling")}))
    assert force_ratio(unloaded) > 10 * bed["settle_force_tol"]
