"""The drop test's instruction to the person at the bench, as one line of text, and its reading.

A drop starts from the arm pressed to a hold angle (seed 001 section 8). The host says which in a
prompt, :func:`hold_prompt` ("press the arm to -5 deg ..."), before it connects; the person reads
it and presses. :func:`prompted_hold_deg` reads the angle back out of a line of text, as an
emulated operator that reads the host's console does (``sashil emulate --prompts``): it learns only
what the console says to a person. Both sides of the operator hold read this one phrase: the
host's plans and the emulated operator, which stands beside the backends in ``sashil.drivers``.
"""

from __future__ import annotations

import re

#: the phrase of every hold prompt (``{angle}`` in degrees, ``:g`` formatted)
HOLD_PHRASE = "press the arm to {angle:g} deg"
_HOLD_RE = re.compile(r"press the arm to ([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?) deg")


def hold_prompt(theta0_deg: float) -> str:
    """The start of a hold prompt: ``press the arm to <theta0_deg> deg``."""
    return HOLD_PHRASE.format(angle=theta0_deg)


def prompted_hold_deg(text: str) -> float | None:
    """The angle [deg] of the last hold prompt in ``text``, or None when it holds none."""
    found = _HOLD_RE.findall(text)
    return float(found[-1]) if found else None
