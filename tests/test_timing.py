"""Loop timing in constant memory: rings of the last cycles, log histograms for the quantiles."""

from __future__ import annotations

import numpy as np
import pytest

from sashil.drivers import rig_parts
from sashil.runtime.timing import (
    BUCKETS_PER_OCTAVE,
    FOLD,
    TimingStats,
    bucket_of,
    bucket_value_ns,
    histogram_quantile_ns,
)


def _fill(stats: TimingStats, columns: dict[str, np.ndarray]) -> None:
    """Write cycles as the loop does: into the rings at cycle & mask, folding every FOLD cycles."""
    n = len(columns["lateness"])
    for cycle in range(n):
        slot = cycle & stats.mask
        for name, values in columns.items():
            getattr(stats, name)[slot] = int(values[cycle])
        stats.cycles = cycle + 1
        if not stats.cycles & (FOLD - 1):
            stats.fold()


def test_buckets_are_log_spaced_and_a_bucket_stands_for_its_middle():
    assert bucket_of(np.array([0, 1, 2, 4, 1024])).tolist() == [
        0,
        1,
        1 + BUCKETS_PER_OCTAVE,
        1 + 2 * BUCKETS_PER_OCTAVE,
        1 + 10 * BUCKETS_PER_OCTAVE,
    ]
    for v in (3, 17, 999, 123_456, 9_876_543):
        assert bucket_value_ns(int(bucket_of(np.array([v]))[0])) == pytest.approx(
            v, rel=2 ** (0.5 / BUCKETS_PER_OCTAVE) - 1 + 1e-9
        )
    counts = np.zeros(4000, dtype=np.int64)
    counts[int(bucket_of(np.array([1000]))[0])] = 99
    counts[int(bucket_of(np.array([50_000]))[0])] = 1
    assert histogram_quantile_ns(counts, 0.5) == pytest.approx(1000, rel=0.003)
    assert histogram_quantile_ns(counts, 0.999) == pytest.approx(50_000, rel=0.003)


def test_a_long_run_keeps_constant_memory_and_its_quantiles_within_a_bucket():
    rng = np.random.default_rng(7)
    n = 3 * 8192 + 1234  # longer than the ring: the quantiles come from the histograms
    columns = {
        "lateness": rng.lognormal(np.log(3_000), 0.6, n),
        "read": rng.lognormal(np.log(8_000), 0.3, n),
        "compute": rng.lognormal(np.log(12_000), 0.4, n),
        "write": rng.lognormal(np.log(2_000), 0.2, n),
    }
    columns = {k: np.floor(v) for k, v in columns.items()}
    stats = TimingStats(1000.0, window=8192)
    _fill(stats, columns)
    assert len(stats.lateness) == 8192 and stats.cycles == n  # the rings never grow
    summary = stats.summary()
    assert summary["quantiles_from"] == "histogram" and summary["cycles"] == n
    for name in ("lateness", "read", "compute", "write"):
        # the order statistic at rank ceil(q N), which a histogram reads (np.quantile's default
        # interpolates between neighbours, far apart in a sparse tail)
        exact = np.quantile(columns[name], [0.5, 0.99, 0.999], method="inverted_cdf") * 1e-3
        got = [summary[f"{name}_us"][k] for k in ("p50", "p99", "p99_9")]
        assert got == pytest.approx(exact, rel=0.006)
        assert summary[f"{name}_us"]["max"] == pytest.approx(columns[name].max() * 1e-3, abs=1e-3)  # exact
    cycle = columns["read"] + columns["compute"] + columns["write"]
    assert summary["cycle_us"]["p99"] == pytest.approx(
        np.quantile(cycle, 0.99, method="inverted_cdf") * 1e-3, rel=0.006
    )
    # the ring holds the last window of cycles in order
    assert stats.first_recent_cycle() == n - 8192
    assert np.array_equal(stats.recent("compute"), columns["compute"][-8192:].astype(np.int64))
    assert stats.value_ns("read", n - 1) == int(columns["read"][-1]) and stats.value_ns("read", 5) is None


def test_a_short_run_is_exact():
    stats = TimingStats(500.0, window=8192)
    values = np.arange(1, 1001) * 1000.0
    _fill(stats, {"lateness": values, "read": values, "compute": values, "write": values})
    summary = stats.summary()
    assert summary["quantiles_from"] == "exact"
    assert summary["lateness_us"]["p50"] == pytest.approx(np.quantile(values, 0.5) * 1e-3)
    assert summary["cycle_us"]["max"] == pytest.approx(3000.0)


def test_the_window_is_a_power_of_two_of_whole_folds():
    with pytest.raises(ValueError):
        TimingStats(1000.0, window=5000)
    with pytest.raises(ValueError):
        TimingStats(1000.0, window=FOLD // 2)


def test_the_loop_runs_past_the_ring_in_constant_memory():
    from sashil.control.stages import ConstantCurrent
    from sashil.drivers import open_rig
    from sashil.engine.resolve import default_config
    from sashil.runtime.clock import VirtualClock
    from sashil.runtime.loop import ControlLoop

    loop = ControlLoop(open_rig(rig_parts(default_config())), ConstantCurrent(0.2), VirtualClock(), 5000.0, 30.0)
    loop.timing = TimingStats(5000.0, window=16384)  # a small ring: 150 000 cycles wrap it 9 times
    loop.result.timing = loop.timing
    loop.run()
    timing = loop.timing
    assert timing.cycles == 150_000 and len(timing.lateness) == 16384
    assert timing.folded == 150_000 - 150_000 % FOLD  # folded as it ran
    summary = timing.summary()
    assert summary["quantiles_from"] == "histogram" and int(timing.histograms["compute"].sum()) == 150_000
