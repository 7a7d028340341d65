"""Ground truth of the emulated rig: the plant's true state at every sample the device sends.

``sashil emulate --truth FILE`` keeps one row per Sample the device produces, taken from the
simulated plant (:class:`~sashil.models.plant.RigPlant`, seed 001 eqs. 9-17) at the instant the
sample is taken: the sample's sequence number as on the wire (16 bit, wraps), the device time
(microseconds since the device booted, before the wire truncates it to 32/24 bit), the plant time,
and the true relative angle theta, rate theta_dot, Bouc-Wen state z, coil current i, damper
torque T = alpha(i) z + c(i) theta_dot (``RigPlant.damper_torque``) and the road angle theta1 the
road wheel applied. A host joins its data.csv
(column ``seq``) with these rows to compare what the controller estimated and asked for with what
the plant did.

Off the real-time path: a row is a handful of float stores into a preallocated block (a new block
every ``BLOCK_ROWS`` rows); the CSV is written once, when the emulator exits (``sashil emulate`` writes :meth:`TruthLog.columns` as a
data file; the emulator itself writes no files). A frame the fault
injection then drops or corrupts still has its row (the device took the sample; the host never
got it, so the join leaves it out).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from sashil.errors import DataFileError
from sashil.models.plant import RigPlant

#: columns of the truth CSV, in order
TRUTH_COLUMNS = (
    "seq",
    "device_time_us",
    "plant_time_s",
    "theta_true_rad",
    "theta_dot_true_rad_s",
    "z_true",
    "current_true_a",
    "torque_true_nm",
    "theta_road_true_rad",
)
#: rows per preallocated block (65536 rows x 8 float64 = 4 MiB, about a minute at 1 kHz)
BLOCK_ROWS = 65536
_INTEGER = {"seq", "device_time_us"}


class TruthLog:
    """Rows of the plant's true state, one per device sample (see module docstring)."""

    def __init__(self, block_rows: int = BLOCK_ROWS):
        self.block_rows = int(block_rows)
        self._blocks: list[np.ndarray] = [np.empty((self.block_rows, len(TRUTH_COLUMNS)))]
        self._n = 0  # rows in the last block

    def __len__(self) -> int:
        return (len(self._blocks) - 1) * self.block_rows + self._n

    def record(self, seq: int, device_time_us: int, plant: RigPlant) -> None:
        """One row: the sample ``seq`` taken at ``device_time_us`` from ``plant`` as it is now."""
        if self._n == self.block_rows:
            self._blocks.append(np.empty((self.block_rows, len(TRUTH_COLUMNS))))
            self._n = 0
        st = plant.state
        row = self._blocks[-1][self._n]
        row[0], row[1], row[2], row[3] = seq, device_time_us, st.time_s, st.theta_rad
        row[4], row[5], row[6], row[7] = st.theta_dot_rad_s, st.z, st.current_a, plant.damper_torque()
        row[8] = st.theta_road_rad
        self._n += 1

    def columns(self) -> dict[str, np.ndarray]:
        """The rows so far as columns (``seq`` and ``device_time_us`` as int64)."""
        data = np.concatenate([*self._blocks[:-1], self._blocks[-1][: self._n]])
        return {
            name: (data[:, k].astype(np.int64) if name in _INTEGER else data[:, k].copy())
            for k, name in enumerate(TRUTH_COLUMNS)
        }


def read_truth_csv(path: str | Path) -> dict[str, np.ndarray]:
    """The columns of a truth CSV written by :meth:`TruthLog.columns` written as a data file (``seq`` and
    ``device_time_us`` as int64); a file of another shape is a one-line DataFileError naming it."""
    path = Path(path)
    try:
        with open(path, encoding="utf-8") as handle:
            header = handle.readline().strip().split(",")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # header only: "Empty input file"
                data = np.loadtxt(handle, delimiter=",", ndmin=2)
    except FileNotFoundError:
        raise DataFileError(f"{path}: no such file") from None
    except (OSError, ValueError) as err:
        raise DataFileError(f"{path}: not a truth CSV ({str(err).splitlines()[0]})") from None
    if tuple(header) != TRUTH_COLUMNS:
        raise DataFileError(f"{path}: expected the truth columns {','.join(TRUTH_COLUMNS)}, got {','.join(header)}")
    if data.size == 0:
        data = np.empty((0, len(TRUTH_COLUMNS)))
    return {
        name: (data[:, k].astype(np.int64) if name in _INTEGER else data[:, k]) for k, name in enumerate(TRUTH_COLUMNS)
    }
