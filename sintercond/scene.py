"""Scene files (TOML): what a thermal run simulates, validated before anything compiles.

A scene has the sections below; every key is checked (unknown keys, wrong
types and out-of-range values raise :class:`SceneError` naming the key).
SI units throughout (m, s, K, W, kg). See ``sintercond/data/default_scene.toml``
for a complete example (the scene ``sintercond run`` uses without arguments).

``[packing]``
    ``kind = "powder_bed"``: ``lateral_size``, ``height``, ``diameter_range``
    ``[low, high]``, ``seed``, ``sinter_swelling`` (relative radius increase
    that turns settled contacts into sintered necks, 0 <= s <= 0.05).
    ``kind = "simple_cubic"``: ``counts`` ``[nx, ny, nz]``, ``spacing``, ``radius``.
``[material]``
    ``density``, ``specific_heat``, ``conductivity`` (all > 0).
``[conduction]``
    ``law`` (a key of ``sintercond.CONDUCTANCE_LAWS``), optional
    ``neck_model`` and ``[conduction.params]``.
``[initial]``
    ``temperature``.
``[boundary]`` (optional)
    ``floor_temperature``: shorthand for a held wall at the bottom (axis 2, min).
``[[walls]]`` (optional, any number)
    ``axis`` (0, 1, 2), ``side`` (``"min"`` or ``"max"``: the wall plane lies
    at the packing's extreme along the axis, moved ``penetration`` mean
    radii into it, default 0.02), ``mode``: ``"held"`` (touching particles
    held at ``temperature``), ``"conducting"`` (touching particles exchange
    heat with a wall at ``temperature`` through the conduction law, the wall
    taken as a very large sphere) or ``"insulated"`` (no flux, the default of
    any face).
``[beam]`` (optional; a heat source moving along a polyline)
    ``kind`` (``"laser"``, Lambert-Beer with ``attenuation`` in 1/m, the
    default; or ``"nozzle"``, linear attenuation to ``max_depth`` in m),
    ``intensity`` (W/m^2), ``spot_radius``, ``absorptance``, ``speed`` (m/s),
    ``path`` ``[[x, y], ...]``.
``[convection]`` / ``[radiation]`` (optional)
    ``environment_temperature`` and ``environment_conductivity``, and
    ``nusselt`` (default 2) or ``reynolds`` and ``prandtl`` (Whitaker's
    correlation) / ``emissivity``.
``[run]``
    ``duration`` (s), ``dt`` (s or ``"auto"`` = 0.9 x the stable step),
    ``output_every`` and ``checkpoint_every`` (steps; the second a multiple of
    the first), ``formats`` (``"vtp"``, ``"lammps"``).
"""

from __future__ import annotations

import importlib.resources
import math
import tomllib
from pathlib import Path

from sintercond.conductance import CONDUCTANCE_LAWS
from sintercond.neck import NECK_MODELS


class SceneError(ValueError):
    """An invalid scene: the message names the key and the allowed range."""


_POSITIVE = ("> 0", lambda v: v > 0)
_NON_NEGATIVE = (">= 0", lambda v: v >= 0)
_FRACTION = ("in [0, 1]", lambda v: 0 <= v <= 1)

# section -> key -> (type, rule or None, required)
_SCHEMA = {
    "material": {
        "density": (float, _POSITIVE, True),
        "specific_heat": (float, _POSITIVE, True),
        "conductivity": (float, _POSITIVE, True),
    },
    "conduction": {"law": (str, None, True), "neck_model": (str, None, False), "params": (dict, None, False)},
    "initial": {"temperature": (float, _POSITIVE, True)},
    "boundary": {"floor_temperature": (float, _POSITIVE, False)},
    "beam": {
        "kind": (str, ('"laser" or "nozzle"', lambda v: v in ("laser", "nozzle")), False),
        "intensity": (float, _NON_NEGATIVE, True),
        "attenuation": (float, _NON_NEGATIVE, False),
        "max_depth": (float, _POSITIVE, False),
        "spot_radius": (float, _POSITIVE, True),
        "absorptance": (float, _FRACTION, True),
        "speed": (float, _NON_NEGATIVE, True),
        "path": (list, None, True),
    },
    "convection": {
        "environment_temperature": (float, _POSITIVE, True),
        "environment_conductivity": (float, _POSITIVE, True),
        "nusselt": (float, _POSITIVE, False),
        "reynolds": (float, _NON_NEGATIVE, False),
        "prandtl": (float, _POSITIVE, False),
    },
    "radiation": {"environment_temperature": (float, _POSITIVE, True), "emissivity": (float, _FRACTION, True)},
    "run": {
        "duration": (float, _POSITIVE, True),
        "dt": (object, None, False),
        "output_every": (int, _POSITIVE, True),
        "checkpoint_every": (int, _POSITIVE, True),
        "formats": (list, None, False),
    },
}
_PACKING = {
    "powder_bed": {
        "kind": (str, None, True),
        "lateral_size": (float, _POSITIVE, True),
        "height": (float, _POSITIVE, True),
        "diameter_range": (list, None, True),
        "seed": (int, _NON_NEGATIVE, False),
        "sinter_swelling": (float, ("in [0, 0.05]", lambda v: 0 <= v <= 0.05), False),
    },
    "simple_cubic": {
        "kind": (str, None, True),
        "counts": (list, None, True),
        "spacing": (float, _POSITIVE, True),
        "radius": (float, _POSITIVE, True),
    },
}
_WALL = {
    "axis": (int, ("one of 0, 1, 2", lambda v: v in (0, 1, 2)), True),
    "side": (str, ('"min" or "max"', lambda v: v in ("min", "max")), True),
    "mode": (str, ('"held", "conducting" or "insulated"', lambda v: v in ("held", "conducting", "insulated")), True),
    "temperature": (float, _POSITIVE, False),
    "penetration": (float, ("in [0, 0.2]", lambda v: 0 <= v <= 0.2), False),
}
_REQUIRED_SECTIONS = ("packing", "material", "conduction", "initial", "run")


def _check_section(name, table, schema):
    if not isinstance(table, dict):
        raise SceneError(f"[{name}] must be a table")
    unknown = set(table) - set(schema)
    if unknown:
        raise SceneError(f"unknown key {name}.{sorted(unknown)[0]}; allowed: {sorted(schema)}")
    out = {}
    for key, (kind, rule, required) in schema.items():
        if key not in table:
            if required:
                raise SceneError(f"missing key {name}.{key}")
            continue
        value = table[key]
        if kind is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise SceneError(f"{name}.{key} must be a number; got {value!r}")
            value = float(value)
            if not math.isfinite(value):
                raise SceneError(f"{name}.{key} must be finite; got {value!r}")
        elif kind is int:
            if isinstance(value, bool) or not isinstance(value, int):
                raise SceneError(f"{name}.{key} must be an integer; got {value!r}")
        elif kind is not object and not isinstance(value, kind):
            raise SceneError(f"{name}.{key} must be a {kind.__name__}; got {value!r}")
        if rule is not None and not rule[1](value):
            raise SceneError(f"{name}.{key} must be {rule[0]}; got {value!r}")
        out[key] = value
    return out


def validate_scene(raw: dict) -> dict:
    """Check a parsed scene and return it with numbers normalised; raises :class:`SceneError`."""
    if not isinstance(raw, dict):
        raise SceneError("a scene must be a TOML table")
    unknown = set(raw) - set(_SCHEMA) - {"packing", "walls"}
    if unknown:
        raise SceneError(f"unknown section [{sorted(unknown)[0]}]; allowed: "
                         f"{sorted(set(_SCHEMA) | {'packing', 'walls'})}")
    for name in _REQUIRED_SECTIONS:
        if name not in raw:
            raise SceneError(f"missing section [{name}]")
    scene = {name: _check_section(name, raw[name], schema) for name, schema in _SCHEMA.items() if name in raw}
    packing = raw["packing"]
    kind = packing.get("kind") if isinstance(packing, dict) else None
    if kind not in _PACKING:
        raise SceneError(f"packing.kind must be one of {sorted(_PACKING)}; got {kind!r}")
    scene["packing"] = _check_section("packing", packing, _PACKING[kind])
    walls = raw.get("walls", [])
    if not isinstance(walls, list):
        raise SceneError("walls must be an array of tables ([[walls]])")
    scene["walls"] = [_check_section(f"walls[{k}]", w, _WALL) for k, w in enumerate(walls)]
    for k, wall in enumerate(scene["walls"]):
        if wall["mode"] != "insulated" and "temperature" not in wall:
            raise SceneError(f"walls[{k}].temperature is required for a {wall['mode']} wall")
    _check_details(scene)
    return scene


def _numbers(name, value, length=None, rule=_POSITIVE, integer=False):
    if not isinstance(value, list) or (length is not None and len(value) != length):
        raise SceneError(f"{name} must be a list of {length or 'some'} numbers; got {value!r}")
    for v in value:
        bad_type = isinstance(v, bool) or not isinstance(v, int if integer else (int, float))
        if bad_type or not math.isfinite(v) or not rule[1](v):
            raise SceneError(f"{name} entries must be {'integers' if integer else 'numbers'} {rule[0]}; got {value!r}")
    return [int(v) if integer else float(v) for v in value]


def _check_details(scene):
    packing = scene["packing"]
    if packing["kind"] == "powder_bed":
        low, high = _numbers("packing.diameter_range", packing["diameter_range"], 2)
        if not low <= high < packing["lateral_size"]:
            raise SceneError("packing.diameter_range must satisfy low <= high < packing.lateral_size; "
                             f"got {packing['diameter_range']} with lateral_size {packing['lateral_size']}")
        packing["diameter_range"] = [low, high]
    else:
        packing["counts"] = _numbers("packing.counts", packing["counts"], 3, integer=True)
        if not packing["spacing"] / 2 <= packing["radius"] <= packing["spacing"]:
            raise SceneError("packing.radius must be in [spacing/2, spacing] (touching to strongly sintered); "
                             f"got radius {packing['radius']} with spacing {packing['spacing']}")
    conduction = scene["conduction"]
    if conduction["law"] not in CONDUCTANCE_LAWS:
        raise SceneError(f"conduction.law must be one of {sorted(CONDUCTANCE_LAWS)}; got {conduction['law']!r}")
    if "neck_model" in conduction and conduction["neck_model"] not in NECK_MODELS:
        raise SceneError(f"conduction.neck_model must be one of {sorted(NECK_MODELS)}; got {conduction['neck_model']!r}")
    allowed = set(CONDUCTANCE_LAWS[conduction["law"]].default_params)
    for key, value in conduction.get("params", {}).items():
        if key not in allowed:
            raise SceneError(f"unknown key conduction.params.{key}; law {conduction['law']!r} takes {sorted(allowed)}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise SceneError(f"conduction.params.{key} must be a finite number; got {value!r}")
    if "beam" in scene:
        beam = scene["beam"]
        beam.setdefault("kind", "laser")
        needed = "attenuation" if beam["kind"] == "laser" else "max_depth"
        if needed not in beam:
            raise SceneError(f"beam.{needed} is required for a {beam['kind']} beam")
        path = scene["beam"]["path"]
        if not path or any(not isinstance(p, list) or len(p) != 2 for p in path):
            raise SceneError(f"beam.path must be a list of [x, y] points; got {path!r}")
        scene["beam"]["path"] = [_numbers("beam.path point", p, 2, rule=("finite", lambda v: True)) for p in path]
    convection = scene.get("convection", {})
    if ("reynolds" in convection) != ("prandtl" in convection):
        raise SceneError("convection.reynolds and convection.prandtl go together (Whitaker's correlation)")
    if "reynolds" in convection and "nusselt" in convection:
        raise SceneError("give convection.nusselt or convection.reynolds and prandtl, not both")
    run = scene["run"]
    dt = run.get("dt", "auto")
    if dt != "auto" and (isinstance(dt, bool) or not isinstance(dt, (int, float)) or not math.isfinite(dt) or dt <= 0):
        raise SceneError(f"run.dt must be \"auto\" or a number > 0 (s); got {dt!r}")
    run["dt"] = dt if dt == "auto" else float(dt)
    if run["checkpoint_every"] % run["output_every"]:
        raise SceneError(f"run.checkpoint_every ({run['checkpoint_every']}) must be a multiple of "
                         f"run.output_every ({run['output_every']})")
    formats = run.get("formats", ["vtp"])
    if not isinstance(formats, list) or not set(formats) <= {"vtp", "lammps"}:
        raise SceneError(f"run.formats must be a list from ['lammps', 'vtp']; got {formats!r}")
    run["formats"] = formats


def load_scene(path=None) -> dict:
    """Read and validate a scene file; ``None`` loads the built-in default scene."""
    if path is None:
        text = importlib.resources.files("sintercond.data").joinpath("default_scene.toml").read_text()
        source = "default scene"
    else:
        path = Path(path)
        if not path.is_file():
            raise SceneError(f"scene file {str(path)!r} does not exist")
        text, source = path.read_text(), str(path)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"{source} is not valid TOML: {err}") from None
    return validate_scene(raw)
