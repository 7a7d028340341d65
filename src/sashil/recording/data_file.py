"""``data.csv``: the column-per-signal data file of a run (docs/architecture.md fixed column names).

Pure functions from columns to text and back; the reader checks what identification and reports
rely on and fails with one line naming the file and the problem.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from sashil.errors import DataFileError

#: docs/architecture.md: the columns every data.csv has, then the ones written when known
REQUIRED_COLUMNS = ("time_s", "theta_rad", "current_a", "current_cmd_a")
OPTIONAL_COLUMNS = (
    "theta_road_rad",
    "theta_dot_rad_s",
    "torque_in_nm",
    "z_hat",
    "torque_hat_nm",
    "torque_cmd_nm",
    "current_law_a",
)

Columns = Mapping[str, "np.ndarray | Sequence[float]"]


def write_all(fd: int, data: bytes) -> None:
    """Write all of ``data`` to the descriptor ``fd`` (``os.write`` may take part of it)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


def format_rows(columns: Columns) -> str:
    """CSV text (header + rows) of equal-length columns, ``repr``-exact floats."""
    names = list(columns)
    arrays = [np.asarray(columns[name]) for name in names]
    lengths = {a.shape[0] for a in arrays}
    if len(lengths) > 1:
        raise ValueError(f"columns of unequal length: {dict(zip(names, (a.shape[0] for a in arrays), strict=True))}")
    out = io.StringIO()
    out.write(",".join(names) + "\n")
    lists = [a.tolist() for a in arrays]
    for row in zip(*lists, strict=True):
        out.write(",".join(repr(v) if isinstance(v, float) else str(v) for v in row) + "\n")
    return out.getvalue()


def write_data_csv(path: str | Path, columns: Columns) -> Path:
    """Write ``columns`` to ``path`` (written to a temporary name first, then renamed)."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".part")
    tmp.write_text(format_rows(columns), encoding="utf-8")
    tmp.replace(path)
    return path


def read_data_csv(
    path: str | Path,
    required: Iterable[str] = ("time_s", "theta_rad", "current_a"),
    min_rows: int = 2,
) -> dict[str, np.ndarray]:
    """Read a data file into float columns, checking what the caller needs.

    Raises DataFileError (one line, names the file) for: a missing file, a missing required
    column, a non-number, NaN/inf in a required column, time not strictly increasing, or fewer
    than ``min_rows`` rows.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataFileError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise DataFileError(f"{path}: cannot read ({err})") from None
    rows = list(csv.reader(io.StringIO(text)))
    while rows and not rows[-1]:
        rows.pop()  # a trailing blank line
    if not rows:
        raise DataFileError(f"{path}: empty file (expected a header with {', '.join(required)})")
    header = [name.strip() for name in rows[0]]
    missing = [name for name in required if name not in header]
    if missing:
        raise DataFileError(f"{path}: missing column(s) {', '.join(missing)} (has: {', '.join(header)})")
    body = rows[1:]
    if len(body) < min_rows:
        raise DataFileError(f"{path}: {len(body)} data row(s), too short (need at least {min_rows})")
    columns: dict[str, np.ndarray] = {}
    for index, name in enumerate(header):
        values = np.empty(len(body))
        for row_number, row in enumerate(body, start=2):
            try:
                values[row_number - 2] = float(row[index])
            except (IndexError, ValueError):
                cell = row[index] if index < len(row) else "<missing>"
                raise DataFileError(f"{path}: line {row_number}, column {name}: not a number ({cell!r})") from None
        columns[name] = values
    for name in required:
        bad = ~np.isfinite(columns[name])
        if bad.any():
            line = int(np.argmax(bad)) + 2
            raise DataFileError(f"{path}: line {line}, column {name}: NaN or inf")
    if "time_s" in columns:
        steps = np.diff(columns["time_s"])
        if (steps <= 0).any():
            line = int(np.argmax(steps <= 0)) + 3
            raise DataFileError(f"{path}: line {line}: time_s not increasing")
    return columns
