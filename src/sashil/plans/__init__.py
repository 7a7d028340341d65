"""The plans a loop builds where it runs, below the engine: the runtime's loop process imports them
by name (:data:`BUILT_IN`), no entry point between them, and the stages a drop hands over to at its
release (:data:`BUILT_IN_STAGES`).

A plan's builder takes the assembled run (its ``plan``: the kind and values; its ``options``), the
rig and where the operator's prompts go, and returns ``(stage, label, road_text)``. A lab's own
plans register under the ``sashil.plans`` entry points (:data:`sashil.plugins.PLANS_GROUP`), and
its own stages under ``sashil.stages`` (:data:`sashil.plugins.STAGES_GROUP`), which are looked up
for a kind not built in.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sashil.plans import drop, run, sweep
from sashil.plans.stages import BUILT_IN_STAGES

__all__ = ["BUILT_IN", "BUILT_IN_STAGES"]

#: the built-in plans by kind: ``build(run, rig, prompt) -> (stage, label, road_text)``
BUILT_IN: dict[str, Callable[..., tuple[Any, str, str]]] = {
    run.KIND: run.build,
    sweep.KIND: sweep.build,
    drop.KIND: drop.drop_in_loop,
}
