"""What a stopped run's outputs were confirmed at, in words: pure, read from a run's summary.

A coil whose current is sensed is confirmed at 0 A by the current itself (``safe_state``: the
loop's settling read it). A board that reads back its outputs (``link.safe_state_confirmed``) but
senses no current confirms its outputs at rest, not 0 A: nothing measures the current. A stop that
confirmed neither says so, and names the E-stop.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: what a stop says when its board confirmed the outputs at rest and no sense measures the coil
NO_SENSE_REST = "outputs at rest (no current sense)"


def rest_phrase(summary: Mapping[str, Any]) -> str:
    """``damper at 0 A`` (a sensed or simulated coil), ``outputs at rest (no current sense)``, or a
    warning that nothing confirmed the rest."""
    safe = summary.get("safe_state") or {}
    link = summary.get("link") or {}
    sensed = safe.get("sensed", True) and str(link.get("current_source", "")) != "none (no current sense)"
    board = link.get("safe_state_confirmed")
    if board is False:
        return "the board did NOT confirm its outputs at rest: use the E-stop"
    if not sensed:
        return NO_SENSE_REST if board else "outputs commanded to rest (no current sense, no readback)"
    if safe and not safe.get("confirmed", True):
        return f"coil NOT confirmed at 0 A ({safe.get('current_a')} A): check the rig"
    return "damper at 0 A"


def safe_state_current(safe: Mapping[str, Any]) -> str:
    """The settled coil current as text: ``coil at 0.012 A``, or ``no current sense``."""
    current = safe.get("current_a")
    return "no current sense" if current is None else f"coil at {float(current):.3f} A"


__all__ = ["NO_SENSE_REST", "rest_phrase", "safe_state_current"]
