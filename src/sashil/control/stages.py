"""The simplest loop stage: a constant coil current (the built-in ``passive`` law as ``sashil run`` runs it).

The damper runs passive at a fixed current, 0 A by default, with no estimator or observer in the
cycle (the passive law needs none). The command object is created once and returned every cycle.
"""

from __future__ import annotations

from typing import Any

from sashil.drivers.interface import RigCommand, RigSample


class ConstantCurrent:
    """Loop stage commanding ``current_a`` every cycle; with ``law`` (the passive law), its
    ``current_a`` instead, read each cycle, so a live change of ``controller.current_a`` applies."""

    name = "passive"

    def __init__(self, current_a: float = 0.0, law: Any = None):
        self.law = law
        self.current_a = float(current_a if law is None else law.current_a)
        self.command = RigCommand(self.current_a)

    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand:
        law = self.law
        if law is not None:
            self.command.current_a = law.current_a
        return self.command
