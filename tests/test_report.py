"""sashil report: plots and the side-by-side Markdown summary of run folders."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sashil.cli import main
from sashil.errors import DataFileError
from sashil.lab.report import RunRecord, drop_torque, markdown_summary, read_record
from sashil.recording.data_file import write_data_csv

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
    assert header == "| metric | passive 0 A | passive 1 A |"  # named by law and current, not by folder
    period = next(line for line in text.splitlines() if line.startswith("| period [s] |"))
    assert period == f"| period [s] | {run_a['period_s']:.4g} | {run_b['period_s']:.4g} |"
    decrement = next(line for line in text.splitlines() if line.startswith("| log decrement |"))
    assert decrement == f"| log decrement | {run_a['log_decrement']:.4g} | {run_b['log_decrement']:.4g} |"
    assert run_b["log_decrement"] > run_a["log_decrement"]  # more current, more damping
    assert "![theta](theta.png)" in text
    assert "reading" in capsys.readouterr().err  # progress lines


def test_drop_torque_is_minus_k_theta_minus_j_theta_ddot():
    # theta = A (1 - cos(w t)): at rest at t = 0, as at a release; T_d = -k theta - J theta''
    k, J, A, w = 109.0, 1.0, 0.08, 7.0
    t = np.arange(0, 3, 1e-3)
    theta = A * (1.0 - np.cos(w * t))
    _theta, velocity, torque, cutoff = drop_torque(t, theta, k, J, until_s=2.5)
    assert cutoff == pytest.approx(3 * np.sqrt(k / J) / (2 * np.pi))
    inner = (t > 0.1) & (t < 2.4)
    # the Butterworth low-pass is flat well below its cut-off (w = 1.1 Hz, cut-off 5 Hz)
    expected = -k * theta - J * A * w * w * np.cos(w * t)
    assert torque[inner] == pytest.approx(expected[inner], abs=0.01 * J * A * w * w)
    assert velocity[inner] == pytest.approx(A * w * np.sin(w * t[inner]), abs=1e-3 * A * w)
    assert np.isnan(torque[t > 2.5]).all() and np.isnan(torque[0])  # after settling; at the release


def test_drop_torque_of_a_quantised_record_is_smooth():
    # a 4096-count encoder: the low-passed T_d stays within a few percent of the authority, not steps
    k, J, A, w = 109.0, 1.0, 0.08, 10.0
    t = np.arange(0, 3, 1e-3)
    q = 2 * np.pi / 4096
    theta = A * (1.0 - np.cos(w * t))
    _theta, _velocity, torque, _cutoff = drop_torque(t, np.round(theta / q) * q, k, J)
    inner = (t > 0.1) & (t < 2.8)
    expected = -k * theta - J * A * w * w * np.cos(w * t)
    assert np.sqrt(np.mean((torque[inner] - expected[inner]) ** 2)) < 0.05 * J * A * w * w


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
    assert err.count("\n") == 0 and "empty: no summary.json or data file: not a sashil run folder" in err
    assert not out.exists()
    with pytest.raises(DataFileError, match="not a folder"):
        read_record(tmp_path / "missing")


def test_summary_marks_missing_values(tmp_path):
    run = RunRecord(tmp_path / "x", "x", {"verb": "run", "exit_status": "stopped"})
    text = markdown_summary([run], [])
    assert "| x | `x` | run | stopped | – | – | – |" in text
