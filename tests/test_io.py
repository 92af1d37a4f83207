"""Run outputs opened by the readers people use: VTK's own XML reader (ParaView) and OVITO's Python module.

Both readers come with the ``readers`` extra, which CI installs (``.ci/run``).
"""

import copy
from xml.etree import ElementTree

import numpy as np
import pytest

from sintercond.output import io
from sintercond import run as runner
from sintercond.scene import validate_scene
from _helpers import reader

vtk = reader("vtk")
ovito_io = reader("ovito.io")
from vtk.util.numpy_support import vtk_to_numpy  # noqa: E402


def _particles(n=5, seed=0):
    rng = np.random.default_rng(seed)
    # NumPy float64 scalars and arrays, as a run hands them over
    return rng.uniform(0, 1e-3, (n, 3)), rng.uniform(2e-5, 6e-5, n), 300.0 + rng.uniform(0, 500, n)


def read_vtp(path):
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0
    data = reader.GetOutput()
    points = vtk_to_numpy(data.GetPoints().GetData())
    point_data = {data.GetPointData().GetArrayName(k): vtk_to_numpy(data.GetPointData().GetArray(k))
                  for k in range(data.GetPointData().GetNumberOfArrays())}
    fields = data.GetFieldData()
    field = {fields.GetArrayName(k): vtk_to_numpy(fields.GetArray(k)) for k in range(fields.GetNumberOfArrays())}
    return data, points, point_data, field


@pytest.mark.parametrize("encoding", io.VTP_ENCODINGS)
def test_vtp_read_by_vtk_with_time_and_step(tmp_path, encoding):
    centres, radii, temperature = _particles()
    io.write_vtp(tmp_path / "a.vtp", centres, radii, temperature, np.int64(70), np.float64(1.25e-3), encoding=encoding)
    data, points, point_data, field = read_vtp(tmp_path / "a.vtp")
    assert data.GetNumberOfPoints() == 5 and data.GetNumberOfVerts() == 5
    np.testing.assert_array_equal(points, centres)
    np.testing.assert_array_equal(point_data["temperature"], temperature)
    np.testing.assert_array_equal(point_data["radius"], radii)
    np.testing.assert_array_equal(point_data["id"], np.arange(5))
    # before the fix, TIME and STEP had no NumberOfTuples and came back as empty arrays
    assert field["TIME"].shape == (1,) and field["TIME"][0] == 1.25e-3
    assert field["STEP"].shape == (1,) and field["STEP"][0] == 70
    mine = io.read_vtp(tmp_path / "a.vtp")  # our own reader, used by the tests, agrees with VTK's
    np.testing.assert_array_equal(mine["position"], centres)
    np.testing.assert_array_equal(mine["temperature"], temperature)
    assert mine["TIME"] == 1.25e-3 and mine["STEP"] == 70


def test_binary_frames_are_smaller_and_exact(tmp_path):
    """Issue 27: frames were ASCII (80 MB each at 1e6 particles). Binary frames hold the same float64 bits."""
    rng = np.random.default_rng(1)
    centres, radii, temperature = rng.uniform(size=(2000, 3)), rng.uniform(1e-5, 2e-5, 2000), rng.uniform(300, 900, 2000)
    for encoding in io.VTP_ENCODINGS:
        io.write_vtp(tmp_path / f"{encoding}.vtp", centres, radii, temperature, 3, 1e-3, encoding=encoding)
    assert (tmp_path / "binary.vtp").stat().st_size < 0.5 * (tmp_path / "ascii.vtp").stat().st_size
    _, points, point_data, _ = read_vtp(tmp_path / "binary.vtp")
    np.testing.assert_array_equal(points, centres)
    np.testing.assert_array_equal(point_data["temperature"], temperature)


def test_lammps_dump_read_by_ovito(tmp_path):
    path = tmp_path / "dump.lammpstrj"
    frames = [_particles(seed=s) for s in range(3)]
    for step, (centres, radii, temperature) in zip((0, 10, 20), frames):
        io.append_lammps(path, centres, radii, temperature, step)
    text = path.read_text()
    assert "np.float64" not in text  # NumPy 2's repr of a scalar broke OVITO's box-bounds parser
    pipeline = ovito_io.import_file(str(path))
    assert pipeline.num_frames == 3
    for frame, (centres, radii, temperature) in enumerate(frames):
        data = pipeline.compute(frame)
        assert data.attributes["Timestep"] == 10 * frame
        order = np.argsort(np.asarray(data.particles["Particle Identifier"]))
        # OVITO's own number parser: within an ulp of the written shortest round-trip text
        np.testing.assert_allclose(np.asarray(data.particles.positions)[order], centres, rtol=3e-16)
        np.testing.assert_allclose(np.asarray(data.particles["Radius"])[order], radii, rtol=1e-7)  # OVITO: float32
        np.testing.assert_allclose(np.asarray(data.particles["temperature"])[order], temperature, rtol=3e-16)
        lo = centres.min(axis=0) - radii.max()
        np.testing.assert_allclose(np.asarray(data.cell[:, 3]), lo, rtol=0, atol=1e-18)
        np.testing.assert_allclose(np.diag(np.asarray(data.cell[:, :3])), centres.max(axis=0) + radii.max() - lo,
                                   rtol=1e-12)


def test_a_run_opens_in_both_readers_with_its_time(tmp_path):
    from tests.test_scene_run import SMALL

    scene = copy.deepcopy(SMALL)
    scene["run"].update(duration=1e-3, output_every=5, checkpoint_every=5)
    scene = validate_scene(scene)
    final, summary = runner.run_scene(scene, tmp_path, progress=False)
    last = sorted((tmp_path / "vtp").glob("step_*.vtp"))[-1]
    _, _, point_data, field = read_vtp(last)
    assert field["STEP"][0] == summary["steps"]
    assert field["TIME"][0] == pytest.approx(summary["simulated_s"], rel=1e-12)
    np.testing.assert_array_equal(point_data["temperature"], np.asarray(final))
    # ParaView's time series: frames.pvd lists every frame at step * dt, and VTK's reader gives each frame that time
    collection = ElementTree.parse(tmp_path / "frames.pvd").getroot()
    listed = [(float(d.get("timestep")), d.get("file")) for d in collection.iter("DataSet")]
    frames = sorted((tmp_path / "vtp").glob("step_*.vtp"))
    assert [name for _, name in listed] == [f"vtp/{f.name}" for f in frames]
    key = vtk.vtkStreamingDemandDrivenPipeline.TIME_STEPS()
    for t, name in listed:
        reader = vtk.vtkXMLPolyDataReader()
        reader.SetFileName(str(tmp_path / name))
        reader.UpdateInformation()  # VTK takes the frame's time from its TimeValue field, as ParaView does
        info = reader.GetOutputInformation(0)
        assert info.Length(key) == 1 and info.Get(key, 0) == t
    assert listed[-1][0] == pytest.approx(summary["simulated_s"], rel=1e-12) and listed[0][0] == 0.0
    _, _, point_data, _ = read_vtp(last)
    assert {"held", "material", "heat_power"} <= set(point_data)
    pipeline = ovito_io.import_file(str(tmp_path / "dump.lammpstrj"))
    assert pipeline.num_frames == -(-summary["steps"] // 5) + 1  # every 5 steps and the (shorter) last chunk
    data = pipeline.compute(pipeline.num_frames - 1)
    order = np.argsort(np.asarray(data.particles["Particle Identifier"]))
    np.testing.assert_allclose(np.asarray(data.particles["temperature"])[order], np.asarray(final), rtol=3e-16)


def test_mechanics_fields_read_by_vtk_and_ovito(tmp_path):
    """Velocity and force [n, 3] and coordination [n] ints: VTK reads them as point arrays, OVITO maps the dump's
    vx vy vz / fx fy fz columns to its Velocity and Force properties."""
    centres, radii, temperature = _particles()
    rng = np.random.default_rng(1)
    fields = {"velocity": rng.normal(size=(5, 3)), "force": rng.normal(size=(5, 3)) * 1e-4,
              "coordination": np.array([0, 1, 2, 3, 4])}
    io.write_vtp(tmp_path / "m.vtp", centres, radii, temperature, 3, 1e-3, fields)
    _, _, point_data, _ = read_vtp(tmp_path / "m.vtp")
    np.testing.assert_array_equal(point_data["velocity"], fields["velocity"])
    np.testing.assert_array_equal(point_data["force"], fields["force"])
    np.testing.assert_array_equal(point_data["coordination"], fields["coordination"])
    io.append_lammps(tmp_path / "m.lammpstrj", centres, radii, temperature, 3, fields)
    data = ovito_io.import_file(str(tmp_path / "m.lammpstrj")).compute()
    # OVITO's own number parser: within an ulp of the written shortest round-trip text
    np.testing.assert_allclose(np.asarray(data.particles["Velocity"]), fields["velocity"], rtol=3e-16)
    np.testing.assert_allclose(np.asarray(data.particles["Force"]), fields["force"], rtol=3e-16)
    np.testing.assert_array_equal(np.asarray(data.particles["Coordination"]), fields["coordination"])
