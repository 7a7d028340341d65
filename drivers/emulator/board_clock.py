"""Simulated time for an emulated board driven in the host's process: the board and the host's waits
on one clock, so a run, a walk or a wait for stillness is the same every time."""

from __future__ import annotations


class BoardClock:
    """The board's clock [ns]: each call (one transfer) moves it 20 us; a wait moves it by the wait."""

    #: how long one transfer takes on this clock [ns]
    TRANSFER_NS = 20_000

    def __init__(self, start_ns: int = 1_000_000_000) -> None:
        self.now = start_ns

    def __call__(self) -> int:
        self.now += self.TRANSFER_NS
        return self.now

    def seconds(self) -> float:
        """The time in seconds (a host's ``time.monotonic`` on this clock)."""
        return self.now * 1e-9

    def sleep(self, seconds: float) -> None:
        """A host's ``time.sleep`` on this clock."""
        self.now += round(seconds * 1e9)
