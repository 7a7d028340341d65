"""What of an RT-DAC bench's wiring is a guess, and the limits a guessed wiring runs under: pure, no I/O.

Nobody outside INTECO knows which counter, output and converter the SAS rig wires where, so every
wiring key of the ``rtdac`` section is a guess until ``sashil doctor --driver rtdac --walk`` confirms
it (``rtdac.confirmed``). A group not wholly confirmed runs under its bring-up cap: the coil at
``rtdac.bringup_current_max_a`` (a wrong coil channel then drives at most the map's output for that
current), the road motor at ``rtdac.bringup_road_output`` of its output limit (a reversed or wrong
road encoder then runs the road away slowly enough for the supervisor's road trips to end it).
"""

from __future__ import annotations

from dataclasses import dataclass

from sashil.config.rtdac_section import COIL_KEYS, ROAD_KEYS, WIRING_KEYS
from sashil.drivers.rtdac_wiring import Wiring


@dataclass(frozen=True)
class BringUp:
    """The guessed keys of a wiring and the limits they impose."""

    #: the wiring keys doctor --walk has not confirmed, in the section's order
    guesses: tuple[str, ...]
    #: the coil's wiring is not wholly confirmed: its current is capped
    coil_capped: bool
    #: the road's wiring is not wholly confirmed: its output is capped
    road_capped: bool
    #: the largest coil current a command may reach [A]
    current_max_a: float
    #: the largest road output magnitude [V, or duty]
    road_output_limit: float
    #: the road output's unit: "V" (a D/A) or "duty" (a PWM)
    road_unit: str = "V"

    @classmethod
    def of(cls, wiring: Wiring, current_max_a: float) -> BringUp:
        """The guesses and caps of ``wiring`` on a rig whose coil takes at most ``current_max_a``."""
        confirmed = set(wiring.confirmed)
        guesses = tuple(key for key in WIRING_KEYS if key not in confirmed)
        coil_capped = any(key in guesses for key in COIL_KEYS)
        road_capped = wiring.road_output != "none" and any(key in guesses for key in ROAD_KEYS)
        current = min(current_max_a, wiring.bringup_current_max_a) if coil_capped else current_max_a
        road = wiring.road_output_limit * (wiring.bringup_road_output if road_capped else 1.0)
        return cls(guesses, coil_capped, road_capped, current, road, "duty" if wiring.road_output == "pwm" else "V")

    def caps(self) -> list[str]:
        """The caps in force, each as a phrase ("the coil at 0.3 A (rtdac.bringup_current_max_a)")."""
        out = []
        if self.coil_capped:
            out.append(f"the coil at {self.current_max_a:g} A (rtdac.bringup_current_max_a)")
        if self.road_capped:
            size = f"{self.road_output_limit:g} V" if self.road_unit == "V" else f"duty {self.road_output_limit:g}"
            out.append(f"the road output at {size} (rtdac.bringup_road_output)")
        return out

    def line(self) -> str | None:
        """One line for a run's start: which keys are guesses and which caps hold (None: all confirmed)."""
        if not self.guesses:
            return None
        caps = self.caps()
        held = f"; until then {' and '.join(caps)}" if caps else ""
        return (
            f"rtdac: guessed wiring, not confirmed by `sashil doctor --driver rtdac --walk`: "
            f"{', '.join(self.guesses)}{held}"
        )

    def facts(self) -> dict[str, object]:
        """The summary's record of it (``link.guesses``, ``link.caps``)."""
        return {"guesses": list(self.guesses), "caps": self.caps()}
