"""A validated scene carries every default its schema declares, filled once (issue 24: the run restated 49 of them
as ``.get(key, default)``, free to drift from the declared ones)."""

import copy
import re
from pathlib import Path

import pytest

from sintercond import scene as sc_scene
from sintercond.scene import _PACKING, _SCHEMA, _WALL, load_scene, validate_scene

LATTICE = {"kind": "simple_cubic", "counts": [3, 3, 2], "spacing": 1e-4, "radius": 0.52e-4}
BASE = {"packing": LATTICE, "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.6},
        "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0},
        "run": {"duration": 1e-3, "output_every": 10, "checkpoint_every": 10}}
MECHANICS = {"physics": {"mechanics": True}, "mechanics": {"young_modulus": 1e9, "poisson_ratio": 0.3},
             "softening": {"onset_temperature": 500.0}}


def _literal(key):
    """The default a key declares as a value (not a description such as "the law's" or a reference to a key)."""
    return key.default is not None and not (isinstance(key.default, str) and key.kind in (float, dict)) \
        and key.default != "the law's"


def _scene(**sections):
    raw = copy.deepcopy(BASE)
    raw.update(copy.deepcopy(sections))
    return raw


def test_every_declared_default_is_filled_with_its_value():
    raw = _scene(**MECHANICS, beam={"intensity": 1e8, "attenuation": 2e4, "spot_radius": 1e-4, "absorptance": 0.7,
                                    "speed": 0.1, "path": [[0.0, 0.0]]},
                 convection={"environment_temperature": 300.0, "environment_conductivity": 0.03},
                 radiation={"environment_temperature": 300.0, "emissivity": 0.4},
                 walls=[{"axis": 0, "side": "max", "mode": "insulated"}])
    checked = validate_scene(raw)
    filled = 0
    for section, schema in [*_SCHEMA.items(), ("packing", _PACKING["simple_cubic"]), ("walls", _WALL)]:
        if section not in checked:
            continue
        table = checked["walls"][0] if section == "walls" else checked[section]
        given = raw["walls"][0] if section == "walls" else raw.get(section, {})
        for key, spec in schema.items():
            if _literal(spec) and key not in given:
                assert table[key] == spec.default, f"{section}.{key}"
                filled += 1
    assert filled >= 24
    m = checked["mechanics"]
    assert m["damping"] == 1.0 and m["wall_friction"] == m["friction"] == 0.0
    assert checked["convection"]["nusselt"] == 2.0
    assert checked["walls"][0]["penetration"] == 0.02 and checked["walls"][0]["velocity"] == [0.0, 0.0, 0.0]


def test_a_default_naming_another_key_takes_its_value():
    raw = _scene(**MECHANICS)
    raw["mechanics"].update(friction=0.4, rolling_friction=0.1)
    m = validate_scene(raw)["mechanics"]
    assert (m["wall_friction"], m["wall_rolling_friction"]) == (0.4, 0.1)


def test_alternatives_and_mechanical_keys_are_not_filled_where_they_do_not_apply():
    raw = _scene(**MECHANICS, convection={"environment_temperature": 300.0, "environment_conductivity": 0.03,
                                          "reynolds": 10.0, "prandtl": 0.7})
    raw["mechanics"]["restitution"] = 0.5
    checked = validate_scene(raw)
    assert "damping" not in checked["mechanics"] and "nusselt" not in checked["convection"]
    thermal = validate_scene(_scene(walls=[{"axis": 2, "side": "min", "mode": "held", "temperature": 400.0}]))
    assert thermal["physics"] == {"mechanics": False}  # no gravity, skin, ... without mechanics
    assert thermal["walls"][0]["velocity"] == [0.0, 0.0, 0.0]  # at rest, as a thermal wall may be given


@pytest.mark.parametrize("name", [None, "quintana2020_5_1", "quintana2020_5_3", "quintana2020_5_4_laser"])
def test_a_filled_scene_validates_again_as_it_is(name):
    """``scene.json`` holds the filled scene and ``--resume`` validates it again: it must come back unchanged."""
    once = validate_scene(load_scene(name))
    assert validate_scene(copy.deepcopy(once)) == once


def test_a_relaxed_bed_without_mechanics_gets_the_rough_bed_penetration():
    bed = {"kind": "powder_bed", "lateral_size": 4e-4, "height": 2e-4, "diameter_range": [4e-5, 6e-5]}
    wall = {"axis": 2, "side": "min", "mode": "held", "temperature": 400.0}
    assert validate_scene(_scene(packing=bed, walls=[wall]))["walls"][0]["penetration"] == \
        sc_scene.ROUGH_BED_PENETRATION
    assert validate_scene(_scene(walls=[wall]))["walls"][0]["penetration"] == _WALL["penetration"].default


def test_the_run_restates_no_declared_default():
    """No ``.get("key", ...)`` of a key whose default the schema declares, in the code that reads a validated scene."""
    declared = {key for schema in [*_SCHEMA.values(), *_PACKING.values(), _WALL] for key, spec in schema.items()
                if _literal(spec)}
    package = Path(sc_scene.__file__).parents[1]
    for module in ("run.py", "output/observe.py", "scene/build.py"):
        source = (package / module).read_text()
        restated = sorted(set(re.findall(r'\.get\("(\w+)", ', source)) & declared)
        assert restated == [], f"{module} restates the defaults of {restated}"
