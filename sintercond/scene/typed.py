"""The validated scene as typed sections: frozen dataclasses whose fields are the schema's keys.

:func:`typed_scene` turns what :func:`sintercond.scene.validate_scene` returns (a dict, numbers normalised and every
default the schema declares filled in; what ``scene.json`` holds) into a :class:`Scene`: one frozen dataclass per
section, made from the schema itself (:mod:`sintercond.scene.schema`, which also writes ``docs/scenes.md``), so a
key, its section's class and its documentation cannot drift apart. A key the scene leaves out and the schema gives
no default is ``None``; an optional section the scene leaves out is ``None``; ``walls`` is a tuple.

The build reads fields (``scene.material.density``, ``scene.beam is None``). Each section is also a read-only
mapping of the keys it holds (``section["density"]``, ``"restitution" in section``), the form the modules below the
build (packing, estimates, observation) take.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from sintercond.scene.schema import _PACKING, _SCHEMA, _SECTIONS, _WALL, Key


class Section(Mapping):
    """A typed scene section: fields are the schema's keys (None where absent), read as attributes or as a mapping
    of the keys present."""

    def __getitem__(self, key):
        value = getattr(self, key) if key in self.__dataclass_fields__ else None
        if value is None:
            raise KeyError(key)
        return value

    def __iter__(self):
        return (name for name in self.__dataclass_fields__ if getattr(self, name) is not None)

    def __len__(self):
        return sum(1 for _ in self)

    def as_dict(self) -> dict:
        """The section as the validated dict holds it (the keys present)."""
        return {name: value.as_dict() if isinstance(value, Section) else
                [v.as_dict() for v in value] if name == "walls" else value for name, value in self.items()}


def _doc(title: str, keys: dict[str, Key]) -> str:
    lines = [f"{title} (frozen; generated from :mod:`sintercond.scene.schema`).", "", "Attributes:"]
    for name, key in keys.items():
        unit = f" ({key.unit})" if key.unit else ""
        lines.append(f"  {name}: {key.doc or name}{unit}")
    return "\n".join(lines)


def _section_class(class_name: str, title: str, keys: dict[str, Key]) -> type:
    cls = dataclasses.make_dataclass(class_name, [(name, Any, dataclasses.field(default=None)) for name in keys],
                                     bases=(Section,), frozen=True, eq=True)
    cls.__module__, cls.__doc__ = __name__, _doc(title, keys)
    return cls


def _class_name(name: str, suffix: str) -> str:
    return "".join(part.capitalize() for part in name.split("_")) + suffix


SECTIONS = {name: _section_class(_class_name(name, "Section"), f"The [{name}] section", keys)
            for name, keys in _SCHEMA.items()}
"""The typed class of each table section (``[material]``, ``[run]``, ...)."""

PACKINGS = {kind: _section_class(_class_name(kind, "Packing"), f'The [packing] section of kind = "{kind}"', keys)
            for kind, keys in _PACKING.items()}
"""The typed class of the ``[packing]`` section, per ``packing.kind``."""

Wall = _section_class("Wall", "One [[walls]] entry", _WALL)

Scene = dataclasses.make_dataclass(
    "Scene", [(name, Any, dataclasses.field(default=() if name == "walls" else None)) for name in _SECTIONS],
    bases=(Section,), frozen=True, eq=True)
Scene.__module__ = __name__
Scene.__doc__ = """A validated scene, one typed section per field (None: a section the scene leaves out; ``walls``:
a tuple of :data:`Wall`). Made by :func:`typed_scene`; ``as_dict()`` gives back the validated dict."""


def typed_scene(scene) -> Scene:
    """The :class:`Scene` of a validated scene dict (:func:`sintercond.scene.validate_scene`); a :class:`Scene` as it
    is."""
    if isinstance(scene, Scene):
        return scene
    sections = {}
    for name, table in scene.items():
        if name == "walls":
            sections[name] = tuple(Wall(**wall) for wall in table)
        elif name == "packing":
            sections[name] = PACKINGS[table["kind"]](**table)
        else:
            sections[name] = SECTIONS[name](**table)
    return Scene(**sections)
