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
import sys as _sys

import jax as _jax

if _os.environ.get("SINTERCOND_ENABLE_X64", "1").strip().lower() not in ("0", "false", "no", "off"):
    _jax.config.update("jax_enable_x64", True)

from sintercond import _deprecation  # noqa: E402
from sintercond.laws.conductance import (  # noqa: E402
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
from sintercond.laws.effective import (  # noqa: E402
    dryden_zok_conductivity,
    dryden_zok_sigma,
    hashin_shtrikman_bounds,
    maxwell_conductivity,
)
from sintercond.laws.neck import (  # noqa: E402
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
    "beds", "cli", "contacts", "examples", "laws", "output", "rollout", "run", "scene", "sim", "simulate", "state",
    "sweep",
})

# the modules that moved into the folders of their layers (docs/architecture.md): old path -> folder, for one release
_MOVED = {
    **dict.fromkeys(["neck", "conductance", "forces", "materials", "heat_sources", "walls", "sintering", "effective",
                     "dryden_zok", "tortuosity", "geometry"], "laws"),
    **dict.fromkeys(["neighbors", "pair_list", "network"], "contacts"),
    **dict.fromkeys(["thermal", "mechanics", "neck_growth", "steady", "guards"], "sim"),
    **dict.fromkeys(["packing", "rolling", "settle", "packing_files"], "beds"),
    **dict.fromkeys(["io", "plots", "observe"], "output"),
}
_MOVED_MODULES = _deprecation.MovedModules(__name__, _MOVED)
if not any(isinstance(f, _deprecation.MovedModules) and f.package == __name__ for f in _sys.meta_path):
    _sys.meta_path.insert(0, _MOVED_MODULES)  # before the path finders: a stale file at an old path loses


def __getattr__(name):
    """``sc.simulate``, ``sc.run``, ...: the submodules, imported on first use (the simulator pulls in jax-md); an
    old path (``sc.network``) gives the moved module with a ``DeprecationWarning``."""
    if name in _SUBMODULES:
        import importlib

        return importlib.import_module(f"sintercond.{name}")
    if name in _MOVED:
        return _MOVED_MODULES.attribute(name)
    raise AttributeError(f"module 'sintercond' has no attribute {name!r}")


__all__ = [
    "CONDUCTANCE_LAWS",
    "ConductanceLaw",
    "NECK_MODELS",
    "NeckStatus",
    "argento_bouvard_pair_conductance",
    "batchelor_obrien_pair_conductance",
    "coble_radius",
    "dryden_zok_conductivity",
    "dryden_zok_sigma",
    "hashin_shtrikman_bounds",
    "maxwell_conductivity",
    "conductivity_pair_conductance",
    "feng_pair_conductance",
    "fitted_pair_conductance",
    "hertz_radius",
    "intersection_radius",
    "max_overlap",
    "neck_radius",
    "neck_residual",
    "neck_status",
    "pair_conductance",
    "rojek_pair_conductance",
    "series_conductance",
    "validate_neck_inputs",
    "validate_pair_conductance_inputs",
]
