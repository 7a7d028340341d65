"""This machine's wake-up jitter at the loop's rate, under the loop's real-time set-up.

A cyclictest-like measurement: the calling thread takes the config's ``loop.rt`` set-up, then
wakes at every period with the loop's own clock (sleep, then spin the last ``spin_margin_us``) and
records how late each wake-up came. :func:`judge` turns the lateness figures into a row; it is
pure, so tests feed it numbers.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil.diagnostics import FAIL, OK, WARN, Check
from sashil.runtime.clock import RealClock
from sashil.runtime.rt_setup import RealtimeSetup

if TYPE_CHECKING:
    from sashil.config.parts import LoopParts

#: histogram edges of the lateness (µs); the last bin holds everything above the last edge
EDGES_US = (0, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000)


def measure(loop: LoopParts, seconds: float, rate_hz: float | None = None) -> dict[str, Any]:
    """Wake at the loop's rate for ``seconds`` and report the lateness (µs) of each wake-up:
    p50/p99/max, the misses (a wake-up a whole period late), a histogram, and the set-up's outcomes."""
    rate = float(rate_hz if rate_hz is not None else loop.rate_hz)
    period_ns = round(1e9 / rate)
    cycles = max(1, round(seconds * rate))
    clock = RealClock.for_rate(loop.spin_margin_us, rate)
    late = np.zeros(cycles, dtype=np.int64)
    rt = RealtimeSetup.from_parts(loop.rt)
    rt.apply()
    try:
        deadline = clock.now_ns() + period_ns
        for k in range(cycles):
            clock.sleep_until(deadline)
            now = clock.now_ns()
            late[k] = now - deadline
            deadline += period_ns
            if now - deadline >= 0:  # a whole period late: skip to the next deadline ahead, as the loop does
                deadline += ((now - deadline) // period_ns + 1) * period_ns
    finally:
        rt.restore()
    return summarise(late * 1e-3, rate, rt.report())


def summarise(lateness_us: np.ndarray, rate_hz: float, realtime: dict[str, Any] | None = None) -> dict[str, Any]:
    """The figures :func:`judge` reads, from the lateness of each wake-up (µs)."""
    period_us = 1e6 / rate_hz
    counts, _ = np.histogram(lateness_us, bins=[*EDGES_US, math.inf])
    return {
        "rate_hz": rate_hz,
        "cycles": int(lateness_us.size),
        "p50_us": round(float(np.percentile(lateness_us, 50)), 1),
        "p99_us": round(float(np.percentile(lateness_us, 99)), 1),
        "max_us": round(float(lateness_us.max()), 1),
        "misses": int(np.count_nonzero(lateness_us >= period_us)),
        "histogram_us": {f">={edge}": int(n) for edge, n in zip(EDGES_US, counts, strict=True)},
        "realtime": realtime or {},
    }


def judge(figures: dict[str, Any]) -> Check:
    """ok: p99 within a tenth of the period and no miss; warn: p99 within half, or misses under
    0.1 %; fail otherwise (the loop would miss deadlines at this rate)."""
    rate = figures["rate_hz"]
    period_us = 1e6 / rate
    p50, p99, peak, misses, cycles = (figures[k] for k in ("p50_us", "p99_us", "max_us", "misses", "cycles"))
    found = (
        f"{cycles} wake-ups at {rate:g} Hz: late p50 {p50:g} / p99 {p99:g} / max {peak:g} us, "
        f"{misses} missed; p99 is {100 * p99 / period_us:.0f} % of the {period_us:g} us period"
    )
    failed = [name for name, o in figures.get("realtime", {}).items() if o.get("status") == "failed"]
    if failed:
        found += f" (set-up failed: {', '.join(failed)})"
    if misses == 0 and p99 <= 0.1 * period_us:
        return Check("machine", "jitter", OK, found + ": this rate is safe", data=figures)
    fix = "fix the rows above (SCHED_FIFO, governor, isolated CPU), or --set loop.rate_hz lower"
    if misses <= 0.001 * cycles and p99 <= 0.5 * period_us:
        return Check("machine", "jitter", WARN, found + ": expect occasional late cycles", fix, data=figures)
    return Check("machine", "jitter", FAIL, found + ": the loop will miss deadlines at this rate", fix, data=figures)


__all__ = ["EDGES_US", "judge", "measure", "summarise"]
