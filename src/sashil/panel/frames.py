"""The binary batches the panel sends its pages: decimated stream rows at the display rate.

A batch is one websocket binary message: a header of two little-endian uint32 (rows, columns)
then the values as little-endian float64, column after column (each trace one contiguous run,
which is what the page's plot takes). The columns are :data:`PLOT_COLUMNS`, in that order; one a
run does not record (the passive law has no observer) is NaN.

Rows are picked on a fixed grid of the stream's row numbers (every ``step``-th row), so every row
a page shows is a row of the run's ``data.csv``, whatever the moment each batch was read.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

#: the traces a page plots, in the order a batch carries them
PLOT_COLUMNS = (
    "time_s",
    "theta_rad",
    "theta_dot_rad_s",
    "torque_cmd_nm",
    "torque_hat_nm",
    "band_lo_nm",
    "band_hi_nm",
    "current_cmd_a",
    "current_a",
    "theta_road_rad",
)
HEADER = struct.Struct("<II")
#: points per second of run time a page is sent (per trace): enough for a 10 s window at 60 fps
DISPLAY_POINTS_PER_S = 250.0


def decimation_step(rate_hz: float, points_per_s: float = DISPLAY_POINTS_PER_S) -> int:
    """Every how many loop rows one is shown: the loop's rate brought down to ``points_per_s``."""
    return max(1, math.ceil(rate_hz / points_per_s))


def next_window(committed: int, sent: int, step: int, keep: int) -> tuple[int, int]:
    """The rows ``[start, stop)`` to read now: from where the last batch stopped, but no further
    back than ``keep`` rows behind the newest (older rows may be gone from the stream's ring, and a
    late page wants the present), ``start`` on the ``step`` grid."""
    start = max(sent, committed - keep, 0)
    start = -(-start // step) * step
    return start, max(start, committed)


def select_columns(
    rows: Sequence[Sequence[float]],
    columns: Sequence[str],
    band: tuple[Mapping[str, float], float] | None = None,
) -> dict[str, np.ndarray]:
    """The :data:`PLOT_COLUMNS` of ``rows`` (named by ``columns``) as float arrays; ``band`` (the
    Bouc-Wen parameters and i_max) adds the feasible torque band at the observed state."""
    table = np.asarray(rows, dtype=float).reshape(len(rows), len(columns))
    named: dict[str, Any] = {name: table[:, i] for i, name in enumerate(columns)}
    if band is not None and len(rows):
        from sashil.recording.rerun_log import feasible_band

        feasible_band(named, *band)
    nan = np.full(len(rows), np.nan)
    return {name: np.asarray(named.get(name, nan), dtype=float) for name in PLOT_COLUMNS}


def encode_batch(traces: Mapping[str, np.ndarray]) -> bytes:
    """One binary batch of ``traces`` (all :data:`PLOT_COLUMNS`, equal lengths)."""
    n = len(traces[PLOT_COLUMNS[0]])
    body = np.concatenate([np.asarray(traces[name], dtype="<f8") for name in PLOT_COLUMNS])
    return HEADER.pack(n, len(PLOT_COLUMNS)) + body.tobytes()


def decode_batch(data: bytes) -> dict[str, np.ndarray]:
    """The traces of one batch (what a page reads; used by the tests)."""
    n, width = HEADER.unpack_from(data)
    values = np.frombuffer(data, dtype="<f8", offset=HEADER.size, count=n * width)
    return {name: values[i * n : (i + 1) * n] for i, name in enumerate(PLOT_COLUMNS[:width])}
