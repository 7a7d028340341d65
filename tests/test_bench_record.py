"""tools/bench_record.py: the record a benchmark keeps, traceable to the commit it measured (dirty
said), the date and the machine's load; a quick run keeps nothing, nor does a run that fails."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import bench_record


def _git(root: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, check=True).stdout.strip()


def test_the_commit_is_heads_and_says_dirty_when_a_tracked_file_differs(tmp_path):
    _git(tmp_path, "init", "-q")
    (tmp_path / "a.txt").write_text("one\n")
    _git(tmp_path, "add", "a.txt")
    _git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "one")
    head = _git(tmp_path, "rev-parse", "HEAD")
    assert bench_record.commit(tmp_path) == head
    (tmp_path / "b.txt").write_text("untracked\n")  # an untracked file is not the measured tree's
    assert bench_record.commit(tmp_path) == head
    (tmp_path / "a.txt").write_text("two\n")
    assert bench_record.commit(tmp_path) == head + "+dirty"
    assert bench_record.commit(Path("/")) == "unknown"  # no checkout


def test_a_record_carries_the_provenance_and_the_figures_as_json_holds_them(tmp_path, monkeypatch):
    monkeypatch.setattr(bench_record.os, "getloadavg", lambda: (1.5, 1.0, 0.5))
    record = bench_record.Recorder("bench_x", command=["bench_x.py", "--dampers", "all"])
    path = record.write(tmp_path / "out" / "bench_x.json", {"gain": float("nan"), "rows": [(1, 2.5)]})
    kept = json.loads(path.read_text())
    assert kept["benchmark"] == "bench_x" and kept["command"] == ["bench_x.py", "--dampers", "all"]
    assert kept["commit"] == bench_record.commit() and kept["cpus"] >= 1
    assert kept["loadavg"] == kept["loadavg_end"] == [1.5, 1.0, 0.5]
    assert kept["date_utc"].endswith("Z") and kept["date_utc"][:2] == "20"
    assert kept["figures"] == {"gain": None, "rows": [[1, 2.5]]}  # NaN as null: strict JSON


def test_keep_output_keeps_what_a_benchmark_prints_but_not_a_quick_or_failed_run(tmp_path, monkeypatch, capsys):
    def main() -> int:
        print("figure 1: 3.2 us")
        print("figure 2: 4 of 5")
        return 0

    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--runs", "5"])
    assert bench_record.keep_output("bench_x", main, tmp_path / "bench_x.json") == 0
    kept = json.loads((tmp_path / "bench_x.json").read_text())
    assert kept["figures"] == {"output": ["figure 1: 3.2 us", "figure 2: 4 of 5"], "exit": 0}
    assert kept["command"] == ["bench_x.py", "--runs", "5"]
    assert "figure 1: 3.2 us" in capsys.readouterr().out  # still printed as it ran

    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--quick"])
    bench_record.keep_output("bench_x", main, tmp_path / "quick.json")
    assert not (tmp_path / "quick.json").exists()

    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--child", "{}"])  # the tool's own child process
    bench_record.keep_output("bench_x", main, tmp_path / "child.json", children=("--child",))
    assert not (tmp_path / "child.json").exists()

    def fails() -> int:
        raise SystemExit(2)

    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--bad"])
    with pytest.raises(SystemExit):
        bench_record.keep_output("bench_x", fails, tmp_path / "failed.json")
    assert not (tmp_path / "failed.json").exists()
    assert sys.stdout is not None and not isinstance(sys.stdout, bench_record._Tee)
