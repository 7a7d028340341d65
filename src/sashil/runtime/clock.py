"""Clocks for the loop: integer nanoseconds from one monotonic source (docs/architecture.md, Time).

``RealClock`` sleeps to a margin before the deadline and spins the rest; ``VirtualClock`` jumps
straight to the deadline, so simulated runs are deterministic and faster than real time.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec


class Clock(Protocol):
    def now_ns(self) -> int: ...

    def sleep_until(self, deadline_ns: int) -> None: ...


class RealClock:
    """``time.perf_counter_ns`` with hybrid sleep-then-spin waiting (``spin_ns`` = 0: no spin)."""

    virtual = False

    def __init__(self, spin_ns: int = 200_000):
        self.spin_ns = int(spin_ns)

    @classmethod
    def for_rate(cls, spin_margin_us: float, rate_hz: float) -> RealClock:
        """The loop's clock: spin margin ``loop.spin_margin_us``, at most a quarter of the period.

        The cap keeps a fast loop sleeping part of every period: a SCHED_FIFO thread that spins
        all the time is throttled by the kernel (``sched_rt_runtime_us``: 50 ms off each second).
        """
        period_ns = 1e9 / rate_hz
        return cls(spin_ns=round(min(spin_margin_us * 1000.0, period_ns / 4)))

    def now_ns(self) -> int:
        return time.perf_counter_ns()

    def sleep_until(self, deadline_ns: int) -> None:
        remaining = deadline_ns - time.perf_counter_ns() - self.spin_ns
        if remaining > 0:
            time.sleep(remaining * 1e-9)
        if self.spin_ns:
            while time.perf_counter_ns() < deadline_ns:
                pass


class VirtualClock:
    """Simulated time: ``sleep_until`` advances the clock to the deadline at once."""

    virtual = True

    def __init__(self, start_ns: int = 0):
        self._now = int(start_ns)

    def now_ns(self) -> int:
        return self._now

    def sleep_until(self, deadline_ns: int) -> None:
        if deadline_ns > self._now:
            self._now = int(deadline_ns)

    def advance(self, ns: int) -> None:
        """Let simulated time pass (tests use it to model compute time or a stall)."""
        self._now += int(ns)


def default_clock(spec: RunSpec) -> Clock:
    """The clock of an assembled run: simulated time when its backend is simulated and the config
    does not ask for the real clock (``spec.virtual``), else the real clock at the loop's rate."""
    if spec.virtual:
        return VirtualClock()
    return RealClock.for_rate(spec.loop.spin_margin_us, spec.loop.rate_hz)
