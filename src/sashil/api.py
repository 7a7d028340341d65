"""The Python API to run folders: ``sashil.load_run(folder)``.

>>> run = sashil.load_run("runs/20261124T101500Z-run")          # doctest: +SKIP
>>> run.data["theta_rad"], run.summary["timing"]["lateness_us"]["p99"], run.config["loop"]["rate_hz"]

A :class:`Run` reads any verb's folder: ``data.csv`` (or ``data.parquet`` / ``data.mat`` when
that is what the folder holds), ``summary.json`` and ``config.yaml``; extra tables such as a
stepped sweep's ``transmissibility.csv`` are in :attr:`Run.tables`. A folder with sub-runs (a
drop test at several currents) lists them in :attr:`Run.runs`, each a :class:`Run` of its own;
for a single run ``run.runs == [run]``, so ``for r in run.runs: ...`` works for both.
Files are read when first asked for.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from sashil.errors import DataFileError
from sashil.recording.data_file import read_data_csv
from sashil.recording.parquet_sink import read_parquet
from sashil.recording.units import column_unit

__all__ = ["DATA_FILES", "Run", "load_run"]

#: the data files a run folder may hold, in the order they are tried
DATA_FILES = ("data.parquet", "data.csv", "data.mat")


def _read_json(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as err:
        raise DataFileError(f"{path}: not readable JSON ({err})") from None
    if not isinstance(doc, dict):
        raise DataFileError(f"{path}: expected a JSON object, got {type(doc).__name__}")
    return doc


def _read_yaml(path: Path) -> dict[str, Any]:
    import yaml

    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, yaml.YAMLError) as err:
        raise DataFileError(f"{path}: not readable YAML ({str(err).splitlines()[0]})") from None
    return doc if isinstance(doc, dict) else {}


def read_data_file(path: Path) -> dict[str, np.ndarray]:
    """Columns of one data file (``.csv``, ``.parquet`` or ``.mat``), column name -> 1-D array."""
    suffix = path.suffix
    if suffix == ".parquet":
        return read_parquet(path)
    if suffix == ".mat":
        from scipy.io import loadmat

        try:
            doc = loadmat(path, squeeze_me=True)
        except (OSError, ValueError) as err:
            raise DataFileError(f"{path}: not a readable MATLAB file ({err})") from None
        names = [str(n) for n in np.atleast_1d(doc.get("columns", []))]
        return {name: np.atleast_1d(np.asarray(doc[name], dtype=float)) for name in names if name in doc}

    return read_data_csv(path, required=(), min_rows=0)


@dataclass
class Run:
    """One run folder (or one sub-run of it). ``data``, ``summary``, ``config`` load on first use."""

    path: Path
    _sub_entries: list[dict[str, Any]] = field(default_factory=list, repr=False)

    @cached_property
    def summary(self) -> dict[str, Any]:
        """``summary.json`` (its common keys: :mod:`sashil.recording.summary_schema`); {} if absent."""
        return _read_json(self.path / "summary.json")

    @cached_property
    def config(self) -> dict[str, Any]:
        """The resolved config the run ran with (``config.yaml``); {} if absent."""
        return _read_yaml(self.path / "config.yaml")

    @property
    def data_file(self) -> Path | None:
        """The data file :attr:`data` reads (Parquet first when pyarrow is installed), or None."""
        for name in DATA_FILES:
            candidate = self.path / name
            if candidate.exists():
                if name == "data.parquet" and not _has_pyarrow():
                    continue
                return candidate
        return None

    @cached_property
    def data(self) -> dict[str, np.ndarray]:
        """Column name -> numpy array (docs/architecture.md columns: ``time_s``, ``theta_rad``, ...)."""
        source = self.data_file
        if source is None:
            if len(self.runs) > 1 or (self.runs and self.runs[0] is not self):
                names = ", ".join(r.name for r in self.runs)
                raise DataFileError(
                    f"{self.path}: holds {len(self.runs)} sub-runs ({names}): use run.runs[i].data or run.run(name).data"
                )
            raise DataFileError(f"{self.path}: no data file ({', '.join(DATA_FILES)})")
        return read_data_file(source)

    @property
    def name(self) -> str:
        """The folder's name (a sub-run's: ``i1.000A``)."""
        return self.path.name

    @property
    def verb(self) -> str | None:
        """The verb that wrote the folder (``summary.json`` → ``verb``), or None."""
        return self.summary.get("verb")

    @cached_property
    def runs(self) -> list[Run]:
        """The sub-runs (a drop test at several currents), else ``[self]``."""
        entries = self.summary.get("runs")
        subs = []
        if isinstance(entries, list):
            for entry in entries:
                folder = entry.get("folder") if isinstance(entry, dict) else None
                if isinstance(folder, str) and folder not in (".", "") and (self.path / folder).is_dir():
                    subs.append(Run(self.path / folder, [entry]))
        return subs or [self]

    def run(self, name: str) -> Run:
        """The sub-run in sub-folder ``name`` (e.g. ``i1.000A``)."""
        for sub in self.runs:
            if sub.name == name:
                return sub
        raise KeyError(f"{self.path}: no sub-run {name!r} (has: {', '.join(r.name for r in self.runs)})")

    @property
    def metrics(self) -> dict[str, Any]:
        """This run's entry of ``summary["runs"]`` (a drop test's period, peaks, damping ratio...), or {}."""
        entries = self._sub_entries or self.summary.get("runs") or []
        return dict(entries[0]) if len(entries) == 1 and isinstance(entries[0], dict) else {}

    @cached_property
    def tables(self) -> dict[str, dict[str, np.ndarray]]:
        """Other CSV tables in the folder by file stem (e.g. ``transmissibility``)."""
        tables = {}
        for path in sorted(self.path.glob("*.csv")):
            if path.name == "data.csv":
                continue
            try:
                tables[path.stem] = read_data_csv(path, required=(), min_rows=0)
            except DataFileError:  # a table with text columns (compare's metrics.csv: the law, its status)
                tables[path.stem] = _read_text_table(path)
        return tables

    @cached_property
    def timing(self) -> dict[str, np.ndarray] | None:
        """Per-cycle loop timing (``timing.npz``: ``lateness_ns``, ``compute_ns``, ...), or None."""
        path = self.path / "timing.npz"
        if not path.exists():
            return None
        try:
            with np.load(path) as doc:
                return {name: np.asarray(doc[name]) for name in doc.files}
        except (OSError, ValueError) as err:
            raise DataFileError(f"{path}: not a readable timing file ({err})") from None

    @property
    def units(self) -> dict[str, str]:
        """Column -> unit, from the column names (``_rad`` -> rad, ``_s`` -> s, ...)."""
        return {name: column_unit(name) for name in self.data}


def _read_text_table(path: Path) -> dict[str, np.ndarray]:
    """A CSV table whose columns are not all numbers: a column whose every cell is a number (an
    empty one: NaN) as floats, any other as text."""
    import csv

    try:
        with path.open(newline="", encoding="utf-8") as handle:
            rows = [row for row in csv.reader(handle) if row]
    except (OSError, UnicodeDecodeError) as err:
        raise DataFileError(f"{path}: cannot read ({err})") from None
    if not rows:
        return {}
    header, body = [name.strip() for name in rows[0]], rows[1:]
    columns: dict[str, np.ndarray] = {}
    for index, name in enumerate(header):
        cells = [row[index] if index < len(row) else "" for row in body]
        try:
            columns[name] = np.array([float(cell) if cell.strip() else np.nan for cell in cells])
        except ValueError:
            columns[name] = np.array(cells, dtype=str)
    return columns


def _has_pyarrow() -> bool:
    import importlib.util

    return importlib.util.find_spec("pyarrow") is not None


def load_run(folder: str | Path) -> Run:
    """Open a run folder written by any sashil verb as a :class:`Run` (its data, summary, config and
    sub-runs, read when first asked for); DataFileError for a folder that is not a run folder."""
    path = Path(folder)
    if not path.is_dir():
        raise DataFileError(f"{path}: not a folder (expected a sashil run folder)")
    if not (path / "summary.json").exists() and not any((path / name).exists() for name in DATA_FILES):
        raise DataFileError(f"{path}: no summary.json or data file: not a sashil run folder")
    return Run(path)
