"""Every scene the docs give runs to completion (issue 43: "Pour, scan, look", copied verbatim, never settled).

The scenes: the ```toml blocks of README.md and docs/*.md, the built-in scenes the docs run by name
(`sintercond run NAME`), and the default scene (a bare `sintercond run`). Each runs with the keys it has, made
smaller where a full run takes minutes: a bed a single layer deep (packing.height the largest diameter), a pour
of a dozen spheres, and run.duration a few dozen of its estimated steps (the docs' --duration, shorter). The
numbers the docs state of the full scenes that cost nothing to check (particle counts) are checked.
"""

import copy
import importlib.resources
import math
import re

import pytest

from sintercond import run as runner
from sintercond.beds.packing import bed_particle_count
from sintercond.scene import builtin_scenes, estimate_run, validate_scene
from tests.test_readme import README, _doc_scene_blocks, _docs_pages, _write_doc_packing

STEPS = 30
"""Estimated steps of each reduced run."""


def _builtin(name):
    import tomllib

    data = importlib.resources.files("sintercond.data")
    path = data.joinpath("default_scene.toml") if name is None else data.joinpath("scenes", f"{name}.toml")
    return tomllib.loads(path.read_text(encoding="utf-8"))


def _named_scenes():
    """The built-in scenes the docs run by name, and the default scene (README's bare `sintercond run`)."""
    text = "".join(page.read_text() for page in [README, *_docs_pages()])
    names = sorted(set(re.findall(r"sintercond run ([a-z0-9_]+)\b", text)) & set(builtin_scenes()))
    assert re.search(r"sintercond run\s*$", text, re.M)  # the bare command: the default scene
    return [(f"built-in {name}", name) for name in names] + [("default scene", None)]


SCENES = [(where, ("block", k)) for k, (where, _) in enumerate(_doc_scene_blocks())] + \
    [(where, ("builtin", name)) for where, name in _named_scenes()]


def reduced(raw):
    """``raw`` with the same keys at a size that runs in seconds: a bed one layer deep, a pour of 12 spheres."""
    p = raw["packing"]
    if p["kind"] == "powder_bed":
        p["height"] = max(p["diameter_range"])  # the least the bed takes: the largest sphere
    elif p["kind"] == "poured":
        p["particles"] = min(p["particles"], 12)
    return raw


@pytest.mark.slow
@pytest.mark.parametrize("source", [s for _, s in SCENES], ids=[w for w, _ in SCENES])
def test_every_scene_of_the_docs_runs_to_completion(tmp_path, source):
    kind, key = source
    raw = copy.deepcopy(_doc_scene_blocks()[key][1] if kind == "block" else _builtin(key))
    _write_doc_packing(raw, tmp_path)
    raw = reduced(raw)
    dt = estimate_run(validate_scene(copy.deepcopy(raw))).dt
    # a neck update needs sintering.every steps, and the estimated step may be a fifth of the run's
    every = raw.get("sintering", {}).get("every", 1)
    raw["run"]["duration"] = min(raw["run"]["duration"], max(STEPS, 10 * every) * dt)
    _, summary = runner.run_scene(validate_scene(raw), tmp_path / "out", progress=False, pictures=False)
    assert summary is not None and summary["steps"] >= 1
    assert math.isfinite(summary["T_max_K"]) and summary["T_max_K"] < raw["material"].get("melting_point", math.inf)


@pytest.mark.parametrize("name, count, stated", [
    ("lpbf_hatch_bed", 10_000, "about 10,000 Ti6Al4V particles"), ("ti6al4v_preheating_bed", 400, "about 400 particles"),
    ("quintana2020_5_4_laser", 87, "87 particles")])
def test_the_particle_counts_the_docs_state(name, count, stated):
    """docs/examples.md's particle counts of the full scenes: the bed's volume over the mean sphere's at the fill
    fraction (sintercond.beds.packing.bed_particle_count); "about" within 5 %."""
    from tests.test_readme import ROOT

    assert stated in (ROOT / "docs" / "examples.md").read_text()
    p = _builtin(name)["packing"]
    got = bed_particle_count(p["lateral_size"], p["height"], p["diameter_range"])
    assert got == count if not stated.startswith("about") else abs(got - count) <= 0.05 * count
