"""Per-cycle timing of the control loop and its summary statistics.

Each cycle stores four integers (nanoseconds) in preallocated ``array('q')`` columns: wake-up
lateness (wake-up time minus the absolute deadline), read latency (``rig.read``), compute
(stage, safety and the recording hand-off, between read and write) and write latency
(``rig.write``). Nothing is allocated per cycle except when a column fills up (it then doubles,
once per ~65 s at 1 kHz for an open-ended run). The statistics (p50/p99/p99.9/max in µs) are
computed after the run; ``summary()`` gives the ``timing`` block of ``summary.json`` with the
fixed keys of DESIGN.md (``rate_hz``, ``cycles``, ``missed_deadlines``, ``lateness_us``,
``compute_us``) and, beside them, ``read_us``, ``write_us`` and ``cycle_us`` (read+compute+write).
"""

from __future__ import annotations

from array import array
from typing import Any

import numpy as np

#: quantiles reported for each timing column (key -> fraction)
QUANTILES = (("p50", 0.50), ("p99", 0.99), ("p99_9", 0.999))


def quantiles_us(values: np.ndarray) -> dict[str, float | None]:
    """``{p50, p99, p99_9, max}`` of durations in µs, rounded to ns (all None when there are none)."""
    out: dict[str, float | None] = dict.fromkeys([*(key for key, _ in QUANTILES), "max"])
    if values.size:
        out.update({key: round(float(np.quantile(values, q)), 3) for key, q in QUANTILES})
        out["max"] = round(float(values.max()), 3)
    return out


COLUMNS = ("lateness", "read", "compute", "write")


def _zeros(n: int) -> array:
    return array("q", bytes(8 * n))


class TimingStats:
    """Preallocated per-cycle timing columns (ns) plus the loop's miss counters."""

    def __init__(self, rate_hz: float, capacity: int = 65536):
        self.rate_hz = float(rate_hz)
        self.capacity = max(int(capacity), 16)
        self.lateness = _zeros(self.capacity)
        self.read = _zeros(self.capacity)
        self.compute = _zeros(self.capacity)
        self.write = _zeros(self.capacity)
        self.cycles = 0
        self.missed_deadlines = 0  # whole periods skipped because a cycle started too late
        self.overruns = 0  # occasions on which periods were skipped

    def grow(self) -> None:
        """Double every column (called by the loop when ``cycles`` reaches ``capacity``)."""
        for name in COLUMNS:
            getattr(self, name).extend(_zeros(self.capacity))
        self.capacity *= 2

    def column_us(self, name: str) -> np.ndarray:
        """One column of the cycles so far, in microseconds."""
        data = np.frombuffer(getattr(self, name), dtype=np.int64, count=self.cycles)
        return data.astype(float) * 1e-3

    def stats_us(self, name: str) -> dict[str, float | None]:
        """``{p50, p99, p99_9, max}`` of a column in µs (None for an empty run)."""
        return quantiles_us(self.column_us(name))

    def summary(self) -> dict[str, Any]:
        """The ``timing`` block of summary.json (DESIGN.md fixed keys plus read/write/cycle)."""
        cycle = self.column_us("read") + self.column_us("compute") + self.column_us("write")
        cycle_stats = quantiles_us(cycle)
        return {
            "rate_hz": self.rate_hz,
            "cycles": self.cycles,
            "missed_deadlines": self.missed_deadlines,
            "overruns": self.overruns,
            "lateness_us": self.stats_us("lateness"),
            "compute_us": self.stats_us("compute"),
            "read_us": self.stats_us("read"),
            "write_us": self.stats_us("write"),
            "cycle_us": cycle_stats,
        }


def format_timing(timing: dict[str, Any]) -> str:
    """A few lines for the end of a run (what ``sashil run`` prints)."""

    def row(label: str, stats: dict[str, float | None]) -> str:
        cells = "  ".join(
            f"{key}={'-' if stats[key] is None else format(stats[key], '.1f')}"
            for key in ("p50", "p99", "p99_9", "max")
        )
        return f"  {label:<9} {cells} us"

    lines = [
        f"timing: {timing['cycles']} cycles at {timing['rate_hz']:g} Hz, "
        f"{timing['missed_deadlines']} missed deadline(s) in {timing['overruns']} overrun(s)",
        row("lateness", timing["lateness_us"]),
        row("compute", timing["compute_us"]),
        row("read", timing["read_us"]),
        row("write", timing["write_us"]),
    ]
    return "\n".join(lines)
