"""The step of every physics combination keeps its numbers while the simulator is reshaped (issue 39).

``tests/data/pinned_steps.npz`` holds each case's state after a few steps (``tests/step_cases.py``), written at the
commit before the refactor began (4d8c5a0, whose step is checked against closed forms, conservation and the
peers by the rest of the suite). Equal to round-off: a relative 1e-11 of each array's scale, where the steps
taken here amplify a last-digit difference by far less (a different machine's or XLA's fusion order); where the
step solves the many-body balance by conjugate gradients, to that solve's relative residual (1e-8), within which
another machine's round-off moves where the iterations stop (``mechanics_sintering``: 1.5e-10 of its neck's scale
on an AMD EPYC against the machine that wrote the file). ``step_cases.tolerance`` says which.
"""

import numpy as np
import pytest

import step_cases

PINNED = np.load(step_cases.PINNED)


def test_every_case_is_pinned_with_finite_numbers():
    assert {key.split("/")[0] for key in PINNED.files} == set(step_cases.CASES)
    assert all(np.isfinite(PINNED[key]).all() for key in PINNED.files)


@pytest.mark.slow
@pytest.mark.parametrize("name", step_cases.CASES)
def test_the_step_keeps_its_numbers(name):
    got, tol = step_cases.outputs(name), step_cases.tolerance(name)
    want = {key.split("/")[1]: PINNED[key] for key in PINNED.files if key.split("/")[0] == name}
    assert set(got) == set(want)
    for key, value in want.items():
        scale = max(float(np.max(np.abs(value))), 1e-300) if value.dtype.kind == "f" else 0.0
        if value.dtype.kind == "f":
            np.testing.assert_allclose(got[key], value, rtol=0, atol=tol * scale, err_msg=f"{name}/{key}")
        else:
            np.testing.assert_array_equal(got[key], value, err_msg=f"{name}/{key}")
