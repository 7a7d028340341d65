"""MATLAB export: a run's ``data.csv`` columns as a ``.mat`` file (scipy.io.savemat, MAT v5).

The file holds one variable per data column, named exactly like the column (``time_s``,
``theta_rad``, ``current_a``, …, all valid MATLAB names), each an N×1 double column vector, plus
``columns`` (a cell array of the names in file order) and ``sashil`` (a struct with the run's
verb, exit status, start time and sashil version when a ``summary.json`` is beside the data).
In MATLAB: ``d = load('data.mat'); plot(d.time_s, d.theta_rad * 180/pi)``.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from sashil.errors import DataFileError
from sashil.recording.data_file import read_data_csv

#: MATLAB variable names: a letter, then letters, digits, underscores (at most 63 characters)
MATLAB_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,62}$")
RESERVED = ("columns", "sashil")


def write_mat(path: str | Path, columns: Mapping[str, Any], meta: Mapping[str, Any] | None = None) -> Path:
    """Write equal-length ``columns`` to ``path`` (a temporary name first, then renamed)."""
    from scipy.io import savemat

    path = Path(path)
    names = list(columns)
    for name in names:
        if not MATLAB_NAME.match(name) or name in RESERVED:
            raise DataFileError(f"{path}: column {name!r} is not usable as a MATLAB variable name")
    arrays = {name: np.asarray(columns[name], dtype=float).reshape(-1, 1) for name in names}
    lengths = {a.shape[0] for a in arrays.values()}
    if len(lengths) > 1:
        raise DataFileError(f"{path}: columns of unequal length {sorted(lengths)}")
    doc: dict[str, Any] = dict(arrays)
    doc["columns"] = np.array(names, dtype=object).reshape(1, -1)
    if meta:
        doc["sashil"] = {key: ("" if value is None else value) for key, value in meta.items()}
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as handle:
        savemat(handle, doc, do_compression=True, oned_as="column")
    tmp.replace(path)
    return path


def run_meta(run_dir: Path) -> dict[str, Any]:
    """verb, exit status, start time and version from a run folder's summary.json (if any)."""
    try:
        summary = json.loads((run_dir / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    meta = {
        "verb": summary.get("verb"),
        "exit_status": summary.get("exit_status"),
        "started_utc": summary.get("started_utc"),
        "sashil_version": (summary.get("provenance") or {}).get("sashil_version"),
    }
    return {key: str(value) for key, value in meta.items() if value is not None}


def export_mat(data_csv: str | Path, out: str | Path | None = None) -> Path:
    """``data.csv`` -> ``data.mat`` beside it (or ``out``), with the run's metadata."""
    data_csv = Path(data_csv)
    columns = read_data_csv(data_csv, required=("time_s",), min_rows=0)
    target = Path(out) if out is not None else data_csv.with_suffix(".mat")
    return write_mat(target, columns, run_meta(data_csv.parent))
