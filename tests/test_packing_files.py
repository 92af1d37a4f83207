"""Own packings (issue 27): a table, a LAMMPS data file and a LIGGGHTS-style dump loaded, k* and the field computed.

Before, a CT-scanned packing could only be listed in the scene (at most 10,000 spheres) and `sintercond effective`
refused listed spheres. The reference is a simple-cubic lattice written into each format (rows shuffled, in
millimetres): its chains along z are independent, so with the face layers held
k* = N_chains K / A exactly (K Rojek's pair conductance, Eq. 43, of the lattice's overlap, A the bounding box's
cross-section). One sphere sits alone in a cell centre and a touching pair floats in another: the three are
reported and have no temperature (before, the pair came out at 0 K).
"""

import math
import textwrap

import numpy as np
import pytest

from sintercond import cli
from sintercond.beds import packing_files
from sintercond.laws import conductance
from sintercond.output import io
from sintercond import run as runner
from sintercond.scene import SceneError, load_scene

A, R = 1e-4, 0.52e-4  # lattice spacing and radius (m)
NX, NY, NZ = 13, 13, 12  # 2,028 spheres


def _lattice():
    grid = np.stack(np.meshgrid(np.arange(NX), np.arange(NY), np.arange(NZ), indexing="ij"), -1).reshape(-1, 3) * A
    # + one sphere in a cell centre, touching nothing, and a touching pair floating in another cell
    loose = [[5.5 * A, 5.5 * A, 5.5 * A], [3.36 * A, 3.5 * A, 3.5 * A], [3.64 * A, 3.5 * A, 3.5 * A]]
    centres = np.vstack([grid, loose])
    radii = np.append(np.full(len(grid), R), [0.2 * A, 0.15 * A, 0.15 * A])
    order = np.random.default_rng(3).permutation(len(radii))
    return centres[order], radii[order]


def _expected_k_star(kappa):
    k_pair = float(conductance.rojek_pair_conductance(R, R, 2 * R - A, kappa))
    area = ((NX - 1) * A + 2 * R) * ((NY - 1) * A + 2 * R)
    return NX * NY * k_pair * A / area  # Q = N K / (NZ - 1) over L = (NZ - 1) A


def _write(tmp_path, fmt):
    centres, radii = _lattice()
    centres, radii = centres.tolist(), radii.tolist()  # Python floats: their repr is the number
    mm = 1e3
    if fmt == "table":
        path = tmp_path / "packing.csv"
        packing_files.write_table(path, centres, radii, "mm")
    elif fmt == "lammps_data":
        path = tmp_path / "bed.data"
        rows = "\n".join(f"{k + 1} 1 {2 * r * mm!r} 4430.0 {x * mm!r} {y * mm!r} {z * mm!r} 0 0 0"
                         for k, ((x, y, z), r) in enumerate(zip(centres, radii)))
        path.write_text(f"LAMMPS data file via write_data\n\n{len(radii)} atoms\n1 atom types\n\n"
                        f"0 2 xlo xhi\n0 2 ylo yhi\n0 2 zlo zhi\n\nAtoms # sphere\n\n{rows}\n\nVelocities\n\n"
                        + "\n".join(f"{k + 1} 0 0 0 0 0 0" for k in range(len(radii))) + "\n")
    else:  # a LIGGGHTS dump of a pour: two frames, the last the settled one; ids out of order
        path = tmp_path / "dump.pour"
        ids = np.random.default_rng(4).permutation(len(radii)) + 1  # row k is particle ids[k]
        rows = sorted(zip(ids.tolist(), centres, radii), key=lambda row: -row[0])  # written in descending id
        centres, radii = [c for _, c, _ in sorted(rows)], [r for _, _, r in sorted(rows)]  # read back by id

        def frame(step, shift):
            return (f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n{len(radii)}\nITEM: BOX BOUNDS ff ff ff\n"
                    f"0 2\n0 2\n0 2\nITEM: ATOMS id type x y z vx vy vz fx fy fz radius\n"
                    + "\n".join(f"{i} 1 {x * mm + shift!r} {y * mm!r} {z * mm!r} 0 0 0 0 0 0 {r * mm!r}"
                                 for i, (x, y, z), r in rows) + "\n")
        path.write_text(frame(0, 0.5) + frame(1000, 0.0))
        return path, np.asarray(centres), np.asarray(radii)
    return path, np.asarray(centres), np.asarray(radii)


@pytest.mark.parametrize("fmt", packing_files.FORMATS)
def test_each_format_reads_back_the_packing(tmp_path, fmt):
    path, centres, radii = _write(tmp_path, fmt)
    assert packing_files.guess_format(path) == fmt
    got_c, got_r = packing_files.read_packing(path, length_unit="mm")
    np.testing.assert_allclose(got_c, centres, rtol=1e-15, atol=1e-20)
    np.testing.assert_allclose(got_r, radii, rtol=1e-15)


def _scene_file(tmp_path, packing_path, fmt="auto"):
    scene = tmp_path / "scene.toml"
    scene.write_text(textwrap.dedent(f"""\
        [packing]
        kind = "file"
        path = "{packing_path.name}"
        format = "{fmt}"
        length_unit = "mm"
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
        duration = 2e-4
        output_every = 5
        checkpoint_every = 10
        """))
    return scene


@pytest.mark.parametrize("fmt", ["table", "lammps_dump"])
def test_effective_on_a_file_packing_is_the_lattices_closed_form(tmp_path, capsys, fmt):
    path, _, _ = _write(tmp_path, fmt)
    scene = _scene_file(tmp_path, path)
    assert cli.main(["effective", str(scene), "--out", str(tmp_path / "field")]) == 0
    out = capsys.readouterr().out
    k_star = float(out.split(":")[1].split()[0])
    assert k_star == pytest.approx(_expected_k_star(12.6), rel=1.2e-6)  # printed to 6 digits: half a unit
    assert "3 particles are joined to neither held face" in out and "face layer" in out
    field = io.read_vtp(tmp_path / "field" / "steady.vtp")
    isolated = field["isolated"] == 1
    assert isolated.sum() == 3 and np.isnan(field["temperature"][isolated]).all()  # the floating pair too
    assert np.all((field["temperature"][~isolated] >= 0) & (field["temperature"][~isolated] <= 1))


@pytest.mark.slow
def test_a_file_packing_runs_from_a_scene_as_a_time_series(tmp_path):
    path, centres, _ = _write(tmp_path, "lammps_data")
    scene = load_scene(_scene_file(tmp_path, path))  # the packing's path is relative to the scene file
    _, summary = runner.run_scene(scene, tmp_path / "out", progress=False, pictures=False)
    assert summary["particles"] == len(centres) and summary["T_max_K"] == 500.0  # the held floor
    assert (tmp_path / "out" / "frames.pvd").exists()


def test_a_bad_packing_file_is_named(tmp_path):
    missing = _scene_file(tmp_path, tmp_path / "nowhere.csv")
    with pytest.raises(SceneError, match=r"packing\.path: .*nowhere\.csv' does not exist"):
        load_scene(missing)
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,z,r\n0,0,0,1\n1,0,0\n")
    with pytest.raises(SceneError, match=r"packing\.path: .*bad\.csv, line 3: 3 columns, expected at least 4"):
        load_scene(_scene_file(tmp_path, bad))
    negative = tmp_path / "negative.csv"
    negative.write_text("0 0 0 1\n1 0 0 -1\n")
    with pytest.raises(SceneError, match=r"line 2: particle 1 .* radii > 0"):
        load_scene(_scene_file(tmp_path, negative))
    assert math.isfinite(_expected_k_star(1.0))


def _heated_files(tmp_path):
    """A table and a LIGGGHTS dump of the lattice carrying each particle's temperature (rows in file order)."""
    centres, radii = _lattice()
    temperature = 300.0 + 500.0 * centres[:, 0] / centres[:, 0].max()
    table = tmp_path / "heated.csv"
    np.savetxt(table, np.column_stack([temperature, centres, radii]), delimiter=",", header="T,x,y,z,radius",
               comments="", fmt="%.17g")
    dump = tmp_path / "heated.dump"
    ids = np.arange(len(radii))[::-1] + 1  # written in descending id; read back by id
    rows = "\n".join(f"{i} {x!r} {y!r} {z!r} {r!r} {t!r}" for i, (x, y, z), r, t in
                     zip(ids, centres.tolist(), radii.tolist(), temperature.tolist()))
    dump.write_text(f"ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{len(radii)}\nITEM: BOX BOUNDS ff ff ff\n0 1\n0 1\n"
                    f"0 1\nITEM: ATOMS id x y z radius f_Temp[0]\n{rows}\n")
    return table, dump, centres, temperature


def test_a_table_and_a_dump_carry_each_particles_temperature(tmp_path):
    table, dump, centres, temperature = _heated_files(tmp_path)
    np.testing.assert_array_equal(packing_files.read_temperatures(table), temperature)
    np.testing.assert_array_equal(packing_files.read_temperatures(dump), temperature[::-1])  # in id order
    np.testing.assert_array_equal(packing_files.read_packing(dump)[0], centres[::-1])
    data, _, _ = _write(tmp_path, "lammps_data")
    with pytest.raises(packing_files.PackingFileError, match="no temperature column.*atom_style sphere"):
        packing_files.read_temperatures(data)
    cold = tmp_path / "cold.csv"
    cold.write_text("x y z r temperature\n0 0 0 1 300\n2 0 0 1 -5\n")
    with pytest.raises(packing_files.PackingFileError, match=r"particle 1 has temperature -5.0.*> 0 \(K\)"):
        packing_files.read_temperatures(cold)


def test_a_scene_starts_from_the_files_temperatures(tmp_path):
    """``initial.from_file``: each particle starts at its file temperature (before: one uniform temperature, so a
    field from another code or a measurement could not be continued)."""
    from sintercond.scene.build import build_model

    table, _, _, temperature = _heated_files(tmp_path)
    scene_path = _scene_file(tmp_path, table)
    text = scene_path.read_text().replace('length_unit = "mm"', 'length_unit = "m"')
    scene_path.write_text(text.replace("temperature = 300.0\n", "temperature = 300.0\nfrom_file = true\n"))
    model = build_model(load_scene(scene_path))
    held = np.asarray(model.state.particles.fixed)
    got = np.asarray(model.state.particles.temperature)
    np.testing.assert_array_equal(got[~held], temperature[~held])
    assert np.all(got[held] == 500.0)  # the held floor overrides
    no_column = _scene_file(tmp_path, _write(tmp_path, "lammps_data")[0])
    no_column.write_text(no_column.read_text().replace("temperature = 300.0\n", "temperature = 300.0\nfrom_file = true\n"))
    with pytest.raises(SceneError, match=r"initial\.from_file: .*no temperature column"):
        load_scene(no_column)
