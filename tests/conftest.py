"""Strict numerics for every test: x64 on (by importing sintercond), strict dtype promotion."""

import os

import hypothesis
import jax

import sintercond  # noqa: F401  (turns on float64)

# the CLI turns JAX's persistent compilation cache on; tests write nothing to ~/.cache
os.environ.setdefault("SINTERCOND_COMPILATION_CACHE", "0")

jax.config.update("jax_numpy_dtype_promotion", "strict")

hypothesis.settings.register_profile(
    "default", deadline=None, max_examples=60, print_blob=True,
    suppress_health_check=[hypothesis.HealthCheck.too_slow],
)
hypothesis.settings.register_profile("thorough", parent=hypothesis.settings.get_profile("default"), max_examples=2000)
hypothesis.settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))

# The longest files first (CPU seconds of a full run on the project's 2-core machine, contended, in brackets; those
# marked * measured again in December 2026 with `python -m pytest -n0 tests/FILE`, CONTRIBUTING.md):
# xdist hands out whole files in collection order (--dist loadfile with --no-loadscope-reorder, pyproject.toml),
# so a long file collected late would run alone at the end while the other worker idles. Those behind these
# keep pytest's order. A worker is given its next file as soon as 2 of its tests are left, before they run:
# hence the short-listed notebook file is followed by test_sintering_mechanics.py, not by the other notebooks.
LONGEST_FIRST = (
    "test_notebooks_alone.py",  # (350; 225*) calibrate_softening
    "test_fit_softening.py",  # (470; 200-300* at load 3-14)
    "test_doc_scenes.py",  # (460 on a loaded machine) every scene of the docs, reduced
    "test_sintering_mechanics.py",  # (190*)
    "test_mechanics.py",  # (130*)
    "test_notebooks.py",  # (220) the other six notebooks (calibrate_posterior: about 90 s of CPU more)
    "test_posterior_kinetics.py",  # (150 on a loaded 2-core machine) NUTS through grow_neck, compiled twice
    "test_moving.py",  # (90)
    "test_shrinkage.py",  # (155 in a full run, Dec 2026)
    "test_sphere_coupling_transient.py",  # (140 in a full run)
    "test_sintering_scene.py",  # (130 in a full run)
    "test_adaptive_reverse.py",  # (120*) adaptive runs compiled for reverse mode and for a fit
    "test_inverse.py",  # (110)
    "test_dryden_zok.py",  # (105)
    "test_packing.py",  # (100)
    "test_neighbors.py",  # (95)
    "test_fit_sintering.py",  # (85)
    "test_sphere_coupling.py",  # (200 on a loaded 2-core machine, Dec 2026) about ten compiled solve shapes
    "test_scene_mechanics.py",  # (85)
    "test_simulate.py",  # (80)
    "test_first_day.py",  # (70)
    "test_fitting.py",  # (65)
    "test_posterior.py",  # (30; 65 on a loaded 2-core machine)
    "test_teeth_thermal.py",  # (60)
    "test_readme.py",  # (60)
    "test_stiffen.py",  # (45)
)


def pytest_collection_modifyitems(session, config, items):
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: each file's tests keep their order
