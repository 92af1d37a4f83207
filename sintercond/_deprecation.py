"""Names resolved on first use: old names and old module paths kept for one release (with a
``DeprecationWarning``), and the re-exports of a subpackage (imported only when asked for)."""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import os
import sys
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


def lazy_names(package: str, names: dict):
    """A ``__getattr__`` for ``package`` resolving its submodules, and ``names = {name: submodule}`` re-exported
    from them, on first use: importing the package imports none of its modules (nor jax-md or matplotlib)."""
    def __getattr__(name):
        if name in names:
            return getattr(importlib.import_module(f"{package}.{names[name]}"), name)
        if importlib.util.find_spec(f"{package}.{name}") is not None:
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__


_IMPORTLIB = os.path.dirname(importlib.__file__)


def _caller_level(*files):
    """The ``stacklevel`` of the first frame outside this module, ``files`` and the import machinery: the user's.
    ``warnings.warn`` does not count the frames of ``importlib._bootstrap``, so neither does this."""
    frame, level = sys._getframe(1), 1
    while frame is not None:
        name = frame.f_code.co_filename
        if "importlib" in name and "_bootstrap" in name:
            frame = frame.f_back
            continue
        if name not in (__file__, *files) and not name.startswith(_IMPORTLIB):
            return level
        frame, level = frame.f_back, level + 1
    return level


class MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Old module paths ``package.old`` of modules moved into subpackages, ``moved = {old: new subpackage}``: an
    import of the old path (``import``, ``from ... import``) warns and gives the module of the new path itself, so
    that patching either path patches both. Registered on ``sys.meta_path`` by the package; :meth:`attribute`
    serves ``package.old`` as an attribute."""

    def __init__(self, package: str, moved: dict):
        self.package, self.moved = package, moved

    def new_path(self, old: str) -> str:
        return f"{self.package}.{self.moved[old]}.{old}"

    def warn(self, old: str):
        warnings.warn(f"{self.package}.{old} moved to {self.new_path(old)}; the old path goes in the next release",
                      DeprecationWarning, stacklevel=_caller_level(sys.modules[self.package].__file__))

    def attribute(self, old: str):
        self.warn(old)
        return importlib.import_module(self.new_path(old))

    def find_spec(self, fullname, path=None, target=None):
        prefix, _, old = fullname.rpartition(".")
        if prefix != self.package or old not in self.moved:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        old = spec.name.rpartition(".")[2]
        self.warn(old)
        module = importlib.import_module(self.new_path(old))
        spec.loader_state = module.__spec__  # the import machinery sets __spec__ to this one: exec_module restores it
        return module

    def exec_module(self, module):
        module.__spec__ = module.__spec__.loader_state
