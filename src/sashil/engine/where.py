"""Where a plan's loop runs: the one rule every verb follows."""

from __future__ import annotations

from typing import Any

from sashil.config.parts import RunSpec

__all__ = ["loop_in_process"]


def loop_in_process(spec: RunSpec, clock: Any, plan: Any = None) -> bool:
    """Whether the loop of ``plan`` in the run ``spec`` runs in a process of its own: on the real
    clock (``clock`` not simulated time) with ``loop.process`` true, for a plan a loop process can
    build (it has a ``spec()`` and it is not None; ``plan`` None: a plan of the run's own kind, which
    can be)."""
    if not spec.loop.process or getattr(clock, "virtual", False):
        return False
    if plan is None:
        return True
    values = getattr(plan, "spec", None)
    return values is not None and values() is not None
