"""A powder-bed engineer's first day (issue 27): each test was written against the defect and failed before.

References: the scene as written (a beam over a poured bed), the physical times a run's outputs carry, VTK's
own reader of the files written.
"""

import copy

import numpy as np
import pytest

from sintercond import run as runner
from sintercond.scene import load_scene, validate_scene


def _poured_with_beam(**run):
    scene = copy.deepcopy(load_scene("quintana2020_5_3"))
    scene["packing"].update(particles=12, lateral_size=0.02)
    scene["beam"] = {"intensity": 1e5, "attenuation": 500.0, "spot_radius": 4e-3, "absorptance": 0.8,
                     "speed": 0.01, "path": [[2e-3, 1e-2], [1.8e-2, 1e-2]]}
    scene["run"].update(run)
    return scene


def test_a_poured_bed_takes_a_beam():
    """`KeyError: 'counts'`: the beam's path was checked against a lattice's extent whatever the packing."""
    scene = validate_scene(_poured_with_beam())
    assert scene["beam"]["path"] == [[2e-3, 1e-2], [1.8e-2, 1e-2]]
    outside = _poured_with_beam()
    outside["beam"]["path"] = [[2e-3, 1e-2], [0.5, 1e-2]]
    with pytest.raises(Exception, match=r"beam\.path\[1\]"):
        validate_scene(outside)


@pytest.mark.slow
def test_pour_then_scan_runs_and_the_beam_heats_the_bed(tmp_path):
    scene = validate_scene(_poured_with_beam(duration=2.0, output_every=5, checkpoint_every=5))
    temperature, summary = runner.run_scene(scene, tmp_path, progress=False)
    assert summary["steps"] > 0 and np.all(np.isfinite(np.asarray(temperature)))
    assert summary["T_max_K"] > scene["initial"]["temperature"] + 1.0  # heated under the spot
