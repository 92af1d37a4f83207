"""The longest notebook, run and compared with its committed outputs as in tests/test_notebooks.py.

A file of its own because xdist hands out whole files (``--dist loadfile``): here it runs on one worker while
tests/test_notebooks.py's other six notebooks run on the other, instead of after them on the same worker (it is
about 4 min of CPU on the 2-core machine, the longest single test of the suite).
"""

import pytest

pytestmark = pytest.mark.slow  # each notebook runs in a fresh kernel, compiling everything anew

pytest.importorskip("nbformat", reason="install the 'notebooks' extra")
pytest.importorskip("nbclient", reason="install the 'notebooks' extra")

from test_notebooks import ALONE, NOTEBOOKS, check_current  # noqa: E402  (after the skips: it needs nbformat)

CHOSEN = [p for p in NOTEBOOKS if p.name in ALONE]


def test_every_notebook_is_run_by_one_of_the_two_files():
    assert len(CHOSEN) == len(ALONE) and set(ALONE) <= {p.name for p in NOTEBOOKS}


@pytest.mark.parametrize("path", CHOSEN, ids=[p.name for p in CHOSEN])
def test_notebook_runs_and_committed_outputs_are_current(path):
    check_current(path)
