"""The simplest loop stage: a constant coil current (the built-in ``passive`` law as ``sashil run`` runs it).

The damper runs passive at a fixed current, 0 A by default, with no estimator or observer in the
cycle (the passive law needs none). The command object is created once and returned every cycle.
"""

from __future__ import annotations

from sashil.drivers.interface import RigCommand, RigSample


class ConstantCurrent:
    """Loop stage commanding ``current_a`` every cycle."""

    name = "passive"

    def __init__(self, current_a: float = 0.0):
        self.current_a = float(current_a)
        self.command = RigCommand(self.current_a)

    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand:
        return self.command
