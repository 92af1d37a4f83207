"""Defects of issue 10 fixed in run.py / thermal.py / network.py: time, limits, phases, stale outputs, API checks.

Each test failed on the code before the fix (written first as a strict xfail).
"""

import copy
import math

import numpy as np
import pytest

from sintercond import run as runner
from sintercond.scene import validate_scene
from tests.test_scene_run import SMALL


def _scene(**run):
    scene = copy.deepcopy(SMALL)
    scene["run"].update(run)
    return validate_scene(scene)


@pytest.mark.slow
def test_simulated_time_ends_at_the_duration(tmp_path):
    scene = _scene(duration=1.3e-3, output_every=7, checkpoint_every=7)
    _, summary = runner.run_scene(scene, tmp_path, progress=False)
    assert summary["simulated_s"] == pytest.approx(1.3e-3, rel=1e-12)


def test_auto_step_is_capped_by_the_duration():
    scene = _scene(duration=1e-9)
    assert runner.build_model(scene).dt <= 1e-9


def test_auto_step_accounts_for_convection():
    scene = copy.deepcopy(SMALL)
    scene["convection"] = {"environment_temperature": 300.0, "environment_conductivity": 0.026, "nusselt": 1e4}
    scene["run"]["duration"] = 2e-3
    plain = runner.build_model(_scene(duration=2e-3))
    cooled = runner.build_model(validate_scene(scene))
    assert cooled.dt < plain.dt


def test_run_leaving_the_physical_range_stops(tmp_path):
    scene = copy.deepcopy(SMALL)
    scene["beam"]["intensity"] = 1e12
    scene["run"].update(duration=2e-3, dt=2e-4)  # stable for conduction, not for a 1e12 W/m^2 source
    with pytest.raises(FloatingPointError, match=r"step \d+.*beam\.intensity"):  # names the likely cause
        runner.run_scene(validate_scene(scene), tmp_path, progress=False)


def test_run_prints_steps_and_stable_step_first(tmp_path, capsys):
    runner.run_scene(_scene(), tmp_path, progress=False)
    out = capsys.readouterr()
    assert "stable step" in out.out + out.err and "steps" in out.out + out.err


@pytest.mark.slow
def test_summary_reports_the_bed(tmp_path):
    scene = copy.deepcopy(SMALL)
    scene["packing"] = {"kind": "powder_bed", "lateral_size": 400e-6, "height": 200e-6,
                        "diameter_range": [45e-6, 105e-6], "sinter_swelling": 0.02}
    scene["beam"]["path"] = [[0.0, 1e-4], [4e-4, 1e-4]]
    scene["run"]["duration"] = 2e-4
    _, summary = runner.run_scene(validate_scene(scene), tmp_path, progress=False)
    assert {"packing_fraction", "coordination", "isolated_particles", "bed_height_m"} <= set(summary)


def test_rerun_leaves_no_stale_frames(tmp_path):
    runner.run_scene(_scene(duration=6e-3), tmp_path, progress=False)  # 15 steps
    runner.run_scene(_scene(duration=1e-3), tmp_path, progress=False)  # 5 steps
    steps = [int(p.stem.split("_")[1]) for p in (tmp_path / "vtp").glob("step_*.vtp")]
    model = runner.build_model(_scene(duration=1e-3))
    assert max(steps) <= model.n_steps


def test_resume_of_a_finished_run_does_nothing(tmp_path, monkeypatch):
    runner.run_scene(_scene(), tmp_path, progress=False)
    monkeypatch.setattr(runner, "build_model", lambda *a, **k: (_ for _ in ()).throw(AssertionError("rebuilt")))
    runner.resume(tmp_path, progress=False)


def test_contact_table_refuses_a_nan_radius():
    from sintercond.contacts import network

    centres = np.array([[0.0, 0, 0], [1.9, 0, 0], [3.8, 0, 0]])
    with pytest.raises(ValueError, match="radii"):
        network.contact_table(centres, np.array([1.0, math.nan, 1.0]), 1.0)


@pytest.mark.parametrize("kwargs,field", [
    ({"method": "rk4"}, "method"), ({"method": "explict"}, "method"),
    ({"n_steps": 10, "save_every": 3}, "save_every"), ({"dt": -1e-3}, "dt"),
])
def test_simulate_refuses_bad_arguments(kwargs, field):
    from sintercond.contacts import network
    from sintercond.simulate import simulate_table

    centres = np.array([[0.0, 0, 0], [1.9, 0, 0]])
    table = network.contact_table(centres, np.array([1.0, 1.0]), 1.0)
    args = {"dt": 1e-3, "n_steps": 10, "save_every": 5, **kwargs}
    with pytest.raises(ValueError, match=field):
        simulate_table(np.array([1.0, 0.0]), table, 1.0, args.pop("dt"), **args)
