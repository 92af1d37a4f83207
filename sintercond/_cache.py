"""JAX's persistent compilation cache, so that a second run of the same scene skips XLA compiles.

A compiled conduction step depends only on shapes, dtypes and the static
physics (law, time step, which sources), never on the packing's values,
which are arguments; so a later process running a packing of the same size
finds its executables on disk instead of compiling them (seconds at 1e5
particles). ``sintercond run`` turns it on (:func:`enable_compilation_cache`
from :func:`sintercond.cli.main`) on accelerators, and on the CPU only when
``SINTERCOND_COMPILATION_CACHE=1``: jaxlib 0.10.1 logs a false "machine type
doesn't match ... SIGILL" error for every CPU executable it loads from the
cache (XLA's own tuning flags ``+prefer-no-gather``/``+prefer-no-scatter``
are compared as if they were CPU features), which a user should not see on
the main job, and on the CPU the cache saves about 0.1 s per run
(benchmarks/RESULTS.md, ``peers_thermal``). Importing the package does not
touch it.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

DEFAULT_CACHE_DIR = "~/.cache/sintercond/jax"
"""Where compiled executables go unless ``$SINTERCOND_CACHE_DIR`` or a path says otherwise."""

MIN_COMPILE_TIME_S = 0.05
"""Compiles shorter than this are not written (JAX's default, 1 s, would skip our steps at 1e4 particles)."""


def cache_by_default() -> bool:
    """Whether the CLI turns the cache on: ``SINTERCOND_COMPILATION_CACHE=1`` forces it, ``0`` refuses it,
    otherwise on for accelerators and off on the CPU (see the module docstring)."""
    setting = os.environ.get("SINTERCOND_COMPILATION_CACHE", "").strip().lower()
    if setting in ("1", "true", "yes", "on"):
        return True
    if setting in ("0", "false", "no", "off"):
        return False
    return jax.default_backend() != "cpu"


def enable_compilation_cache(path=None) -> Path | None:
    """Turn on JAX's persistent compilation cache; returns its directory, or None when opted out.

    Args:
      path: cache directory; default ``$SINTERCOND_CACHE_DIR``, else
        ``~/.cache/sintercond/jax``. Created if missing.

    ``SINTERCOND_COMPILATION_CACHE=0`` (or ``false``/``no``/``off``) in the
    environment turns it off everywhere, even with a ``path``. Call it before
    the first compile of the process: JAX sets its cache up once.
    """
    if os.environ.get("SINTERCOND_COMPILATION_CACHE", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    directory = Path(path or os.environ.get("SINTERCOND_CACHE_DIR") or DEFAULT_CACHE_DIR).expanduser()
    directory.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(directory))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME_S)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return directory
