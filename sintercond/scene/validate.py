"""Validation of a scene: keys, types, ranges and combinations checked, the declared defaults filled once
(:func:`validate_scene`), and scene files read by path or built-in name (:func:`load_scene`)."""

from __future__ import annotations

import copy
import importlib.resources
import math
import tomllib
from pathlib import Path

import numpy as np

from sintercond.laws.conductance import CONDUCTANCE_LAWS
from sintercond.sim.mechanics import validate_mechanical_params
from sintercond.laws.sintering import KINETIC_LAWS
from sintercond.scene.estimate import estimate_run
from sintercond.scene.integrator import scene_integrator
from sintercond.scene.schema import (
    DEFAULT_CHECKPOINT_OUTPUTS, Key, MAX_LATTICE_PARTICLES, MAX_LISTED_SPHERES, MECHANICAL_FIELDS, POUR_START,
    SceneError, _LAW_PARAMS, _PACKING,
    TEMPERATURE, _REQUIRED_SECTIONS, _SCHEMA, _SECTIONS, _SINTERING_PARAMS, _WALL, _check_keys, _check_section,
    _describe, _numbers, _suggest, _value, _within, file_packing, file_temperatures,
)


def validate_scene(raw: dict) -> dict:
    """Check a parsed scene and return it with numbers normalised and its defaults filled; raises :class:`SceneError`.

    Everything is checked here, before any packing or network is built:
    keys, types and ranges, combinations (beam path over the packing,
    lattice overlap within the neck model's domain, bed size), and the work
    of the run estimated from the scene (particles, steps, frames, output
    bytes, memory) against the limits above.
    """
    if not isinstance(raw, dict):
        raise SceneError("a scene must be a TOML table")
    for name in raw:
        if name not in _SECTIONS:
            raise SceneError(f"unknown section [{name}]{_suggest(name, _SECTIONS)}; allowed sections: "
                             f"{sorted(_SECTIONS)}")
    for name in _REQUIRED_SECTIONS:
        if name not in raw:
            raise SceneError(f"missing section [{name}] (required: {list(_REQUIRED_SECTIONS)})")
    scene = {name: _check_section(name, raw[name], schema) for name, schema in _SCHEMA.items() if name in raw}
    packing = raw["packing"]
    kind = packing.get("kind") if isinstance(packing, dict) else None
    if kind not in _PACKING:
        if isinstance(packing, dict):  # a misspelt key (kindx = ...) is named before the kind it hides
            _check_keys("packing", packing, {key: None for schema in _PACKING.values() for key in schema})
        raise SceneError(f"packing.kind must be one of {sorted(_PACKING)}; got {kind!r}")
    scene["packing"] = _check_section("packing", packing, _PACKING[kind])
    walls = raw.get("walls", [])
    if not isinstance(walls, list):
        raise SceneError(f"walls must be an array of tables ([[walls]]) with keys {sorted(_WALL)}; got {walls!r}")
    scene["walls"] = [_check_section(f"walls[{k}]", w, _WALL) for k, w in enumerate(walls)]
    for k, wall in enumerate(scene["walls"]):
        if wall["mode"] != "insulated" and "temperature" not in wall:
            raise SceneError(f"walls[{k}].temperature is required for a {wall['mode']} wall "
                             f"({_describe(_WALL['temperature'])})")
        if "velocity" in wall:
            wall["velocity"] = _numbers(f"walls[{k}].velocity", wall["velocity"], 3, _within(-1e3, 1e3, "m/s"))
    _check_mechanics(scene)
    _fill_defaults(scene)
    _check_details(scene)
    estimate_run(scene)
    return scene


# keys whose default holds only without another key (given instead), or only with mechanics
_ALTERNATIVES = {("mechanics", "damping"): "restitution", ("convection", "nusselt"): "reynolds"}


_MECHANICAL_ONLY = {("physics", key) for key in _SCHEMA["physics"] if key != "mechanics"}


def _default_of(section, key, spec: Key, table, on):
    """The value ``spec`` declares for a missing key (None: no default to fill): a literal the key's own rule
    accepts, or the value of the key its default names (``mechanics.wall_friction`` defaults to
    ``mechanics.friction``); a default that needs another key absent, or mechanics on, only then."""
    if spec.default is None or (section, key) in _ALTERNATIVES and _ALTERNATIVES[section, key] in table:
        return None
    if (section, key) == ("walls", "penetration"):  # computed from the packing: default_penetration
        return None
    if (section, key) in _MECHANICAL_ONLY and not on:
        return None
    if isinstance(spec.default, str) and spec.kind is float:
        return table.get(spec.default)  # a reference, itself filled first (the schema lists it before)
    try:
        return _value(f"{section}.{key}", copy.deepcopy(spec.default), spec)
    except SceneError:  # a description ("the law's"): computed where it is used
        return None


def _fill_defaults(scene):
    """Fill every missing key of the sections present with the default its :class:`Key` declares, once, so that
    the run reads ``scene[section][key]`` and no code restates a default. Run after the checks of what was
    given; the filled scene validates again as it is (``scene.json``, read back by ``--resume``)."""
    on = scene["physics"].get("mechanics", False)
    tables = [(name, scene[name], _SCHEMA[name]) for name in _SCHEMA if name in scene]
    tables.append(("packing", scene["packing"], _PACKING[scene["packing"]["kind"]]))
    tables += [("walls", wall, _WALL) for wall in scene["walls"]]
    for section, table, schema in tables:
        for key, spec in schema.items():
            if key not in table:
                value = _default_of(section, key, spec, table, on)
                if value is not None:
                    table[key] = value
    penetration = default_penetration(scene)  # with the packing's method filled
    for wall in scene["walls"]:
        wall.setdefault("penetration", penetration)


ROUGH_BED_PENETRATION = 0.1
"""``walls[k].penetration`` (mean radii) on a powder bed settled by relaxation without mechanics: the face layer of
such a bed spreads over about a tenth of a radius, so the schema's 0.02 touches only the particles that stick out."""


def default_penetration(scene) -> float:
    """``walls[k].penetration`` where the scene gives none (mean radii): :data:`ROUGH_BED_PENETRATION` on a relaxed
    powder bed without mechanics, else the schema's default."""
    p = scene["packing"]
    rough = p["kind"] == "powder_bed" and p["method"] != "dem" and not scene["physics"]["mechanics"]
    return ROUGH_BED_PENETRATION if rough else _WALL["penetration"].default


def _lateral_extent(packing):
    """``((x_lo, x_hi), (y_lo, y_hi))`` (m) of the packing, from the scene alone."""
    if packing["kind"] in ("powder_bed", "poured"):  # both fill the square [0, L]^2
        return (0.0, packing["lateral_size"]), (0.0, packing["lateral_size"])
    if packing["kind"] == "spheres":
        c, r = packing["centres"], packing["radii"]
        return tuple((min(p[k] - q for p, q in zip(c, r)), max(p[k] + q for p, q in zip(c, r))) for k in (0, 1))
    if packing["kind"] == "file":
        c, r = file_packing(packing)
        return tuple((float(np.min(c[:, k] - r)), float(np.max(c[:, k] + r))) for k in (0, 1))
    nx, ny, _ = packing["counts"]
    return ((0.0, (nx - 1) * packing["spacing"] + 2 * packing["radius"]),
            (0.0, (ny - 1) * packing["spacing"] + 2 * packing["radius"]))


def _check_mechanics(scene):
    """The thermo-mechanical sections: [mechanics] and [softening] only with physics.mechanics, combinations."""
    physics = scene.setdefault("physics", {})
    on = physics.get("mechanics", False)
    packing = scene["packing"]
    pours = packing["kind"] == "poured" or packing.get("method") == "dem"
    if pours and "mechanics" not in scene:
        raise SceneError("a poured packing (packing.kind = \"poured\" or packing.method = \"dem\") needs a [mechanics] "
                         "section: the contact material it is poured with (at least mechanics.young_modulus and "
                         "mechanics.poisson_ratio)")
    if packing["kind"] == "powder_bed" and packing.get("method") == "dem":
        packing.setdefault("start", POUR_START.default)
    elif packing["kind"] == "powder_bed" and "start" in packing:
        raise SceneError("packing.start is where a DEM pour starts from: it needs packing.method = \"dem\"")
    if "soft_modulus" in packing:
        if not pours:
            raise SceneError("packing.soft_modulus applies to a poured packing only (packing.kind = \"poured\" or "
                             "packing.method = \"dem\")")
        modulus = scene.get("mechanics", {}).get("young_modulus")
        if isinstance(modulus, (int, float)) and not packing["soft_modulus"] < modulus:
            raise SceneError(f"packing.soft_modulus must be below mechanics.young_modulus = {modulus:g} Pa (the "
                             f"modulus it is stiffened to); got {packing['soft_modulus']:g} Pa")
    for section in ("mechanics", "softening"):
        if section == "mechanics" and pours:
            continue
        if section in scene and not on:
            raise SceneError(f"[{section}] needs physics.mechanics = true (the packing moves); without it the run is "
                             "thermal only: drop the section or set physics.mechanics = true")
    for k, wall in enumerate(scene["walls"]):
        if "velocity" in wall and any(wall["velocity"]) and not on:
            raise SceneError(f"walls[{k}].velocity needs physics.mechanics = true (a wall moves only with mechanics)")
    if "gravity" in physics:
        physics["gravity"] = _numbers("physics.gravity", physics["gravity"], 3, _within(-1e3, 1e3, "m/s^2"))
    if not on and scene.get("mechanics", {}).get("quasi_static"):
        raise SceneError("mechanics.quasi_static = true needs physics.mechanics = true (the [mechanics] section "
                         "alone is the contact material a packing is poured with; the run's packing stays put)")
    if not on:
        for key in physics:
            if key != "mechanics":
                raise SceneError(f"physics.{key} needs physics.mechanics = true (without it nothing moves and "
                                 f"physics.{key} would be ignored)")
        return
    if "mechanics" not in scene:
        raise SceneError("physics.mechanics = true needs a [mechanics] section (the contact material: at least "
                         f"mechanics.young_modulus ({_describe(_SCHEMA['mechanics']['young_modulus'])}) and "
                         f"mechanics.poisson_ratio ({_describe(_SCHEMA['mechanics']['poisson_ratio'])}))")
    m = scene["mechanics"]
    if "restitution" in m and "damping" in m:
        raise SceneError("give mechanics.damping or mechanics.restitution, not both (restitution sets the damping)")
    # the Python API's rules on the values the scene gives (ranges, as the keys', and E_min <= E0)
    given = {}
    for key, field in MECHANICAL_FIELDS.items():
        section, name = key.split(".")
        if name in scene.get(section, {}):
            given[field] = scene[section][name]
    try:
        validate_mechanical_params(given, names={field: key for key, field in MECHANICAL_FIELDS.items()})
    except ValueError as err:
        raise SceneError(str(err)) from None


def check_distinct_centres(packing, centres):
    """Raise :class:`SceneError` if two particles have the same centre ``centres`` [n, 3] (m), naming both: for
    ``packing`` a validated ``[packing]`` table whose particles they are, a file's lines or the listed spheres' keys,
    for None (a packing built or read back from a run folder) their indices. The
    contact laws divide by the centre distance, so such a run crashed after the build or took a step of 0 s."""
    centres = np.asarray(centres, np.float64)
    _, first, inverse = np.unique(centres, axis=0, return_index=True, return_inverse=True)
    duplicates = np.flatnonzero(first[inverse.reshape(-1)] != np.arange(len(centres)))  # each after its first
    if duplicates.size == 0:
        return
    j = int(duplicates[0])
    i = int(first[inverse.reshape(-1)[j]])
    where, fix = f"particles {i} and {j} of the packing", ""
    kind = None if packing is None else packing["kind"]
    if kind == "file":
        from sintercond.beds.packing_files import particle_lines

        lines = particle_lines(packing["path"], packing["format"])
        where = f"packing.path: particles {i} and {j} (lines {int(lines[i])} and {int(lines[j])} of the file)"
        fix = "; remove the duplicated rows"
    elif kind == "spheres":
        where, fix = f"packing.centres[{i}] and packing.centres[{j}]", "; remove the duplicated centres"
    raise SceneError(f"{where} have the same centre {centres[i].tolist()} m ({duplicates.size} such "
                     f"duplicate(s) in all): two particles cannot sit in one place{fix}")


RADIUS_RANGE = (1e-8, 1.0)
RADIUS = _within(*RADIUS_RANGE, "m")
"""The radius range of a sphere of any packing kind (listed, lattice, bed, file)."""


def _check_packing(packing, conduction, sintering=False):
    from sintercond.laws import neck
    from sintercond.beds.packing import MAX_PARTICLES, MAX_ROLLED_PARTICLES, PackingError, check_bed
    from sintercond.beds.packing_files import LENGTH_UNITS, particle_lines

    if packing["kind"] == "file":
        packing["path"] = str(Path(packing["path"]).resolve())  # scene.json then finds it from anywhere
        centres, radii = file_packing(packing)  # read (once) and checked now: a bad file is named before anything is built
        check_distinct_centres(packing, centres)
        low, high = RADIUS_RANGE
        outside = np.flatnonzero(~((radii >= low) & (radii <= high)))
        if outside.size:
            k, unit = int(outside[0]), packing["length_unit"]
            others = [u for u in LENGTH_UNITS if u != unit]
            line = int(particle_lines(packing["path"], packing["format"])[k])
            raise SceneError(f"packing.path: particle {k} (line {line} of the file) has radius {float(radii[k]):g} m, "
                             f"its file value read in packing.length_unit = {unit!r}; radii must be {RADIUS[0]}: is "
                             f"the file in other units? set packing.length_unit to one of {others}")
        return
    if packing["kind"] == "spheres":
        centres, radii = packing["centres"], packing["radii"]
        rule = ("a list of 3 numbers in [-1, 1] m", lambda v: -1.0 <= v <= 1.0)
        if not centres or len(centres) > MAX_LISTED_SPHERES:
            raise SceneError(f"packing.centres must be {_describe(_PACKING['spheres']['centres'])}; got "
                             f"{len(centres)} points")
        packing["centres"] = [_numbers(f"packing.centres[{k}]", c, 3, rule) for k, c in enumerate(centres)]
        radius_rule = RADIUS
        if not isinstance(radii, list):
            radii = [radii] * len(centres)
        packing["radii"] = _numbers("packing.radii", radii, len(centres), radius_rule)
        check_distinct_centres(packing, packing["centres"])
        return
    if packing["kind"] == "poured":
        from sintercond.beds.packing import check_radius_distribution

        try:
            check_radius_distribution(packing["radius_mean"], packing["radius_std"], packing["truncation"])
        except PackingError as err:
            raise SceneError(f"packing: {err}") from None
        largest = packing["radius_mean"] + packing["truncation"] * packing["radius_std"]
        if not packing["lateral_size"] > 2 * largest:
            raise SceneError(f"packing.lateral_size must be > the largest diameter {2 * largest:g} m "
                             f"(2 (radius_mean + truncation radius_std)); got {packing['lateral_size']:g}")
        return
    if packing["kind"] == "powder_bed":
        packing["diameter_range"] = _numbers("packing.diameter_range", packing["diameter_range"], 2,
                                             _within(1e-8, 1.0, "m"))
        try:
            check_bed(packing["lateral_size"], packing["height"], packing["diameter_range"],
                      MAX_ROLLED_PARTICLES if packing["method"] == "roll" else MAX_PARTICLES,
                      names={k: f"packing.{k}" for k in ("lateral_size", "height", "diameter_range")})
        except PackingError as err:
            raise SceneError(str(err)) from None
        return
    packing["counts"] = _numbers("packing.counts", packing["counts"], 3, _within(1, 10_000), integer=True)
    n = math.prod(packing["counts"])
    if n > MAX_LATTICE_PARTICLES:
        raise SceneError(f"packing.counts {packing['counts']} make {n} particles; the limit is "
                         f"{MAX_LATTICE_PARTICLES} (product of the counts)")
    radius, spacing = packing["radius"], packing["spacing"]
    if sintering and radius == spacing / 2:
        return  # point contacts: the necks grow from them
    if not radius > spacing / 2:
        raise SceneError(f"packing.radius must be > packing.spacing/2 = {spacing / 2:g} m for the lattice to conduct "
                         f"(touching spheres have no neck); got {radius:g}")
    model = conduction.get("neck_model", CONDUCTANCE_LAWS[conduction["law"]].neck_model)
    try:
        neck.validate_neck_inputs(radius, radius, 2 * radius - spacing, model=model,
                                  names=("packing.radius", "packing.radius", "the overlap 2 packing.radius - "
                                         "packing.spacing"))
    except ValueError as err:
        raise SceneError(f"{err} ({model} neck of conduction.law {conduction['law']!r}; packing.radius must be in "
                         f"(spacing/2, {_largest_lattice_radius(model, spacing):g}] m)") from None


def _largest_lattice_radius(model, spacing):
    # equal spheres: h_max = 2r/3 (volume-conserving), h < 2r (intersection), any h (Coble, Hertz)
    return {"volume_conserving": 0.75 * spacing}.get(model, spacing)


def _check_sintering(scene):
    """``[sintering]``: its law's parameters, and the physics necks grow on; ``[preheating]``."""
    if "preheating" in scene:
        ramp = scene["preheating"]
        floor = "floor_temperature" in scene.get("boundary", {})
        if ramp["hold"] == "walls" and not (floor or any(w["mode"] == "held" for w in scene["walls"])):
            raise SceneError("[preheating] with preheating.hold = \"walls\" ramps the held walls: give a held "
                             "[[walls]] (or boundary.floor_temperature), or preheating.hold = \"all\"")
        if ramp["hold"] == "all" and (floor or any(w["mode"] != "insulated" for w in scene["walls"])):
            raise SceneError("preheating.hold = \"all\" holds every particle on the ramp from initial.temperature: "
                             "held or conducting walls (and boundary.floor_temperature) would be ignored; drop them "
                             "or use preheating.hold = \"walls\"")
        if scene["physics"]["mechanics"] and not scene.get("mechanics", {}).get("quasi_static"):
            raise SceneError("[preheating] with physics.mechanics = true needs mechanics.quasi_static = true (and "
                             "sintering.shrinkage = \"many_body\"): the inertial step at the elastic limit would take "
                             "hours for a preheat of seconds")
    if scene.get("mechanics", {}).get("quasi_static") and scene.get("sintering", {}).get(
            "shrinkage") != "many_body":
        raise SceneError("mechanics.quasi_static = true moves the particles by the many-body balance of the "
                         "sintering necks: it needs [sintering] with sintering.shrinkage = \"many_body\" (without "
                         "sintering nothing would move; drop mechanics.quasi_static)")
    if scene.get("mechanics", {}).get("quasi_static"):
        for k, wall in enumerate(scene["walls"]):
            if any(wall.get("velocity", [0.0])):
                raise SceneError(f"walls[{k}].velocity: a moving wall pushes by its contact forces, which need "
                                 "inertia: drop mechanics.quasi_static (quasi-static particles move by the necks' "
                                 "balance only)")
    if "sintering" not in scene:
        return
    s, conduction = scene["sintering"], scene["conduction"]
    _check_law_params("sintering.params", s.get("params", {}), KINETIC_LAWS[s["law"]], _SINTERING_PARAMS,
                      "kinetic law")
    if "neck_rtol" in s and s.get("every", 1) == 1:
        raise SceneError("sintering.neck_rtol lets the necks set the interval between updates up to sintering.every "
                         "steps, which is 1 here: give sintering.every > 1 (the longest interval, e.g. 500)")
    if "start_necks" in s and not scene["physics"]["mechanics"]:
        raise SceneError("sintering.start_necks chooses how the necks of a run with physics.mechanics start; "
                         "without the mechanics they start from the packing's overlaps: drop it")
    model = conduction.get("neck_model", CONDUCTANCE_LAWS[conduction["law"]].neck_model)
    if model != "volume_conserving":
        raise SceneError(f"[sintering] grows Rojek's volume-conserving necks: conduction.neck_model must be "
                         f"\"volume_conserving\" (conduction.law {conduction['law']!r} takes {model!r})")


def _check_law_params(section, params, law, keys, kind):
    """A law's parameters in ``[section]``: each a key of ``law``, in the range of its :class:`Key` in ``keys``
    (normalised in place); an unknown one is named with the law's keys."""
    for key, value in params.items():
        if key not in law.default_params:
            raise SceneError(f"unknown key {section}.{key}{_suggest(key, list(law.default_params))}; "
                             f"{kind} {law.name!r} takes {sorted(law.default_params)}")
        params[key] = _value(f"{section}.{key}", value, keys[key])


def _check_property_table(material, key, symbol, low, high):
    """``material.<key>``: at least 2 ``[T, value]`` pairs, T strictly increasing, values in ``[low, high]``."""
    table = material.get(key)
    if table is None:
        return
    rule = _SCHEMA["material"][key].rule[0]
    if len(table) < 2:
        raise SceneError(f"material.{key} must be {rule}; got {table!r}")
    rows = [_numbers(f"material.{key}[{k}]", row, 2, (f"[T, {symbol}] in (0, 1e5]", lambda v: 0 < v <= 1e5))
            for k, row in enumerate(table)]
    temperatures, values = zip(*rows)
    if any(b <= a for a, b in zip(temperatures, temperatures[1:])) or not all(low <= v <= high for v in values):
        raise SceneError(f"material.{key} must be {rule}; got {table!r}")
    material[key] = [list(r) for r in rows]


def _check_coupling(scene):
    """``conduction.coupling = "sphere"``: only what the coupled transient supports (static packing, necks that
    stay or grow independently, no conducting walls, held walls on one axis: their spheres' mirror plane)."""
    if scene["conduction"].get("coupling", "none") != "sphere":
        return
    walls = scene.get("walls", [])
    refused = {"physics.mechanics = true": scene["physics"].get("mechanics", False),
               "sintering.shrinkage = \"many_body\"": scene.get("sintering", {}).get("shrinkage") == "many_body",
               "a conducting wall": any(w["mode"] == "conducting" for w in walls),
               "run.integrator = \"implicit\" (the coupled necks are stepped explicitly)":
                   scene["run"].get("integrator") == "implicit"}
    for what, present in refused.items():
        if present:
            raise SceneError(f"conduction.coupling = \"sphere\" is not supported with {what} yet; use "
                             "conduction.coupling = \"none\"")
    axes = {w["axis"] for w in walls if w["mode"] == "held"} | ({2} if "floor_temperature" in scene.get(
        "boundary", {}) else set())
    if len(axes) > 1:
        raise SceneError(f"conduction.coupling = \"sphere\" mirrors held spheres across the plane normal to their "
                         f"walls' axis: held walls on one axis only; got axes {sorted(axes)}")


def _check_details(scene):
    _check_property_table(scene["material"], "conductivity_table", "kappa", 1e-6, 1e4)
    _check_property_table(scene["material"], "specific_heat_table", "c", 1.0, 1e5)
    _check_coupling(scene)
    conduction = scene["conduction"]
    _check_law_params("conduction.params", conduction.get("params", {}), CONDUCTANCE_LAWS[conduction["law"]],
                      _LAW_PARAMS, "law")
    _check_sintering(scene)
    _check_packing(scene["packing"], conduction, "sintering" in scene)
    if scene["initial"]["from_file"]:
        if scene["packing"]["kind"] != "file":
            raise SceneError(f"initial.from_file = true takes the temperatures of a packing file (packing.kind = "
                             f"\"file\"); this packing is {scene['packing']['kind']!r}")
        temperatures = file_temperatures(scene["packing"])
        if len(temperatures) != len(file_packing(scene["packing"])[1]):
            raise SceneError("initial.from_file: the file's temperature column and its particles differ in length")
        low, high = TEMPERATURE[0], TEMPERATURE[1]
        outside = [float(t) for t in temperatures if not high(float(t))]
        if outside:
            raise SceneError(f"initial.from_file: the file's temperatures must be {low}; got {outside[0]:g} K")
    if "beam" in scene:
        beam = scene["beam"]
        needed = "attenuation" if beam["kind"] == "laser" else "max_depth"
        if needed not in beam:
            raise SceneError(f"beam.{needed} is required for a {beam['kind']} beam "
                             f"({_describe(_SCHEMA['beam'][needed])})")
        if ("intensity" in beam) == ("power" in beam):
            raise SceneError("give beam.intensity (W/m^2) or beam.power (W), one of them")
        if "power" in beam:
            beam["intensity"] = beam.pop("power") / (math.pi * beam["spot_radius"] ** 2)
            low = _SCHEMA["beam"]["intensity"].rule[0]
            if not _SCHEMA["beam"]["intensity"].rule[1](beam["intensity"]):
                raise SceneError(f"beam.power over the spot (pi beam.spot_radius^2) gives an intensity of "
                                 f"{beam['intensity']:.4g} W/m^2; it must be {low}")
        path = beam["path"]
        if not path or any(not isinstance(p, list) for p in path):
            raise SceneError(f"beam.path must be a non-empty list of [x, y] points (m); got {path!r}")
        (x0, x1), (y0, y1) = _lateral_extent(scene["packing"])
        reach = beam["spot_radius"]
        rule = (f"within the packing's lateral extent [{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m widened by "
                f"beam.spot_radius", lambda v: True)
        beam["path"] = [_numbers(f"beam.path[{k}]", p, 2, rule) for k, p in enumerate(path)]
        for k, (x, y) in enumerate(beam["path"]):
            if not (x0 - reach <= x <= x1 + reach and y0 - reach <= y <= y1 + reach):
                raise SceneError(f"beam.path[{k}] = {[x, y]} must be {rule[0]} (beam coordinates are absolute)")
        on = beam.get("segments_on")
        if on is not None and (not isinstance(on, list) or len(on) != len(path) - 1
                               or any(not isinstance(v, bool) for v in on)):
            raise SceneError(f"beam.segments_on must be a list of {len(path) - 1} booleans (true or false), one per "
                             f"segment of beam.path; got {on!r}")
    _check_melting_point(scene)
    convection = scene.get("convection", {})
    if ("reynolds" in convection) != ("prandtl" in convection):
        raise SceneError("convection.reynolds and convection.prandtl go together (Whitaker's correlation)")
    if "reynolds" in convection and "nusselt" in convection:
        raise SceneError("give convection.nusselt or convection.reynolds and prandtl, not both")
    run = scene["run"]
    run["dt"] = run["dt"] if run["dt"] == "auto" else float(run["dt"])
    if "checkpoint_every" in run and "output_every" not in run:
        raise SceneError(f"run.checkpoint_every ({run['checkpoint_every']}) needs run.output_every (it is a multiple "
                         f"of it); without both, the run checkpoints every {DEFAULT_CHECKPOINT_OUTPUTS} outputs")
    if "output_every" in run and run.get("checkpoint_every", run["output_every"]) % run["output_every"]:
        raise SceneError(f"run.checkpoint_every ({run['checkpoint_every']}) must be a multiple of "
                         f"run.output_every ({run['output_every']})")
    formats = run["formats"]
    allowed = ("lammps", "vtp")
    if (not formats or any(not isinstance(f, str) or f not in allowed for f in formats)
            or len(set(formats)) != len(formats)):
        raise SceneError(f"run.formats must be a non-empty list of distinct names from {list(allowed)}; "
                         f"got {formats!r}")
    run["formats"] = list(formats)
    scene_integrator(scene)  # implicit with inertial mechanics is refused here, naming run.integrator


def held_temperatures(scene) -> dict:
    """``{key: temperature (K)}`` of what a scene holds particles at: held walls, the floor, a preheating ramp's end."""
    held = {f"walls[{k}].temperature": w["temperature"] for k, w in enumerate(scene["walls"]) if w["mode"] == "held"}
    if "floor_temperature" in scene.get("boundary", {}):
        held["boundary.floor_temperature"] = scene["boundary"]["floor_temperature"]
    if "preheating" in scene:
        held["preheating.end_temperature"] = scene["preheating"]["end_temperature"]
    return held


def _check_melting_point(scene):
    """``material.melting_point`` above the start: the initial temperatures (a run starting molten stopped after
    its first output chunk), and with ``on_melting = "stop"`` the temperatures particles are held at."""
    melting = scene["material"].get("melting_point")
    if melting is None:
        return
    start = {"initial.temperature": scene["initial"]["temperature"]}
    if scene["initial"]["from_file"]:
        start = {"initial.from_file (the file's hottest particle)": float(np.max(file_temperatures(scene["packing"])))}
    if scene["material"]["on_melting"] == "stop":
        start.update(held_temperatures(scene))
    for key, value in start.items():
        if value > melting:
            raise SceneError(f"material.melting_point = {melting:g} K is below {key} = {value:g} K: the run would "
                             f"stop at its first output (the model has no melting); {key} must be below the melting "
                             "point (check both: a solidus in K, not in degrees Celsius?)")


def _builtin_dir():
    return importlib.resources.files("sintercond.data").joinpath("scenes")


def builtin_scenes() -> dict:
    """The example scenes shipped with the package: ``{name: one-line description}`` (their first comment line)."""
    scenes = {}
    for entry in sorted(_builtin_dir().iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".toml"):
            first = entry.read_text(encoding="utf-8").splitlines()[0]
            scenes[entry.name.removesuffix(".toml")] = first.lstrip("# ").strip()
    return scenes


def load_scene(path=None, duration=None) -> dict:
    """Read and validate a scene file or a built-in scene by name; ``None`` loads the built-in default scene.

    ``path`` is a TOML file, or the name of a built-in example scene
    (:func:`builtin_scenes`, e.g. ``"quintana2020_5_1"``) when no such file
    exists. ``duration`` (s) replaces ``run.duration`` before validation
    (a shorter run of the same scene).
    """
    if path is None:
        data = importlib.resources.files("sintercond.data").joinpath("default_scene.toml").read_bytes()
        source = "default scene"
    elif not Path(path).is_file() and str(path) in builtin_scenes():
        data = _builtin_dir().joinpath(f"{path}.toml").read_bytes()
        source = f"built-in scene {str(path)!r}"
    else:
        path = Path(path)
        if not path.is_file():
            raise SceneError(f"scene file {str(path)!r} does not exist (built-in scenes: "
                             f"{', '.join(builtin_scenes())}; `sintercond scenes` lists them)")
        data, source = path.read_bytes(), str(path)
    if b"\x00" in data:
        raise SceneError(f"{source} is a binary file, not a TOML scene (UTF-8 text)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise SceneError(f"{source} is not UTF-8 text (byte {err.start}: {data[err.start:err.start + 1]!r}; "
                         "Latin-1?): save the scene as UTF-8") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"{source} is not valid TOML: {err}") from None
    if duration is not None:
        if isinstance(raw.get("run"), dict):
            raw["run"]["duration"] = duration
    packing = raw.get("packing")
    if (isinstance(packing, dict) and packing.get("kind") == "file" and isinstance(packing.get("path"), str)
            and isinstance(path, Path) and not Path(packing["path"]).is_absolute()):
        packing["path"] = str((path.parent / packing["path"]).resolve())  # relative to the scene file
    return validate_scene(raw)

