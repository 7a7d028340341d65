"""The run folders a page may browse: those directly under the runs folder, and only their files.

A page names a run by its folder's name and a file by one of :data:`RUN_FILES`; anything else is
not found. A name with a separator, ``..``, a hidden name, a symbolic link (to a folder or a file)
or a path that resolves outside the runs folder is refused, so no request reaches a file outside it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sashil.errors import ConfigError, SashilError
from sashil.panel.frames import PLOT_COLUMNS, encode_batch

#: the files of a run a page may open, and their media types
RUN_FILES = {
    "summary.json": "application/json",
    "config.yaml": "text/plain; charset=utf-8",
    "report.md": "text/plain; charset=utf-8",
    "events.csv": "text/plain; charset=utf-8",
    "run.png": "image/png",
    "timing.png": "image/png",
}
#: rows of a run sent for an overlay (decimated evenly to at most this many)
OVERLAY_ROWS = 5000


def run_folder(runs_dir: str | Path, name: str) -> Path | None:
    """The folder of run ``name`` directly under ``runs_dir``, or None when the name is not one."""
    root = Path(runs_dir)
    if not name or name.startswith(".") or "/" in name or "\\" in name or name != Path(name).name:
        return None
    folder = root / name
    if folder.is_symlink() or not folder.is_dir():
        return None
    if folder.resolve().parent != root.resolve():
        return None
    return folder


def run_file(runs_dir: str | Path, name: str, file: str) -> Path | None:
    """The file ``file`` (one of :data:`RUN_FILES`) of run ``name``, or None."""
    folder = run_folder(runs_dir, name)
    if folder is None or file not in RUN_FILES:
        return None
    path = folder / file
    if path.is_symlink() or not path.is_file() or path.resolve().parent != folder.resolve():
        return None
    return path


def list_runs(runs_dir: str | Path) -> list[dict[str, Any]]:
    """The run folders under ``runs_dir``, newest first: name, verb, law, road, exit status, start
    time, duration, cycles and missed deadlines (from each ``summary.json``; blank when a run is
    still running or was never summarised)."""
    root = Path(runs_dir)
    if not root.is_dir():
        return []
    runs = []
    for child in sorted(root.iterdir(), reverse=True):
        if run_folder(root, child.name) is None:
            continue
        summary: dict[str, Any] = {}
        path = run_file(root, child.name, "summary.json")
        if path is not None:
            try:
                summary = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                summary = {}
        timing = summary.get("timing") or {}
        runs.append(
            {
                "name": child.name,
                "verb": summary.get("verb", ""),
                "law": str(summary.get("controller") or ""),
                "road": str(summary.get("road") or ""),
                "exit_status": summary.get("exit_status", "running" if path is None else ""),
                "started_utc": summary.get("started_utc", ""),
                "duration_s": summary.get("duration_s"),
                "cycles": timing.get("cycles"),
                "missed_deadlines": timing.get("missed_deadlines"),
                "data": any((child / f).is_file() for f in ("data.csv", "data.parquet")),
                "files": [f for f in RUN_FILES if run_file(root, child.name, f) is not None],
            }
        )
    return runs


def run_traces(runs_dir: str | Path, name: str) -> bytes | None:
    """The :data:`~sashil.panel.frames.PLOT_COLUMNS` of run ``name``'s data, evenly decimated to
    at most :data:`OVERLAY_ROWS` rows, as one binary batch; None when it has no data."""
    from sashil.api import load_run

    folder = run_folder(runs_dir, name)
    if folder is None:
        return None
    try:
        data = load_run(folder).data
    except (SashilError, OSError, ValueError):
        return None
    if "time_s" not in data or not len(data["time_s"]):
        return None
    n = len(data["time_s"])
    step = max(1, -(-n // OVERLAY_ROWS))
    nan = np.full(len(range(0, n, step)), np.nan)
    traces = {c: np.asarray(data[c], dtype=float)[::step] if c in data else nan for c in PLOT_COLUMNS}
    return encode_batch(traces)


#: seconds ``sashil report`` is given for a page's selection
REPORT_TIMEOUT_S = 300.0


def report_runs(runs_dir: str | Path, names: list[str]) -> str:
    """``report.md`` of ``sashil report`` on the runs ``names`` (run in a child process, into a
    temporary folder: the table and figures ``sashil report`` makes); ConfigError (one line) for a
    name that is not a run or a report that fails."""
    import subprocess
    import sys
    import tempfile

    folders = []
    for name in names:
        folder = run_folder(runs_dir, name) if isinstance(name, str) else None
        if folder is None:
            raise ConfigError(f"report: {name!r} is not a run folder in the runs folder")
        folders.append(str(folder))
    if not folders:
        raise ConfigError("report: select one run or more")
    with tempfile.TemporaryDirectory(prefix="sashil-panel-report-") as tmp:
        out = Path(tmp) / "report"
        argv = [sys.executable, "-m", "sashil", "report", "--quiet", f"--out={out}", "--", *folders]
        try:
            done = subprocess.run(
                argv, capture_output=True, text=True, timeout=REPORT_TIMEOUT_S, stdin=subprocess.DEVNULL
            )
        except subprocess.TimeoutExpired:
            raise ConfigError(f"report: no answer within {REPORT_TIMEOUT_S:g} s") from None
        if done.returncode != 0 or not (out / "report.md").is_file():
            lines = done.stderr.strip().splitlines()
            raise ConfigError(lines[-1] if lines else f"report: exit {done.returncode}")
        return (out / "report.md").read_text(encoding="utf-8")
