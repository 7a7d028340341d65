"""sashil report: plots and the side-by-side Markdown summary of run folders."""

from __future__ import annotations

import json
from typing import ClassVar

import numpy as np
import pytest

from sashil.cli import main
from sashil.errors import DataFileError
from sashil.recording.data_file import write_data_csv
from sashil.recording.report import drop_torque, load_run, markdown_summary

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def two_drop_runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("drops")
    assert main(["drop-test", "--current", "0", "--duration", "3", "--out", str(root / "A")]) == 0
    assert main(["drop-test", "--current", "1", "--duration", "3", "--out", str(root / "B")]) == 0
    return root / "A", root / "B"


def test_report_on_two_drop_tests_writes_plots_and_side_by_side_summary(two_drop_runs, tmp_path, capsys):
    a, b = two_drop_runs
    out = tmp_path / "R"
    assert main(["report", str(a), str(b), "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["hysteresis.png", "report.md", "theta.png"]
    for name in ("theta.png", "hysteresis.png"):
        assert (out / name).read_bytes()[:8] == PNG
    text = (out / "report.md").read_text()
    (run_a,) = json.loads((a / "summary.json").read_text())["runs"]
    (run_b,) = json.loads((b / "summary.json").read_text())["runs"]
    header = next(line for line in text.splitlines() if line.startswith("| metric |"))
    assert header == "| metric | A 0 A | B 1 A |"
    period = next(line for line in text.splitlines() if line.startswith("| period [s] |"))
    assert period == f"| period [s] | {run_a['period_s']:.4g} | {run_b['period_s']:.4g} |"
    decrement = next(line for line in text.splitlines() if line.startswith("| log decrement |"))
    assert decrement == f"| log decrement | {run_a['log_decrement']:.4g} | {run_b['log_decrement']:.4g} |"
    assert run_b["log_decrement"] > run_a["log_decrement"]  # more current, more damping
    assert "![theta](theta.png)" in text
    assert "reading" in capsys.readouterr().err  # progress lines


def test_drop_torque_is_minus_k_theta_minus_j_theta_ddot():
    # theta = A sin(w t): T_d = -k theta - J theta'' = A (J w^2 - k) sin(w t)
    k, J, A, w = 109.0, 1.0, 0.08, 7.0
    t = np.arange(0, 3, 1e-3)
    _theta, velocity, torque = drop_torque(t, A * np.sin(w * t), k, J)
    inner = slice(100, -100)
    # the 0.12 s cubic Savitzky-Golay fit attenuates theta'' by ~1 % at 7 rad/s: allow 2 % of J A w^2
    assert torque[inner] == pytest.approx(A * (J * w * w - k) * np.sin(w * t[inner]), abs=0.02 * J * A * w * w)
    assert velocity[inner] == pytest.approx(A * w * np.cos(w * t[inner]), abs=1e-3 * A * w)


def test_timing_and_transmissibility_plots_when_the_runs_have_them(tmp_path):
    run = tmp_path / "S"
    run.mkdir()
    (run / "summary.json").write_text(
        json.dumps(
            {
                "verb": "sweep",
                "exit_status": "ok",
                "timing": {
                    "rate_hz": 1000.0,
                    "cycles": 3,
                    "missed_deadlines": 1,
                    "lateness_us": {"p50": 1.0, "p99": 2.0, "max": 1500.0},
                    "compute_us": {"p50": 10.0, "p99": 20.0, "max": 30.0},
                },
                "trips": [{"time_s": 0.002, "reason": "angle interlock"}],
            }
        )
    )
    write_data_csv(run / "transmissibility.csv", {"frequency_hz": [1.0, 1.6, 3.0], "transmissibility": [1.2, 3.5, 0.4]})
    np.savez(
        run / "timing.npz", lateness_ns=np.array([1000, 2000, 1_500_000]), compute_ns=np.array([10_000, 20_000, 30_000])
    )
    out = tmp_path / "R"
    assert main(["report", str(run), "--out", str(out), "--quiet"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["report.md", "timing.png", "transmissibility.png"]
    text = (out / "report.md").read_text()
    assert "| missed deadlines | 1 |" in text
    assert "| lateness p50 / p99 / max [µs] | 1 / 2 / 1500 |" in text
    assert "| trips | 0.002 s angle interlock |" in text


def test_bad_run_folder_is_one_line_exit_2_and_nothing_written(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    out = tmp_path / "R"
    assert main(["report", str(tmp_path / "empty"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "summary.json: no such file" in err
    assert not out.exists()
    with pytest.raises(DataFileError, match="not a folder"):
        load_run(tmp_path / "missing")


def test_summary_marks_missing_values():
    class Run:
        path, label = "x", "x"
        traces: ClassVar[list] = []
        summary: ClassVar[dict] = {"verb": "run", "exit_status": "stopped"}

    text = markdown_summary([Run()], [])
    assert "| x | run | stopped | – | – | – |" in text
