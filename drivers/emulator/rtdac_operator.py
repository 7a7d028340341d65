"""The person at the emulated RT-DAC bench during ``sashil doctor --walk``: reads the walk's prompts
and does what they ask on the simulated rig behind an :class:`~sashil.drivers.emulator.rtdac_board.RtdacBoard`.

:class:`BenchOperator` holds the arm at a marked angle and lets it go (waiting until it rests before
answering), watches a mark on the road wheel while the motor turns it (Enter as it comes round), or
turns the wheel one revolution by hand (slowing as the mark comes, as a person lines it up), and
reads a clamp meter on the coil's lead (the simulated coil's true current). Its choices (``choices``)
say which steps it agrees to and how; it keeps the terminal's text as a transcript.

It reaches the bench through the simulated rig's own operator hold and road wheel only; the board's
registers are the host's business.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from sashil.drivers.emulator.rtdac_board import RtdacBoard

TWO_PI = 2.0 * math.pi
#: the arm rests when its rate stays under this [rad/s] for REST_FOR_S
REST_RATE_RAD_S = 0.002
REST_FOR_S = 0.5
#: the hand's road speed [rad/s], and its speed within SLOW_RAD of the mark
HAND_RAD_S = 3.0
SLOW_RAD_S = 0.1
SLOW_RAD = 0.05


@dataclass
class BenchOperator:
    """The emulated operator (module docstring). ``choices``: ``outputs`` and ``coil`` ("y"/"n"),
    ``arm`` ("y", or "s" to skip), ``revolution`` ("m", "h" or "s"), ``scale`` (a number in A/V,
    "m" for the meter, or "s")."""

    board: RtdacBoard
    #: the board's clock [s]
    clock: Callable[[], float]
    choices: dict[str, str] = field(default_factory=dict)
    transcript: list[str] = field(default_factory=list)
    _waiting: Callable[[], str | None] | None = None
    _line: str = ""

    # the terminal ---------------------------------------------------------------------------------
    def say(self, text: str) -> None:
        self.transcript.append(text)

    def ask(self, prompt: str) -> str | None:
        """The walk's prompt (``""``: still waiting): an answer, or None while the operator is busy."""
        if prompt:
            self._line = prompt
            self._waiting = self._respond(prompt)
        if self._waiting is None:
            return None
        answer = self._waiting()
        if answer is not None:
            self.transcript.append(self._line + answer)
            self._waiting = None
        return answer

    def _respond(self, prompt: str) -> Callable[[], str | None]:
        """What the operator does for ``prompt``: a function that answers once it is done."""
        text = prompt.lower()
        if "hold the arm at the" in text:
            if self.choices.get("arm", "y") != "y":
                return lambda: "s"
            degrees = float(text.split("hold the arm at the ")[1].split(" deg")[0])
            self.hold_arm(math.radians(degrees))
            return lambda: ""
        if "let the arm go" in text:
            self.let_go()
            return self._arm_rests()
        if "pulse each output" in text:
            return lambda: self.choices.get("outputs", "y")
        if "m, h or s" in text or "h or s (skip)" in text:
            return lambda: self.choices.get("revolution", "m")
        if "press enter as the mark comes back" in text:
            return self._mark_round()
        if "turn the wheel one revolution" in text:
            return self._turn_by_hand()
        if "sense's scale in a per v" in text:
            return lambda: self.choices.get("scale", "s")
        if "your meter reads" in text:
            return lambda: f"{self.board.rig.plant.state.current_a:.4f}"
        if text.strip().startswith("drive "):
            return lambda: self.choices.get("coil", "y")
        return lambda: "s"

    # the bench ------------------------------------------------------------------------------------
    def hold_arm(self, theta_rad: float) -> None:
        """Press the arm to ``theta_rad`` (from the road wheel) and keep it there."""
        self.board.rig.operator_hold(theta_rad, math.inf)

    def let_go(self) -> None:
        self.board.rig.plant.release()

    def _arm_rests(self) -> Callable[[], str | None]:
        still_since: list[float] = []

        def answer() -> str | None:
            rate = abs(self.board.rig.plant.state.theta_dot_rad_s)
            now = self.clock()
            if rate > REST_RATE_RAD_S:
                still_since.clear()
                return None
            if not still_since:
                still_since.append(now)
            return "" if now - still_since[0] >= REST_FOR_S else None

        return answer

    def _road_rad(self) -> float:
        return self.board.rig.plant.state.theta_road_rad

    def _mark_round(self) -> Callable[[], str | None]:
        """Enter at the first look after the wheel has turned a revolution from here."""
        start = self._road_rad()
        return lambda: "" if abs(self._road_rad() - start) >= TWO_PI else None

    def _turn_by_hand(self) -> Callable[[], str | None]:
        """Turn the wheel one revolution forward, slowing near the mark; Enter once it is still there."""
        rig = self.board.rig
        start = self._road_rad()
        rig.wheel.set_speed(rig.plant, HAND_RAD_S)

        def answer() -> str | None:
            left = start + TWO_PI - self._road_rad()
            if left <= 0.0:
                rig.wheel.set_speed(rig.plant, 0.0)
                return ""
            if left < SLOW_RAD and rig.wheel.speed_rad_s > SLOW_RAD_S:
                rig.wheel.set_speed(rig.plant, SLOW_RAD_S)
            return None

        return answer
