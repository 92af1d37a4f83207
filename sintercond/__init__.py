"""sintercond: differentiable heat conduction through sintered particles.

Importing ``sintercond`` turns on 64-bit floats in JAX
(``jax_enable_x64``), because neck solves and conductance sums are
ill-conditioned enough that float32 loses digits users care about. To opt
out, set the environment variable ``SINTERCOND_ENABLE_X64=0`` before the
import, or call ``jax.config.update("jax_enable_x64", False)`` after it.
Every public function also runs in float32; the accuracy it reaches there is
stated in its docstring.
"""

import os as _os

import jax as _jax

if _os.environ.get("SINTERCOND_ENABLE_X64", "1").strip().lower() not in ("0", "false", "no", "off"):
    _jax.config.update("jax_enable_x64", True)

from sintercond import conductance, dryden_zok, effective, neck, sintering  # noqa: E402
from sintercond.conductance import (  # noqa: E402
    CONDUCTANCE_LAWS,
    ConductanceLaw,
    argento_bouvard_pair_conductance,
    batchelor_obrien_pair_conductance,
    conductivity_pair_conductance,
    feng_pair_conductance,
    fitted_pair_conductance,
    pair_conductance,
    rojek_pair_conductance,
    series_conductance,
    validate_pair_conductance_inputs,
)
from sintercond.effective import (  # noqa: E402
    dryden_zok_conductivity,
    dryden_zok_sigma,
    hashin_shtrikman_bounds,
    maxwell_conductivity,
)
from sintercond.neck import (  # noqa: E402
    NECK_MODELS,
    NeckStatus,
    coble_radius,
    hertz_radius,
    intersection_radius,
    max_overlap,
    neck_radius,
    neck_residual,
    neck_status,
    validate_neck_inputs,
)

__version__ = "0.1.0"

_SUBMODULES = frozenset({
    "cli", "conductance", "dryden_zok", "effective", "examples", "forces", "geometry", "guards", "heat_sources",
    "io", "materials", "mechanics", "neck", "neck_growth", "neighbors", "network", "observe", "packing",
    "packing_files", "pair_list", "plots", "rolling", "rollout", "run", "scene", "settle", "sim", "simulate", "sintering",
    "state", "steady", "sweep", "thermal", "tortuosity", "walls",
})


def __getattr__(name):
    """``sc.simulate``, ``sc.run``, ...: the submodules, imported on first use (the simulator pulls in jax-md)."""
    if name in _SUBMODULES:
        import importlib

        return importlib.import_module(f"sintercond.{name}")
    raise AttributeError(f"module 'sintercond' has no attribute {name!r}")


__all__ = [
    "CONDUCTANCE_LAWS",
    "ConductanceLaw",
    "NECK_MODELS",
    "NeckStatus",
    "argento_bouvard_pair_conductance",
    "batchelor_obrien_pair_conductance",
    "coble_radius",
    "conductance",
    "dryden_zok",
    "dryden_zok_conductivity",
    "dryden_zok_sigma",
    "effective",
    "hashin_shtrikman_bounds",
    "maxwell_conductivity",
    "conductivity_pair_conductance",
    "feng_pair_conductance",
    "fitted_pair_conductance",
    "hertz_radius",
    "intersection_radius",
    "max_overlap",
    "neck",
    "neck_radius",
    "neck_residual",
    "neck_status",
    "pair_conductance",
    "rojek_pair_conductance",
    "series_conductance",
    "sintering",
    "validate_neck_inputs",
    "validate_pair_conductance_inputs",
]
