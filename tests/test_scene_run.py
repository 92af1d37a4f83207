"""Scene files, `sintercond run`, outputs, checkpoints and exact resume."""

import copy
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from sintercond import run as runner
from sintercond.sim import thermal
from sintercond.scene import SceneError, load_scene, validate_scene

SMALL = {
    "packing": {"kind": "simple_cubic", "counts": [6, 3, 3], "spacing": 1e-4, "radius": 0.52e-4},
    "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.6},
    "conduction": {"law": "rojek"},
    "initial": {"temperature": 300.0},
    "boundary": {"floor_temperature": 300.0},
    "beam": {"intensity": 2e8, "attenuation": 2e4, "spot_radius": 1e-4, "absorptance": 0.7, "speed": 0.05,
             "path": [[0.0, 1e-4], [6e-4, 1e-4]]},
    "radiation": {"environment_temperature": 300.0, "emissivity": 0.4},
    "run": {"duration": 6e-3, "dt": "auto", "output_every": 5, "checkpoint_every": 10, "formats": ["vtp", "lammps"]},
}


def test_default_scene_is_valid():
    scene = load_scene(None)
    assert scene["packing"]["kind"] == "powder_bed" and scene["run"]["dt"] == "auto"


@pytest.mark.parametrize(
    "mutate,message",
    [
        (lambda s: s["material"].update(colour="red"), r"unknown key material\.colour"),
        (lambda s: s.update(magnetism={}), r"unknown section \[magnetism\]"),
        (lambda s: s["material"].update(density=-1.0), r"material\.density must be a number in \[1, 100000\] kg/m\^3; got -1\.0"),
        (lambda s: s["material"].update(conductivity="high"), r"material\.conductivity must be a number"),
        (lambda s: s["packing"].update(radius=1.2e-4), r"packing\.radius must be in \(spacing/2, 7\.5e-05\] m"),
        (lambda s: s["conduction"].update(law="magic"), r"conduction\.law must be one of"),
        (lambda s: s["conduction"].update(params={"slop": 1.0}), r"unknown key conduction\.params\.slop"),
        (lambda s: s["run"].update(checkpoint_every=7), r"run\.checkpoint_every \(7\) must be a multiple"),
        (lambda s: s["run"].update(dt=-1.0), r"run\.dt must be"),
        (lambda s: s["beam"].update(absorptance=1.5), r"beam\.absorptance must be a number in \[0, 1\]"),
        (lambda s: s.pop("initial"), r"missing section \[initial\]"),
        (lambda s: s["run"].update(formats=["xyz"]), r"run\.formats"),
    ],
)
def test_bad_scenes_name_the_field(mutate, message):
    scene = copy.deepcopy(SMALL)
    mutate(scene)
    with pytest.raises(SceneError, match=message):
        validate_scene(scene)


def test_unstable_dt_and_overlap_beyond_the_neck_model():
    scene = copy.deepcopy(SMALL)
    scene["run"]["dt"] = 1.0
    with pytest.raises(SceneError, match=r"run\.dt: dt = 1 s exceeds the explicit stability limit"):
        runner.build_model(validate_scene(scene))
    scene = copy.deepcopy(SMALL)
    scene["packing"]["radius"] = 0.9e-4  # h = 2r - a = 0.8e-4 > max_overlap = 2r/3: caught by the neck model
    with pytest.raises(SceneError, match="max_overlap"):
        validate_scene(scene)  # at validation, before the lattice and network are built


@pytest.mark.slow
def test_run_writes_outputs_and_resume_is_exact(tmp_path):
    long = copy.deepcopy(SMALL)
    long["run"]["duration"] = 9e-3  # 18 steps: chunks end at 5, 10, 15 and 18 (the last one shorter)
    scene = validate_scene(long)
    full, summary = runner.run_scene(scene, tmp_path / "full", progress=False)
    assert summary["simulated_s"] == pytest.approx(9e-3, rel=1e-12) and summary["T_max_K"] > 300.0
    # killed after 3 chunks (15 steps; last checkpoint at 10), then resumed
    runner.run_scene(validate_scene(copy.deepcopy(long)), tmp_path / "cut", progress=False, stop_after_chunks=3)
    (tmp_path / "cut" / "checkpoint.tmp.npz").write_bytes(b"half-written")  # a kill during the next write
    resumed, _ = runner.resume(tmp_path / "cut", progress=False)
    np.testing.assert_array_equal(np.asarray(resumed), np.asarray(full))
    # outputs of the resumed run equal the uninterrupted run's
    full_files = sorted(p.name for p in (tmp_path / "full" / "vtp").iterdir())
    assert full_files == sorted(p.name for p in (tmp_path / "cut" / "vtp").iterdir())
    for name in full_files:
        assert (tmp_path / "full" / "vtp" / name).read_bytes() == (tmp_path / "cut" / "vtp" / name).read_bytes()
    assert (tmp_path / "full" / "dump.lammpstrj").read_text() == (tmp_path / "cut" / "dump.lammpstrj").read_text()


def test_vtp_is_valid_polydata(tmp_path):
    centres = np.random.default_rng(0).uniform(size=(4, 3))
    runner.write_vtp(tmp_path / "x.vtp", centres, np.full(4, 0.1), np.arange(4.0) + 300, 7, 1e-3, encoding="ascii")
    root = ET.parse(tmp_path / "x.vtp").getroot()
    piece = root.find("PolyData/Piece")
    assert root.get("type") == "PolyData" and piece.get("NumberOfPoints") == "4"
    points = np.array(piece.find("Points/DataArray").text.split(), float).reshape(4, 3)
    np.testing.assert_array_equal(points, centres)
    temps = [a for a in piece.find("PointData") if a.get("Name") == "temperature"][0]
    np.testing.assert_array_equal(np.array(temps.text.split(), float), np.arange(4.0) + 300)


@pytest.mark.slow
def test_cli_run_and_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(
        '[packing]\nkind = "simple_cubic"\ncounts = [3, 1, 1]\nspacing = 1e-4\nradius = 0.52e-4\n'
        '[material]\ndensity = -1\nspecific_heat = 560.0\nconductivity = 12.6\n'
        '[conduction]\nlaw = "rojek"\n[initial]\ntemperature = 300.0\n'
        '[run]\nduration = 1e-3\noutput_every = 5\ncheckpoint_every = 5\n'
    )
    result = subprocess.run([sys.executable, "-m", "sintercond.cli", "run", str(bad)], capture_output=True, text=True)
    assert result.returncode == 2 and "material.density must be a number in [1, 100000]" in result.stderr
    assert "Traceback" not in result.stderr
    result = subprocess.run([sys.executable, "-m", "sintercond.cli", "run", str(tmp_path / "none.toml")],
                            capture_output=True, text=True)
    assert result.returncode == 2 and "does not exist" in result.stderr


def test_walls_held_and_conducting(tmp_path):
    scene = copy.deepcopy(SMALL)
    scene.pop("beam"), scene.pop("radiation"), scene.pop("boundary")
    scene["walls"] = [{"axis": 0, "side": "min", "mode": "held", "temperature": 900.0},
                      {"axis": 0, "side": "max", "mode": "conducting", "temperature": 300.0},
                      {"axis": 1, "side": "min", "mode": "insulated"}]
    model = runner.build_model(validate_scene(scene))
    assert int(np.sum(np.asarray(model.state.particles.fixed))) == 9  # the x = min face of the 6x3x3 lattice
    k_w = np.asarray(model.state.contacts.wall_conductance)
    assert np.sum(k_w > 0) == 9 and np.all(np.asarray(model.state.contacts.wall_temperature)[k_w > 0] == 300.0)
    bad = copy.deepcopy(scene)
    bad["walls"][1].pop("temperature")
    with pytest.raises(SceneError, match=r"walls\[1\]\.temperature is required for a conducting wall"):
        validate_scene(bad)
    bad = copy.deepcopy(scene)
    bad["walls"][0]["axis"] = 3
    with pytest.raises(SceneError, match=r"walls\[0\]\.axis must be one of 0, 1, 2"):
        validate_scene(bad)


@pytest.mark.slow
def test_cli_effective(tmp_path):
    scene = tmp_path / "sc.toml"
    scene.write_text(
        '[packing]\nkind = "simple_cubic"\ncounts = [4, 2, 2]\nspacing = 1e-4\nradius = 0.52e-4\n'
        '[material]\ndensity = 4430.0\nspecific_heat = 560.0\nconductivity = 20.0\n'
        '[conduction]\nlaw = "rojek"\n[initial]\ntemperature = 300.0\n'
        '[run]\nduration = 1e-3\noutput_every = 5\ncheckpoint_every = 5\n'
    )
    result = subprocess.run([sys.executable, "-m", "sintercond.cli", "effective", str(scene), "--axis", "0"],
                            capture_output=True, text=True, check=True)
    from sintercond.laws.conductance import rojek_pair_conductance

    expected = float(rojek_pair_conductance(0.52e-4, 0.52e-4, 0.04e-4, 20.0)) / 1e-4  # K_pair / a
    value = float(result.stdout.split(":")[1].split()[0])
    assert value == pytest.approx(expected, rel=1e-5)


def test_nozzle_and_whitaker_convection():
    scene = copy.deepcopy(SMALL)
    scene["beam"] = {"kind": "nozzle", "intensity": 2e8, "max_depth": 1e-4, "spot_radius": 1e-4, "absorptance": 0.7,
                     "speed": 0.05, "path": [[0.0, 1e-4], [6e-4, 1e-4]]}
    scene["convection"] = {"environment_temperature": 300.0, "environment_conductivity": 0.026, "reynolds": 10.0,
                           "prandtl": 0.7}
    model = runner.build_model(validate_scene(scene))
    assert model.physics.sources.beam == "nozzle" and float(model.params.convection.nusselt) > 2.0
    t = np.asarray(thermal.source_power(model.physics.sources, model.state, model.params))
    assert t.max() > 0  # the nozzle heats the particles under the spot
    bad = copy.deepcopy(scene)
    bad["beam"].pop("max_depth")
    with pytest.raises(SceneError, match=r"beam\.max_depth is required for a nozzle beam"):
        validate_scene(bad)
    bad = copy.deepcopy(scene)
    bad["convection"].pop("prandtl")
    with pytest.raises(SceneError, match="reynolds and convection.prandtl go together"):
        validate_scene(bad)


# test_run_killed_mid_way_resumes_identically: now deterministic, in tests/test_teeth_thermal.py


def test_history_csv_reads_back_as_numbers(tmp_path):
    """history.csv (one row per output step) must parse as plain numbers: NumPy 2's repr wrote
    'np.float64(...)' into it, which every CSV reader takes as text, and the history plot came out empty."""
    scene = validate_scene(copy.deepcopy(SMALL))
    final, summary = runner.run_scene(scene, tmp_path, progress=False)
    history = runner.read_history(tmp_path)
    assert np.all(np.isfinite(history["T_max_K"])) and len(history["time"]) == -(-summary["steps"] // 5) + 1
    assert history["time"][-1] == pytest.approx(summary["simulated_s"], rel=1e-12)
    assert history["T_max_K"][-1] == float(np.max(np.asarray(final)))
    assert (tmp_path / "history.png").stat().st_size > 0


def test_history_reports_the_heat_through_held_and_conducting_walls(tmp_path):
    """At the start (uniform 300 K) the heat through a held 900 K face of the 6x3x3 lattice is 9 pairs of the
    Rojek conductance times 600 K (its neighbours within the face are held too), and through a conducting 350 K
    face the wall conductances of the 9 particles it cuts times 50 K: closed forms of the laws."""
    from sintercond.laws.conductance import rojek_pair_conductance
    from sintercond.laws.walls import wall_conductance

    scene = copy.deepcopy(SMALL)
    scene.pop("beam"), scene.pop("radiation"), scene.pop("boundary")
    scene["walls"] = [{"axis": 0, "side": "min", "mode": "held", "temperature": 900.0},
                      {"axis": 0, "side": "max", "mode": "conducting", "temperature": 350.0}]
    scene["run"].update(duration=1e-4, formats=["vtp"])
    runner.run_scene(validate_scene(scene), tmp_path, progress=False)
    first = {k: v[0] for k, v in runner.read_history(tmp_path).items()}
    r, kappa = 0.52e-4, 12.6
    held = 9 * float(rojek_pair_conductance(r, r, 2 * r - 1e-4, kappa)) * 600.0
    assert first["heat_wall0_W"] == pytest.approx(held, rel=1e-12)
    conducting = 9 * float(wall_conductance("rojek", r, 0.02 * r, kappa)) * 50.0
    assert first["heat_wall1_W"] == pytest.approx(conducting, rel=1e-12)
