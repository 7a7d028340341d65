"""A small declarative schema for YAML configs: types, ranges, choices, unknown keys.

Validation errors are one line that names the file, the dotted key and what was expected, e.g.
``configs/lab.yaml: rig.coil_tau_s: expected a number >= 0, got -1``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from sashil.errors import ConfigError


@dataclass(frozen=True)
class Field:
    """One leaf key: its kind, default and allowed range or choices."""

    kind: str  # "float" | "int" | "bool" | "str" | "choice" | "float?" | "str?" | "float_list" | "choice_list"
    default: Any
    low: float | None = None
    high: float | None = None
    low_open: bool = False  # True: value must be strictly greater than ``low``
    choices: tuple[str, ...] = ()
    doc: str = ""

    def expected(self) -> str:
        """Human description of what the field accepts."""
        if self.kind.rstrip("?") == "choice":
            text = "one of " + ", ".join(repr(c) for c in self.choices)
            return text + (" or null" if self.kind.endswith("?") else "")
        if self.kind == "bool":
            return "true or false"
        if self.kind in ("str", "str?"):
            return "a string" + (" or null" if self.kind.endswith("?") else "")
        if self.kind == "float_list":
            return "a list of numbers"
        if self.kind == "choice_list":
            return "a list of names from " + ", ".join(repr(c) for c in self.choices)
        word = "an integer" if self.kind == "int" else "a number"
        parts = []
        if self.low is not None:
            parts.append(f"{'>' if self.low_open else '>='} {self.low:g}")
        if self.high is not None:
            parts.append(f"<= {self.high:g}")
        text = word + (" " + " and ".join(parts) if parts else "")
        return text + (" or null" if self.kind.endswith("?") else "")

    def check(self, value: Any, where: str) -> Any:
        """Return the value coerced to its kind, or raise ConfigError naming ``where``."""

        def fail() -> ConfigError:
            return ConfigError(f"{where}: expected {self.expected()}, got {value!r}")

        if value is None and self.kind.endswith("?"):
            return None
        kind = self.kind.rstrip("?")
        if kind == "bool":
            if not isinstance(value, bool):
                raise fail()
            return value
        if kind == "str":
            if not isinstance(value, str):
                raise fail()
            return value
        if kind == "choice":
            if value not in self.choices:
                raise fail()
            return value
        if kind == "choice_list":
            if not isinstance(value, (list, tuple)) or any(item not in self.choices for item in value):
                raise fail()
            return list(dict.fromkeys(value))
        if kind == "float_list":
            if not isinstance(value, (list, tuple)):  # a resolved (read-only) config holds tuples
                raise fail()
            out = []
            for item in value:
                if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
                    raise fail()
                out.append(float(item))
            return out
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise fail()
        if kind == "int" and (not isinstance(value, int) and not float(value).is_integer()):
            raise fail()
        number = int(value) if kind == "int" else float(value)
        if not math.isfinite(number):
            raise fail()
        if self.low is not None and (number < self.low or (self.low_open and number == self.low)):
            raise fail()
        if self.high is not None and number > self.high:
            raise fail()
        return number


#: a whole-section check: ``check(given, section, source, dotted)`` -> the section to keep, where
#: ``given`` is the document's own value and ``section`` it merged over the defaults
SectionCheck = Callable[[Any, dict[str, Any], str, str], dict[str, Any]]


@dataclass
class Section:
    """A mapping of keys to Fields or nested Sections; ``open_keys`` allows free-form keys;
    ``check`` checks the section as a whole once its keys are (the model's parameters, whose
    symbols depend on its name)."""

    fields: dict[str, Any] = field(default_factory=dict)
    open_keys: bool = False
    doc: str = ""
    check: SectionCheck | None = None


def defaults(schema: Mapping[str, Any]) -> dict[str, Any]:
    """The default document of a schema (nested dicts of default values)."""
    out: dict[str, Any] = {}
    for key, spec in schema.items():
        if isinstance(spec, Section):
            out[key] = defaults(spec.fields)
        else:
            out[key] = list(spec.default) if isinstance(spec.default, list) else spec.default
    return out


def _raise_if_unindented(doc: Mapping[Any, Any], schema: Mapping[str, Any], key: Any, source: str, prefix: str) -> None:
    """An unknown key that belongs to the empty section just above it (``controller:`` with nothing
    under it, then ``law: skyhook`` not indented): say that the section is not a mapping, and why."""
    keys = list(doc)
    holder = None
    for earlier in reversed(keys[: keys.index(key)]):
        spec = schema.get(earlier) if isinstance(earlier, str) else None
        if isinstance(spec, Section) and doc[earlier] is None:
            holder = earlier
            break
        if spec is not None:
            return  # a known key between them: the unknown key is not the empty section's
    if holder is None:
        return
    section = schema[holder]
    stray = [k for k in keys[keys.index(holder) + 1 :] if isinstance(k, str) and k not in schema]
    if not section.open_keys and key not in section.fields:
        return
    raise ConfigError(
        f"{source}: {prefix}{holder}: expected a mapping, got nothing ({', '.join(stray)} "
        f"{'follows' if len(stray) == 1 else 'follow'} it at its level: indent {'it' if len(stray) == 1 else 'them'} "
        f"under {holder}:)"
    )


def validate(doc: Any, schema: Mapping[str, Any], source: str, prefix: str = "") -> dict[str, Any]:
    """Validate ``doc`` against ``schema`` and merge it over the defaults.

    Unknown keys, wrong types and out-of-range values raise :class:`ConfigError` with one line
    ``<source>: <dotted.key>: <problem>``.
    """
    where_root = f"{source}: {prefix.rstrip('.')}" if prefix else source
    if doc is None:
        doc = {}
    if not isinstance(doc, Mapping):
        raise ConfigError(f"{where_root}: expected a mapping of keys, got {type(doc).__name__}")
    out = defaults(schema)
    for key, value in doc.items():
        dotted = f"{prefix}{key}"
        spec = schema.get(key) if isinstance(key, str) else None
        if spec is None:
            _raise_if_unindented(doc, schema, key, source, prefix)
            known = ", ".join(sorted(schema)) or "(none)"
            raise ConfigError(f"{source}: {dotted}: unknown key (known keys here: {known})")
        if isinstance(spec, Section):
            if spec.open_keys:
                if value is None:
                    value = {}
                if not isinstance(value, Mapping):
                    raise ConfigError(f"{source}: {dotted}: expected a mapping, got {value!r}")
                merged = dict(out[key])
                for sub_key, sub_value in value.items():
                    sub_spec = spec.fields.get(sub_key)
                    merged[sub_key] = (
                        sub_spec.check(sub_value, f"{source}: {dotted}.{sub_key}")
                        if isinstance(sub_spec, Field)
                        else sub_value
                    )
                out[key] = merged
            else:
                out[key] = validate(value, spec.fields, source, dotted + ".")
            if spec.check is not None:
                out[key] = spec.check(value, out[key], source, dotted)
        else:
            out[key] = spec.check(value, f"{source}: {dotted}")
    return out
