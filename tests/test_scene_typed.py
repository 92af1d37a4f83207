"""The typed scene (issue 39): sections made from the schema, the build reading fields, walls built once.

References: the schema itself (every key a field, every field a key), the validated dict (a typed scene gives it
back), the model built from the dict (the same from the typed scene), and a count of the wall builds.
"""

import dataclasses

import numpy as np
import pytest

from sintercond.output import observe
from sintercond.scene import build, load_scene, validate_scene
from sintercond.scene import schema, typed
from sintercond.scene.typed import Scene, typed_scene

BUILT_IN = ["default", "quintana2020_5_1", "quintana2020_5_3", "rizza2024_sc_cell", "sintering_hot_floor",
            "ti6al4v_preheating_bed", "lpbf_hatch_bed", "quintana2020_5_4_laser"]


def test_every_key_of_the_schema_is_a_field_of_its_section_and_nothing_else():
    for name, keys in schema._SCHEMA.items():
        assert [f.name for f in dataclasses.fields(typed.SECTIONS[name])] == list(keys), name
    for kind, keys in schema._PACKING.items():
        assert [f.name for f in dataclasses.fields(typed.PACKINGS[kind])] == list(keys), kind
    assert [f.name for f in dataclasses.fields(typed.Wall)] == list(schema._WALL)
    assert [f.name for f in dataclasses.fields(Scene)] == list(schema._SECTIONS)


@pytest.mark.parametrize("name", BUILT_IN)
def test_a_typed_scene_gives_back_the_validated_scene(name):
    checked = load_scene(None if name == "default" else name)
    scene = typed_scene(checked)
    assert scene.as_dict() == checked
    assert typed_scene(scene) is scene
    for section, table in checked.items():
        if section == "walls":
            assert [dict(w) for w in scene.walls] == table
            continue
        typed_section = getattr(scene, section)
        assert dict(typed_section) == table  # the mapping holds exactly the keys present
        for key, value in table.items():
            assert getattr(typed_section, key) == value == typed_section[key]


def test_absent_keys_and_sections_are_none_and_a_scene_is_frozen():
    scene = typed_scene(load_scene("rizza2024_sc_cell"))
    assert scene.beam is None and scene.get("beam") is None and "beam" not in scene
    assert scene.material.specific_heat_table is None and "specific_heat_table" not in scene.material
    with pytest.raises(KeyError):
        scene.material["specific_heat_table"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.material.density = 1.0


def _small_scene():
    return validate_scene({
        "packing": {"kind": "simple_cubic", "counts": [3, 3, 2], "spacing": 78e-6, "radius": 40e-6},
        "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 7.0},
        "conduction": {"law": "rojek"}, "initial": {"temperature": 300.0},
        "walls": [{"axis": 2, "side": "min", "mode": "held", "temperature": 900.0},
                  {"axis": 2, "side": "max", "mode": "conducting", "temperature": 250.0},
                  {"axis": 0, "side": "max", "mode": "insulated"}],
        "run": {"duration": 1e-3, "output_every": 1, "checkpoint_every": 1}})


def test_the_build_reads_a_typed_scene_as_it_reads_the_dict():
    checked = _small_scene()
    from_dict, from_typed = build.build_model(checked), build.build_model(typed_scene(checked))
    assert from_dict.n_steps == from_typed.n_steps and from_dict.limits == from_typed.limits
    for a, b in zip(*(np.asarray(x) for x in (from_dict.state.particles.temperature,
                                              from_typed.state.particles.temperature))):
        assert a == b
    assert from_dict.planes == from_typed.planes


def test_the_walls_are_built_once_per_model_and_never_per_frame(monkeypatch):
    """Before: scene_walls ran five times in a build and again at every output frame."""
    calls = []
    original = build.scene_walls
    monkeypatch.setattr(build, "scene_walls", lambda *a: calls.append(1) or original(*a))
    monkeypatch.setattr(observe, "scene_walls", lambda *a: calls.append(1) or original(*a))
    checked = _small_scene()
    model = build.build_model(checked)
    assert len(calls) == 1 and len(model.planes) == 3
    assert [w.mode for w in model.planes] == ["held", "conducting", "insulated"]
    probe = observe._probe_fn(model)
    for _ in range(3):
        observe.observe(checked, model, model.state, probe)
    assert len(calls) == 1
