"""A run's recorded config, read back from its folder (``config.yaml``) for a report, a plot or a
label: leniently, since a folder may hold a config an older sashil wrote, with keys missing or
sections of another shape; a missing value is None or the schema's default, never an error.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from sashil.config.sections import CONTROLLER

__all__ = ["RecordedModel", "recorded_controller", "recorded_law"]


def recorded_controller(config: Mapping[str, Any]) -> dict[str, Any]:
    """The ``controller:`` mapping of a recorded config ({} when absent or not a mapping)."""
    section = config.get("controller") if isinstance(config, Mapping) else None
    return dict(section) if isinstance(section, Mapping) else {}


def recorded_law(config: Mapping[str, Any]) -> str:
    """The law a recorded config names (``controller.law``; the schema's default when not recorded)."""
    return str(recorded_controller(config).get("law", CONTROLLER.fields["law"].default))


@dataclass(frozen=True)
class RecordedModel:
    """The damper model a recorded config names and the rig's current range it ran in."""

    #: ``model.name`` (None: not recorded)
    name: str | None
    #: ``model.params`` (None: not recorded, or not a mapping)
    params: Mapping[str, Any] | None
    #: ``rig.current_max_a`` [A] (the schema's default, 1 A, when not recorded; None: not a number)
    current_max_a: float | None

    @classmethod
    def read(cls, config: Mapping[str, Any]) -> RecordedModel:
        model = config.get("model") if isinstance(config, Mapping) else None
        rig = config.get("rig") if isinstance(config, Mapping) else None
        model = model if isinstance(model, Mapping) else {}
        rig = rig if isinstance(rig, Mapping) else {}
        params, name = model.get("params"), model.get("name")
        try:
            current_max_a: float | None = float(rig.get("current_max_a", 1.0))
        except (TypeError, ValueError):
            current_max_a = None
        return cls(
            name=None if name is None else str(name),
            params=params if isinstance(params, Mapping) else None,
            current_max_a=current_max_a,
        )
