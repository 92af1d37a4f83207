"""Every scene key reaches the field it sets (issue 28: walls[k].velocity was validated, then dropped).

One row per key: a value unlike its default, and where the built model holds it. A key of the schema with no
row fails the completeness test, so a new key must say where it goes. The reference is the value written in the
scene (or its printed transform: a density times the sphere's volume, the Tsuji damping ratio of a
restitution, Whitaker's Nusselt number).
"""

import copy
import math

import numpy as np
import pytest

from sintercond import scene, simulate
from sintercond.laws import heat_sources
from sintercond import run as runner
from sintercond.scene import restitution_damping_ratio, validate_scene

R = 1e-3
BASE = {
    "packing": {"kind": "spheres", "centres": [[2e-3, 2e-3, 1e-3], [4.5e-3, 2e-3, 1e-3]], "radii": R},
    "material": {"density": 3000.0, "specific_heat": 100.0, "conductivity": 60.0},
    "conduction": {"law": "rojek", "neck_model": "hertz"},
    "initial": {"temperature": 300.0},
    "walls": [{"axis": 2, "side": "min", "mode": "conducting", "temperature": 350.0, "penetration": 0.0},
              {"axis": 0, "side": "max", "mode": "held", "temperature": 320.0, "penetration": 0.0}],
    "beam": {"intensity": 1e6, "attenuation": 1e3, "spot_radius": 1e-3, "absorptance": 0.5, "speed": 0.01,
             "path": [[2e-3, 2e-3], [4e-3, 2e-3]]},
    "convection": {"environment_temperature": 290.0, "environment_conductivity": 0.026},
    "radiation": {"environment_temperature": 295.0, "emissivity": 0.3},
    "physics": {"mechanics": True},
    "mechanics": {"young_modulus": 1e6, "poisson_ratio": 0.3},
    "softening": {"onset_temperature": 400.0},
    "run": {"duration": 1e-3, "output_every": 10, "checkpoint_every": 10, "formats": ["vtp"]},
}


def _set(path, value, base=None):
    s = copy.deepcopy(base or BASE)
    *head, last = path
    target = s
    for k in head:
        target = target.setdefault(k, {}) if isinstance(k, str) else target[k]
    target[last] = value
    return s


def f(x):
    return float(np.asarray(x).ravel()[0])


mech = lambda m: m.params.mechanics  # noqa: E731
# (key, value, read(model)): read gives back the value the key set
ROWS = [
    ("material.density", 5000.0, lambda m: f(m.state.particles.mass) / (4 / 3 * math.pi * R**3)),
    ("material.specific_heat", 700.0, lambda m: f(m.params.specific_heat)),
    ("material.conductivity", 20.0, lambda m: f(m.params.conductivity)),
    ("conduction.law", "conductivity", lambda m: m.physics.conduction.law),
    ("conduction.neck_model", "intersection", lambda m: m.physics.neck),
    ("conduction.params", {"slope": 1.2}, lambda m: {k: f(v) for k, v in m.params.law.items()}),
    ("initial.temperature", 310.0, lambda m: f(m.state.particles.temperature)),
    ("beam.intensity", 2e6, lambda m: f(m.params.beam.intensity)),
    ("beam.attenuation", 2e3, lambda m: f(m.params.beam.reach)),
    ("beam.spot_radius", 5e-4, lambda m: f(m.params.beam.spot_radius)),
    ("beam.absorptance", 0.8, lambda m: f(m.params.beam.absorptance)),
    ("beam.speed", 0.02, lambda m: f(m.params.beam.speed)),
    ("beam.path", [[2.5e-3, 2e-3], [3e-3, 2.5e-3]], lambda m: np.asarray(m.params.beam.path).tolist()),
    ("beam.segments_on", [False], lambda m: np.asarray(m.params.beam.segments_on).tolist()),
    ("beam.after_path", "stay", lambda m: f(m.params.beam.after_path)),
    ("convection.environment_temperature", 280.0, lambda m: f(m.params.convection.environment_temperature)),
    ("convection.environment_conductivity", 0.05, lambda m: f(m.params.convection.environment_conductivity)),
    ("convection.nusselt", 3.0, lambda m: f(m.params.convection.nusselt)),
    ("radiation.environment_temperature", 285.0, lambda m: f(m.params.radiation.environment_temperature)),
    ("radiation.emissivity", 0.6, lambda m: f(m.params.radiation.emissivity)),
    ("physics.gravity", [0.0, -1.0, -9.0], lambda m: list(m.physics.mechanics.gravity)),
    ("physics.shear", "mindlin", lambda m: m.physics.mechanics.shear),
    ("physics.slip_direction", "velocity", lambda m: m.physics.mechanics.slip_direction),
    ("physics.rolling_projection", True, lambda m: m.physics.mechanics.rolling_projection),
    ("physics.damping_clamp", True, lambda m: m.physics.mechanics.damping_clamp),
    ("physics.impact_velocity", 0.2, lambda m: m.sized_speed),
    ("mechanics.young_modulus", 2e6, lambda m: f(mech(m).E0)),
    ("mechanics.poisson_ratio", 0.25, lambda m: f(mech(m).nu)),
    ("mechanics.friction", 0.4, lambda m: (f(mech(m).mu), m.physics.mechanics.friction)),
    ("mechanics.rolling_friction", 0.1, lambda m: (f(mech(m).mu_r), m.physics.mechanics.rolling)),
    ("mechanics.wall_friction", 0.2, lambda m: (f(mech(m).mu_wall), m.physics.mechanics.wall_friction)),
    ("mechanics.wall_rolling_friction", 0.05, lambda m: (f(mech(m).mu_r_wall), m.physics.mechanics.wall_rolling)),
    ("mechanics.damping", 0.7, lambda m: f(mech(m).xi_con)),
    ("mechanics.tangential_damping", 0.6, lambda m: f(mech(m).xi_fric)),
    ("mechanics.rolling_damping", 0.3, lambda m: f(mech(m).xi_rol)),
    ("softening.onset_temperature", 450.0, lambda m: f(mech(m).theta_star)),
    ("softening.rate", 2.0, lambda m: f(mech(m).rate)),
    ("softening.min_modulus", 1e5, lambda m: f(mech(m).E_min)),
    ("run.dt", 1e-6, lambda m: m.dt),
    ("run.duration", 2e-3, lambda m: m.n_steps * m.dt),
]
EXPECTED = {
    "beam.segments_on": [0.0], "beam.after_path": 1.0,
    "mechanics.friction": (0.4, True), "mechanics.rolling_friction": (0.1, True),
    "mechanics.wall_friction": (0.2, True), "mechanics.wall_rolling_friction": (0.05, True),
}
# keys whose field is not a number of the model: where each is checked instead
ELSEWHERE = {
    "boundary.floor_temperature": "test_floor_temperature_is_a_held_floor (below)",
    "physics.mechanics": "every row above builds the coupled model; test_scene_mechanics builds the thermal one",
    "physics.skin": "test_the_skin_reaches_the_contact_list (below)",
    "physics.container": "test_first_week.py: test_a_moving_powder_bed_is_held_in_its_box (the box's walls)",
    "mechanics.restitution": "test_restitution_sets_the_tsuji_damping_ratio (below)",
    "convection.reynolds": "test_reynolds_and_prandtl_give_whitakers_nusselt (below)",
    "convection.prandtl": "test_reynolds_and_prandtl_give_whitakers_nusselt (below)",
    "beam.kind": "test_nozzle_reach (below): a nozzle needs its max_depth",
    "beam.max_depth": "test_nozzle_reach (below)",
    "beam.power": "test_first_day.py: test_a_beam_given_by_its_power (it sets beam.intensity)",
    "material.melting_point": "test_first_day.py: a run crossing it stops or warns, naming it",
    "material.on_melting": "test_first_day.py: a run crossing it stops or warns, naming it",
    "run.output_every": "test_observable_times.py: history rows at every output_every steps",
    "conduction.coupling": "test_sphere_coupling_transient.py: test_scene_key_round_trip_and_refusals",
    "run.integrator": "test_adaptive.py: auto resolved to implicit without mechanics (BASE has mechanics)",
    "run.rtol": "test_adaptive.py: the scene's rtol and atol reach Conduction (BASE has mechanics)",
    "run.atol": "test_adaptive.py: the scene's rtol and atol reach Conduction (BASE has mechanics)",
    "run.checkpoint_every": "test_scene_mechanics.py: the resume test cuts at a checkpoint",
    "run.formats": "test_scene_run.py: the formats written",
    "run.vtp_encoding": "test_io.py: both encodings read back by VTK (binary is the default a run writes)",
    "run.override_limits": "test_bad_input.py: the limits refused and overridden",
    "initial.from_file": "test_packing_files.py: test_a_scene_starts_from_the_files_temperatures",
    **{f"sintering.{key}": "test_sintering_scene.py: test_the_sintering_keys_reach_the_model (no mechanics)"
       for key in ("law", "every", "params", "neck_rtol")},
    "sintering.shrinkage": "test_sintering_scene.py: test_many_body_shrinkage_holds_the_bottom_layer_on_its_floor...",
    "sintering.start_necks": "test_sintering_mechanics.py: test_the_start_of_the_necks_is_a_key_of_runs_with_the_"
                             "mechanics_only, and the coupled scene starts from point contacts",
    "mechanics.quasi_static": "test_sintering_mechanics.py: test_quasi_static_sintering_steps_at_the_thermal_limit_"
                              "not_the_elastic_one (the built step), and the quasi-static cell and bed runs",
    "run.contact_network": "test_contact_network.py: network frames written when asked, none otherwise",
    "material.conductivity_table": "test_conductivity_table.py: test_a_scenes_table_reaches_the_run",
    "material.specific_heat_table": "test_specific_heat_table.py: test_a_scenes_table_reaches_the_run...",
    "sintering.k_star_axis": "test_sintering_scene.py: the SC cell's k_star_W_mK against K_pair / spacing",
    "sintering.k_star_coupling": "test_sintering_scene.py: test_a_bed_measures_k_star_from_its_floor_to_its_mean_"
                                 "surface_like_its_bulk (none reaches the model; the default reads below it)",
    **{f"preheating.{key}": "test_sintering_scene.py: the SC cell on the ramp, test_a_held_wall_follows_the_ramp"
       for key in ("end_temperature", "duration", "steps", "hold")},
}
WALL_ROWS = [  # walls[0] with mechanics is physics.walls[0]
    ("axis", 1, lambda w: tuple(w.normal), (0.0, 1.0, 0.0)),
    ("side", "max", lambda w: tuple(w.normal), (0.0, 0.0, -1.0)),
    ("mode", "insulated", lambda w: w.mode, "insulated"),
    ("temperature", 360.0, lambda w: w.temperature, 360.0),
    ("penetration", 0.1, lambda w: w.point[2], 0.1 * R),  # the floor at z = 0 moved 0.1 mean radii up
    ("velocity", [1e-3, 0.0, 2e-3], lambda w: w.velocity, (1e-3, 0.0, 2e-3)),
]


def test_every_schema_key_has_a_row_or_says_where_it_is_checked():
    keys = {f"{section}.{key}" for section, table in scene._SCHEMA.items() for key in table}
    covered = {row[0] for row in ROWS} | set(ELSEWHERE)
    assert keys == covered, (keys - covered, covered - keys)
    assert {row[0] for row in WALL_ROWS} == set(scene._WALL)


@pytest.mark.parametrize("key,value,read", ROWS, ids=[r[0] for r in ROWS])
def test_a_scene_key_reaches_its_field(key, value, read):
    model = runner.build_model(validate_scene(_set(key.split("."), value)))
    got = read(model)
    expected = EXPECTED.get(key, value)
    if isinstance(value, float):
        assert got == pytest.approx(expected, rel=1e-12)
    else:
        assert got == expected


@pytest.mark.parametrize("key,value,read,expected", WALL_ROWS, ids=[r[0] for r in WALL_ROWS])
def test_a_wall_key_reaches_its_wall(key, value, read, expected):
    s = _set(("walls", 0, key), value)
    if key == "mode":
        s["walls"][0].pop("temperature")
    model = runner.build_model(validate_scene(s))
    got = read(model.physics.mechanics.walls[0])
    assert got == (pytest.approx(expected, rel=1e-12) if isinstance(expected, (float, tuple)) else expected)


def test_restitution_sets_the_tsuji_damping_ratio():
    model = runner.build_model(validate_scene(_set(("mechanics", "restitution"), 0.5)))
    assert f(mech(model).xi_con) == pytest.approx(restitution_damping_ratio(0.5), rel=1e-15)


def test_reynolds_and_prandtl_give_whitakers_nusselt():
    s = _set(("convection", "reynolds"), 10.0)
    s["convection"]["prandtl"] = 0.7
    model = runner.build_model(validate_scene(s))
    nusselt = 2 + (0.4 * 10**0.5 + 0.06 * 10 ** (2 / 3)) * 0.7**0.4  # Eq. 39
    assert f(model.params.convection.nusselt) == pytest.approx(nusselt, rel=1e-12)
    assert float(heat_sources.whitaker_nusselt(10.0, 0.7)) == pytest.approx(nusselt, rel=1e-12)


def test_nozzle_reach():
    s = _set(("beam", "kind"), "nozzle")
    s["beam"].pop("attenuation")
    s["beam"]["max_depth"] = 4e-4
    model = runner.build_model(validate_scene(s))
    assert model.physics.sources.beam == "nozzle" and f(model.params.beam.reach) == pytest.approx(4e-4, rel=1e-15)


def test_floor_temperature_is_a_held_floor():
    s = copy.deepcopy(BASE)
    for key in ("physics", "mechanics", "softening"):
        s.pop(key)
    s["walls"] = []
    s["boundary"] = {"floor_temperature": 333.0}
    model = runner.build_model(validate_scene(s))
    particles = model.state.particles
    assert model.physics.conduction.held and bool(np.all(np.asarray(particles.fixed)))  # both spheres touch the floor
    np.testing.assert_allclose(np.asarray(particles.fixed_temperature), 333.0, rtol=1e-15)


def test_the_skin_reaches_the_contact_list(monkeypatch):
    seen = []
    original = simulate.dynamic_contacts

    def spy(positions, radii, skin, *args, **kwargs):
        seen.append(skin)
        return original(positions, radii, skin, *args, **kwargs)

    monkeypatch.setattr(simulate, "dynamic_contacts", spy)
    runner.build_model(validate_scene(_set(("physics", "skin"), 0.3)))
    assert seen == [pytest.approx(0.3 * R, rel=1e-15)]  # in largest radii
