"""``--format``: which files a run writes beside ``data.csv``, checked before anything runs.

Data formats hold the same rows as ``data.csv``: ``mat`` (MATLAB, scipy) and ``parquet``
(pyarrow, the ``parquet`` extra). CAN trace formats hold the raw frames of both directions, with
timestamps, written by python-can's ``can.Logger`` as ``can.<ext>``: ``blf`` (Vector), ``asc``
(Vector ASCII), ``log`` (SocketCAN candump) and ``mf4`` (ASAM MDF 4, asammdf, the ``mf4``
extra); they need a driver with CAN frames (``driver.name: can``).
"""

from __future__ import annotations

import importlib.util
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from sashil.errors import ConfigError

DATA_FORMATS = ("csv", "mat", "parquet")
CAN_FORMATS = ("blf", "asc", "log", "mf4")
FORMATS = DATA_FORMATS + CAN_FORMATS
#: format -> (module it needs, the sashil extra that installs it)
NEEDS = {"parquet": ("pyarrow", "parquet"), "mf4": ("asammdf", "mf4")}
#: backends whose frames are CAN frames
CAN_DRIVERS = ("can",)

HELP = (
    "extra files beside data.csv, repeatable: mat (MATLAB data.mat), parquet (data.parquet, units and "
    "config in its metadata); on the can driver a raw frame trace can.<ext>: blf, asc, log, mf4"
)


def check_formats(formats: Iterable[str] | None, driver: str | None) -> tuple[str, ...]:
    """The requested formats, each once, or a ConfigError naming the one that cannot be written."""
    out: list[str] = []
    for fmt in formats or ():
        if fmt not in FORMATS:
            raise ConfigError(f"--format {fmt}: unknown format (known: {', '.join(FORMATS)})")
        if fmt in NEEDS:
            module, extra = NEEDS[fmt]
            if importlib.util.find_spec(module) is None:
                raise ConfigError(
                    f"--format {fmt}: needs {module}, which is not installed (pip install 'sashil[{extra}]')"
                )
        if fmt in CAN_FORMATS and driver not in CAN_DRIVERS:
            raise ConfigError(
                f"--format {fmt}: a CAN frame trace needs the can driver (--driver can), this run uses {driver or 'none'}"
            )
        if fmt not in out:
            out.append(fmt)
    return tuple(out)


def can_formats(formats: Iterable[str] | None) -> tuple[str, ...]:
    return tuple(fmt for fmt in formats or () if fmt in CAN_FORMATS)


def write_data_formats(
    folder: Path,
    formats: Iterable[str] | None,
    columns: Mapping[str, Any] | None,
    meta: Mapping[str, Any],
) -> list[Path]:
    """Write the data formats asked for into ``folder``, from ``columns`` (or, when None, from the
    folder's ``data.csv``, e.g. after a loop run has closed it); a parquet file carries the folder's
    ``config.yaml`` as written. Returns the files written."""
    wanted = [fmt for fmt in formats or () if fmt in ("mat", "parquet")]
    if not wanted:
        return []
    if columns is None:
        from sashil.recording.data_file import read_data_csv

        columns = read_data_csv(folder / "data.csv", required=("time_s",), min_rows=0)
    written = []
    for fmt in wanted:
        if fmt == "mat":
            from sashil.recording.matlab import write_mat

            written.append(write_mat(folder / "data.mat", columns, {k: v for k, v in meta.items() if v is not None}))
        else:
            from sashil.recording.parquet_sink import write_parquet

            config_file = folder / "config.yaml"
            config_yaml = config_file.read_text(encoding="utf-8") if config_file.exists() else None
            written.append(write_parquet(folder / "data.parquet", columns, config_yaml, meta))
    return written
