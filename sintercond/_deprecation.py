"""Old names kept for one release: a module ``__getattr__`` that resolves them with a ``DeprecationWarning``."""

from __future__ import annotations

import importlib
import warnings


def old_names(module: str, moved: dict):
    """A ``__getattr__`` for ``module`` resolving ``moved = {old: (new module, new name)}`` by name (so that the
    module imports nothing above its layer), warning that the old name goes in the next release."""
    def __getattr__(name):
        if name in moved:
            target, new = moved[name]
            warnings.warn(f"{module}.{name} moved to {target}.{new}; the old name goes in the next release",
                          DeprecationWarning, stacklevel=2)
            return getattr(importlib.import_module(target), new)
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__
