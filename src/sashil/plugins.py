"""Finding plug-ins: the entry-point groups ``sashil.laws``, ``sashil.backends``, ``sashil.plans``
and ``sashil.stages``, and classes named as ``package.module:Class`` or ``path/to/file.py:Class``.

Built-in laws and backends are registered through the same entry points (``pyproject.toml``) as a
lab's own package, so there is one table per group. The built-in plans and stages are
:mod:`sashil.plans`' own tables (``BUILT_IN``, ``BUILT_IN_STAGES``), which the runtime imports by
name; the ``sashil.plans`` and ``sashil.stages`` groups hold a lab's own. Two entry points claiming one name are an
error that names both (a silent winner would run a different law than the one the user meant).
Loading is lazy: the table holds entry points; a class is imported when it is asked for.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cache
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path
from typing import TypeVar

from sashil.errors import ConfigError

T = TypeVar("T")

__all__ = [
    "BACKENDS_GROUP",
    "LAWS_GROUP",
    "PLANS_GROUP",
    "STAGES_GROUP",
    "Plugin",
    "built_in_or_registered",
    "entry_point_table",
    "is_class_spec",
    "load_class",
    "load_target",
]

LAWS_GROUP = "sashil.laws"
BACKENDS_GROUP = "sashil.backends"
#: a lab's own plans: kind -> the function that builds the plan of a ``plan.spec()`` in a loop
#: process, as ``build(run, rig, prompt) -> (stage, label, road_text)`` (``run.plan``: the spec), so
#: the runtime imports no experiment; looked up for a kind not built in (``sashil.plans.BUILT_IN``)
PLANS_GROUP = "sashil.plans"
#: a lab's own stages: kind -> the class whose ``from_spec(spec)`` builds a stage a drop hands over to
#: at its release; looked up for a kind not built in (``sashil.plans.BUILT_IN_STAGES``)
STAGES_GROUP = "sashil.stages"


@dataclass(frozen=True)
class Plugin:
    """One registered name: where it comes from (``built-in``, a package, or a file) and its target."""

    name: str
    target: str  # "package.module:Class" or "path/file.py:Class"
    origin: str


def _origin(point: EntryPoint) -> str:
    dist = getattr(point, "dist", None)
    dist_name = getattr(dist, "name", None) or "?"
    return "built-in" if dist_name == "sashil" else f"package {dist_name}"


@cache
def entry_point_table(group: str) -> dict[str, Plugin]:
    """Name -> :class:`Plugin` of every installed entry point in ``group`` (built-ins first).

    Raises ConfigError when two distributions register the same name."""
    table: dict[str, Plugin] = {}
    points = sorted(entry_points(group=group), key=lambda p: (_origin(p) != "built-in", p.name))
    for point in points:
        plugin = Plugin(point.name, point.value, _origin(point))
        other = table.get(point.name)
        if other is not None and other.target != plugin.target:
            raise ConfigError(
                f"{group}: {point.name!r} is claimed twice: by {other.target} ({other.origin}) and by "
                f"{plugin.target} ({plugin.origin}); uninstall one, or select a class as package.module:Class"
            )
        table[point.name] = plugin
    return table


def built_in_or_registered(
    what: str,
    kind: str,
    built_in: Mapping[str, T],
    group: str,
    load: Callable[[str, str], T],
    refusal: Callable[[str, str], str],
) -> T:
    """The ``what`` (a plan, a stage) of ``kind``: ``built_in``'s, else the entry point of that name
    in ``group``, loaded by ``load(target, where)``. Any other kind is a one-line ConfigError,
    ``refusal(kind, known)``, ``known`` the built-in and registered kinds."""
    if kind in built_in:
        return built_in[kind]
    table = entry_point_table(group)
    if kind not in table:
        raise ConfigError(refusal(kind, ", ".join([*built_in, *table])))
    return load(table[kind].target, f"{what} {kind!r}")


def is_class_spec(text: str) -> bool:
    """Whether ``text`` names a class (``module:Class`` or ``file.py:Class``) rather than a registered name."""
    return ":" in text


def load_class(spec: str, where: str) -> type:
    """The class that ``spec`` (``package.module:Class`` or ``path/to/file.py:Class``) names.

    A module that does not import, or a missing class, is a one-line ConfigError naming ``where``
    (the config key or option) and the first line of the import error."""
    module_part = spec.rpartition(":")[0]
    target = load_target(spec, where)
    if not isinstance(target, type):
        raise ConfigError(f"{where}: {module_part} has no class {spec.rpartition(':')[2]}")
    return target


def load_target(spec: str, where: str) -> object:
    """What ``spec`` (``package.module:name`` or ``path/to/file.py:name``) names: a class or a function.

    A module that does not import, or a missing name, is a one-line ConfigError naming ``where``."""
    module_part, _, class_name = spec.rpartition(":")
    if not module_part or not class_name.isidentifier():
        raise ConfigError(f"{where}: expected package.module:Class or path/to/file.py:Class, got {spec!r}")
    try:
        if module_part.endswith(".py") or "/" in module_part or "\\" in module_part:
            module = _import_file(Path(module_part), where)
        else:
            module = importlib.import_module(module_part)
    except ConfigError:
        raise
    except (Exception, SystemExit) as err:  # whatever the module raises at import (a sys.exit too)
        first = (str(err).splitlines() or [""])[0]
        raise ConfigError(f"{where}: {module_part} does not import: {type(err).__name__}: {first}") from None
    target = getattr(module, class_name, None)
    if target is None:
        raise ConfigError(f"{where}: {module_part} has no class {class_name}")
    return target


class LawFileImport(BaseException):
    """Raised by a run started while a law's file is being imported: a script that defines its law
    and calls ``sashil.run(MyLaw)`` at its top level, with no ``if __name__ == "__main__":``
    guard, is imported for its class (by the session's checks and by the loop process), and that
    import must not start a second run. The import stops there and keeps what the file defined."""


#: law files being imported right now (nested imports count)
_importing = 0


def check_not_importing(what: str) -> None:
    """Raise :class:`LawFileImport` when called from the top level of a law file being imported."""
    if _importing:
        raise LawFileImport(f"{what} called while its law's file is imported")


def _import_file(path: Path, where: str) -> object:
    """Import a Python file as a module of its own (a stable name per absolute path, cached). A run
    the file starts at its top level ends the import there (:class:`LawFileImport`)."""
    global _importing
    if not path.is_file():
        raise ConfigError(f"{where}: {path}: no such file")
    resolved = path.resolve()
    digest = hashlib.sha1(str(resolved).encode()).hexdigest()[:10]
    name = f"sashil_plugin_{resolved.stem}_{digest}"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, resolved)
    if spec is None or spec.loader is None:
        raise ConfigError(f"{where}: {path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    _importing += 1
    try:
        spec.loader.exec_module(module)
    except LawFileImport:
        pass  # the file's own run, not this import's business: what it defined before is kept
    except BaseException:
        del sys.modules[name]
        raise
    finally:
        _importing -= 1
    return module
