"""A user's first week (issue 43): nothing silently wrong, every refusal names what to change.

Each test fails on the code before its fix: a file cut short read with fewer particles, a packing in micrometres
read as metres, coincident centres that crashed after the build, and the like.
"""

import copy
import json
from types import SimpleNamespace

import numpy as np
import pytest

from sintercond import cli
from sintercond.beds import packing, packing_files, settle
from sintercond.laws import walls
from sintercond.output import io
from sintercond.sim import mechanics, neck_growth
from sintercond import run as runner
from sintercond.scene import SceneError, load_scene, validate_scene
from sintercond.scene.build import build_model

DUMP_ROWS = [f"{i} 1 {2.0 * i!r} 0.0 0.0 1.0" for i in range(1, 9)]  # 8 touching unit spheres along x (file units)


def _dump(rows, count=8):
    return (f"ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{count}\nITEM: BOX BOUNDS ff ff ff\n0 20\n-1 1\n-1 1\n"
            "ITEM: ATOMS id type x y z radius\n" + "\n".join(rows) + "\n")


def _data(rows, count=8):
    return (f"LAMMPS data file\n\n{count} atoms\n1 atom types\n\n0 20 xlo xhi\n-1 1 ylo yhi\n-1 1 zlo zhi\n\n"
            "Atoms # sphere\n\n" + "\n".join(rows) + "\n")


DATA_ROWS = [f"{i} 1 2.0 1.0 {2.0 * i!r} 0.0 0.0" for i in range(1, 9)]


def test_a_file_cut_at_a_line_boundary_is_refused(tmp_path):
    """Before: a dump or data file cut after 6 of its 8 rows was read as 6 particles, silently."""
    dump, data = tmp_path / "pour.dump", tmp_path / "bed.data"
    dump.write_text(_dump(DUMP_ROWS))
    data.write_text(_data(DATA_ROWS))
    assert len(packing_files.read_packing(dump)[1]) == 8 and len(packing_files.read_packing(data)[1]) == 8
    dump.write_text(_dump(DUMP_ROWS[:6]))
    with pytest.raises(packing_files.PackingFileError, match=r"NUMBER OF ATOMS' says 8 particles, but 6 .*cut short"):
        packing_files.read_packing(dump)
    data.write_text(_data(DATA_ROWS[:6]))
    with pytest.raises(packing_files.PackingFileError, match=r"'N atoms' says 8 particles, but 6 .*cut short"):
        packing_files.read_packing(data)


def _file_scene(tmp_path, packing_path, length_unit="m", extra=""):
    scene = tmp_path / "scene.toml"
    scene.write_text(f"""[packing]
kind = "file"
path = "{packing_path.name}"
length_unit = "{length_unit}"
[material]
density = 4430.0
specific_heat = 560.0
conductivity = 12.6
[conduction]
law = "rojek"
[initial]
temperature = 300.0
[boundary]
floor_temperature = 500.0
[run]
duration = 1e-4
output_every = 5
checkpoint_every = 10
{extra}""")
    return scene


def test_a_packing_in_micrometres_read_as_metres_is_refused(tmp_path):
    """Before: a table in micrometres with length_unit left at "m" ran spheres of 520 m (exit 0, nothing warmed).
    File radii take the range of every other packing kind, [1e-8, 1] m, and the message points at length_unit."""
    table = tmp_path / "bed.csv"
    table.write_text("# a CT scan, in um\nx,y,z,r\n0,0,520,520\n1040,0,520,520\n")
    with pytest.raises(SceneError, match=r"particle 0 \(line 3 of the file\) has radius 520 m.*\[1e-08, 1\] m.*"
                                         r"packing\.length_unit to one of \['mm', 'um', 'nm'\]"):
        load_scene(_file_scene(tmp_path, table))
    assert load_scene(_file_scene(tmp_path, table, "um"))["packing"]["length_unit"] == "um"


def test_coincident_centres_are_refused_naming_the_particles_and_the_lines(tmp_path, capsys):
    """Before: a duplicated row of a packing file (or two listed spheres at one centre) passed validation, wrote
    scene.json and crashed after the build (ZeroDivisionError with mechanics) or ran with a step of 0 s."""
    table = tmp_path / "bed.csv"
    table.write_text("x y z r\n0 0 1 1.02\n2 0 1 1.02\n# a duplicated row:\n2 0 1 1.02\n")
    scene = _file_scene(tmp_path, table, "mm")
    with pytest.raises(SystemExit) as exc:
        cli.main(["run", str(scene), "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "Traceback" not in err and not (tmp_path / "out").exists()
    assert "packing.path: particles 1 and 2 (lines 3 and 5 of the file) have the same centre [0.002, 0.0, 0.001] m" \
        in err, err
    table.write_text("x y z r\n0 0 1 1.02\n2 0 1 1.02\n")
    listed = {"kind": "spheres", "centres": [[0.0, 0.0, 1e-3], [2e-3, 0.0, 1e-3], [2e-3, 0.0, 1e-3]], "radii": 1e-3}
    raw = load_scene(scene)
    with pytest.raises(SceneError, match=r"packing\.centres\[1\] and packing\.centres\[2\] have the same centre"):
        validate_scene({**raw, "packing": listed})
    with pytest.raises(SceneError, match=r"particles 0 and 2 of the packing have the same centre"):  # a packing.npz
        build_model(raw, np.array([[0.0, 0.0, 1e-3], [2e-3, 0.0, 1e-3], [0.0, 0.0, 1e-3]]), np.full(3, 1.02e-3))


def _lattice_scene(**sections):
    scene = {"packing": {"kind": "simple_cubic", "counts": [3, 1, 1], "spacing": 1e-4, "radius": 0.52e-4},
             "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.6},
             "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0},
             "run": {"duration": 1e-3, "output_every": 5, "checkpoint_every": 10}}
    for name, table in sections.items():
        scene[name] = {**scene.get(name, {}), **table} if isinstance(table, dict) else table
    return scene


@pytest.mark.parametrize("sections, key", [
    ({"material": {"melting_point": 280.0}}, r"initial\.temperature = 300 K"),
    ({"material": {"melting_point": 800.0}, "boundary": {"floor_temperature": 900.0}},
     r"boundary\.floor_temperature = 900 K"),
    ({"material": {"melting_point": 800.0}, "walls": [{"axis": 0, "side": "min", "mode": "held",
                                                       "temperature": 1200.0}]}, r"walls\[0\]\.temperature = 1200 K"),
])
def test_a_melting_point_below_the_start_is_refused_at_validation(sections, key):
    """Before: a melting point below the initial (or a held) temperature was found after the first output chunk."""
    with pytest.raises(SceneError, match=r"material\.melting_point = \d+ K is below " + key):
        validate_scene(_lattice_scene(**sections))
    warn = copy.deepcopy(sections)
    warn["material"]["on_melting"] = "warn"  # a held wall above it then only warns when the run crosses it
    if "initial" not in key:
        validate_scene(_lattice_scene(**warn))


def test_the_melting_advice_names_the_heat_inputs_the_scene_has():
    """Before: a run without a beam that crossed the melting point was told to lower beam.power."""
    hot = {"material": {"melting_point": 800.0},
           "walls": [{"axis": 0, "side": "min", "mode": "conducting", "temperature": 1200.0}],
           "convection": {"environment_temperature": 290.0, "environment_conductivity": 0.026}}
    scene = validate_scene(_lattice_scene(**hot))
    state = SimpleNamespace(step=np.int64(40), dt=np.float64(1e-6), sintering=None,  # the fields the check reads
                            particles=SimpleNamespace(temperature=np.array([900.0, 600.0, 400.0])))
    with pytest.raises(runner.MeltingPointCrossed, match=r"lower the heat input \(walls\[0\]\.temperature\), or") as e:
        runner.physical_range_check(scene)(state)
    assert "beam" not in str(e.value) and "convection" not in str(e.value)


SINTERING = {"sintering": {"every": 1000}, "packing": {"radius": 0.5e-4},
             "conduction": {"law": "rojek", "neck_model": "volume_conserving"}}


def test_sintering_every_above_the_step_count_is_refused():
    """Before: sintering.every = 1000 in a run of 100 steps was accepted and no neck grew."""
    with pytest.raises(SceneError, match=r"sintering\.every = 1000 steps is more than the run's 100 steps"):
        validate_scene(_lattice_scene(run={"dt": 1e-5}, **SINTERING))  # an explicit step: 1e-3 s in 100 steps


@pytest.mark.slow
def test_sintering_every_above_the_automatic_step_count_is_refused_at_the_build():
    scene = validate_scene(_lattice_scene(**SINTERING))  # the automatic step: the build counts the steps
    with pytest.raises(SceneError, match=r"sintering\.every = 1000 steps is more than the run's \d+ steps"):
        build_model(scene)


def test_without_output_every_the_outputs_follow_the_duration(tmp_path):
    """Before: run.output_every was required, and the preheating scene's 20,000 steps gave 3 history rows with the
    docs' --duration 1. Not given, the run writes about 100 outputs whatever its duration, and a resume keeps them."""
    assert "output_every" not in load_scene("ti6al4v_preheating_bed", duration=1.0)["run"]
    scene = _lattice_scene(walls=[{"axis": 0, "side": "min", "mode": "held", "temperature": 500.0}],
                           run={"duration": 2e-3, "dt": 1e-5})  # 200 steps
    del scene["run"]["output_every"], scene["run"]["checkpoint_every"]
    _, summary = runner.run_scene(validate_scene(scene), tmp_path, progress=False, pictures=False)
    steps = [int(row.split(",")[0]) for row in (tmp_path / "history.csv").read_text().splitlines()[1:]]
    assert summary["steps"] == 200 and steps == list(range(0, 201, 2))  # 100 outputs after the start
    saved = json.loads((tmp_path / "scene.json").read_text())["run"]
    assert (saved["output_every"], saved["checkpoint_every"]) == (2, 20)
    with pytest.raises(SceneError, match=r"run\.checkpoint_every \(20\) needs run\.output_every"):
        validate_scene({**scene, "run": {**scene["run"], "checkpoint_every": 20}})


def test_a_file_packing_run_resumes_after_the_file_moved(tmp_path):
    """Before: --resume re-read packing.path and failed once the file had moved, though the run folder holds the
    packing. The reference: the same run uninterrupted (a resume gives identical results)."""
    table = tmp_path / "bed.csv"
    table.write_text("x y z r T\n0 0 1 1.02 300\n2 0 1 1.02 310\n4 0 1 1.02 320\n")
    scene_path = _file_scene(tmp_path, table, "mm", extra='dt = 1e-5\n[[walls]]\naxis = 0\nside = "min"\nmode = '
                                                           '"held"\ntemperature = 500.0\n')
    scene_path.write_text(scene_path.read_text().replace("[boundary]\nfloor_temperature = 500.0\n", "")
                          .replace("checkpoint_every = 10", "checkpoint_every = 5")
                          .replace("temperature = 300.0\n", "temperature = 300.0\nfrom_file = true\n", 1))
    whole, _ = runner.run_scene(load_scene(scene_path), tmp_path / "whole", progress=False, pictures=False)
    runner.run_scene(load_scene(scene_path), tmp_path / "cut", progress=False, pictures=False, stop_after_chunks=1)
    table.rename(tmp_path / "moved.csv")
    resumed, summary = runner.resume(tmp_path / "cut", progress=False, pictures=False)
    assert summary["steps"] == 10 and (tmp_path / "cut" / "packing.csv").exists()  # checkpointed at step 5 of 10
    np.testing.assert_array_equal(np.asarray(resumed), np.asarray(whole))


NEGATIVE = np.float64(-0.00052)


@pytest.mark.parametrize("call", [
    lambda: settle.DemMaterial(density=NEGATIVE),
    lambda: walls.PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), "held", NEGATIVE),
    lambda: packing.powder_bed(3e-4, NEGATIVE, (2e-5, 6e-5)),
    lambda: mechanics.validate_mechanical_params({"E0": NEGATIVE}),
    lambda: neck_growth.Sintering(balance_tol=NEGATIVE),
], ids=["DemMaterial", "PlaneWall", "powder_bed", "validate_mechanical_params", "Sintering"])
def test_messages_show_numbers_as_numbers(call):
    """Before: ``got np.float64(-0.00052)``; the number a user gave is shown as the number."""
    with pytest.raises(ValueError) as err:
        call()
    assert "got -0.00052" in str(err.value) and "np." not in str(err.value), str(err.value)


def test_a_dump_cut_inside_a_row_names_the_line_and_a_table_row_reads_plainly(tmp_path):
    """Before: NumPy's own advice ("use `usecols` to select a subset") for a dump cut inside its last row, and
    "must be a list of 2 numbers a [T, c] pair of positive numbers" for a short specific_heat_table row."""
    dump = tmp_path / "pour.dump"
    dump.write_text(_dump([*DUMP_ROWS[:7], "8 1 16.0 0"])[:-1])  # cut inside the last row, after its x
    with pytest.raises(packing_files.PackingFileError, match=r"pour\.dump, line 17: 4 fields \['8', '1', '16\.0', "
                                                             r"'0'\], expected 6 numbers \(id type x y z radius\)") as e:
        packing_files.read_packing(dump)
    assert "usecols" not in str(e.value)
    with pytest.raises(SceneError, match=r"material\.specific_heat_table\[1\] must be a list of 2 numbers \[T, c\] in "
                                         r"\(0, 1e5\]; got \[400\.0\]$"):
        validate_scene(_lattice_scene(material={"specific_heat_table": [[300.0, 500.0], [400.0]]}))


def test_the_lammps_dump_carries_the_time_and_the_fields_of_the_vtp_frames(tmp_path):
    """Before: the dump had no ITEM: TIME and no held or heat_power columns, which the VTP frames carry. Each
    frame's time and columns equal the VTP frame's (VTK's own field data)."""
    scene = _lattice_scene(walls=[{"axis": 0, "side": "min", "mode": "held", "temperature": 500.0}],
                           run={"duration": 2e-4, "dt": 1e-5, "formats": ["vtp", "lammps"]})  # 20 steps, 4 frames
    runner.run_scene(validate_scene(scene), tmp_path, progress=False, pictures=False)
    frames = (tmp_path / "dump.lammpstrj").read_text().split("ITEM: TIME\n")[1:]
    vtps = sorted((tmp_path / "vtp").glob("step_*.vtp"))
    assert len(frames) == len(vtps) == 5
    for frame, path in zip(frames, vtps):
        lines = frame.splitlines()
        vtp = io.read_vtp(path)
        assert float(lines[0]) == float(vtp["TIME"]) and int(lines[2]) == int(vtp["STEP"])
        columns = lines[9].split()[2:]
        rows = np.array([line.split() for line in lines[10:]], np.float64)
        for name in ("held", "heat_power", "temperature"):
            np.testing.assert_array_equal(rows[:, columns.index(name)], vtp[name])
    assert np.asarray(vtp["held"]).sum() == 1 and np.any(np.asarray(vtp["heat_power"]) != 0)


def test_a_resume_truncates_the_dump_at_a_frames_time(tmp_path):
    """A frame now starts at its ITEM: TIME: truncated after step 10 (a resume), the dump is its first three frames,
    and it stays a dump the packing reader takes."""
    centres, radii = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]), np.ones(2)
    frames = [io.lammps_frame(centres + step, radii, np.full(2, 300.0), step, time=step * 1e-3)
              for step in (0, 5, 10, 15)]
    path = tmp_path / "dump.lammpstrj"
    path.write_text("".join(frames))
    io.truncate_lammps(path, 10)
    assert path.read_text() == "".join(frames[:3])
    np.testing.assert_array_equal(packing_files.read_packing(path)[0], centres + 10)


def _moving_bed(**physics):
    scene = _lattice_scene(boundary={"floor_temperature": 300.0}, physics={"mechanics": True, **physics},
                           mechanics={"young_modulus": 1e6, "poisson_ratio": 0.3})
    scene["packing"] = {"kind": "powder_bed", "lateral_size": 4e-4, "height": 2e-4, "diameter_range": [8e-5, 1e-4]}
    return validate_scene(scene)


def test_a_moving_powder_bed_is_held_in_its_box():
    """Before: with the mechanics a powder bed had no container and spread over its floor into a monolayer five
    times its box, the summary reporting a shrinkage of 0.4967. The box [0, L]^2 now holds it (insulated walls on
    the faces the scene leaves open, the floor being the scene's), unless physics.container = false."""
    from sintercond.scene import build

    L = 4e-4
    centres, radii = np.array([[1e-4, 1e-4, 5e-5], [3e-4, 3e-4, 5e-5]]), np.full(2, 5e-5)
    floor = ((0, 0, 1), 0.0 + 0.02 * 5e-5)  # the scene's floor: the bed's bottom moved 0.02 mean radii in
    for container, faces in ((True, {floor, ((1, 0, 0), 0.0), ((-1, 0, 0), L), ((0, 1, 0), 0.0), ((0, -1, 0), L)}),
                             (False, {floor})):
        scene = _moving_bed(container=container)
        planes = build.scene_walls(scene, centres, radii)  # the held floor, at the bed's bottom
        spec = build.mechanical_physics(scene, build.scene_physics(scene), planes).mechanics
        got = {(tuple(int(v) for v in w.normal), float(np.dot(w.point, np.abs(w.normal)))) for w in spec.walls}
        assert got == faces, (container, got)


def test_particles_leaving_the_box_are_warned_about():
    scene = _moving_bed(container=False)
    model = SimpleNamespace(radii=np.full(3, 5e-5))
    state = SimpleNamespace(step=np.int64(300), dt=np.float64(1e-7),
                            particles=SimpleNamespace(positions=np.array([[2e-4, 2e-4, 5e-5], [4.6e-4, 2e-4, 5e-5],
                                                                          [-0.6e-4, 1e-4, 5e-5]])))
    with pytest.warns(runner.PackingBoxWarning, match=r"2 of 3 particles \(particle 1 first\) left the packing's box "
                                                      r"by step 300.*physics\.container = false"):
        assert runner._warn_escaped(scene, model, state) == [1, 2]
    state.particles.positions[1:, 0] = [4.4e-4, -0.4e-4]  # out by less than their radius: still at the wall
    assert runner._warn_escaped(scene, model, state) == []


def test_a_relaxation_that_does_not_settle_names_the_unsupported_sphere():
    """Before: "largest net force 1 of a sphere's weight" for 140 s, then "did not settle", never saying which
    sphere: here sphere 2, dropped from 40 radii, still falls (its net force its weight) when the steps run out."""
    centres = np.array([[1e-4, 1e-4, 5e-5], [2e-4, 1e-4, 5e-5], [1.5e-4, 1e-4, 2e-3]])
    seen = []
    with pytest.raises(settle.PackingError, match=r"largest net force is 1 of a sphere's weight \(allowed < 0\.002\), "
                                                  r"on sphere 2 at \[0\.00015, 0\.0001, 0\.00"):
        settle.relax_under_gravity(centres, np.full(3, 5e-5), 3e-4, max_steps=500,
                                   progress=lambda *figures, worst: seen.append(worst))
    assert seen and all(w.startswith("sphere 2 at") for w in seen)
    with pytest.raises(settle.PackingError):  # a callback of the five documented figures still works
        settle.relax_under_gravity(centres, np.full(3, 5e-5), 3e-4, max_steps=100, progress=lambda *a: seen.append(a))


def _two_spheres():
    from sintercond.state import particle_state

    return particle_state(np.array([[0.0, 0.0, 1e-3], [2e-3, 0.0, 1e-3]]), np.full(2, 1e-3), 300.0, 4430.0, 560.0)


@pytest.mark.parametrize("v_rel, params, message", [
    (0.0, {}, r"v_rel must be finite and > 0 m/s; got 0\.0"),
    (-1.0, {}, r"v_rel must be finite and > 0 m/s; got -1\.0"),
    (float("nan"), {}, r"v_rel must be finite and > 0 m/s; got nan"),
    (0.05, {"E0": -1.0}, r"MechanicalParams\.E0 must be finite and in \[1, 1e\+13\] Pa; got -1\.0"),
])
def test_the_mechanical_time_step_refuses_what_gave_nan(v_rel, params, message):
    """Before: mechanical_time_step returned NaN for v_rel = 0, -1 or NaN and for E0 = -1."""
    spec = mechanics.Mechanics.create()
    material = mechanics.MechanicalParams(**{"E0": 1e6, "nu": 0.3, **params})
    with pytest.raises(ValueError, match=message):
        mechanics.mechanical_time_step(spec, _two_spheres(), np.array([[1], [0]]), material, v_rel)


def test_a_velocity_of_the_wrong_shape_is_refused():
    """Before: a velocity [n, 2] (or [3]) broadcast silently into the step."""
    for bad in (np.zeros((2, 2)), np.zeros(3)):  # refused before the contacts are looked at
        with pytest.raises(ValueError, match=r"velocity must be \[n, 3\] like the positions \(2, 3\); got shape"):
            mechanics.mechanical_state(mechanics.Mechanics.create(), _two_spheres().positions, None, velocity=bad)


def test_softening_readings_and_synthetic_data_refuse_what_ran():
    """Before: readings at E0 < 0 or theta* = 0, and synthetic_data with sigma = -1, ran. The checks come before
    the run, so a stand-in experiment (only its channels) reaches them."""
    from fitting import softening

    experiment = SimpleNamespace(channels=("temperature", "overlap"))
    for values, message in (({"E0": -1.0}, r"values\['E0'\] must be finite and in \[1, 1e\+13\] Pa; got -1\.0"),
                            ({"theta_star": 0.0}, r"values\['theta_star'\] must be finite and in \[1, 10000\] K"),
                            ({"conductivity": 0.0}, r"values\['conductivity'\] must be finite and > 0")):
        with pytest.raises(ValueError, match=message):
            softening.SofteningExperiment.readings(experiment, values)
    with pytest.raises(ValueError, match=r"sigma \(noise standard deviation per channel\) must be finite and > 0; "
                                         r"got \[-1\.0, -1\.0\]"):
        softening.synthetic_data(experiment, {}, sigma=-1.0)


def _temperature_at(series, t):
    """The temperature a series' history holds at times ``t`` (s): its piecewise-constant steps."""
    ends = np.cumsum(series.durations)
    return np.asarray(series.temperatures)[np.searchsorted(ends, t)]


def test_a_neck_series_is_read_from_a_csv_with_its_temperature_history(tmp_path):
    """Before: fitting one's own necks meant building a NeckSeries by hand. Rizza & Galati's 80-80 couple (Table
    3) written as a CSV, with their preheating staircase as a [t, T] table, reads back as the hand-built series:
    the same readings and the same temperature at every moment."""
    from fitting import sintering as fs
    from fitting.reference import rizza_galati_table

    t3 = rizza_galati_table(3)
    path = tmp_path / "couple.csv"
    path.write_text("# my couple\ntime_s,neck_um\n0,0\n" + "".join(f"{t!r},{a!r}\n" for t, a in
                                                                  zip(t3["time_s"].tolist(), t3["x_couple1_um"].tolist())))
    steps = 845.0 + np.arange(1, 26) * (1273.0 - 845.0) / 25  # Eq. 6: each 0.38 s step held at its end temperature
    staircase = [[0.38 * k + d, float(steps[k])] for k in range(25) for d in (1e-9, 0.38 - 1e-9)]
    got = fs.read_neck_series(path, 40 * fs.UM, temperature=staircase)  # Table 3: r = 40 um
    want = fs.neck_series("80-80")
    np.testing.assert_array_equal(got.times, want.times)
    np.testing.assert_array_equal(got.necks_um, want.necks_um)
    assert (got.r_i.tolist(), got.r_j.tolist(), got.name) == (want.r_i.tolist(), want.r_j.tolist(), "couple")
    t = (np.arange(950) + 0.5) * 0.01  # every 10 ms of the 9.5 s, off the steps' edges
    np.testing.assert_array_equal(_temperature_at(got, t), _temperature_at(want, t))
    np.testing.assert_array_equal(np.cumsum(got.durations)[got.interval], got.times)  # each reading ends a row

    ratio = tmp_path / "ratio.csv"  # the neck over the smaller radius, at a temperature column: 1000 K
    ratio.write_text("t neck_ratio temperature_K\n1.0 0.1 1000\n2.0 0.15 1000\n")
    series = fs.read_neck_series(ratio, 40e-6, 29.3e-6, temperature="column")
    np.testing.assert_allclose(series.necks_um, [0.1 * 29.3, 0.15 * 29.3], rtol=1e-15)
    assert np.all(np.asarray(series.temperatures) == 1000.0) and np.sum(series.durations) == 2.0
    ramp = fs.read_neck_series(ratio, 40e-6, temperature=[[0.0, 800.0], [2.0, 1200.0]])
    middles = np.cumsum(ramp.durations) - 0.5 * np.asarray(ramp.durations)
    np.testing.assert_allclose(ramp.temperatures, 800.0 + 200.0 * middles, rtol=1e-12)  # the line at each middle
    bad = tmp_path / "bad.csv"
    bad.write_text("t,a\n1,2\n")
    with pytest.raises(ValueError, match=r"must name a time column .* and a neck column"):
        fs.read_neck_series(bad, 40e-6, temperature=1000.0)


@pytest.mark.parametrize("flag", ["friction", "rolling"])
def test_a_mechanics_flag_that_is_not_a_boolean_is_refused(flag):
    """Before: Physics.create(friction="no") turned friction on (bool("no") is True)."""
    from sintercond import simulate

    with pytest.raises(ValueError, match=rf"Mechanics\.{flag} must be True or False; got 'no'"):
        simulate.Physics.create(mechanics=True, **{flag: "no"})
