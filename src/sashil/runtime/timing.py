"""Per-cycle timing of the control loop and its summary statistics, in constant memory.

Each cycle stores four integers (nanoseconds) in preallocated ``array('q')`` rings of ``window``
entries (default 65 536: about a minute at 1 kHz): wake-up lateness (wake-up time minus the
absolute deadline), read latency (``rig.read``), compute (stage, safety and the recording hand-off,
between read and write) and write latency (``rig.write``). Every ``FOLD`` cycles the loop folds the
block just completed into log-spaced histograms (``BUCKETS_PER_OCTAVE`` buckets per doubling: a
quantile read from them is within 0.6 % of the exact one), so a run of any length — 24 h at 5 kHz
is 432 million cycles — keeps the same memory: the rings (2 MB) and five histograms (200 kB).
Nothing is allocated per cycle.

``summary()`` gives the ``timing`` block of ``summary.json`` with the fixed keys of docs/architecture.md
(``rate_hz``, ``cycles``, ``missed_deadlines``, ``lateness_us``, ``compute_us``) and, beside them,
``read_us``, ``write_us`` and ``cycle_us`` (read+compute+write): p50/p99/p99.9 exact while the run
fits in the ring, from the histograms beyond it (``quantiles_from``: ``exact`` or ``histogram``);
``max`` always exact. Lateness counts every *scheduled* cycle: the deadlines an overrun skipped
(:meth:`TimingStats.skip`) enter its quantiles with the lateness each had when the late cycle
finally ran, so a run that lost half its deadlines cannot report a small p99. ``recent(name)`` is the ring's content in cycle order (what ``timing.npz``
holds: the last ``window`` cycles).
"""

from __future__ import annotations

import math
from array import array
from typing import Any

import numpy as np

#: quantiles reported for each timing column (key -> fraction)
QUANTILES = (("p50", 0.50), ("p99", 0.99), ("p99_9", 0.999))
COLUMNS = ("lateness", "read", "compute", "write")
#: the histograms: the four columns and the whole cycle (read + compute + write)
HISTOGRAMS = (*COLUMNS, "cycle")
#: histogram resolution: bucket edges at 2**(k / BUCKETS_PER_OCTAVE) ns
BUCKETS_PER_OCTAVE = 128
#: octaves covered (1 ns .. 2**40 ns = 18 min); longer values land in the last bucket
OCTAVES = 40
N_BUCKETS = 2 + BUCKETS_PER_OCTAVE * OCTAVES
#: cycles per fold of the rings into the histograms (a power of two, dividing the window)
FOLD = 4096
DEFAULT_WINDOW = 65536


def quantiles_us(values: np.ndarray) -> dict[str, float | None]:
    """``{p50, p99, p99_9, max}`` of durations in µs, rounded to ns (all None when there are none)."""
    out: dict[str, float | None] = dict.fromkeys([*(key for key, _ in QUANTILES), "max"])
    if values.size:
        out.update({key: round(float(np.quantile(values, q)), 3) for key, q in QUANTILES})
        out["max"] = round(float(values.max()), 3)
    return out


def bucket_of(values_ns: np.ndarray) -> np.ndarray:
    """Histogram bucket of each duration: 0 for < 1 ns, then BUCKETS_PER_OCTAVE per doubling."""
    v = np.asarray(values_ns, dtype=np.float64)
    out = np.zeros(v.shape, dtype=np.int64)
    positive = v >= 1.0
    out[positive] = 1 + np.floor(np.log2(v[positive]) * BUCKETS_PER_OCTAVE).astype(np.int64)
    return np.minimum(out, N_BUCKETS - 1)


def bucket_value_ns(bucket: int) -> float:
    """The duration a bucket stands for: the geometric middle of its edges (0 for bucket 0)."""
    if bucket <= 0:
        return 0.0
    return float(2.0 ** ((bucket - 1 + 0.5) / BUCKETS_PER_OCTAVE))


def histogram_quantile_ns(counts: np.ndarray, q: float) -> float:
    """The ``q`` quantile of the durations counted in ``counts`` (within half a bucket: 0.3 %)."""
    total = int(counts.sum())
    if total == 0:
        return math.nan
    rank = max(1, math.ceil(q * total))
    bucket = int(np.searchsorted(np.cumsum(counts), rank))
    return bucket_value_ns(bucket)


def _zeros(n: int) -> array:
    return array("q", bytes(8 * n))


def shared_size(window: int = DEFAULT_WINDOW) -> int:
    """Bytes of a shared buffer holding the four rings of ``window`` cycles and the histograms."""
    return 8 * (len(COLUMNS) * window + len(HISTOGRAMS) * N_BUCKETS)


class TimingStats:
    """Per-cycle timing rings (ns), their histograms, and the loop's miss counters (see module doc)."""

    def __init__(self, rate_hz: float, window: int = DEFAULT_WINDOW, shared: Any = None):
        """``shared``: a writable buffer of :func:`shared_size` bytes to hold the rings and the
        histograms (the run's stream, which the session process reads while the loop process
        writes); None: private memory."""
        if window < FOLD or window & (window - 1):
            raise ValueError(f"window must be a power of two >= {FOLD}, got {window}")
        self.rate_hz = float(rate_hz)
        self.window = int(window)
        #: index mask of the rings (the loop writes column[cycle & mask])
        self.mask = self.window - 1
        if shared is None:
            self.lateness, self.read, self.compute, self.write = (_zeros(self.window) for _ in COLUMNS)
            self.histograms = {name: np.zeros(N_BUCKETS, dtype=np.int64) for name in HISTOGRAMS}
        else:
            view = memoryview(shared).cast("B")
            if len(view) < shared_size(self.window):
                raise ValueError(f"shared timing buffer of {len(view)} bytes; {shared_size(self.window)} needed")
            ring = 8 * self.window
            rings: Any = [view[k * ring : (k + 1) * ring].cast("q") for k in range(len(COLUMNS))]
            self.lateness, self.read, self.compute, self.write = rings
            base = len(COLUMNS) * ring
            self.histograms = {
                name: np.frombuffer(view, dtype=np.int64, count=N_BUCKETS, offset=base + 8 * N_BUCKETS * k)
                for k, name in enumerate(HISTOGRAMS)
            }
        self.max_ns = dict.fromkeys(HISTOGRAMS, 0)
        self.folded = 0  # cycles already in the histograms
        self.cycles = 0
        self.missed_deadlines = 0  # whole periods skipped because a cycle started too late
        self.overruns = 0  # occasions on which periods were skipped
        #: lateness of the skipped deadlines (ns), kept for exact quantiles up to ``window`` of them
        self.skipped_lateness: list[np.ndarray] = []
        self.skipped_kept = 0

    def skip(self, late_ns: int, period_ns: int, missed: int) -> None:
        """Count the ``missed`` deadlines an overrun skipped: the cycle that ran ``late_ns`` after its
        deadline passed the next ``missed`` ones, each then ``late_ns - j * period_ns`` late (j = 1..)."""
        if missed <= 0:
            return
        values = late_ns - period_ns * np.arange(1, missed + 1, dtype=np.int64)
        self.histograms["lateness"] += np.bincount(bucket_of(values), minlength=N_BUCKETS)
        room = self.window - self.skipped_kept
        if room > 0:
            self.skipped_lateness.append(values[:room])
            self.skipped_kept += min(room, missed)

    def counters(self) -> dict[str, Any]:
        """What a reader of the shared rings needs beside them to give the same :meth:`summary`: the
        counts, the maxima and the skipped deadlines' lateness (JSON-ready)."""
        return {
            "cycles": self.cycles,
            "missed_deadlines": self.missed_deadlines,
            "overruns": self.overruns,
            "folded": self.folded,
            "max_ns": dict(self.max_ns),
            "skipped_lateness": [int(v) for part in self.skipped_lateness for v in part],
        }

    def restore(self, counters: dict[str, Any]) -> TimingStats:
        """Take the loop's :meth:`counters` (this instance reads the same shared rings)."""
        self.cycles = int(counters["cycles"])
        self.missed_deadlines = int(counters["missed_deadlines"])
        self.overruns = int(counters["overruns"])
        self.folded = int(counters["folded"])
        self.max_ns.update({name: int(value) for name, value in counters["max_ns"].items()})
        skipped = np.asarray(counters.get("skipped_lateness", ()), dtype=np.int64)
        self.skipped_lateness = [skipped] if skipped.size else []
        self.skipped_kept = int(skipped.size)
        return self

    # the loop's side -------------------------------------------------------------------------
    def fold(self) -> None:
        """Add the cycles recorded since the last fold to the histograms (the loop calls this every
        FOLD cycles, after the cycle's write; and ``summary`` for the rest)."""
        start, stop = self.folded, self.cycles
        if stop <= start:
            return
        index = np.arange(start, stop, dtype=np.int64) & self.mask
        block = {name: np.frombuffer(getattr(self, name), dtype=np.int64)[index] for name in COLUMNS}
        block["cycle"] = block["read"] + block["compute"] + block["write"]
        for name, values in block.items():
            self.histograms[name] += np.bincount(bucket_of(values), minlength=N_BUCKETS)
            self.max_ns[name] = max(self.max_ns[name], int(values.max()))
        self.folded = stop

    # readers ---------------------------------------------------------------------------------
    def recent(self, name: str) -> np.ndarray:
        """The ring of one column in cycle order: the last ``min(cycles, window)`` cycles (int64 ns)."""
        data = np.frombuffer(getattr(self, name), dtype=np.int64)
        if self.cycles <= self.window:
            return data[: self.cycles].copy()
        start = self.cycles & self.mask
        return np.concatenate([data[start:], data[:start]])

    def first_recent_cycle(self) -> int:
        """The cycle number of ``recent(...)[0]``."""
        return max(0, self.cycles - self.window)

    def value_ns(self, name: str, cycle: int) -> int | None:
        """One column's value at ``cycle`` while it is still in the ring (else None)."""
        if not self.first_recent_cycle() <= cycle < self.cycles:
            return None
        return int(getattr(self, name)[cycle & self.mask])

    def column_us(self, name: str) -> np.ndarray:
        """One column of the cycles in the ring, in microseconds."""
        return self.recent(name).astype(float) * 1e-3

    def stats_us(self, name: str) -> dict[str, float | None]:
        """``{p50, p99, p99_9, max}`` of a column (or ``cycle``) in µs (None for an empty run); lateness
        with the skipped deadlines (see module doc)."""
        skipped = self.missed_deadlines if name == "lateness" else 0
        exact = self.cycles <= self.window and skipped <= self.skipped_kept
        if exact:  # all of it is in the ring (and the skipped deadlines kept): exact
            if name == "cycle":
                return quantiles_us(self.column_us("read") + self.column_us("compute") + self.column_us("write"))
            values = self.column_us(name)
            if skipped:
                values = np.concatenate([values, *(part.astype(float) * 1e-3 for part in self.skipped_lateness)])
            return quantiles_us(values)
        self.fold()
        counts = self.histograms[name]
        out: dict[str, float | None] = {key: round(histogram_quantile_ns(counts, q) * 1e-3, 3) for key, q in QUANTILES}
        out["max"] = round(self.max_ns[name] * 1e-3, 3)
        return out

    def summary(self) -> dict[str, Any]:
        """The ``timing`` block of summary.json (docs/architecture.md fixed keys plus read/write/cycle)."""
        return {
            "rate_hz": self.rate_hz,
            "cycles": self.cycles,
            "missed_deadlines": self.missed_deadlines,
            "overruns": self.overruns,
            "lateness_us": self.stats_us("lateness"),
            "compute_us": self.stats_us("compute"),
            "read_us": self.stats_us("read"),
            "write_us": self.stats_us("write"),
            "cycle_us": self.stats_us("cycle"),
            "quantiles_from": "exact" if self.cycles <= self.window else "histogram",
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
