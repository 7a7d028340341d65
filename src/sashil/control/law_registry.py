"""Laws by name: the ``sashil.laws`` entry points, plus ``package.module:Class`` and ``file.py:Class``.

:func:`find_law` turns ``controller.law`` (or ``--controller``) into a checked law class;
:func:`known_laws` lists every registered one (``sashil laws``). Built-in laws come through the
same entry-point group as a lab's package (``pyproject.toml``), so there is one table.

Bad input is one line naming ``controller.law``: an unknown name (with the known ones), a module
or file that does not import, a class that is not a :class:`~sashil.control.law_api.Law` or
implements neither ``torque`` nor ``current``, two laws claiming one name.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sashil.config.sections import CONTROLLER
from sashil.control.law_api import Law
from sashil.errors import ConfigError
from sashil.plugins import LAWS_GROUP, entry_point_table, is_class_spec, load_class

__all__ = ["LawEntry", "describe", "find_law", "known_laws", "law_label", "law_names"]

WHERE = "controller.law"


@dataclass(frozen=True)
class LawEntry:
    """A law class and where it was found (``built-in``, ``package NAME`` or ``file PATH``)."""

    spec: str
    cls: type[Law]
    origin: str


def law_label(spec: str) -> tuple[str, str]:
    """What a run calls the law ``spec`` names, and where it came from: its ``name`` (never the
    path or module it was given by) and its origin (``built-in``, ``package NAME``, ``file PATH``)."""
    entry = find_law(spec)
    return entry.cls.name, entry.origin


def law_names() -> list[str]:
    """The registered law names (built-ins first)."""
    return list(entry_point_table(LAWS_GROUP))


def _checked(cls: type, spec: str, origin: str) -> LawEntry:
    if not (isinstance(cls, type) and issubclass(cls, Law)):
        raise ConfigError(f"{WHERE}: {spec} is not a sashil.control.Law (subclass Law and implement torque or current)")
    kind = cls.output_kind()
    if not kind:
        both = cls.torque is not Law.torque
        raise ConfigError(
            f"{WHERE}: {spec} implements "
            + ("both torque and current (one output only)" if both else "neither torque(state) nor current(state)")
        )
    if not isinstance(cls.name, str) or not cls.name:
        raise ConfigError(f"{WHERE}: {spec} has no name (set the class attribute name = '...')")

    for key in cls.params():
        if key in CONTROLLER.fields:
            raise ConfigError(
                f"{WHERE}: {spec} declares a parameter {key!r}, which is the controller's own key "
                f"controller.{key}: rename the parameter"
            )
        if key == "context" or hasattr(Law, key):  # Law(context, **params) and the API's own names
            raise ConfigError(f"{WHERE}: {spec} declares a parameter {key!r}, a name the Law API uses: rename it")
    return LawEntry(spec, cls, origin)


def find_law(spec: str) -> LawEntry:
    """The law ``spec`` names: a registered name, ``package.module:Class`` or ``path/file.py:Class``."""
    if not isinstance(spec, str) or not spec:
        raise ConfigError(f"{WHERE}: expected a law name, package.module:Class or path/file.py:Class, got {spec!r}")
    table = entry_point_table(LAWS_GROUP)
    rival = None
    if is_class_spec(spec):
        cls = load_class(spec, WHERE)
        # the registered law of the same name, loaded with it: a name a class given by its path
        # may not claim
        name = getattr(cls, "name", None)
        registered = table.get(name) if isinstance(name, str) else None
        if registered is not None and registered.target != spec:
            rival = (registered, load_class(registered.target, WHERE))
        module_part = spec.rpartition(":")[0]
        target, origin = spec, f"file {module_part}" if module_part.endswith(".py") else f"module {module_part}"
    else:
        plugin = table.get(spec)
        if plugin is None:
            known = ", ".join(table) or "none installed: reinstall sashil (pip install -e .)"
            raise ConfigError(
                f"{WHERE}: unknown law {spec!r} (known: {known}; or give package.module:Class or path/file.py:Class)"
            )
        cls, target, origin = load_class(plugin.target, WHERE), plugin.target, plugin.origin
    entry = _checked(cls, target, origin)
    if rival is not None and not _same_class(rival[1], entry.cls):
        raise ConfigError(
            f"{WHERE}: {spec} claims the name {entry.cls.name!r}, which {rival[0].target} "
            f"({rival[0].origin}) already has: rename one of them"
        )
    if not is_class_spec(spec) and entry.cls.name != spec:
        raise ConfigError(
            f"{WHERE}: the entry point {spec!r} ({origin}) loads {target}, whose name is "
            f"{entry.cls.name!r}: the two must agree"
        )
    return entry


def _same_class(a: type, b: type) -> bool:
    """One class, possibly imported twice (by its package and by its file path)."""
    if a is b:
        return True
    try:
        same_file = Path(inspect.getfile(a)).resolve() == Path(inspect.getfile(b)).resolve()
    except (TypeError, OSError):
        return False
    return same_file and a.__qualname__ == b.__qualname__


def known_laws() -> list[LawEntry]:
    """Every registered law, loaded and checked (for ``sashil laws``)."""
    return [find_law(name) for name in law_names()]


def describe(entry: LawEntry) -> dict[str, Any]:
    """One law as a plain mapping: name, output, origin, target and parameters (``sashil laws``, the
    panel's law list)."""
    cls = entry.cls
    paragraph = (cls.__doc__ or "").strip().split("\n\n")[0]
    doc = [" ".join(line.strip() for line in paragraph.splitlines())] if paragraph else []
    return {
        "name": cls.name,
        "output": cls.output_kind(),
        "reads_road_ahead": bool(getattr(cls, "reads_road_ahead", False)),
        "origin": entry.origin,
        "class": entry.spec,
        "doc": doc[0] if doc else "",
        "parameters": [
            {
                "name": key,
                "default": None if param.required else param.default,
                "required": param.required,
                "unit": param.unit,
                "low": param.low,
                "high": param.high,
                "low_open": param.low_open,
                "accepts": param.field.expected(),
                "doc": param.doc,
            }
            for key, param in cls.params().items()
        ],
    }
