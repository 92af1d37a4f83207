"""Packings from files: an x, y, z, r table, a LAMMPS data file, a LAMMPS or LIGGGHTS dump.

What a user brings from a CT scan, a LIGGGHTS pour or another DEM code, read into ``(centres [n, 3], radii [n])``
in metres (``length_unit`` scales the file's numbers). The formats:

``table``
    CSV or whitespace-separated rows ``x y z r``, ``#`` comments; an optional header row naming the columns
    (``x, y, z`` and ``r``/``radius`` or ``d``/``diameter``, in any order, other columns ignored).
``lammps_data``
    A LAMMPS data file of ``atom_style sphere``: its ``Atoms`` section rows ``id type diameter density x y z``
    (image flags after them ignored), the order LAMMPS writes them.
``lammps_dump``
    A LAMMPS or LIGGGHTS text dump (``ITEM: ATOMS`` with column names): ``radius`` or ``diameter``, and ``x y z``,
    unwrapped ``xu yu zu``, or scaled ``xs ys zs`` (with the frame's box); the last frame, rows sorted by ``id``.

A table or a dump may also carry each particle's temperature (K), read by :func:`read_temperatures`: a table's
header column ``T``, ``temp`` or ``temperature``; a dump's column ``temperature`` (LAMMPS's granular heat model),
``f_Temp`` or ``f_Temp[0]`` (LIGGGHTS's ``property/atom`` Temp), or ``temp``.
"""

from __future__ import annotations

import functools
import io as _io
import warnings
from pathlib import Path

import numpy as np

FORMATS = ("table", "lammps_data", "lammps_dump")
TEMPERATURE_COLUMNS = ("t", "temp", "temperature", "f_temp", "f_temp[0]")
"""Column names (any case) that hold a particle's temperature (K)."""
LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9}


class PackingFileError(ValueError):
    """A packing file that cannot be read; the message names the file, the line or column, and what was expected."""


def guess_format(path) -> str:
    """The format of ``path`` from its name: ``*.data``/``data.*`` a LAMMPS data file, ``*.dump``,
    ``*.lammpstrj``/``dump.*`` a dump, anything else a table."""
    name = Path(path).name.lower()
    if name.endswith(".data") or name.startswith("data."):
        return "lammps_data"
    if name.endswith((".dump", ".lammpstrj", ".liggghts")) or name.startswith("dump."):
        return "lammps_dump"
    return "table"


def read_packing(path, format="auto", length_unit="m") -> tuple[np.ndarray, np.ndarray]:
    """``(centres [n, 3], radii [n])`` (m) of the packing in ``path`` (see the module docstring)."""
    path, format = _checked(path, format)
    if length_unit not in LENGTH_UNITS:
        raise PackingFileError(f"length_unit must be one of {list(LENGTH_UNITS)}; got {length_unit!r}")
    centres, radii, _, lines = _read(path, format)
    scale = LENGTH_UNITS[length_unit]
    centres, radii = centres * scale, radii * scale
    bad = ~(np.all(np.isfinite(centres), axis=1) & np.isfinite(radii) & (radii > 0))
    if bad.any():
        k = int(np.argmax(bad))
        raise PackingFileError(f"{path}, line {lines[k]}: particle {k} has centre {centres[k].tolist()} and radius "
                               f"{float(radii[k])!r}: centres must be finite and radii > 0")
    return centres, radii


def read_temperatures(path, format="auto") -> np.ndarray:
    """``[n]`` temperatures (K) of the particles in ``path``, in :func:`read_packing`'s order, from the column
    named as :data:`TEMPERATURE_COLUMNS` says; raises :class:`PackingFileError` if there is none or a value is not
    finite and > 0."""
    path, format = _checked(path, format)
    temperature = _read(path, format)[2]
    if temperature is None:
        where = {"table": "a header column T or temperature", "lammps_dump": "a column temperature or f_Temp",
                 "lammps_data": "nothing: a data file of atom_style sphere carries no temperature"}[format]
        raise PackingFileError(f"{path}: no temperature column; read as {format!r} it takes {where}")
    bad = ~(np.isfinite(temperature) & (temperature > 0))
    if bad.any():
        k = int(np.argmax(bad))
        raise PackingFileError(f"{path}: particle {k} has temperature {float(temperature[k])!r}; temperatures must be "
                               "finite and > 0 (K)")
    return temperature


def particle_lines(path, format="auto") -> np.ndarray:
    """``[n]`` line numbers (1-based) of each particle's row in ``path``, in :func:`read_packing`'s order: where a
    message about particle k sends the user."""
    path, format = _checked(path, format)
    return _read(path, format)[3]


def _checked(path, format):
    path = Path(path)
    if format == "auto":
        format = guess_format(path)
    if format not in FORMATS:
        raise PackingFileError(f"format must be one of {list(FORMATS)} or 'auto'; got {format!r}")
    if not path.is_file():
        raise PackingFileError(f"{str(path)!r} does not exist")
    return path, format


def _read(path, format):
    stat = path.stat()
    return _read_cached(str(path.resolve()), stat.st_mtime_ns, stat.st_size, format)


@functools.lru_cache(maxsize=8)
def _read_cached(path, mtime, size, format):
    """The file read once per version (validation and the build both ask), in the file's units:
    ``(centres, radii, temperatures or None, line of each particle's row)``."""
    text = Path(path).read_text(errors="replace")
    reader = {"table": _read_table, "lammps_data": _read_lammps_data, "lammps_dump": _read_lammps_dump}[format]
    centres, radii, temperature, lines = reader(text, path)
    if len(radii) == 0:
        raise PackingFileError(f"{path}: no particles found (read as {format!r})")
    for array in (centres, radii, temperature, lines):
        if array is not None:
            array.setflags(write=False)
    return centres, radii, temperature, lines


def _read_table(text, path):
    lines = [line.split("#", 1)[0].strip() for line in text.splitlines()]
    rows = [(k + 1, line.replace(",", " ").replace(";", " ").split()) for k, line in enumerate(lines) if line]
    fast = _read_uniform_table(text)
    if fast is not None:
        return (*fast, np.array([line for line, _ in rows[len(rows) - len(fast[1]):]]))
    if not rows:
        return np.zeros((0, 3)), np.zeros(0), None, np.zeros(0, int)
    columns = {"x": 0, "y": 1, "z": 2, "r": 3}
    diameter = False
    first = rows[0][1]
    try:
        [float(v) for v in first]
    except ValueError:
        names = [v.lower() for v in first]
        try:
            columns = {axis: names.index(axis) for axis in "xyz"}
        except ValueError:
            raise PackingFileError(f"{path}: the header {first} must name columns x, y, z and r (or radius, d, "
                                   "diameter)") from None
        for key, is_diameter in (("r", False), ("radius", False), ("d", True), ("diameter", True)):
            if key in names:
                columns["r"], diameter = names.index(key), is_diameter
                break
        else:
            raise PackingFileError(f"{path}: the header {first} names no radius column (r, radius, d or diameter)")
        heat = [names.index(key) for key in TEMPERATURE_COLUMNS if key in names]
        if heat:
            columns["t"] = heat[0]
        rows = rows[1:]
    width = max(columns.values()) + 1
    counts = {len(fields) for _, fields in rows}
    values = None
    if len(counts) == 1 and min(counts) >= width:  # every row alike: one parse of all numbers
        try:
            table = np.array([v for _, fields in rows for v in fields], dtype=np.float64).reshape(len(rows), -1)
            values = table[:, [columns[c] for c in columns]]
        except ValueError:
            values = None
    if values is None:  # find the row at fault
        values = np.empty((len(rows), len(columns)))
        for k, (line, fields) in enumerate(rows):
            if len(fields) < width:
                raise PackingFileError(f"{path}, line {line}: {len(fields)} columns, expected at least {width} "
                                       "(x y z r)")
            try:
                values[k] = [float(fields[columns[c]]) for c in columns]
            except ValueError:
                raise PackingFileError(f"{path}, line {line}: {fields} are not all numbers") from None
    radii = values[:, 3] / 2 if diameter else values[:, 3]
    return (values[:, :3].copy(), radii.copy(), values[:, 4].copy() if "t" in columns else None,
            np.array([line for line, _ in rows]))


def _read_uniform_table(text):
    """:func:`_read_table` of a table whose rows are all numbers of one width (NumPy's parser, no per-row
    Python), or None for anything else (:func:`_read_table` then reads it row by row and names the row at fault)."""
    body = text.replace(",", " ").replace(";", " ")
    head, _, rest = body.lstrip().partition("\n")
    head = head.split("#", 1)[0].split()
    names = [v.lower() for v in head]
    columns, diameter = {"x": 0, "y": 1, "z": 2, "r": 3}, False
    if head and not all(_is_number(v) for v in head):
        if not all(axis in names for axis in "xyz"):
            return None
        columns = {axis: names.index(axis) for axis in "xyz"}
        for key, is_diameter in (("r", False), ("radius", False), ("d", True), ("diameter", True)):
            if key in names:
                columns["r"], diameter = names.index(key), is_diameter
                break
        else:
            return None
        heat = [names.index(key) for key in TEMPERATURE_COLUMNS if key in names]
        if heat:
            columns["t"] = heat[0]
        body = rest
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # an empty or ragged table: the slow path says which row
            table = np.loadtxt(_io.StringIO(body), comments="#", ndmin=2)
    except (ValueError, UserWarning):
        return None
    if table.shape[0] == 0 or table.shape[1] < max(columns.values()) + 1 or table.shape[1] != len(head):
        return None
    values = table[:, [columns[c] for c in columns]]
    radii = values[:, 3] / 2 if diameter else values[:, 3]
    return values[:, :3].copy(), radii.copy(), values[:, 4].copy() if "t" in columns else None


def _is_number(text):
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_lammps_data(text, path):
    lines = text.splitlines()
    start = next((k for k, line in enumerate(lines) if line.split("#", 1)[0].strip() == "Atoms"), None)
    if start is None:
        raise PackingFileError(f"{path}: no 'Atoms' section (a LAMMPS data file of atom_style sphere)")
    style = lines[start].split("#", 1)[1].strip() if "#" in lines[start] else "sphere"
    if style != "sphere":
        raise PackingFileError(f"{path}: the Atoms section is atom_style {style!r}; sphere (id type diameter "
                               "density x y z) is read")
    rows, at = [], []
    for k in range(start + 1, len(lines)):
        line = lines[k].split("#", 1)[0].strip()
        if not line:
            if rows:
                break
            continue
        if line[0].isalpha():  # the next section
            break
        fields = line.split()
        if len(fields) < 7:
            raise PackingFileError(f"{path}, line {k + 1}: {len(fields)} columns in Atoms, expected id type "
                                   "diameter density x y z")
        rows.append([float(v) for v in fields[:7]])
        at.append(k + 1)
    data = np.asarray(rows).reshape(-1, 7)
    declared = next((line.split()[0] for line in lines[:start] if line.split("#", 1)[0].split()[1:] == ["atoms"]),
                    None)
    _check_count(path, declared, len(data), "the header's 'N atoms'", "rows in its Atoms section")
    order = np.argsort(data[:, 0], kind="stable")
    data = data[order]
    return data[:, 4:7].copy(), data[:, 2] / 2, None, np.asarray(at, int)[order]


def _read_lammps_dump(text, path):
    frames = text.split("ITEM: TIMESTEP")
    if len(frames) < 2:
        raise PackingFileError(f"{path}: no 'ITEM: TIMESTEP' (a LAMMPS or LIGGGHTS text dump)")
    frame = frames[-1]
    box_at = frame.find("ITEM: BOX BOUNDS")
    atoms_at = frame.find("ITEM: ATOMS")
    if atoms_at < 0:
        raise PackingFileError(f"{path}: the last frame has no 'ITEM: ATOMS' section")
    header, _, body = frame[atoms_at:].partition("\n")
    names = header.split()[2:]
    first = text.count("\n", 0, len(text) - len(frame) + atoms_at) + 2  # the line after the ITEM: ATOMS header
    try:
        data = np.loadtxt(_io.StringIO(body), ndmin=2) if body.strip() else np.zeros((0, len(names)))
    except ValueError:  # name the row at fault (NumPy's message advises its own arguments)
        for k, line in enumerate(body.splitlines()):
            fields = line.split()
            if fields and (len(fields) != len(names) or not all(_is_number(v) for v in fields)):
                raise PackingFileError(f"{path}, line {first + k}: {len(fields)} fields {fields}, expected "
                                       f"{len(names)} numbers ({' '.join(names)}); a dump cut short?") from None
        raise
    if data.shape[1] != len(names):
        raise PackingFileError(f"{path}: {data.shape[1]} columns for the {len(names)} names {names}")
    count_at = frame.find("ITEM: NUMBER OF ATOMS")
    declared = frame[count_at:].splitlines()[1].strip() if count_at >= 0 and frame[count_at:].count("\n") else None
    _check_count(path, declared, len(data), "the last frame's 'ITEM: NUMBER OF ATOMS'", "rows under its ITEM: ATOMS")
    column = {name: data[:, k] for k, name in enumerate(names)}
    heat = next((data[:, k] for k, name in enumerate(names) if name.lower() in TEMPERATURE_COLUMNS), None)
    if "radius" in column:
        radii = column["radius"]
    elif "diameter" in column:
        radii = column["diameter"] / 2
    else:
        raise PackingFileError(f"{path}: the dump has no radius or diameter column (columns: {names})")
    for axes in (("x", "y", "z"), ("xu", "yu", "zu"), ("xs", "ys", "zs")):
        if all(a in column for a in axes):
            centres = np.stack([column[a] for a in axes], axis=1)
            if axes[0] == "xs":
                if box_at < 0:
                    raise PackingFileError(f"{path}: scaled coordinates without an 'ITEM: BOX BOUNDS'")
                bounds = np.array([[float(v) for v in line.split()[:2]]
                                   for line in frame[box_at:atoms_at].splitlines()[1:4]])
                centres = bounds[:, 0] + centres * (bounds[:, 1] - bounds[:, 0])
            break
    else:
        raise PackingFileError(f"{path}: the dump has no x y z (or xu yu zu, xs ys zs) columns (columns: {names})")
    order = np.argsort(column["id"], kind="stable") if "id" in column else np.arange(len(radii))
    body_lines = [first + k for k, line in enumerate(body.splitlines()) if line.strip()]
    return (centres[order].copy(), radii[order].copy(), None if heat is None else heat[order].copy(),
            np.asarray(body_lines, int)[order])


def _check_count(path, declared, found, where, what):
    """Raise :class:`PackingFileError` unless the particle count a file declares (``declared``, its text, None
    if it declares none) is the ``found`` rows read: a file cut short at a line boundary reads cleanly otherwise."""
    if declared is None:
        return
    try:
        count = int(declared)
    except ValueError:
        raise PackingFileError(f"{path}: {where} is {declared!r}, not a whole number") from None
    if count != found:
        cut = "; the file is cut short?" if found < count else ""
        raise PackingFileError(f"{path}: {where} says {count} particles, but {found} {what} were read{cut}")


def write_table(path, centres, radii, length_unit="m", temperature=None):
    """Write ``centres``, ``radii`` (m) as a CSV table with a header, in ``length_unit``, and with ``temperature``
    (K, [n]) a column ``T`` (read back by :func:`read_temperatures`)."""
    scale = LENGTH_UNITS[length_unit]
    columns = [np.asarray(centres) / scale, np.asarray(radii) / scale]
    columns += [] if temperature is None else [np.asarray(temperature)]
    header = "x,y,z,r" + ("" if temperature is None else ",T")
    np.savetxt(path, np.column_stack(columns), delimiter=",", header=header, comments="", fmt="%.17g")
