"""The fits printed in the committed notebooks are what the library computes now, and what a closed form gives.

Cheap (no Jupyter kernel): reads the committed outputs as JSON. A notebook whose
outputs were not regenerated after a change of a fit fails here even where the
notebook tests are skipped (`python tests/test_notebooks.py NAME` regenerates it).
"""

import json
import pathlib
import re

import numpy as np

from fitting import phi as phi_fit
from fitting.reference import fe_neck_conductance
from fitting.slope import fit_slope

NOTEBOOKS = pathlib.Path(__file__).resolve().parents[1] / "notebooks"


def printed(name, pattern):
    """The groups of the first line of the notebook's printed output that matches ``pattern``."""
    notebook = json.loads((NOTEBOOKS / name).read_text())
    for cell in notebook["cells"]:
        for output in cell.get("outputs", []):
            if output.get("output_type") == "stream":
                match = re.search(pattern, "".join(output["text"]))
                if match:
                    return match.groups()
    raise AssertionError(f"{name}: no committed output matches {pattern!r} (run `python tests/test_notebooks.py {name}`)")


def test_printed_slope_fit_is_current_and_the_closed_form():
    s, ds = printed("calibrate_slope.ipynb", r"s = ([\d.]+) \+- ([\d.]+) \(1 sigma, converged\)")
    data = fe_neck_conductance()
    fit = fit_slope(data["a_over_r"], data["K_over_Kcyl"], max_a_over_r=0.7)
    assert float(s) == round(fit.params["slope"], 4) and float(ds) == round(fit.stderr["slope"], 4)
    assert fit.converged  # not the step count: Adam's count at its tolerance moves with the round-off
    # independent: least squares through the origin, s = sum(x y) / sum(x^2), stderr from the residual variance
    keep = data["a_over_r"] <= 0.7
    x, y = data["a_over_r"][keep], data["K_over_Kcyl"][keep]
    closed = np.sum(x * y) / np.sum(x * x)
    stderr = np.sqrt(np.sum((y - closed * x) ** 2) / (x.size - 1) / np.sum(x * x))
    assert abs(float(s) - closed) <= 0.5e-4 + 1e-9 and abs(float(ds) - stderr) <= 0.5e-4 + 1e-9


def test_printed_phi_fit_is_current():
    # the printed line gives no step count: Adam's count at the stopping tolerance moves with the machine's
    # round-off (310 -> 291 under reassociated sums) while the estimate and its interval do not
    phi, dphi = printed("calibrate_phi.ipynb", r"phi = ([\d.]+) \+- ([\d.]+) \(1 sigma;.*?, converged\)")
    fit = phi_fit.fit_phi(phi_fit.bcc_inputs())
    assert float(phi) == round(fit.params["phi"], 3) and float(dphi) == round(fit.stderr["phi"], 3)
    assert fit.converged
