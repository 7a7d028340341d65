"""``--set section.key=value``: change config values from the command line.

Each override is parsed as YAML (``500`` is a number, ``skyhook`` a string, ``null``, ``true``,
``[0.1, 0.9]`` a list, exactly as in a config file), set at its dotted key in a copy of the
resolved config, and the whole config is validated again by the config file's own code path
(:func:`sashil.config.schema.validate`, with the model section's own check; the law's own check
follows where the config is resolved, :func:`sashil.engine.resolve.apply_values`). So a
``--set`` accepts exactly what a config file accepts, and a bad one fails with one line naming the
key and what was expected, e.g. ``--set: loop.rate_hz: expected a number > 0 and <= 20000, got
'fast'``.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from typing import Any

import yaml

from sashil.config.schema import validate
from sashil.config.sections import CONTROLLER, SCHEMA
from sashil.errors import ConfigError

#: the source named in error messages
SOURCE = "--set"


def parse_override(text: str, source: str = SOURCE) -> tuple[list[str], Any]:
    """``"loop.rt.priority=0"`` -> ``(["loop", "rt", "priority"], 0)``; the value is read as YAML
    (``source``: the option or command named in an error)."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigError(f"{source} {text!r}: expected section.key=value (e.g. loop.rate_hz=500)")
    path = key.split(".")
    if len(path) < 2 or any(not part for part in path):
        raise ConfigError(f"{source} {text!r}: expected section.key=value, with a dotted key (e.g. loop.rate_hz=500)")
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError as err:
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise ConfigError(f"{source}: {key}: not a valid YAML value ({problem}): {raw!r}") from None
    return path, value


def _set(doc: dict[str, Any], path: list[str], value: Any) -> None:
    node = doc
    for depth, part in enumerate(path[:-1]):
        child = node.setdefault(part, {})
        if not isinstance(child, dict):
            where = ".".join(path[: depth + 1])
            raise ConfigError(f"{SOURCE}: {'.'.join(path)}: {where} is a value, not a section (set {where}=VALUE)")
        node = child
    node[path[-1]] = value


def set_values(
    config: Mapping[str, Any], values: Sequence[tuple[list[str], Any]], source: str
) -> tuple[dict[str, Any], set[str]]:
    """A copy of ``config`` with each ``(dotted path, value)`` set in order, validated against the
    schema as a config file is (``source``: the option named in error messages; ``config`` itself
    when there is nothing to set), and the parameters of a law that a new ``controller.law``
    replaced (the law's own check drops them)."""
    if not values:
        return config, set()  # type: ignore[return-value]
    doc: dict[str, Any] = copy.deepcopy(dict(config))
    keep = {path[1] for path, _ in values if len(path) == 2 and path[0] == "controller"}
    replaced: set[str] = set()
    for path, value in values:
        section = doc.get("controller")
        if path == ["controller", "law"] and isinstance(section, dict) and section.get("law") != value:
            # the previous law's parameters (the checked section's keys beyond the controller's
            # own) go with it, unless the new law declares them or they are set alongside it
            replaced |= {key for key in section if key not in CONTROLLER.fields} - keep
        _set(doc, path, value)
    return validate(doc, SCHEMA, source), replaced
