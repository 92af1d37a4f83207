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
