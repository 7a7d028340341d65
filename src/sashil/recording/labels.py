"""Names of what ran, for plot legends and report tables: the law and its parameters, not the folder.

The law comes from ``summary.json`` (``controller``, e.g. ``skyhook`` or ``passive 0.5 A``), its
parameters from the run's ``config.yaml`` ``controller:`` mapping, compared with the law's declared
defaults (:mod:`sashil.control.law_api`) and the controller section's own.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from sashil.config.recorded import recorded_controller
from sashil.config.schema import defaults
from sashil.config.sections import CONTROLLER
from sashil.errors import ConfigError


def controller_section(config: Mapping[str, Any]) -> dict[str, Any]:
    """The ``controller:`` mapping of a run's config ({} when absent or not a mapping)."""
    return recorded_controller(config)


def law_parameters(config: Mapping[str, Any]) -> dict[str, Any]:
    """Every set parameter of the config's controller: the keys besides ``law`` whose value is not null."""
    return {key: value for key, value in controller_section(config).items() if key != "law" and value is not None}


def default_parameters() -> dict[str, Any]:
    """The controller section's defaults from the config schema."""
    return defaults(CONTROLLER.fields)


def law_defaults(law: Any) -> dict[str, Any] | None:
    """The declared parameters of law ``law`` with their defaults, or None when it cannot be found
    (a plug-in that is not installed here)."""
    from sashil.control.law_registry import find_law

    try:
        params = find_law(str(law)).cls.params()
    except ConfigError:
        return None
    return {key: param.default for key, param in params.items()}


def changed_parameters(config: Mapping[str, Any]) -> dict[str, Any]:
    """The controller's keys and the law's parameters set away from their defaults (those that tell
    two runs apart); keys the law does not declare are left out."""
    base = default_parameters()
    declared = law_defaults(controller_section(config).get("law"))
    out = {}
    for key, value in law_parameters(config).items():
        if key in base:
            default = base[key]
        elif declared is None:
            default = None
        elif key in declared:
            default = declared[key]
        else:
            continue
        if value != default:
            out[key] = value
    return out


def format_value(value: Any) -> str:
    """A parameter value as a reader writes it: ``2``, ``0.35``, ``[0.1, 0.9]``, ``kalman``."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    return str(value)


def format_parameters(params: Mapping[str, Any]) -> str:
    """``c_sky=2, zeta=0.3`` (empty when there are none)."""
    return ", ".join(f"{key}={format_value(value)}" for key, value in params.items())


def law_name(summary: Mapping[str, Any], config: Mapping[str, Any]) -> str:
    """What ran, as the run's summary names it (``skyhook``, ``passive 0.5 A``), else the config's law."""
    name = summary.get("controller") if isinstance(summary, Mapping) else None
    if isinstance(name, str) and name:
        return name
    law = controller_section(config).get("law")
    return str(law) if law else "?"


def controller_label(summary: Mapping[str, Any], config: Mapping[str, Any]) -> str:
    """The law and the parameters set away from their defaults: ``skyhook (c_sky=2)``, ``passive 1 A``.

    A passive run's current is in its name already, so ``current_a`` is not repeated."""
    name = law_name(summary, config)
    params = changed_parameters(config)
    if name.startswith("passive"):
        params.pop("current_a", None)
    text = format_parameters(params)
    return f"{name} ({text})" if text else name


def unique_labels(labels: Sequence[str], folders: Sequence[str]) -> list[str]:
    """``labels`` with the folder added to those that two runs share (``passive 0 A [run-a]``)."""
    out = []
    for label, folder in zip(labels, folders, strict=True):
        out.append(f"{label} [{folder}]" if labels.count(label) > 1 else label)
    return out
