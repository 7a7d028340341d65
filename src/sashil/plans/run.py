"""``sashil run``'s plan, built where its loop runs: the law on its road for the run's duration."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from sashil.roads.option import RoadParts, RoadStage, parse_road

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec
    from sashil.drivers.interface import RigInterface

__all__ = ["KIND", "build"]

#: the plan's kind (``RunSpec.plan["kind"]``); its values are the run's ``options``: ``road``, the
#: road's parts (:attr:`~sashil.roads.option.RoadParts.READS`) and ``duration_s``
KIND = "run"


def build(run: RunSpec, rig: RigInterface, prompt: Callable[[str], None]) -> tuple[Any, str, str]:
    """The stage of ``run``: the law on its road (the rig's road motor gets the profile's speed) for
    ``options["duration_s"]``; its label and the road's text. ``rig`` and ``prompt``: unused (the
    run asks the operator nothing)."""
    from sashil.control.registry import make_stage  # the law's stage: only where a loop runs, never to parse a road

    options = run.options
    label, stage = make_stage(run.stage)
    road, road_text = parse_road(options["road"], RoadParts.of(options))
    if road is not None:
        stage = RoadStage(stage, road, options["duration_s"])
    return stage, label, road_text
