"""The run folder of docs/architecture.md: ``config.yaml``, ``data.csv``, ``summary.json``, plots
(``config.yaml`` and ``summary.json`` through their one writer, :mod:`sashil.writer.summary_writer`).

A run folder is created only after every input has been checked, so a bad argument leaves nothing
behind; files are written under a temporary name and renamed, so a reader never sees half a file.
"""

from __future__ import annotations

import csv
import io
import shutil
from collections.abc import Iterable, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from sashil.errors import ConfigError
from sashil.recording.data_file import Columns, write_data_csv


def utc_now() -> datetime:
    return datetime.now(timezone.utc)


def utc_stamp(moment: datetime | None = None) -> str:
    """``20261121T103000Z``-style stamp for folder names."""
    return (moment or utc_now()).strftime("%Y%m%dT%H%M%SZ")


#: the run folders this process created (path, whether it made the folder itself): bad input found
#: after a folder was made (a port that cannot be opened, ...) leaves nothing behind (discard_unused)
CREATED: list[tuple[Path, bool]] = []
#: files that hold a run's recorded rows (the verb's record, the runner's stream of every cycle)
DATA_FILES = ("data.csv", "cycles.csv")


def _has_rows(data_csv: Path) -> bool:
    """Whether a data.csv holds at least one row below its header."""
    with data_csv.open("rb") as handle:
        return sum(1 for _ in zip(range(2), handle, strict=False)) > 1


def discard_unused() -> list[Path]:
    """Remove the run folders this process created that hold no recorded data (no ``data.csv`` or
    ``cycles.csv`` with a row, no ``params.yaml``) — what bad input leaves behind; a folder given with ``--out`` that existed
    (empty) is emptied again instead. Returns what was removed."""
    removed = []
    for path, made in CREATED:
        recorded = [f for name in DATA_FILES for f in path.rglob(name)]
        if not path.is_dir() or any(_has_rows(f) for f in recorded) or any(path.rglob("params.yaml")):
            continue
        if made:
            shutil.rmtree(path, ignore_errors=True)
        else:
            for child in path.iterdir():
                if child.is_dir():
                    shutil.rmtree(child, ignore_errors=True)
                else:
                    child.unlink(missing_ok=True)
        removed.append(path)
    CREATED.clear()
    return removed


class RunFolder:
    """One run's folder; every writer is atomic (temp file + rename)."""

    def __init__(self, path: Path, verb: str | None = None):
        self.path = path
        self.verb = verb
        self.started_utc = utc_now()
        self.summary_written = False

    @classmethod
    def create(cls, out: str | Path | None, verb: str, root: str | Path = "runs") -> RunFolder:
        """``out`` or ``runs/<UTC timestamp>-<verb>/``; an existing non-empty ``out`` is refused."""
        if out is None:
            base = Path(root) / f"{utc_stamp()}-{verb}"
            path, suffix = base, 1
            while path.exists():
                suffix += 1
                path = base.with_name(f"{base.name}-{suffix}")
        else:
            path = Path(out)
            if path.exists() and (not path.is_dir() or any(path.iterdir())):
                raise ConfigError(f"--out {path}: exists and is not an empty folder (choose another)")
        made = not path.exists()
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ConfigError(f"--out {path}: cannot create folder ({err.strerror})") from None
        CREATED.append((path, made))
        return cls(path, verb)

    def file(self, name: str) -> Path:
        return self.path / name

    def discard(self) -> None:
        """Remove what this folder holds (and the folder, when this process made it): a run that
        never started leaves nothing behind."""
        made = next((was_made for path, was_made in CREATED if path == self.path), True)
        if made:
            shutil.rmtree(self.path, ignore_errors=True)
        else:
            for child in self.path.iterdir():
                shutil.rmtree(child, ignore_errors=True) if child.is_dir() else child.unlink(missing_ok=True)

    def recorded(self) -> bool:
        """Whether any recorded row (``data.csv`` or ``cycles.csv``, here or in a sub-folder) is on disk."""
        return any(_has_rows(f) for name in DATA_FILES for f in self.path.rglob(name))

    def write_text(self, name: str, text: str) -> Path:
        target = self.file(name)
        tmp = target.with_name(target.name + ".part")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(target)
        return target

    def write_rows(self, name: str, columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> Path:
        """A small CSV table (a header, then ``rows``; None as an empty field), e.g. ``events.csv``."""
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows([["" if value is None else value for value in row] for row in rows])
        return self.write_text(name, buffer.getvalue())

    def write_data(self, columns: Columns, name: str = "data.csv") -> Path:
        return write_data_csv(self.file(name), columns)

    def write_timing(self, timing: Any, name: str = "timing.npz") -> Path:
        """Per-cycle loop timing (``lateness_ns``, ``read_ns``, ``compute_ns``, ``write_ns``, int64
        arrays, one entry per cycle; ``first_cycle``) of a :class:`~sashil.runtime.timing.TimingStats`,
        for reports: the last ``window`` cycles (all of a run of up to about a minute at 1 kHz)."""
        import numpy as np

        target = self.file(name)
        tmp = target.with_name(target.name + ".part")
        arrays = {f"{column}_ns": timing.recent(column) for column in ("lateness", "read", "compute", "write")}
        with open(tmp, "wb") as handle:
            np.savez_compressed(
                handle, rate_hz=np.float64(timing.rate_hz), first_cycle=np.int64(timing.first_recent_cycle()), **arrays
            )
        tmp.replace(target)
        return target
