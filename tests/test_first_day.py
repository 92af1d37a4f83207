"""A powder-bed engineer's first day (issue 27): each test was written against the defect and failed before.

References: the scene as written (a beam over a poured bed), the physical times a run's outputs carry, VTK's
own reader of the files written.
"""

import copy
from xml.etree import ElementTree

import numpy as np
import pytest

from sintercond import run as runner
from sintercond.scene import build
from sintercond.scene import load_scene, validate_scene


def _poured_with_beam(**run):
    scene = copy.deepcopy(load_scene("quintana2020_5_3"))
    scene["packing"].update(particles=12, lateral_size=0.02)
    scene["beam"] = {"intensity": 1e5, "attenuation": 500.0, "spot_radius": 4e-3, "absorptance": 0.8,
                     "speed": 0.01, "path": [[2e-3, 1e-2], [1.8e-2, 1e-2]]}
    scene["run"].update(run)
    return scene


def test_a_poured_bed_takes_a_beam():
    """`KeyError: 'counts'`: the beam's path was checked against a lattice's extent whatever the packing."""
    scene = validate_scene(_poured_with_beam())
    assert scene["beam"]["path"] == [[2e-3, 1e-2], [1.8e-2, 1e-2]]
    outside = _poured_with_beam()
    outside["beam"]["path"] = [[2e-3, 1e-2], [0.5, 1e-2]]
    with pytest.raises(Exception, match=r"beam\.path\[1\]"):
        validate_scene(outside)


@pytest.mark.slow
def test_pour_then_scan_runs_and_the_beam_heats_the_bed(tmp_path):
    scene = validate_scene(_poured_with_beam(duration=2.0, output_every=5, checkpoint_every=5))
    temperature, summary = runner.run_scene(scene, tmp_path, progress=False)
    assert summary["steps"] > 0 and np.all(np.isfinite(np.asarray(temperature)))
    assert summary["T_max_K"] > scene["initial"]["temperature"] + 1.0  # heated under the spot


def _lattice_with_beam(**beam):
    scene = {"packing": {"kind": "simple_cubic", "counts": [4, 1, 1], "spacing": 1e-4, "radius": 0.52e-4},
             "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.6},
             "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0},
             "beam": {"intensity": 2e8, "attenuation": 2e4, "spot_radius": 5e-5, "absorptance": 0.7, "speed": 0.1,
                      # along the row and back: 3e-4 m out, 3e-4 m back, 6e-3 s in all
                      "path": [[0.52e-4, 0.52e-4], [3.52e-4, 0.52e-4], [0.52e-4, 0.52e-4]]},
             "run": {"duration": 1e-2, "dt": "auto", "output_every": 5, "checkpoint_every": 10, "formats": ["vtp"]}}
    scene["beam"].update(beam)
    scene["beam"] = {k: v for k, v in scene["beam"].items() if v is not None}
    return runner.build_model(validate_scene(scene))


def _beam_power_at(model, t):
    import dataclasses

    from sintercond.sim import thermal

    state = dataclasses.replace(model.state, step=np.asarray(round(t / model.dt), model.state.step.dtype))
    return np.asarray(thermal.source_power(model.physics.sources, state, model.params))


def test_the_beam_is_off_once_its_path_is_done():
    """The beam used to stay on at its last waypoint for the rest of the run."""
    model = _lattice_with_beam()
    assert _beam_power_at(model, 1e-3).sum() > 0  # on its way out
    assert _beam_power_at(model, 8e-3).sum() == 0.0  # the path took 6e-3 s
    stays = _lattice_with_beam(after_path="stay")
    power = _beam_power_at(stays, 8e-3)
    assert power[0] > 0 and power[2:].sum() == 0.0  # on at the last waypoint: over sphere 0 (and 1, within reach)


def test_the_beam_jumps_between_hatch_lines_switched_off():
    model = _lattice_with_beam(segments_on=[True, False])
    assert _beam_power_at(model, 1e-3).sum() > 0 and _beam_power_at(model, 4.5e-3).sum() == 0.0


def test_a_beam_given_by_its_power():
    model = _lattice_with_beam(power=2.0, intensity=None)
    assert float(model.params.beam.intensity) == pytest.approx(2.0 / (np.pi * 5e-5**2), rel=1e-15)
    with pytest.raises(Exception, match=r"beam\.power over the spot .* gives an intensity of .* it must be in \[0, 1e\+12\]"):
        _lattice_with_beam(power=1e6, intensity=None)


def test_pictures_can_be_skipped_and_the_closing_line_lists_what_was_written(tmp_path, capsys):
    from sintercond import cli

    out = tmp_path / "out"
    assert cli.main(["run", "--out", str(out), "--no-progress", "--no-pictures", "--duration", "2e-4"]) == 0
    closing = capsys.readouterr().out.strip().splitlines()[-1]
    assert not (out / "final_state.png").exists() and not (out / "history.png").exists()
    assert "final_state.png" not in closing and "history.png" not in closing  # it listed them, written or not
    assert "frames.pvd" in closing and "history.csv" in closing and "checkpoint.npz" in closing


def test_walls_say_how_many_particles_they_hold_and_warn_on_a_handful():
    """Issue 27: held walls on a rough packing held about 3 particles with the default penetration, silently."""
    import warnings

    scene = load_scene(None)  # the built-in powder bed on a held floor
    with warnings.catch_warnings():
        warnings.simplefilter("error", build.WallContactWarning)  # the default reaches its face layer
        model = runner.build_model(validate_scene(copy.deepcopy(scene)))
    centres, radii = model.centres, model.radii
    bottom = centres[:, 2] - radii
    face = np.count_nonzero(bottom < bottom.min() + 0.5 * radii.mean())
    assert model.bed["wall0_particles"] == int(np.count_nonzero(np.asarray(model.state.particles.fixed)))
    assert model.bed["wall0_particles"] >= 0.9 * face
    r = 1e-4  # ten spheres in a row, each 4 % of a radius higher than the last, on the floor shorthand
    rough = {"packing": {"kind": "spheres", "centres": [[3 * r * k, 0.0, r * (1 + 0.04 * k)] for k in range(10)],
                         "radii": r},
             "material": scene["material"], "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0},
             "boundary": {"floor_temperature": 400.0},
             "run": {"duration": 1e-3, "output_every": 5, "checkpoint_every": 10, "formats": ["vtp"]}}
    with pytest.warns(build.WallContactWarning, match=r"boundary\.floor_temperature \(held, axis 2 min\) touches 1 "
                                                       r"of the 10 .*replace boundary\.floor_temperature by a held"):
        build.wall_contacts(validate_scene(rough), np.asarray(rough["packing"]["centres"]), np.full(10, r))
    shallow = copy.deepcopy(scene)
    shallow.pop("boundary")
    shallow["walls"] = [{"axis": 2, "side": "min", "mode": "held", "temperature": 300.0, "penetration": 0.0}]
    with pytest.warns(build.WallContactWarning, match=r"walls\[0\] \(held, axis 2 min\) touches 1 of the \d+ "
                                                       r"particles facing it; only a handful: raise walls\[0\]"):
        runner.build_model(validate_scene(shallow))


def test_a_lattice_summary_has_its_packing_fraction_and_coordination():
    """Issue 27: `nan` coordination and packing fraction on lattices."""
    import math

    from sintercond.beds import packing

    bed = packing.from_scene({"kind": "simple_cubic", "counts": [4, 3, 3], "spacing": 1e-4, "radius": 0.52e-4})
    r, a = 0.52e-4, 1e-4
    h = r - a / 2  # the cap each of the six neighbours cuts
    assert bed.packing_fraction == pytest.approx((4 / 3 * math.pi * r**3 - 6 * math.pi * h**2 * (3 * r - h) / 3)
                                                 / a**3, rel=1e-14)
    bonds = 3 * 36 - (3 * 3 + 4 * 3 + 4 * 3)  # the bonds across the missing faces excluded
    assert bed.coordination == pytest.approx(2 * bonds / 36, rel=1e-15)
    # touching spheres are point contacts (a [sintering] lattice grows necks from them): 12 bonds of 8 spheres
    touching = packing.from_scene({"kind": "simple_cubic", "counts": [2, 2, 2], "spacing": 1e-4, "radius": 0.5e-4})
    assert touching.packing_fraction == pytest.approx(math.pi / 6, rel=1e-14) and touching.coordination == 3.0
    apart = packing.from_scene({"kind": "simple_cubic", "counts": [2, 2, 2], "spacing": 1e-4, "radius": 0.49e-4})
    assert apart.coordination == 0.0


@pytest.mark.parametrize("mode", ["stop", "warn"])
def test_a_run_crossing_the_melting_point_stops_or_warns_naming_it(tmp_path, mode):
    """Issue 27: an L-PBF spot took the bed to 17,530 K without a word; the model has no melting.

    On a lattice, so that the hottest particle does not depend on the machine: the default scene's relaxed bed
    is settled by a chaotic dynamics whose last digits follow the CPU's instruction set, and its hottest
    particle (the one worst connected under the spot) reached 1,000 K on one machine and 688 K on another."""
    scene = copy.deepcopy(load_scene(None, duration=2e-3))
    scene["packing"] = {"kind": "simple_cubic", "counts": [5, 5, 3], "spacing": 1e-4, "radius": 0.52e-4}
    scene["beam"]["path"] = [[0.0, 2e-4], [4e-4, 2e-4]]  # the default beam takes this lattice to about 1,190 K
    scene["material"].update(melting_point=800.0, on_melting=mode)
    scene = validate_scene(scene)
    if mode == "stop":
        with pytest.raises(runner.MeltingPointCrossed, match=r"above material\.melting_point = 800 K: the model "
                                                             r"has no melting"):
            runner.run_scene(scene, tmp_path, progress=False, pictures=False)
    else:
        with pytest.warns(runner.MeltingPointWarning, match=r"material\.melting_point = 800 K"):
            _, summary = runner.run_scene(scene, tmp_path, progress=False, pictures=False)
        assert summary["T_max_K"] > 800.0


@pytest.mark.slow
def test_a_finished_run_is_extended_with_its_own_step(tmp_path, capsys):
    """Issue 27: runs could not be extended from their last state (`--duration` was refused with `--resume`).
    Extended from 1 ms to 2 ms, the run goes on with its own step; the reference is a run that took that step
    from the start (run.dt fixed) to the same step count."""
    from sintercond import cli

    out = tmp_path / "out"
    assert cli.main(["run", "--out", str(out), "--no-progress", "--no-pictures", "--duration", "1e-3"]) == 0
    first = np.genfromtxt(out / "history.csv", delimiter=",", names=True)
    assert cli.main(["run", "--resume", str(out), "--no-progress", "--no-pictures", "--duration", "2e-3"]) == 0
    extended = np.genfromtxt(out / "history.csv", delimiter=",", names=True)
    dt = first["time_s"][-1] / first["step"][-1]
    assert 2e-3 <= extended["time_s"][-1] < 2e-3 + dt and np.all(np.diff(extended["step"]) > 0)
    np.testing.assert_array_equal(extended[: len(first)], first)  # the first millisecond untouched
    scene = copy.deepcopy(load_scene(None))
    scene["run"].update(dt=dt, duration=float(extended["step"][-1]) * dt)
    runner.run_scene(validate_scene(scene), tmp_path / "ref", progress=False, pictures=False)
    reference = np.genfromtxt(tmp_path / "ref" / "history.csv", delimiter=",", names=True)
    assert reference["step"][-1] == extended["step"][-1]  # their outputs fall at other steps, their ends together
    for name in ("T_mean_K", "T_min_K", "T_max_K"):
        assert extended[name][-1] == pytest.approx(reference[name][-1], rel=1e-12)
    ended = np.load(out / "checkpoint.npz")["temperature"]
    np.testing.assert_allclose(ended, np.load(tmp_path / "ref" / "checkpoint.npz")["temperature"], rtol=1e-12)


@pytest.mark.slow
def test_an_interrupted_extension_resumes_with_the_runs_own_step(tmp_path):
    """The extension killed after one chunk, then a plain --resume: it keeps the run's step (the rebuilt model's
    would differ), checkpoints as it goes, and ends where the uninterrupted extension ends."""
    def first_ms(out):
        runner.run_scene(validate_scene(load_scene(None, duration=1e-3)), out, progress=False, pictures=False)

    first_ms(tmp_path / "whole")
    whole, _ = runner.resume(tmp_path / "whole", progress=False, pictures=False, duration=6e-3)
    first_ms(tmp_path / "cut")
    start = int(np.load(tmp_path / "cut" / "checkpoint.npz")["step"])
    runner.resume(tmp_path / "cut", progress=False, pictures=False, duration=6e-3, stop_after_chunks=3)
    saved = int(np.load(tmp_path / "cut" / "checkpoint.npz")["step"])
    assert start < saved < int(np.load(tmp_path / "whole" / "checkpoint.npz")["step"])  # one inside the extension
    resumed, summary = runner.resume(tmp_path / "cut", progress=False, pictures=False)
    np.testing.assert_array_equal(np.asarray(resumed), np.asarray(whole))
    assert summary["simulated_s"] >= 6e-3
    listed = ElementTree.parse(tmp_path / "cut" / "frames.pvd").getroot()
    times = [float(d.get("timestep")) for d in listed.iter("DataSet")]
    assert times == sorted(times) and times[-1] == pytest.approx(summary["simulated_s"], rel=1e-12)


def test_a_bed_that_settles_reports_its_progress_with_an_estimate(monkeypatch):
    """Issue 27: a bed of thousands was "building the scene's packing" for 13 minutes with nothing printed."""
    from sintercond.beds import packing

    monkeypatch.setattr(build, "PROGRESS_EVERY_S", 0.0)
    lines = []
    p = {"kind": "powder_bed", "lateral_size": 4e-4, "height": 2e-4, "diameter_range": [40e-6, 60e-6], "seed": 0,
         "method": "relax", "sinter_swelling": 0.0}
    calls = []
    bed = packing.from_scene(p, progress=lambda *a: calls.append(a))
    assert calls and calls[-1][3] < calls[-1][4] == 2e-3  # the last report is the settled one
    assert [c[1] for c in calls] == sorted(c[1] for c in calls) and all(c[0] == "relaxing" for c in calls)
    np.testing.assert_array_equal(packing.from_scene(p).centres, bed.centres)  # reporting changes nothing
    scene = {"packing": p, "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 7.0},
             "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0},
             "run": {"duration": 1e-4, "output_every": 1, "checkpoint_every": 1}}
    build.build_packing(validate_scene(scene), lines.append)
    relaxing = [line for line in lines if line.startswith("packing: relaxing")]
    assert len(relaxing) == len(calls)
    assert "settled below 0.002" in relaxing[-1] and "steps (at most" in relaxing[-1]
    assert any("s left at this rate" in line for line in relaxing)


def test_a_rolled_bed_and_the_run_report_every_phase_with_its_time(monkeypatch, tmp_path):
    """Issue 27: every phase that can take more than a few seconds says so: the rolled bed counts its spheres down
    with the time left, the network and the compile give their times, and a slow output is named."""
    from sintercond.beds import rolling

    monkeypatch.setattr(build, "PROGRESS_EVERY_S", 0.0)
    monkeypatch.setattr(rolling, "PROGRESS_EVERY", 20)
    monkeypatch.setattr(runner, "SLOW_OUTPUT_S", 0.0)
    lines = []
    monkeypatch.setattr(runner, "_log", lines.append)
    scene = {"packing": {"kind": "powder_bed", "lateral_size": 3e-4, "height": 1.2e-4, "diameter_range": [30e-6, 50e-6]},
             "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 7.0},
             "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0}, "boundary": {"floor_temperature": 400.0},
             "run": {"duration": 1e-2, "output_every": 2, "checkpoint_every": 2, "formats": ["lammps"]}}
    _, summary = runner.run_scene(validate_scene(scene), tmp_path / "out", progress=False, pictures=False)
    assert summary["steps"] > 4
    rolled = [line for line in lines if line.startswith("packing: rolling")]
    down = [int(line.split(": ")[2].split()[0].replace(",", "")) for line in rolled]
    assert len(rolled) >= 2 and down == sorted(down) and all("s left" in line for line in rolled[:-1])
    assert f"packing: {summary['particles']:,} particles in " in "\n".join(lines)
    assert any(line.startswith(f"network: {summary['contacts']:,} contacts in ") for line in lines)
    assert sum(line.startswith("compiled the step and ran steps 0 to 2 in ") for line in lines) == 1
    written = [line for line in lines if line.startswith("outputs of step")]
    assert len(written) == -(-summary["steps"] // 2) and "lammps" in written[-1] and "checkpoint" in written[-1]
