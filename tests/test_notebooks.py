"""The notebooks in notebooks/ run top to bottom (nbclient), and their committed outputs are current.

The notebooks are committed with their outputs (plots and printed fits), so a
reader sees them on the repository page. Each test executes one notebook
against this checkout's package and compares the numbers in every text output
with the committed ones: a number may differ by one unit in its last printed
digit (the printing's round-off) or by 1e-6 relative, no more (integers, counts, exactly); lines with
"wall time" are timings and are skipped. A plot cell must still make its
plots. Regenerate the committed outputs after a change with

    python tests/test_notebooks.py            # all notebooks, or name some

which executes them in place (cell execution timestamps stripped).
"""

import copy
import os
import pathlib
import re
import sys

import pytest

pytestmark = pytest.mark.slow  # each notebook runs in a fresh kernel, compiling everything anew

nbformat = pytest.importorskip("nbformat", reason="install the 'notebooks' extra")
nbclient = pytest.importorskip("nbclient", reason="install the 'notebooks' extra")

ROOT = pathlib.Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
# calibrate_softening (about 4 min of CPU, the longest test of the suite) runs from tests/test_notebooks_alone.py:
# xdist hands out whole files (--dist loadfile), so in a file of its own it runs on one worker while the other
# notebooks run on the other, instead of all seven one after another on one worker.
ALONE = ("calibrate_softening.ipynb",)
# committed with the outputs of their full size (a 1e4-particle preheat: half an hour of CPU), run here at the size
# SINTERCOND_NOTEBOOK_SCALE=small asks of them: they must run top to bottom and print and plot the same lines, whose
# numbers are those of the smaller case (the pipeline's values are tested in tests/test_adaptive_reverse.py)
SCALED = ("calibrate_preheat.ipynb",)
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
RELATIVE = 1e-6


def execute(path, small=False):
    """The notebook at ``path`` executed by a fresh kernel that imports this checkout's sintercond and fitting
    (``small``: with ``SINTERCOND_NOTEBOOK_SCALE=small``; a :data:`SCALED` notebook at full size has no time
    limit)."""
    notebook = nbformat.read(path, as_version=4)
    saved = {name: os.environ.get(name) for name in ("PYTHONPATH", "SINTERCOND_NOTEBOOK_SCALE")}
    env_path = saved["PYTHONPATH"] or ""
    os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env_path] if env_path else []))
    if small:
        os.environ["SINTERCOND_NOTEBOOK_SCALE"] = "small"
    else:
        os.environ.pop("SINTERCOND_NOTEBOOK_SCALE", None)
    try:
        client = nbclient.NotebookClient(notebook, timeout=None if path.name in SCALED and not small else 600,
                                         kernel_name="python3", resources={"metadata": {"path": str(path.parent)}})
        client.execute()
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
    for cell in notebook.cells:
        cell.metadata.pop("execution", None)
    return notebook


def text_outputs(notebook):
    """Per code cell: its printed and displayed text (timing lines dropped), and its number of images."""
    cells = []
    for cell in notebook.cells:
        if cell.cell_type != "code":
            continue
        text, images = [], 0
        for output in cell.outputs:
            if output.output_type == "stream" and output.name == "stdout":
                text.append(output.text)
            elif output.output_type in ("execute_result", "display_data"):
                images += "image/png" in output.data
                if "image/png" not in output.data:
                    text.append(output.data.get("text/plain", ""))
        lines = [line for line in "".join(text).splitlines() if "wall time" not in line]
        cells.append((lines, images))
    return cells


def _last_digit(token):
    """One unit in the last printed digit of a number token; 0 for an integer (a count: exact)."""
    if not re.search(r"[.eE]", token):
        return 0.0
    mantissa, _, exponent = token.lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 10.0 ** (int(exponent or 0) - decimals)


def line_differences(committed, current):
    """Where two lines of output differ beyond round-off: their words, or a number by more than it allows."""
    words_then, words_now = NUMBER.sub("#", committed), NUMBER.sub("#", current)
    if words_then != words_now:
        return [f"text changed: {committed!r} -> {current!r}"]
    out = []
    for then, now in zip(NUMBER.findall(committed), NUMBER.findall(current)):
        a, b = float(then), float(now)
        allowed = max(RELATIVE * abs(a), 1.000001 * max(_last_digit(then), _last_digit(now)))
        if abs(a - b) > allowed:
            out.append(f"{then} -> {now} in {current!r}")
    return out


def stale_outputs(committed, current):
    """Every difference beyond round-off between the committed and the re-executed outputs of a notebook."""
    problems = []
    for k, ((lines_then, images_then), (lines_now, images_now)) in enumerate(
            zip(text_outputs(committed), text_outputs(current), strict=True)):
        if images_then != images_now:
            problems.append(f"code cell {k}: {images_then} plots committed, {images_now} now")
        if len(lines_then) != len(lines_now):
            problems.append(f"code cell {k}: {len(lines_then)} lines committed, {len(lines_now)} now")
            continue
        problems += [f"code cell {k}: {d}" for a, b in zip(lines_then, lines_now) for d in line_differences(a, b)]
    return problems


def test_number_comparison_allows_round_off_only():
    assert not line_differences("kappa = 7.0012 +- 0.0040", "kappa = 7.0013 +- 0.0040")
    assert line_differences("kappa = 7.0012 +- 0.0040", "kappa = 7.0015 +- 0.0040")
    assert not line_differences("g = -1.2345678901e+02", "g = -1.2345678905e+02")
    assert line_differences("g = -1.2345678901e+02", "g = -1.2346678901e+02")
    assert line_differences("phi = 4.83", "psi = 4.83")
    assert not line_differences("bed: 385 particles", "bed: 385 particles")
    assert line_differences("bed: 385 particles", "bed: 386 particles")


def test_a_changed_fit_in_an_output_is_reported():
    """The comparison itself, on the committed calibrate_slope outputs: the same notebook is current, one
    changed digit of the printed fit or a lost plot is stale."""
    committed = nbformat.read(ROOT / "notebooks" / "calibrate_slope.ipynb", as_version=4)
    assert not stale_outputs(committed, committed)
    changed = copy.deepcopy(committed)
    stream = next(o for c in changed.cells if c.cell_type == "code" for o in c.outputs
                  if o.output_type == "stream" and o.text.startswith("s = "))
    stream.text = re.sub(r"s = (\d)\.(\d)", lambda m: f"s = {m[1]}.{(int(m[2]) + 1) % 10}", stream.text, count=1)
    assert any("s = " in p for p in stale_outputs(committed, changed))
    no_plot = copy.deepcopy(committed)
    cell = next(c for c in no_plot.cells if c.cell_type == "code" and any("image/png" in o.get("data", {})
                                                                          for o in c.outputs))
    cell.outputs = [o for o in cell.outputs if "image/png" not in o.get("data", {})]
    assert any("plots committed" in p for p in stale_outputs(committed, no_plot))


def check_current(path):
    """``path`` runs without an error and its committed outputs are current (the same numbers to round-off)."""
    committed = nbformat.read(path, as_version=4)
    assert any(c.get("outputs") for c in committed.cells if c.cell_type == "code"), (
        f"{path.name} is committed without outputs; run `python tests/test_notebooks.py {path.name}`")
    current = execute(path)
    errors = [o for c in current.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors
    problems = stale_outputs(committed, current)
    assert not problems, (f"{path.name}: committed outputs are stale; run `python tests/test_notebooks.py "
                          f"{path.name}` and commit it:\n" + "\n".join(problems[:20]))


THOUSANDS = re.compile(r"(?<=\d),(?=\d{3}(?!\d))")


def _words(line):
    """``line`` with its numbers (counts printed with thousands separators too) replaced by ``#``."""
    return NUMBER.sub("#", THOUSANDS.sub("", line))


def same_shape(committed, current):
    """Where two runs of a notebook differ in what they print and plot, numbers aside: per code cell, the number of
    plots and of lines, and each line's words."""
    problems = []
    for k, ((lines_then, images_then), (lines_now, images_now)) in enumerate(
            zip(text_outputs(committed), text_outputs(current), strict=True)):
        if images_then != images_now or len(lines_then) != len(lines_now):
            problems.append(f"code cell {k}: {images_then} plots and {len(lines_then)} lines committed, "
                            f"{images_now} and {len(lines_now)} now")
            continue
        problems += [f"code cell {k}: {a!r} -> {b!r}" for a, b in zip(lines_then, lines_now) if _words(a) != _words(b)]
    return problems


def test_the_shape_of_outputs_ignores_numbers_only():
    assert not same_shape_of_lines("bed: 9,762 particles, 25,784 contacts", "bed: 321 particles, 769 contacts")
    assert not same_shape_of_lines("Q = 36.9 +- 1.7 kJ/mol, 1,234.5", "Q = -35.86 +- 0.7 kJ/mol, 2.5e-3")
    assert same_shape_of_lines("Q = 36.9 kJ/mol", "Q = 36.9 kJ")
    assert same_shape_of_lines("a, b 1", "a b 1")


def same_shape_of_lines(then, now):
    """:func:`same_shape`'s verdict on one line of one cell."""
    cell = nbformat.v4.new_code_cell()
    committed, current = nbformat.v4.new_notebook(cells=[cell]), nbformat.v4.new_notebook(cells=[copy.deepcopy(cell)])
    committed.cells[0].outputs = [nbformat.v4.new_output("stream", name="stdout", text=then)]
    current.cells[0].outputs = [nbformat.v4.new_output("stream", name="stdout", text=now)]
    return same_shape(committed, current)


TOGETHER = [p for p in NOTEBOOKS if p.name not in ALONE + SCALED]


@pytest.mark.parametrize("path", TOGETHER, ids=[p.name for p in TOGETHER])
def test_notebook_runs_and_committed_outputs_are_current(path):
    check_current(path)


@pytest.mark.parametrize("path", [p for p in NOTEBOOKS if p.name in SCALED], ids=list(SCALED))
def test_a_full_size_notebook_runs_small_and_prints_what_it_committed(path):
    committed = nbformat.read(path, as_version=4)
    assert any(c.get("outputs") for c in committed.cells if c.cell_type == "code"), (
        f"{path.name} is committed without outputs; run `python tests/test_notebooks.py {path.name}`")
    current = execute(path, small=True)
    errors = [o for c in current.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors
    problems = same_shape(committed, current)
    assert not problems, f"{path.name}: its outputs changed shape; rerun it at full size:\n" + "\n".join(problems[:20])


if __name__ == "__main__":
    chosen = [p for p in NOTEBOOKS if not sys.argv[1:] or p.name in sys.argv[1:]]
    for path in chosen:
        print(f"executing {path.name}", flush=True)
        nbformat.write(execute(path), path)
