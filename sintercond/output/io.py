"""Writers of run outputs: VTK XML PolyData (ParaView), LAMMPS dumps (OVITO), atomic files, checkpoints.

Both formats are checked by the readers people open them with, VTK's
``vtkXMLPolyDataReader`` and OVITO's ``import_file`` (``tests/test_io.py``,
with the ``readers`` extra):

* ``write_vtp``: one vertex per particle, point data ``temperature`` (K),
  ``radius`` (m) and ``id`` (and more fields: from a run with mechanics ``velocity``
  (m/s), ``force`` (N, contact force) and ``coordination``); field data ``TIME`` (s) and ``STEP`` with
  ``NumberOfTuples="1"`` (without it VTK reads them back empty), and ``TIME`` again as
  ``TimeValue``, the field VTK's and ParaView's readers take as the frame's time. Binary
  (appended, zlib-compressed) by default, or ASCII with Python's shortest
  round-trip ``repr`` of each float; both hold the exact float64 values.
  ``read_vtp`` reads either back; ``write_pvd`` lists the frames with their
  physical times for ParaView.
* ``append_lammps``: one ``ITEM: TIMESTEP`` frame per call (after its ``ITEM: TIME``, s), box bounds the
  particles' bounding box widened by the largest radius, columns
  ``id radius x y z temperature`` (OVITO maps ``radius`` and ``x y z`` to its
  Radius and Position properties).
"""

from __future__ import annotations

import os
import re
import zlib
from pathlib import Path
from xml.etree import ElementTree

import jax
import jax.numpy as jnp
import numpy as np


def _number(value) -> str:
    """Shortest round-trip text of a float (never NumPy's ``np.float64(...)`` repr)."""
    return repr(float(value))


def _extra_fields(fields, n):
    """``{name: [n] or [n, k] array}`` checked (``n`` points or cells); integer arrays stay integers."""
    out = {}
    for name, values in (fields or {}).items():
        values = np.asarray(values)
        if values.shape[0] != n or values.ndim not in (1, 2):
            raise ValueError(f"field {name!r} must be [n] or [n, k] with n = {n}; got shape {values.shape}")
        out[name] = values
    return out


VTP_ENCODINGS = ("binary", "ascii")


def write_vtp(path, centres, radii, temperature, step, t, fields=None, encoding="binary"):
    """VTK XML PolyData with one vertex per particle: temperature, radius, id; TIME and STEP field data.

    ``fields``: more point data, ``{name: [n] or [n, k]}`` (e.g. ``velocity``
    ``[n, 3]`` m/s, ``force`` ``[n, 3]`` N, ``coordination`` ``[n]`` ints),
    written as Float64 or, for integer arrays, Int64. ``encoding``:
    ``"binary"`` (the point data appended raw after the XML, each array one
    zlib-compressed block behind a UInt64 header, as VTK writes it) or
    ``"ascii"`` (shortest round-trip text). Both hold the exact float64 values.
    """
    n = len(radii)
    fields = _extra_fields(fields, n)
    out = _ArrayWriter(encoding)
    array = out.array
    body = (
        f'<Piece NumberOfPoints="{n}" NumberOfVerts="{n}" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="0">\n'
        f'<Points>{array("position", centres, components=3)}</Points>\n'
        f'<Verts>{array("connectivity", np.arange(n), "Int64")}{array("offsets", np.arange(1, n + 1), "Int64")}</Verts>\n'
        f'<PointData Scalars="temperature">{array("temperature", temperature)}{array("radius", radii)}'
        f'{array("id", np.arange(n), "Int64")}' + out.arrays(fields) + '</PointData>\n</Piece>\n'
    )
    out.write(path, step, t, body)


def write_network_vtp(path, centres, pairs, step, t, fields=None, encoding="binary"):
    """The contact network as VTK XML PolyData: one line per contact between the two particle centres.

    ``pairs`` ``[p, 2]`` particle indices; ``fields``: cell data, one value (or ``k``) per contact,
    ``{name: [p] or [p, k]}`` (e.g. ``neck_radius`` m, ``conductance`` W/K, ``heat_flow`` W); TIME and STEP
    as :func:`write_vtp`, so a ``.pvd`` of these frames plays beside the particles' in ParaView.
    """
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    p, n = len(pairs), len(centres)
    fields = _extra_fields(fields, p)
    out = _ArrayWriter(encoding)
    array = out.array
    body = (
        f'<Piece NumberOfPoints="{n}" NumberOfVerts="0" NumberOfLines="{p}" NumberOfStrips="0" NumberOfPolys="0">\n'
        f'<Points>{array("position", centres, components=3)}</Points>\n'
        f'<Lines>{array("connectivity", pairs, "Int64")}{array("offsets", 2 * np.arange(1, p + 1), "Int64")}</Lines>\n'
        f'<CellData>' + out.arrays(fields) + '</CellData>\n</Piece>\n'
    )
    out.write(path, step, t, body)


class _ArrayWriter:
    """The DataArrays of one VTP file in ``encoding``: inline text, or appended zlib blocks (VTK's layout)."""

    def __init__(self, encoding):
        if encoding not in VTP_ENCODINGS:
            raise ValueError(f"encoding must be one of {list(VTP_ENCODINGS)}; got {encoding!r}")
        self.binary = encoding == "binary"
        self.blocks, self.offset = [], 0

    def array(self, name, values, kind="Float64", components=1, tuples=None, inline=False):
        count = "" if tuples is None else f' NumberOfTuples="{tuples}"'
        head = f'<DataArray type="{kind}" Name="{name}" NumberOfComponents="{components}"{count}'
        if not self.binary or inline:
            body = " ".join(_number(v) if kind == "Float64" else str(int(v)) for v in np.ravel(values))
            return f'{head} format="ascii">{body}</DataArray>'
        raw = np.ascontiguousarray(np.ravel(values), "<f8" if kind == "Float64" else "<i8").tobytes()
        packed = zlib.compress(raw, 6)
        block = np.asarray([1, len(raw), len(raw), len(packed)], "<u8").tobytes() + packed
        self.blocks.append(block)
        self.offset, at = self.offset + len(block), self.offset
        return f'{head} format="appended" offset="{at}"/>'

    def arrays(self, fields):
        """Float64 (or Int64 for integer arrays) DataArrays of ``{name: [m] or [m, k]}``."""
        return "".join(self.array(name, v, "Int64" if np.issubdtype(v.dtype, np.integer) else "Float64",
                                  1 if v.ndim == 1 else v.shape[1]) for name, v in fields.items())

    def write(self, path, step, t, piece):
        """The file: header, TIME/TimeValue/STEP field data, ``piece``, and the appended blocks."""
        array = self.array
        xml = (
            '<?xml version="1.0"?>\n<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian"'
            + (' header_type="UInt64" compressor="vtkZLibDataCompressor"' if self.binary else "") + '>\n<PolyData>\n'
            f'<FieldData>{array("TIME", [t], tuples=1, inline=True)}{array("TimeValue", [t], tuples=1, inline=True)}'
            f'{array("STEP", [step], "Int64", tuples=1, inline=True)}</FieldData>\n' + piece + '</PolyData>\n'
        )
        if self.binary:
            atomic_write_bytes(path, xml.encode() + b'<AppendedData encoding="raw">\n_' + b"".join(self.blocks)
                               + b"\n</AppendedData>\n</VTKFile>\n")
        else:
            atomic_write_text(path, xml + "</VTKFile>\n")


def read_vtp(path) -> dict:
    """The arrays of a :func:`write_vtp` file (either encoding): ``position`` ``[n, 3]``, every point array by name
    (``[n]`` or ``[n, k]``), and the field data ``TIME`` and ``STEP`` (scalars)."""
    data = Path(path).read_bytes()
    marker = data.find(b"<AppendedData")
    xml = data if marker < 0 else data[:marker] + b"</VTKFile>"
    appended = b"" if marker < 0 else data[data.index(b"_", marker) + 1:]
    root = ElementTree.fromstring(xml)
    out = {}
    for node in root.iter("DataArray"):
        dtype = "<f8" if node.get("type") == "Float64" else "<i8"
        if node.get("format") == "appended":
            at = int(node.get("offset"))
            blocks, _, _, size = np.frombuffer(appended[at:at + 32], "<u8")
            if blocks != 1:
                raise ValueError(f"{path}: only single-block arrays are read")
            values = np.frombuffer(zlib.decompress(appended[at + 32:at + 32 + int(size)]), dtype)
        else:
            values = np.array((node.text or "").split(), float).astype(dtype)
        components = int(node.get("NumberOfComponents", "1"))
        out[node.get("Name")] = values.reshape(-1, components) if components > 1 else values
    for name in ("TIME", "TimeValue", "STEP"):
        out[name] = out[name][0]
    return out


def write_pvd(path, frames):
    """A ParaView collection ``path`` (``.pvd``) of ``frames`` ``[(time s, file relative to path's folder)]``:
    ParaView plays the frames as a time series at their physical times."""
    rows = "".join(f'<DataSet timestep="{_number(t)}" group="" part="0" file="{name}"/>\n' for t, name in frames)
    atomic_write_text(path, '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" '
                            f'byte_order="LittleEndian">\n<Collection>\n{rows}</Collection>\n</VTKFile>\n')


def _lammps_columns(fields):
    """Dump columns of extra fields: ``velocity`` -> ``vx vy vz``, ``force`` -> ``fx fy fz`` (LAMMPS' names,
    which OVITO maps to Velocity and Force), any other ``[n, k]`` field ``name_0 ... name_k-1``."""
    names = []
    for name, values in fields.items():
        if values.ndim == 1:
            names.append(name)
        elif name in ("velocity", "force") and values.shape[1] == 3:
            names += [f"{name[0]}{axis}" for axis in "xyz"]
        else:
            names += [f"{name}_{k}" for k in range(values.shape[1])]
    return names


def lammps_frame(centres, radii, temperature, step, fields=None, time=None) -> str:
    """One LAMMPS dump frame (text) of the particles; ``fields`` as :func:`write_vtp`'s, as more columns; with
    ``time`` (s) an ``ITEM: TIME`` before its ``ITEM: TIMESTEP``, as LAMMPS' ``dump_modify time yes`` writes it."""
    centres = np.asarray(centres, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    fields = _extra_fields(fields, len(radii))
    lo, hi = centres.min(axis=0) - radii.max(), centres.max(axis=0) + radii.max()
    lines = [] if time is None else [f"ITEM: TIME\n{float(time)!r}\n"]
    lines += [f"ITEM: TIMESTEP\n{int(step)}\nITEM: NUMBER OF ATOMS\n{len(radii)}\nITEM: BOX BOUNDS ff ff ff\n"]
    lines += [f"{_number(lo[k])} {_number(hi[k])}\n" for k in range(3)]
    lines.append(" ".join(["ITEM: ATOMS id radius x y z temperature"] + _lammps_columns(fields)) + "\n")
    columns = [radii, *centres.T, np.asarray(temperature, dtype=np.float64)]
    columns += [c for v in fields.values() for c in np.asarray(v).reshape(len(radii), -1).T]
    # column by column: repr of each number (the shortest that reads back exactly), then one join per row
    text = [map(str, range(1, len(radii) + 1))] + [map(repr, c.tolist()) for c in columns]
    lines.append("\n".join(map(" ".join, zip(*text))) + ("\n" if len(radii) else ""))
    return "".join(lines)


def append_lammps(path, centres, radii, temperature, step, fields=None, time=None):
    """Append one frame (:func:`lammps_frame`) to the LAMMPS dump at ``path``."""
    with open(path, "a") as f:
        f.write(lammps_frame(centres, radii, temperature, step, fields, time))


def truncate_lammps(path, last_step):
    """Drop the frames after ``last_step`` from the LAMMPS dump at ``path`` (for a resumed run)."""
    text = Path(path).read_text()
    later = next((m.start() for m in re.finditer(r"(?m)^(?:ITEM: TIME\n[^\n]*\n)?ITEM: TIMESTEP\n(\d+)\n", text)
                  if int(m.group(1)) > last_step), len(text))  # a frame starts at its ITEM: TIME, if any
    atomic_write_text(path, text[:later])


def atomic_write_text(path, text):
    """Write to ``path.tmp`` and rename: a killed writer leaves the old file or the new one, never half of one."""
    atomic_write_bytes(path, text.encode())


def atomic_write_bytes(path, data: bytes):
    """:func:`atomic_write_text` for bytes."""
    tmp = Path(str(path) + ".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def save_checkpoint(directory, state, **extra):
    """Write the whole :class:`~sintercond.simulate.SimState` to ``directory/checkpoint.npz`` atomically.

    Every leaf is stored under its path in the state (plus ``temperature`` and
    ``step`` for a quick look, and the arrays ``extra``), written to a
    temporary file and renamed, so a killed run leaves the last complete
    checkpoint. With mechanics the leaves include velocities, spins, the
    pair and wall springs and the neighbour list.
    """
    leaves = {jax.tree_util.keystr(path): np.asarray(leaf)
              for path, leaf in jax.tree_util.tree_flatten_with_path(state)[0]}
    tmp = Path(directory) / "checkpoint.tmp.npz"
    np.savez(tmp, temperature=np.asarray(state.particles.temperature), step=int(state.step), **extra, **leaves)
    os.replace(tmp, Path(directory) / "checkpoint.npz")


def load_checkpoint(path, like):
    """The state saved by :func:`save_checkpoint`, with the structure (and neighbour-list capacity) of ``like``."""
    saved = np.load(path)
    paths, treedef = jax.tree_util.tree_flatten_with_path(like)
    leaves = []
    for key, leaf in paths:
        name = jax.tree_util.keystr(key)
        if name not in saved:
            raise ValueError(f"{path} does not hold {name}: written by another version or scene")
        if name.startswith(".sintering.") and saved[name].shape != np.shape(leaf):  # no capacity to carry over
            raise ValueError(f"{path} holds {name} of shape {saved[name].shape}, not {np.shape(leaf)}: written by "
                             "another version or scene")
        leaves.append(jnp.asarray(saved[name], dtype=jnp.asarray(leaf).dtype))
    return jax.tree_util.tree_unflatten(treedef, leaves)


