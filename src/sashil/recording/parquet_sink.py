"""``data.parquet``: a run's columns as Apache Parquet (pyarrow), beside ``data.csv``, same rows.

Parquet is what pandas, polars, DuckDB and Arrow users load directly; pyarrow writes it (an optional
extra, ``pip install 'sashil[parquet]'``: a columnar, compressed, typed format is not something to
hand-write). Every column is float64 except the integer ones (``seq``, ``trip_code``: int64). The
file carries its own description:

* each field's metadata ``unit`` (``rad``, ``A``, ``N m``, ... from the column name);
* the schema metadata ``sashil.units`` (JSON: column -> unit), ``sashil.config`` (the run folder's
  ``config.yaml`` as written, when there is one) and ``sashil.run`` (JSON: verb and what else the writer passes).

In pandas: ``pd.read_parquet("data.parquet")``; the metadata:
``pyarrow.parquet.read_schema("data.parquet").metadata[b"sashil.config"]``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from sashil.errors import DataFileError
from sashil.recording.units import column_unit

#: columns stored as int64 (when every value is a whole number)
INTEGER_COLUMNS = ("seq", "trip_code")
EXTRA = "parquet"


def _pyarrow() -> tuple[Any, Any]:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise DataFileError(
            f"--format parquet: needs pyarrow, which is not installed (pip install 'sashil[{EXTRA}]')"
        ) from None
    return pa, pq


def _array(pa: Any, name: str, values: Any) -> Any:
    data = np.asarray(values)
    if name in INTEGER_COLUMNS and data.size and np.all(np.isfinite(data)) and np.all(data == np.round(data)):
        return pa.array(data.astype(np.int64))
    return pa.array(data.astype(np.float64))


def write_parquet(
    path: str | Path,
    columns: Mapping[str, Any],
    config_yaml: str | None = None,
    meta: Mapping[str, Any] | None = None,
) -> Path:
    """Write equal-length ``columns`` to ``path`` (a temporary name first, then renamed), with
    ``config_yaml`` (the run folder's ``config.yaml``, as written) in the metadata when given."""
    pa, pq = _pyarrow()
    path = Path(path)
    arrays = [_array(pa, name, values) for name, values in columns.items()]
    lengths = {len(a) for a in arrays}
    if len(lengths) > 1:
        raise DataFileError(f"{path}: columns of unequal length {sorted(lengths)}")
    units = {name: column_unit(name) for name in columns}
    fields = [pa.field(name, a.type, metadata={"unit": units[name]}) for name, a in zip(columns, arrays, strict=True)]
    metadata = {"sashil.units": json.dumps(units), "sashil.run": json.dumps(dict(meta or {}))}
    if config_yaml is not None:
        metadata["sashil.config"] = config_yaml
    table = pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata=metadata))
    tmp = path.with_name(path.name + ".part")
    pq.write_table(table, tmp, compression="zstd")
    tmp.replace(path)
    return path


def read_parquet(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a ``data.parquet`` (column name -> numpy array)."""
    _, pq = _pyarrow()
    path = Path(path)
    try:
        table = pq.read_table(path)
    except (OSError, ValueError) as err:
        raise DataFileError(f"{path}: not a readable Parquet file ({err})") from None
    return {name: table.column(name).to_numpy() for name in table.column_names}


def read_metadata(path: str | Path) -> dict[str, Any]:
    """The sashil metadata of a ``data.parquet``: ``units`` (dict), ``config`` (dict or None), ``run``."""
    _, pq = _pyarrow()
    import yaml

    raw = pq.read_schema(Path(path)).metadata or {}
    config = raw.get(b"sashil.config")
    return {
        "units": json.loads(raw.get(b"sashil.units", b"{}")),
        "config": yaml.safe_load(config) if config else None,
        "run": json.loads(raw.get(b"sashil.run", b"{}")),
    }
