"""The ``controller:`` section's law and its parameters, checked like every other config key.

The section holds the controller's own keys (estimator, inverse, ...: the schema's ``CONTROLLER``
fields), ``law``, and the chosen law's parameters as ``controller.<param>``. :func:`check_controller`
finds the law, checks each parameter with the law's own :class:`~sashil.control.law_api.Param`
fields (the schema's code), and writes every parameter's value into the section, so a run
folder's ``config.yaml`` says which law ran with which parameters.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

from sashil.config.parts import StageParts
from sashil.config.sections import CONTROLLER
from sashil.control.law_api import Law, LawContext
from sashil.control.law_registry import WHERE, LawEntry, find_law
from sashil.errors import ConfigError
from sashil.models.hysteresis import BoucWenParams

__all__ = ["check_controller", "law_context", "law_parameters"]


def law_parameters(section: Mapping[str, Any]) -> dict[str, Any]:
    """The section's keys that are law parameters (everything but the controller's own keys)."""
    core = CONTROLLER.fields
    return {key: value for key, value in section.items() if key not in core}


def law_context(parts: StageParts) -> LawContext | None:
    """What a law may know of the rig: the controller's Bouc-Wen model, current range, rate and coil
    lag (None when the controller's model is not the rig's Bouc-Wen model)."""
    model = parts.model
    if model.name != "bouc-wen":
        return None
    return LawContext(
        model=BoucWenParams.from_mapping(model.params),
        current_max_a=parts.current_max_a,
        rate_hz=parts.rate_hz,
        coil_tau_s=parts.coil_tau_s,
    )


def build_law(entry: LawEntry, parts: StageParts, section: Mapping[str, Any]) -> Law:
    """An instance of ``entry``'s law with the section's parameters (ConfigError naming the key)."""
    return entry.cls(law_context(parts), **law_parameters(section))


def reads_road_ahead(spec: str) -> bool:
    """Whether the law ``spec`` (a name, ``package.module:Class`` or ``file.py:Class``) reads the road
    ahead (``Law.reads_road_ahead``); False for one that cannot be found (its own check says why)."""
    try:
        return bool(getattr(find_law(spec).cls, "reads_road_ahead", False))
    except ConfigError:
        return False


def check_controller(
    section: dict[str, Any], parts: StageParts, steps: Mapping[str, str], replaced: Collection[str] = ()
) -> LawEntry:
    """Check the ``controller`` ``section`` of a config being resolved (not yet frozen): its law and
    the law's parameters, in place, the law built on the stage's ``parts``; fill in every
    parameter's value, and return the law found. ``replaced``: the parameters of a law that a new
    ``controller.law`` replaced; those the new law does not declare go with the old law, the rest
    keep their values.

    ``steps``: where each key came from (``controller.<key>`` -> the step that set it, as a message
    names it: a file, ``--set``, an option). Errors are one line ``<step>: controller.<key>:
    <problem>``, the step that set the failing key, else the step that set ``controller.law`` (a
    parameter the law gave its default)."""
    try:
        entry = find_law(section["law"])
        for key in set(replaced) - set(entry.cls.params()):
            section.pop(key, None)
        law = build_law(entry, parts, section)
    except ConfigError as err:
        key = str(err).partition(":")[0].strip()
        raise ConfigError(f"{steps.get(key, steps[WHERE])}: {err}") from None
    section.update(law.parameter_values())
    return entry
