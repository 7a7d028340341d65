"""The stages a drop hands over to at its release, found by kind where its loop runs: a built-in
stage of :data:`BUILT_IN_STAGES` by name, else a lab's own under the ``sashil.stages`` entry
points (:data:`sashil.plugins.STAGES_GROUP`)."""

from __future__ import annotations

from typing import Any

from sashil.plans import calibration_step
from sashil.plugins import STAGES_GROUP, built_in_or_registered, load_class

__all__ = ["BUILT_IN_STAGES", "stage_class", "stage_from_spec"]

#: the built-in stages by kind: each class's ``from_spec(spec)`` builds it from its ``spec()``
BUILT_IN_STAGES: dict[str, type] = {calibration_step.KIND: calibration_step.StepStage}


def stage_class(kind: str) -> type:
    """The class of the stage of ``kind``: built in, else the ``sashil.stages`` entry point of that
    name; a one-line ConfigError naming the known kinds (built-in and registered) for any other."""
    return built_in_or_registered(
        "stage",
        kind,
        BUILT_IN_STAGES,
        STAGES_GROUP,
        load_class,
        lambda kind, known: f"no stage of kind {kind!r} is built in or registered (known: {known})",
    )


def stage_from_spec(spec: dict[str, Any]) -> Any:
    """The stage a ``spec()`` describes (its ``kind`` names the class, whose ``from_spec`` builds it)."""
    return stage_class(str(spec.get("kind"))).from_spec(spec)  # type: ignore[attr-defined]  # the stage's own constructor
