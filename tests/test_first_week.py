"""A user's first week (issue 43): nothing silently wrong, every refusal names what to change.

Each test fails on the code before its fix: a file cut short read with fewer particles, a packing in micrometres
read as metres, coincident centres that crashed after the build, and the like.
"""

import pytest

from sintercond import packing_files

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
