"""A corpus of broken scenes and bad API calls: each is refused at validation with the key and the range named.

Scenes go through the command line (``sintercond.cli.main``) as TOML files:
exit code 2, one line on stderr naming the key and the allowed range, no
traceback, nothing built and nothing compiled. API calls
raise ``ValueError`` (or a subclass) naming the argument. "Nothing compiled" is checked, not timed: JAX's
caches are cleared before each refusal and its compile events counted (the shared time of a 2-core CI machine
made a wall-clock budget fail on code that had not changed).
"""

import contextlib
import copy
import json
import math
import re

import jax
import jax.monitoring
import numpy as np
import pytest

from sintercond import cli, scene

_COMPILE_EVENTS = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, _seconds, **_: _COMPILE_EVENTS.append(event) if event.startswith("/jax/core/compile/") else None)


@contextlib.contextmanager
def nothing_compiled(label):
    """Fail unless the block traces and compiles nothing in JAX; its caches are cleared first, so that work done
    before a refusal is seen whatever ran before in this process."""
    jax.clear_caches()
    before = len(_COMPILE_EVENTS)
    yield
    compiled = _COMPILE_EVENTS[before:]
    assert not compiled, f"{label}: JAX traced or compiled before the refusal ({sorted(set(compiled))})"

BASE = {
    "packing": {"kind": "simple_cubic", "counts": [4, 2, 2], "spacing": 1e-4, "radius": 0.52e-4},
    "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.6},
    "conduction": {"law": "rojek"},
    "initial": {"temperature": 300.0},
    "boundary": {"floor_temperature": 300.0},
    "beam": {"intensity": 2e8, "attenuation": 2e4, "spot_radius": 1e-4, "absorptance": 0.7, "speed": 0.05,
             "path": [[0.0, 1e-4], [3e-4, 1e-4]]},
    "convection": {"environment_temperature": 300.0, "environment_conductivity": 0.026},
    "radiation": {"environment_temperature": 300.0, "emissivity": 0.4},
    "walls": [{"axis": 0, "side": "max", "mode": "conducting", "temperature": 350.0}],
    "run": {"duration": 1e-3, "dt": "auto", "output_every": 5, "checkpoint_every": 10, "formats": ["vtp"]},
}
MECHANICS = {"young_modulus": 1e6, "poisson_ratio": 0.3}
BED = {"kind": "powder_bed", "lateral_size": 400e-6, "height": 300e-6, "diameter_range": [45e-6, 105e-6],
       "seed": 0, "sinter_swelling": 0.02}


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v == math.inf else "-inf" if v == -math.inf else repr(v))
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    return json.dumps(v)


def to_toml(raw):
    """TOML text of a scene dict (sections, [[walls]], inline tables for nested ones)."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in raw.items()
             if not isinstance(v, dict) and not (isinstance(v, list) and v and all(isinstance(t, dict) for t in v))]
    for section, table in raw.items():
        if isinstance(table, list) and all(isinstance(t, dict) for t in table) and table:
            for t in table:
                lines.append(f"[[{section}]]")
                lines += [f"{k} = {_toml_value(v)}" for k, v in t.items()]
        elif isinstance(table, dict):
            lines.append(f"[{section}]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def _set(path, value):
    def mutate(s):
        *parents, last = path.split(".")
        t = s
        for p in parents:
            t = t[int(p)] if isinstance(t, list) else t.setdefault(p, {})
        t[last] = value
    return mutate


def _drop(path):
    def mutate(s):
        *parents, last = path.split(".")
        t = s
        for p in parents:
            t = t[int(p)] if isinstance(t, list) else t[p]
        del t[last]
    return mutate


def _range_cases():
    """Every bounded number of the schema: wrong type, NaN, inf, below and above its range."""
    cases = []
    sections = {name: keys for name, keys in scene._SCHEMA.items() if name != "conduction"}
    sections["packing"] = scene._PACKING["simple_cubic"]
    sections["walls.0"] = scene._WALL
    for section, keys in sections.items():
        for key, spec in keys.items():
            if spec.kind not in (float, int) or spec.rule is None or not spec.rule[0].startswith("in "):
                continue
            bounds = re.match(r"in ([\[(])([^,]+), ([^\]]+)\]", spec.rule[0])
            low, high = float(bounds.group(2)), float(bounds.group(3))
            name = f"{section.replace('.0', '[0]')}.{key}"
            rng = re.escape(bounds.group(0))
            values = ["text", math.nan, math.inf, low - max(abs(low), 1.0), high * 10 + 1]
            if spec.kind is int:
                values = ["text", 1.5, low - 1, int(high * 10 + 1), True]
            for value in values:
                if isinstance(value, float) and math.isnan(value) and spec.kind is int:
                    continue
                cases.append((f"{name}={value!r}", _set(f"{section}.{key}", value), name, rng))
    return cases


STRUCTURAL = [
    ("unknown section", lambda s: s.update(magnetism={}), r"unknown section \[magnetism\]", "allowed sections"),
    ("misspelled section", lambda s: s.update(materal={}), r"unknown section \[materal\]", "did you mean 'material'"),
    ("unknown key", _set("material.colour", "red"), r"unknown key material\.colour", "allowed keys"),
    ("misspelled key", _set("material.conductivty", 1.0), r"material\.conductivty", "did you mean 'conductivity'"),
    ("misspelled run key", _set("run.durations", 1.0), r"run\.durations", "did you mean 'duration'"),
    ("misspelled wall key", _set("walls.0.temprature", 1.0), r"walls\[0\]\.temprature", "allowed keys"),
    ("missing section", lambda s: s.pop("initial"), r"missing section \[initial\]", "required"),
    ("missing run", lambda s: s.pop("run"), r"missing section \[run\]", "required"),
    ("missing density", _drop("material.density"), r"missing key material\.density", r"in \[1, 100000\]"),
    ("missing duration", _drop("run.duration"), r"missing key run\.duration", r"in \(0, 1e\+06\]"),
    ("missing spot", _drop("beam.spot_radius"), r"missing key beam\.spot_radius", r"in \[1e-09, 1\]"),
    ("missing wall temperature", _drop("walls.0.temperature"), r"walls\[0\]\.temperature is required",
     r"in \[1, 10000\]"),
    ("section not a table", lambda s: s.update(material=3), r"\[material\] must be a table", "density"),
    ("walls not a list", lambda s: s.update(walls={"axis": 0}), r"walls must be an array of tables", "axis"),
    ("wall not a table", lambda s: s.update(walls=[1]), r"\[walls\[0\]\] must be a table", "axis"),
    ("packing kind", _set("packing.kind", "fcc"), r"packing\.kind must be one of", "powder_bed"),
    ("counts length", _set("packing.counts", [4, 2]), r"packing\.counts must be a list of 3 integers", r"\[1, 10000\]"),
    ("counts float", _set("packing.counts", [4, 2, 2.5]), r"packing\.counts", r"\[1, 10000\]"),
    ("counts zero", _set("packing.counts", [4, 0, 2]), r"packing\.counts", r"\[1, 10000\]"),
    ("counts huge", _set("packing.counts", [2000, 2000, 2]), r"packing\.counts", "limit is 2000000"),
    ("touching lattice does not conduct", _set("packing.radius", 0.5e-4), r"packing\.radius must be > packing\.spacing/2",
     "spacing/2"),
    ("lattice overlap beyond the neck", _set("packing.radius", 0.8e-4), r"packing\.radius", r"\(spacing/2, 7\.5e-05\]"),
    ("lattice overlap beyond the neck of another law", lambda s: (_set("packing.radius", 0.8e-4)(s),
     _set("conduction.law", "batchelor_obrien")(s)), r"packing\.radius", r"\(spacing/2, 7\.5e-05\]"),
    ("law", _set("conduction.law", "magic"), r"conduction\.law must be one of", "rojek"),
    ("neck model", _set("conduction.neck_model", "spline"), r"conduction\.neck_model must be one of", "coble"),
    ("params not a table", _set("conduction.params", 3), r"conduction\.params must be a table", "table"),
    ("misspelled param", _set("conduction.params", {"slop": 1.0}), r"conduction\.params\.slop",
     "did you mean 'slope'"),
    ("param of another law", _set("conduction.params", {"thickness": 1.0}), r"conduction\.params\.thickness",
     "takes"),
    ("negative slope", _set("conduction.params", {"slope": -1.0}), r"conduction\.params\.slope", r"\(0, 100\]"),
    ("zero slope", _set("conduction.params", {"slope": 0.0}), r"conduction\.params\.slope", r"\(0, 100\]"),
    ("huge slope", _set("conduction.params", {"slope": 1e300}), r"conduction\.params\.slope", r"\(0, 100\]"),
    ("NaN slope", _set("conduction.params", {"slope": math.nan}), r"conduction\.params\.slope", r"\(0, 100\]"),
    ("negative contact resistance", _set("conduction.params", {"contact_resistance": -1.0}),
     r"conduction\.params\.contact_resistance", r"\[0, 1e\+12\]"),
    ("string param", _set("conduction.params", {"slope": "1.0"}), r"conduction\.params\.slope", r"\(0, 100\]"),
    ("feng thickness", lambda s: (_set("conduction.law", "feng")(s), _set("conduction.params", {"thickness": -1.0})(s)),
     r"conduction\.params\.thickness", r"\(0, 1000\]"),
    ("subnormal conductivity", _set("material.conductivity", 5e-324), r"material\.conductivity", r"\[1e-06, 10000\]"),
    ("dt string", _set("run.dt", "fast"), r"run\.dt", r'"auto" or a number in \(0, 1e3\]'),
    ("dt negative", _set("run.dt", -1.0), r"run\.dt", r'"auto" or a number in \(0, 1e3\]'),
    ("dt bool", _set("run.dt", True), r"run\.dt", r'"auto" or a number'),
    ("dt list", _set("run.dt", [1.0]), r"run\.dt", r'"auto" or a number'),
    ("checkpoint multiple", _set("run.checkpoint_every", 7), r"run\.checkpoint_every \(7\) must be a multiple",
     r"run\.output_every"),
    ("formats nested", _set("run.formats", [[1]]), r"run\.formats", r"\['lammps', 'vtp'\]"),
    ("formats empty", _set("run.formats", []), r"run\.formats must be a non-empty list", r"\['lammps', 'vtp'\]"),
    ("formats unknown", _set("run.formats", ["xyz"]), r"run\.formats", r"\['lammps', 'vtp'\]"),
    ("formats repeated", _set("run.formats", ["vtp", "vtp"]), r"run\.formats", "distinct"),
    ("formats string", _set("run.formats", "vtp"), r"run\.formats must be a non-empty list", "vtp"),
    ("override not bool", _set("run.override_limits", 1), r"run\.override_limits", "true or false"),
    ("too many steps", _set("run.duration", 1e5), r"run\.duration", "limit is 1e\\+07"),
    ("too many frames", lambda s: (_set("run.duration", 10.0)(s), _set("run.output_every", 1)(s),
                                   _set("run.checkpoint_every", 1)(s)), r"run\.output_every", "limit is 10000"),
    ("too many files (issue: 2e5 files)", lambda s: (_set("run.duration", 1e3)(s), _set("run.dt", 1e-3)(s)),
     r"run\.output_every", "limit is 10000"),
    ("beam kind", _set("beam.kind", "electron"), r"beam\.kind must be one of", "laser"),
    ("nozzle without depth", _set("beam.kind", "nozzle"), r"beam\.max_depth is required", r"\[1e-09, 1\]"),
    ("laser without attenuation", _drop("beam.attenuation"), r"beam\.attenuation is required", r"\[0, 1e\+09\]"),
    ("path empty", _set("beam.path", []), r"beam\.path must be a non-empty list", r"\[x, y\]"),
    ("path point short", _set("beam.path", [[0.0]]), r"beam\.path\[0\]", "lateral extent"),
    ("path point text", _set("beam.path", [["a", 0.0]]), r"beam\.path\[0\]", "lateral extent"),
    ("path NaN", _set("beam.path", [[math.nan, 0.0]]), r"beam\.path\[0\]", "lateral extent"),
    ("path outside the packing (relative coordinates?)", _set("beam.path", [[0.0, 0.0], [0.5, 0.0]]),
     r"beam\.path\[1\]", r"\[0, 0\.000404\]"),
    ("path not a list of lists", _set("beam.path", [1.0, 2.0]), r"beam\.path must be a non-empty list", r"\[x, y\]"),
    ("reynolds alone", _set("convection.reynolds", 10.0), r"convection\.reynolds and convection\.prandtl go together",
     "prandtl"),
    ("nusselt and reynolds", lambda s: s["convection"].update(reynolds=10.0, prandtl=0.7, nusselt=2.0),
     r"convection\.nusselt", "not both"),
    ("wall axis", _set("walls.0.axis", 3), r"walls\[0\]\.axis must be one of 0, 1, 2", "0, 1, 2"),
    ("wall side", _set("walls.0.side", "top"), r"walls\[0\]\.side", '"min" or "max"|one of'),
    ("wall mode", _set("walls.0.mode", "hot"), r"walls\[0\]\.mode", "held"),
    ("bed: tiny height", lambda s: s.update(packing={**BED, "height": 1e-6}), r"packing\.height must be >=",
     "largest diameter"),
    ("bed: too many particles", lambda s: s.update(packing={**BED, "lateral_size": 1e-1}), r"packing\.lateral_size",
     "limit is 1000000"),
    ("bed: too many particles to relax", lambda s: s.update(packing={**BED, "lateral_size": 1e-2, "method": "relax"}),
     r"packing\.lateral_size", "limit is 20000"),
    ("bed: range reversed", lambda s: s.update(packing={**BED, "diameter_range": [105e-6, 45e-6]}),
     r"packing\.diameter_range", "low <= high"),
    ("bed: range wider than the box", lambda s: s.update(packing={**BED, "diameter_range": [45e-6, 500e-6]}),
     r"packing\.diameter_range", "high < packing.lateral_size"),
    ("bed: range one number", lambda s: s.update(packing={**BED, "diameter_range": [45e-6]}),
     r"packing\.diameter_range must be a list of 2", r"\[1e-08, 1\]"),
    ("bed: range text", lambda s: s.update(packing={**BED, "diameter_range": "45-105 um"}),
     r"packing\.diameter_range", r"\[1e-08, 1\]"),
    ("bed: negative seed", lambda s: s.update(packing={**BED, "seed": -1}), r"packing\.seed", r"\[0, "),
    ("bed: swelling", lambda s: s.update(packing={**BED, "sinter_swelling": 0.5}), r"packing\.sinter_swelling",
     r"\[0, 0\.05\]"),
    ("bed: lattice key", lambda s: s.update(packing={**BED, "spacing": 1e-4}), r"packing\.spacing", "allowed keys"),
    ("bed: huge", lambda s: s.update(packing={**BED, "lateral_size": 1.0, "height": 1.0}), r"packing\.lateral_size",
     "limit is 1000000"),
    ("bed: method", lambda s: s.update(packing={**BED, "method": "shake"}), r"packing\.method must be one of",
     '"relax"'),
    ("mechanics without its material", _set("physics.mechanics", True),
     r"physics\.mechanics = true needs a \[mechanics\] section", r"\[1, 1e\+13\] Pa"),
    ("mechanics not a bool", _set("physics.mechanics", "yes"), r"physics\.mechanics", "true or false"),
    ("material without mechanics", lambda s: s.update(mechanics=dict(MECHANICS)),
     r"\[mechanics\] needs physics\.mechanics = true", "thermal only"),
    ("softening without mechanics", lambda s: s.update(softening={"onset_temperature": 400.0}),
     r"\[softening\] needs physics\.mechanics = true", "thermal only"),
    ("damping and restitution", lambda s: s.update(physics={"mechanics": True},
                                                    mechanics={**MECHANICS, "damping": 1.0, "restitution": 0.5}),
     r"mechanics\.damping or mechanics\.restitution", "not both"),
    ("missing modulus", lambda s: s.update(physics={"mechanics": True}, mechanics={"poisson_ratio": 0.3}),
     r"missing key mechanics\.young_modulus", r"\[1, 1e\+13\] Pa"),
    ("misspelled mechanics key", lambda s: s.update(physics={"mechanics": True},
                                                     mechanics={**MECHANICS, "frition": 0.3}),
     r"mechanics\.frition", "did you mean 'friction'"),
    ("gravity two numbers", _set("physics.gravity", [0.0, -9.81]), r"physics\.gravity must be a list of 3",
     r"\[-1000, 1000\] m/s\^2"),
    ("gravity huge", _set("physics.gravity", [0.0, 0.0, -1e4]), r"physics\.gravity", r"\[-1000, 1000\]"),
    ("gravity without mechanics", _set("physics.gravity", [0.0, 0.0, -9.81]),
     r"physics\.gravity needs physics\.mechanics = true", "ignored"),
    ("shear convention", _set("physics.shear", "voigt"), r"physics\.shear must be one of", '"mindlin"'),
    ("slip direction", _set("physics.slip_direction", "force"), r"physics\.slip_direction must be one of", '"trial"'),
    ("wall velocity without mechanics", _set("walls.0.velocity", [0.0, 0.0, 1e-3]),
     r"walls\[0\]\.velocity needs physics\.mechanics", "mechanics = true"),
    ("wall velocity text", _set("walls.0.velocity", "up"), r"walls\[0\]\.velocity must be a list of 3",
     r"\[-1000, 1000\] m/s"),
    ("spheres: no centres", lambda s: s.update(packing={"kind": "spheres", "centres": [], "radii": 1e-4}),
     r"packing\.centres must be", "at most 10000"),
    ("spheres: centre short", lambda s: s.update(packing={"kind": "spheres", "centres": [[0.0, 0.0]], "radii": 1e-4}),
     r"packing\.centres\[0\] must be a list of 3 numbers", r"\[-1, 1\] m"),
    ("spheres: radii count", lambda s: s.update(packing={"kind": "spheres", "centres": [[0.0, 0.0, 1e-4]] * 2,
                                                         "radii": [1e-4]}),
     r"packing\.radii must be a list of 2 numbers", r"\[1e-08, 1\] m"),
    ("spheres: radius negative", lambda s: s.update(packing={"kind": "spheres", "centres": [[0.0, 0.0, 1e-4]],
                                                             "radii": -1e-4}),
     r"packing\.radii", r"\[1e-08, 1\] m"),
]

SCENES = [(name, mutate, key, rng) for name, mutate, key, rng in _range_cases()] + STRUCTURAL


def _cli_error(tmp_path, text, capsys, name="scene.toml", data=None):
    path = tmp_path / name
    if data is None:
        path.write_text(text)
    else:
        path.write_bytes(data)
    with nothing_compiled(name), pytest.raises(SystemExit) as exc:
        cli.main(["run", str(path), "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "Traceback" not in err and err.startswith("sintercond: error: ")
    assert not (tmp_path / "out").exists()  # refused before anything was written or built
    return err


def test_the_corpus_is_large_enough():
    assert len(SCENES) + len(FILES) >= 100 and len(API_CALLS) >= 100


@pytest.mark.parametrize("name,mutate,key,rng", SCENES, ids=[c[0] for c in SCENES])
def test_broken_scene_is_refused_naming_key_and_range(tmp_path, capsys, name, mutate, key, rng):
    raw = copy.deepcopy(BASE)
    mutate(raw)
    err = _cli_error(tmp_path, to_toml(raw), capsys)
    assert re.search(key if "\\" in key else re.escape(key), err), err
    assert re.search(rng, err), err


FILES = [
    ("binary", None, b"\x00\x01\x02\x89PNG\r\n", "binary file"),
    ("latin-1", None, "[material]\ndensity = 4430.0 # kg/m\xb3\n".encode("latin-1"), "not UTF-8 text"),
    ("syntax error", "[material\ndensity = 1\n", None, "not valid TOML"),
    ("unterminated string", '[conduction]\nlaw = "rojek\n', None, "not valid TOML"),
    ("duplicate key", "[initial]\ntemperature = 300.0\ntemperature = 310.0\n", None, "not valid TOML"),
    ("empty file", "", None, r"missing section"),
    ("only comments", "# a scene\n", None, r"missing section"),
    ("array at top", "packing = [1, 2]\n", None, r"missing section"),
]


@pytest.mark.parametrize("name,text,data,message", FILES, ids=[f[0] for f in FILES])
def test_unreadable_scene_files(tmp_path, capsys, name, text, data, message):
    err = _cli_error(tmp_path, text, capsys, data=data)
    assert re.search(message, err), err


def test_valid_base_scene_passes_validation():
    scene.validate_scene(copy.deepcopy(BASE))
    scene.load_scene(None)


def test_scene_reference_is_generated_from_the_schema():
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "scenes.md").read_text()
    assert doc == scene.scene_reference() + "\n"
    for keys in (*scene._SCHEMA.values(), *scene._PACKING.values(), scene._WALL, scene._LAW_PARAMS):
        for key in keys:
            assert f"| `{key}` |" in doc


# ------------------------------------------------------------------- API calls

def _api_cases():
    import sintercond as sc
    from fitting import core
    from sintercond.beds import packing

    cases = []
    laws = [("rojek_pair_conductance", sc.rojek_pair_conductance, "kappa_i"),
            ("argento_bouvard_pair_conductance", sc.argento_bouvard_pair_conductance, "kappa_i"),
            ("batchelor_obrien_pair_conductance", sc.batchelor_obrien_pair_conductance, "kappa_i"),
            ("conductivity_pair_conductance", sc.conductivity_pair_conductance, "kappa_i"),
            ("feng_pair_conductance", sc.feng_pair_conductance, "kappa_i"),
            ("fitted_pair_conductance", sc.fitted_pair_conductance, "kappa_i")]
    for name, fn, arg in laws:
        for bad in (-394.0, 0.0, math.nan, math.inf, 5e-324, np.array([394.0, -1.0])):
            cases.append((f"{name}(kappa={bad!r})", fn, (1e-3, 3e-3, 0.06e-3, bad), {}, arg))
    for bad in (-1.064, 0.0, math.nan, math.inf):
        cases.append((f"rojek slope={bad}", sc.rojek_pair_conductance, (1e-3, 3e-3, 0.06e-3, 394.0), {"slope": bad},
                      "slope"))
    for bad in (-0.5, 0.0):
        cases.append((f"rojek contact_conductance={bad}", sc.rojek_pair_conductance, (1e-3, 3e-3, 0.06e-3, 394.0),
                      {"contact_conductance": bad}, "contact_conductance"))
    for bad in (-1.0, 0.0, math.nan):
        cases.append((f"feng thickness={bad}", sc.feng_pair_conductance, (1e-3, 3e-3, 0.06e-3, 394.0),
                      {"thickness": bad}, "thickness"))
    cases += [
        ("unknown law", sc.pair_conductance, ("magic", 1e-3, 1e-3, 1e-5, 1.0), {}, "law must be one of"),
        ("unknown neck", sc.pair_conductance, ("rojek", 1e-3, 1e-3, 1e-5, 1.0), {"neck_model": "x"}, "neck_model"),
        ("unknown param", sc.pair_conductance, ("rojek", 1e-3, 1e-3, 1e-5, 1.0), {"params": {"slop": 1.0}}, "slop"),
        ("kappa_j negative", sc.pair_conductance, ("conductivity", 1e-3, 1e-3, 1e-5, 1.0, -2.0), {}, "kappa_j"),
        ("series resistance via params", sc.pair_conductance, ("rojek", 1e-3, 1e-3, 1e-5, 1.0),
         {"params": {"contact_resistance": -1.0}}, "contact_resistance"),
    ]
    for args, field in [((-1.0, 1.0, 0.1), "r_i"), ((1.0, math.nan, 0.1), "r_j"), ((1.0, 1.0, math.inf), "h"),
                        ((1.0, 1.0, 0.7), "max_overlap"), ((0.0, 1.0, 0.1), "r_i"), ((1.0, -3.0, 0.1), "r_j")]:
        cases.append((f"validate_neck_inputs{args}", sc.validate_neck_inputs, args, {}, field))
    for args, kw, field in [((1e-3, 3e-3, 0.06e-3, -1.0), {}, "kappa_i"),
                            ((1e-3, 3e-3, 0.06e-3, 1.0), {"params": {"slope": -1.0}}, "slope"),
                            ((-1e-3, 3e-3, 0.06e-3, 1.0), {}, "r_i"),
                            ((1e-3, 3e-3, 5e-3, 1.0), {}, "max_overlap")]:
        cases.append((f"validate_pair_conductance_inputs{args}{kw}", sc.validate_pair_conductance_inputs,
                      ("rojek", *args), kw, field))
    bed_cases = [((math.nan, 1e-4, (2e-5, 6e-5)), "lateral_size"), ((3e-4, -1e-4, (2e-5, 6e-5)), "height"),
                 ((3e-4, 1e-6, (2e-5, 6e-5)), "height"), ((3e-4, 1e-4, (6e-5, 2e-5)), "diameter_range"),
                 ((3e-4, 1e-4, (2e-5, 4e-4)), "diameter_range"), ((3e-4, 1e-4, (0.0, 6e-5)), "diameter_range"),
                 ((3e-4, 1e-4, "20-60 um"), "diameter_range"), ((1e-2, 1e-2, (2e-5, 6e-5)), "limit is 1000000"),
                 ((3e-4, math.inf, (2e-5, 6e-5)), "height"), ((3e-4, 1e-4, (2e-5, math.nan)), "diameter_range"),
                 (("300 um", 1e-4, (2e-5, 6e-5)), "lateral_size")]
    for args, field in bed_cases:
        cases.append((f"powder_bed{args}", packing.powder_bed, args, {}, field))

    def line(p, x):
        return p["a"] * x + p["b"]

    x = np.linspace(0.0, 1.0, 20)
    y = 2.0 * x + 1.0
    good = {"a": 1.0, "b": 0.0}
    fits = [
        ("NaN in y", (line, x, np.where(x > 0.5, np.nan, y), good), {}, "y must be finite"),
        ("inf in y", (line, x, np.where(x > 0.5, np.inf, y), good), {}, "y must be finite"),
        ("relative with y = 0", (line, x, 2.0 * x, good), {"relative": True}, "y must be nonzero"),
        ("Positive start <= 0", (line, x, y, {"a": -1.0, "b": 0.0}), {"transforms": {"a": core.Positive()}},
         r"params0\['a'\] must be > 0"),
        ("Bounded start outside", (line, x, y, good), {"transforms": {"a": core.Bounded(2.0, 3.0)}},
         r"params0\['a'\] must be in \(2, 3\)"),
        ("Bounded start on the bound", (line, x, y, {"a": 2.0, "b": 0.0}), {"transforms": {"a": core.Bounded(2.0, 3.0)}},
         r"params0\['a'\] must be in \(2, 3\)"),
        ("misspelled transform key", (line, x, y, good), {"transforms": {"aa": core.Positive()}}, "transforms"),
        ("transform not a transform", (line, x, y, good), {"transforms": {"a": "positive"}}, r"transforms\['a'\]"),
        ("underdetermined", (line, x[:1], y[:1], good), {}, "underdetermined"),
        ("shape mismatch", (line, x, y[:5], good), {}, "shape"),
        ("weights shape", (line, x, y, good), {"weights": np.ones(3)}, "weights"),
        ("negative weights", (line, x, y, good), {"weights": -np.ones(20)}, "weights"),
        ("NaN start", (line, x, y, {"a": math.nan, "b": 0.0}), {}, r"params0\['a'\]"),
        ("empty params", (line, x, y, {}), {}, "params0"),
        ("empty y", (line, x[:0], y[:0], good), {}, "y must be a non-empty"),
        ("scalar y", (line, 1.0, 3.0, good), {}, "y must be a non-empty"),
        ("method typo", (line, x, y, good), {"method": "levenberg"}, "method"),
        ("model fails", (lambda p, x: p["c"] * x, x, y, good), {}, "model"),
    ]
    for name, args, kw, field in fits:
        cases.append((f"least_squares: {name}", core.least_squares, args, kw, field))
    for args, field in [((0.0, 1e-4, (2e-5, 6e-5)), "lateral_size"), ((3e-4, 0.0, (2e-5, 6e-5)), "height"),
                        ((3e-4, 1e-4, (2e-5,)), "diameter_range"), ((3e-4, 1e-4, None), "diameter_range"),
                        ((True, 1e-4, (2e-5, 6e-5)), "lateral_size"), ((3e-4, 1e-4, (-2e-5, 6e-5)), "diameter_range")]:
        cases.append((f"check_bed{args}", packing.check_bed, args, {}, field))
    for raw, field in [(3, "TOML table"), ([], "TOML table"), ("scene.toml", "TOML table"), ({}, "missing section")]:
        cases.append((f"validate_scene({raw!r})", scene.validate_scene, (raw,), {}, field))
    for args, kw, field in [(("rojek", {"slope": math.inf}, 1.0), {}, "slope"),
                            (("feng", {"thickness": 0.0}, 1.0), {}, "thickness"),
                            (("fitted", {"c1": math.nan}, 1.0), {}, "c1"),
                            (("rojek", None, 1.0, -1.0), {}, "kappa_j")]:
        cases.append((f"validate_law_inputs{args}", sc.laws.conductance.validate_law_inputs, args, kw, field))
    return cases


API_CALLS = _api_cases()


@pytest.mark.parametrize("name,fn,args,kwargs,field", API_CALLS, ids=[c[0] for c in API_CALLS])
def test_bad_api_call_names_the_argument(name, fn, args, kwargs, field):
    # least_squares evaluates the user's model (jitted, by design) before it can check the residuals' shape
    guard = contextlib.nullcontext() if name.startswith("least_squares") else nothing_compiled(name)
    with guard, pytest.raises(ValueError, match=field):
        fn(*args, **kwargs)


def test_laws_under_jit_give_nan_for_invalid_materials_never_negative():
    import jax

    import sintercond as sc

    k = jax.jit(lambda kappa, slope: sc.rojek_pair_conductance(1e-3, 3e-3, 0.06e-3, kappa, slope=slope))
    assert np.isnan(k(-394.0, 1.064)) and np.isnan(k(394.0, -1.064)) and k(394.0, 1.064) > 0
    f = jax.jit(lambda t: sc.feng_pair_conductance(1e-3, 3e-3, 0.06e-3, 394.0, thickness=t))
    assert np.isnan(f(-1.0)) and f(1.0) > 0


@pytest.mark.slow
def test_feng_float32_reverse_mode_gradients_are_finite():
    import jax
    import jax.numpy as jnp

    import sintercond as sc

    rng = np.random.default_rng(0)
    n = 20_000
    r_i = rng.uniform(0.1, 10, n).astype(np.float32)
    r_j = (r_i * rng.uniform(1, 100, n)).astype(np.float32)
    u = rng.uniform(0, 1, n).astype(np.float32)
    h = np.concatenate([u[: n // 2] * 2 * np.minimum(r_i, r_j)[: n // 2],  # up to the lens limit (a/r -> 1)
                        (u[n // 2:] ** 30 * r_i[n // 2:])]).astype(np.float32)  # h -> 0+

    def k(a, b, c):
        return sc.feng_pair_conductance(a, b, c, jnp.float32(1.0))

    grads = jax.jit(jax.vmap(jax.grad(k, argnums=(0, 1, 2))))(r_i, r_j, h)
    values = jax.jit(jax.vmap(k))(r_i, r_j, h)
    assert values.dtype == jnp.float32 and np.all(np.isfinite(np.asarray(values)))
    for g in grads:  # before the fix: NaN where a/r rounds to 1 in float32
        assert g.dtype == jnp.float32 and np.all(np.isfinite(np.asarray(g)))
    # away from the singular ends (h -> 0, a/r -> 1) the float32 gradient matches float64
    a_over_r = np.asarray(sc.intersection_radius(r_i.astype(np.float64), r_j.astype(np.float64),
                                                 h.astype(np.float64))) / np.minimum(r_i, r_j)
    inside = (h > 1e-3 * r_i) & (a_over_r < 0.95)
    g64 = jax.vmap(jax.grad(lambda c, a, b: sc.feng_pair_conductance(a, b, c, 1.0)))(
        h[inside].astype(np.float64), r_i[inside].astype(np.float64), r_j[inside].astype(np.float64))
    np.testing.assert_allclose(np.asarray(grads[2])[inside], np.asarray(g64), rtol=2e-2, atol=1e-4)
