"""Scene validation at the edges of every bounded key: the limit itself is accepted, just past it is an error
naming the key. Each case below survived a deliberate bug in sintercond/scene.py before this file existed
(a bound moved or dropped, a finiteness check removed, the Nusselt/Reynolds exclusivity dropped)."""

import copy
import math

import pytest

from sintercond.scene import SceneError, validate_scene

BED = {
    "packing": {"kind": "powder_bed", "lateral_size": 5e-4, "height": 3e-4, "diameter_range": [45e-6, 150e-6]},
    "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.6},
    "conduction": {"law": "rojek"},
    "initial": {"temperature": 300.0},
    "walls": [{"axis": 2, "side": "min", "mode": "held", "temperature": 300.0}],
    "convection": {"environment_temperature": 300.0, "environment_conductivity": 0.026},
    "run": {"duration": 1e-3, "output_every": 5, "checkpoint_every": 10},
}


def _scene(edit):
    scene = copy.deepcopy(BED)
    edit(scene)
    return scene


@pytest.mark.parametrize("section,key,good,bad,message", [
    ("packing", "sinter_swelling", [0.0, 0.05], [-1e-3, 0.0501], r"packing\.sinter_swelling must be a number in \[0, 0\.05\]"),
    ("walls", "penetration", [0.0, 0.2], [-1e-3, 0.201], r"walls\[0\]\.penetration must be a number in \[0, 0\.2\]"),
])
def test_bounded_keys_accept_their_limits_and_refuse_beyond(section, key, good, bad, message):
    def put(value):
        return lambda s: (s[section][0] if section == "walls" else s[section]).update({key: value})

    for value in good:
        validate_scene(_scene(put(value)))
    for value in bad:
        with pytest.raises(SceneError, match=message):
            validate_scene(_scene(put(value)))


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
@pytest.mark.parametrize("section,key", [("material", "conductivity"), ("initial", "temperature"),
                                         ("run", "duration"), ("packing", "height"),
                                         ("convection", "environment_conductivity")])
def test_non_finite_numbers_are_refused(section, key, value):
    with pytest.raises(SceneError, match=rf"{section}\.{key} must be a number in .*; got {value}"):
        validate_scene(_scene(lambda s: s[section].update({key: value})))


def test_non_finite_list_entries_and_dt_are_refused():
    with pytest.raises(SceneError, match=r"packing\.diameter_range must be a list of 2 numbers in .*; got \[4\.5e-05, inf\]"):
        validate_scene(_scene(lambda s: s["packing"].update(diameter_range=[45e-6, math.inf])))
    with pytest.raises(SceneError, match=r"run\.dt must be"):
        validate_scene(_scene(lambda s: s["run"].update(dt=math.inf)))


def test_nusselt_or_reynolds_and_prandtl_not_both():
    conv = {"environment_temperature": 300.0, "environment_conductivity": 0.026}
    validate_scene(_scene(lambda s: s.update(convection={**conv, "nusselt": 3.0})))
    validate_scene(_scene(lambda s: s.update(convection={**conv, "reynolds": 10.0, "prandtl": 0.7})))
    with pytest.raises(SceneError, match=r"convection\.nusselt or convection\.reynolds and prandtl, not both"):
        validate_scene(_scene(lambda s: s.update(convection={**conv, "nusselt": 3.0, "reynolds": 10.0,
                                                              "prandtl": 0.7})))
    for lone in ({"reynolds": 10.0}, {"prandtl": 0.7}):
        with pytest.raises(SceneError, match="reynolds and convection.prandtl go together"):
            validate_scene(_scene(lambda s: s.update(convection={**conv, **lone})))
