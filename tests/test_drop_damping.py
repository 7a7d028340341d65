"""A drop test's damping ratio does not depend on the record length; its interval, notes and sentences."""

from __future__ import annotations

import json
import math
import runpy
import sys
from pathlib import Path

import numpy as np
import pytest

from sashil.cli import main
from sashil.engine.resolve import default_config
from sashil.lab._drop_test import run_drop_test
from sashil.lab.metrics import (
    DAMPING_CYCLES,
    damping_ratio_of,
    drop_metrics,
    log_decrement_of,
    no_peaks_reason,
    settling_text,
)

COUNT = 2 * math.pi / 4096  # one count of the default encoder [rad]
TOOLS = Path(__file__).resolve().parents[1] / "tools"


def _drop(params: dict[str, float], current: float, duration: float, counts: int = 4096):
    config = default_config()
    config["model"]["params"].update(params)
    config["rig"]["encoder_counts_per_rev"] = counts
    return run_drop_test(config, -5.0, current, duration).metrics


@pytest.mark.parametrize(
    "params,current",
    [({}, 0.0), ({}, 1.0), ({"c1": 0.05}, 0.0), ({"J": 2.0, "k": 70.0}, 0.0), ({"alpha1": 2.0, "delta": 300.0}, 0.0)],
)
def test_damping_ratio_agrees_over_3_4_and_10_s_records(params, current):
    ratios = [_drop(params, current, duration).damping_ratio for duration in (3.0, 4.0, 10.0)]
    assert None not in ratios
    assert (max(ratios) - min(ratios)) / ratios[-1] <= 0.02


def test_interval_holds_the_unquantised_decrement_of_the_same_peaks():
    coarse = _drop({}, 0.0, 4.0)
    fine = _drop({}, 0.0, 4.0, counts=2**24).peaks_deg
    k = coarse.damping_cycles
    assert k == DAMPING_CYCLES
    reference = damping_ratio_of(math.log(fine[0] / fine[k]) / k)
    low, high = coarse.damping_ratio_interval
    assert low < coarse.damping_ratio < high
    assert low <= reference <= high


def test_log_decrement_spans_the_first_cycles_on_peaks_of_eight_counts():
    amplitudes = [50, 40, 33, 27, 7]  # counts; the later peaks would raise a record-long mean
    peaks = [(0.3 + 0.6 * n, a * COUNT) for n, a in enumerate(amplitudes)]
    fit = log_decrement_of(peaks, COUNT, record_end_s=10.0, period_s=0.6)
    assert fit.cycles == 2 and fit.note is None
    assert fit.value == pytest.approx(math.log(50 / 33) / 2)
    assert fit.low == pytest.approx(math.log(49.5 / 33.5) / 2)
    assert fit.high == pytest.approx(math.log(50.5 / 32.5) / 2)


def test_a_record_that_ends_within_the_cycles_says_so():
    peaks = [(0.3, 50 * COUNT), (0.9, 40 * COUNT)]
    fit = log_decrement_of(peaks, COUNT, record_end_s=1.2, period_s=0.6)
    assert fit.cycles == 1 and fit.record_short
    assert "the record ends 1.2 s after the release, before the next peak; record at least 1.6 s" in fit.note


def test_a_swing_that_decays_below_eight_counts_is_not_called_short():
    peaks = [(0.3, 50 * COUNT), (0.9, 12 * COUNT), (1.5, 5 * COUNT)]
    fit = log_decrement_of(peaks, COUNT, record_end_s=10.0, period_s=0.6)
    assert fit.cycles == 1 and not fit.record_short
    assert fit.note == (
        "the damping ratio spans 1 of 2 cycles: 2 peaks are at least 8 encoder counts (0.70 deg) high, "
        "the later ones are lower"
    )
    none = log_decrement_of([(0.3, 7 * COUNT)], COUNT, record_end_s=10.0, period_s=None)
    assert none.value is None and none.cycles == 0 and not none.record_short


def test_no_peaks_says_why():
    t = np.linspace(0.0, 3.0, 3001)
    overdamped = -math.radians(5.0) * np.exp(-3.0 * t)
    assert "did not swing past +0.35 deg" in no_peaks_reason(t, overdamped, math.radians(0.35))
    short = t[:201]
    swing = -math.radians(5.0) * np.cos(2 * math.pi * short / 0.6)
    assert "ends 0.2 s after the release, before the first swing above 0 is over" in no_peaks_reason(
        short, swing, math.radians(0.35)
    )
    assert no_peaks_reason(t[:0], t[:0], 0.01) == "nothing was recorded after the release"


def test_settling_sentences():
    t = np.linspace(0.0, 2.0, 2001)
    decaying = drop_metrics(t, math.radians(5.0) * np.exp(-3.0 * t) * np.cos(10 * t))
    assert settling_text(decaying, 2.0).startswith("stays inside ±0.25 deg from ")
    moving = drop_metrics(t, math.radians(5.0) * np.cos(10 * t))
    assert settling_text(moving, 2.0) == "still outside ±0.25 deg at the end of the record (2 s)"


def test_cli_prints_and_records_the_damping_ratio_with_its_interval(tmp_path, capsys):
    out = tmp_path / "D"
    assert main(["drop-test", "--duration", "3", "--out", str(out)]) == 0
    (run,) = json.loads((out / "summary.json").read_text())["runs"]
    low, high = run["damping_ratio_interval"]
    assert low < run["damping_ratio"] < high and run["damping_cycles"] == 2
    err = capsys.readouterr().err
    assert f"ζ {run['damping_ratio']:.4f} [{low:.4f}, {high:.4f}] (first 2 cycles)" in err
    assert "still outside ±0.25 deg at the end of the record (3 s)" in err
    assert "not within the record" not in err


def test_cli_warns_when_no_peak_was_found(tmp_path, capsys):
    assert main(["drop-test", "--duration", "0.2", "--out", str(tmp_path / "D")]) == 0
    err = capsys.readouterr().err
    assert "period -, peaks [] deg" in err
    assert "drop test at 0 A: no peaks: the record ends 0.2 s after the release" in err


@pytest.mark.parametrize("theta0", ["-0.087", "0.3", "0"])
def test_a_theta0_inside_the_release_threshold_is_refused_at_once(tmp_path, capsys, theta0):
    out = tmp_path / "D"
    assert main(["drop-test", "--theta0-deg", theta0, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--theta0-deg: expected an angle at least drop_test.release_threshold_deg = 0.5 deg from 0" in err
    assert "\n" not in err and not out.exists()


def test_bench_quick_meets_the_goal(capsys, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["bench_drop_damping.py", "--quick"])
    runpy.run_path(str(TOOLS / "bench_drop_damping.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "spread of zeta over 3/4/10 s records, 5 drops: worst 0.00 %" in out
    assert "interval holds the unquantised encoder's zeta: 5 of 5" in out
