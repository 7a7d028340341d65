"""Live view and ``.rrd`` recording of a run with rerun-sdk (API of rerun-sdk 0.41).

What is logged (timeline ``time``, seconds of the run, a duration timeline):

==============================  ===========================================================
entity                          series (data.csv columns)
==============================  ===========================================================
``signals/angle_deg``           θ (``theta_rad``), θ1 (``theta_road_rad``), in degrees
``signals/velocity_rad_s``      θ̇ (``theta_dot_rad_s``)
``signals/current_a``           commanded (``current_cmd_a``), measured (``current_a``)
``signals/torque_nm``           T̂ (``torque_hat_nm``), T* (``torque_cmd_nm``), the feasible
                                band T(0), T(i_max) (seed 001 eq. 9 with ẑ and θ̇)
``signals/z_hat``               ẑ (``z_hat``)
``timing/lateness_us``          loop wake-up lateness per cycle
``hysteresis/torque_vs_*``      T̂ against θ̇ [deg/s] and against θ [deg], as 2-D points
``events/trips``                safety trips (text log, level ERROR)
``events/notes``                run events such as the start of each drop test (level INFO)
==============================  ===========================================================

A series is logged only when its columns exist. 2-D views draw y downward, so the hysteresis
points are stored as (x, −T̂) and the view is named accordingly; the torque values themselves are
in ``signals/torque_nm`` unchanged.

Never blocking the loop: :class:`LiveTap` runs in its own thread. Every ``batch_s`` it copies
every ``every``-th committed row from the recorder's ring (:meth:`Recorder.copy_rows`), builds one
column batch per entity and sends each with ``rr.send_columns`` (one call per entity, ~0.1 ms).
Like the recorder's writer, it starts a send only when it fits before the loop's next wake-up
(``recorder.window_end_ns``), so it uses the interpreter while the loop sleeps. It never waits for
the loop; if it falls behind the ring it skips rows (counted in ``rows_skipped``).
"""

from __future__ import annotations

import logging
import math
import shutil
import sys
import threading
import time
from collections.abc import Mapping, MutableMapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sashil.errors import ConfigError, DataFileError
from sashil.models.hysteresis import BoucWenParams
from sashil.recording.viewer import DEFAULT_PORT, reachable_host, spawn_viewer

DEG = 180.0 / math.pi
TIMELINE = "time"
TRIPS_ENTITY = "events/trips"
NOTES_ENTITY = "events/notes"
APP_ID = "sashil"
#: a send is started only this long before the loop's next wake-up
SEND_BUDGET_NS = 300_000
POLL_S = 0.002
FLUSH_TIMEOUT_S = 10.0

log = logging.getLogger("sashil.rerun")


@dataclass(frozen=True)
class Series:
    """One time-series entity: several data columns drawn in one plot."""

    entity: str
    title: str
    columns: tuple[str, ...]
    names: tuple[str, ...]
    scale: float = 1.0


SERIES: tuple[Series, ...] = (
    Series(
        "signals/angle_deg", "angle θ, θ1 [deg]", ("theta_rad", "theta_road_rad"), ("θ (relative)", "θ1 (road)"), DEG
    ),
    Series("signals/velocity_rad_s", "velocity θ̇ [rad/s]", ("theta_dot_rad_s",), ("θ̇",)),
    Series("signals/current_a", "coil current [A]", ("current_cmd_a", "current_a"), ("commanded", "measured")),
    Series(
        "signals/torque_nm",
        "damper torque [N·m]",
        ("torque_hat_nm", "torque_cmd_nm", "band_lo_nm", "band_hi_nm"),
        ("T̂ (observer)", "T* (target)", "band T(0)", "band T(i_max)"),
    ),
    Series("signals/z_hat", "hysteretic state ẑ", ("z_hat",), ("ẑ",)),
    Series("timing/lateness_us", "loop lateness [µs]", ("lateness_us",), ("wake-up lateness",)),
)

#: (entity, x column, x scale, view title); y is always -torque_hat_nm (see module doc)
HYSTERESIS: tuple[tuple[str, str, float, str], ...] = (
    ("hysteresis/torque_vs_velocity", "theta_dot_rad_s", DEG, "hysteresis: T̂ [N·m, up] against θ̇ [deg/s]"),
    ("hysteresis/torque_vs_angle", "theta_rad", DEG, "hysteresis: T̂ [N·m, up] against θ [deg]"),
)


def feasible_band(columns: MutableMapping[str, np.ndarray], params: Mapping[str, float], current_max_a: float) -> None:
    """Add ``band_lo_nm``/``band_hi_nm``: the torque range T(0), T(i_max) at the observed state.

    Seed 001 eq. 9 with eqs. 11-12 (:meth:`BoucWenParams.torque`): ``T(i) = (alpha1 + alpha2 i) z + (c1 + c2 i) theta_dot``, linear
    in i, so the band's ends are its values at 0 A and at i_max. Needs ``z_hat`` and
    ``theta_dot_rad_s``; does nothing without them or when the band is already there.
    """
    if "band_lo_nm" in columns or "z_hat" not in columns or "theta_dot_rad_s" not in columns:
        return
    z, v = np.asarray(columns["z_hat"], float), np.asarray(columns["theta_dot_rad_s"], float)
    model = BoucWenParams.from_mapping(dict(params))
    columns["band_lo_nm"] = model.torque(z, v, 0.0)
    columns["band_hi_nm"] = model.torque(z, v, current_max_a)


def present_series(columns: Sequence[str]) -> list[tuple[Series, tuple[int, ...]]]:
    """The series with at least one column in ``columns``, and which of their columns are there."""
    have = set(columns)
    out = []
    for series in SERIES:
        idx = tuple(i for i, name in enumerate(series.columns) if name in have)
        if idx:
            out.append((series, idx))
    return out


def blueprint(columns: Sequence[str]) -> Any:
    """Panels: time series on the left (angle, velocity, current, torque, ẑ, lateness), the two
    hysteresis loops (built up over the whole run) and the trip log on the right."""
    import rerun.blueprint as rrb

    left = [rrb.TimeSeriesView(origin=f"/{s.entity}", name=s.title) for s, _ in present_series(columns)]
    right: list[Any] = []
    if "torque_hat_nm" in columns:
        whole_run = rrb.VisibleTimeRange(
            TIMELINE, start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.cursor_relative()
        )
        for entity, x_name, _, title in HYSTERESIS:
            if x_name in columns:
                right.append(rrb.Spatial2DView(origin=f"/{entity}", name=title, time_ranges=[whole_run]))
    right.append(rrb.TextLogView(origin="/events", name="trips and events"))
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(*left), rrb.Vertical(*right), column_shares=[3, 2]),
        rrb.TimePanel(
            state="expanded", timeline=TIMELINE
        ),  # scrub back through a run (live: the view follows the newest data)
    )


class RerunLog:
    """A rerun recording stream with the sashil layout: a viewer, an ``.rrd`` file, or both."""

    def __init__(self, stream: Any, columns: Sequence[str] = ()):
        self.rec = stream
        self.failed = False
        self._named: set[str] = set()
        self.sends = 0
        self.send_ns_max = 0
        self.send_ns_total = 0
        self.columns = tuple(columns)

    @classmethod
    def open(
        cls,
        columns: Sequence[str],
        *,
        save: str | Path | None = None,
        viewer: bool = False,
        connect: str | None = None,
        name: str | None = None,
        bind: str = "127.0.0.1",
    ) -> RerunLog:
        """Open a stream to ``save`` (``.rrd``), a spawned viewer (``viewer``), a viewer at
        ``connect`` (a ``rerun+http://…/proxy`` URL), or several of them; sends the blueprint."""
        import rerun as rr

        rec = rr.RecordingStream(APP_ID)
        if name:
            rec.send_recording_name(name)
        sinks: list[Any] = []
        if viewer and connect is None:
            # the viewer that rerun-sdk installs beside this Python, else `rerun` on PATH
            beside = Path(sys.executable).with_name("rerun")
            executable = str(beside) if beside.is_file() else shutil.which("rerun")
            if executable is None:
                raise ConfigError(
                    "--rerun: no rerun viewer executable (pip install rerun-sdk); use --rerun-save FILE.rrd"
                )

            spawn_viewer(executable, DEFAULT_PORT, bind)  # on the loopback interface unless asked
            connect = f"rerun+http://{reachable_host(bind)}:{DEFAULT_PORT}/proxy"
        if viewer or connect is not None:
            sinks.append(rr.GrpcSink(connect) if connect else rr.GrpcSink())
        if save is not None:
            path = Path(save)
            if not path.parent.is_dir():
                raise ConfigError(f"--rerun-save {path}: folder {path.parent} does not exist")
            sinks.append(rr.FileSink(str(path)))
        rec.set_sinks(*sinks)
        log = cls(rec, columns)
        rec.send_blueprint(blueprint(columns))
        log.warm_up()
        return log

    def warm_up(self) -> None:
        """Pay the SDK's first-call costs (~20 ms for the first time column) before the loop
        starts, and name the series of every entity (static ``SeriesLines``)."""
        import rerun as rr

        for series, idx in present_series(self.columns):
            self._name_series(series, idx)
        rr.TimeColumn(TIMELINE, duration=np.zeros(2))
        rr.Scalars.columns(scalars=np.zeros((2, 2)))
        rr.Points2D.columns(positions=np.zeros((2, 2)), radii=np.full(2, -1.5)).partition([2])

    def _name_series(self, series: Series, idx: tuple[int, ...]) -> None:
        import rerun as rr

        if series.entity not in self._named:
            self.rec.log(series.entity, rr.SeriesLines(names=[series.names[i] for i in idx]), static=True)
            self._named.add(series.entity)

    # sending -------------------------------------------------------------------------------
    def _send(self, entity: str, times: Any, archetype_columns: Any) -> None:
        import rerun as rr

        t0 = time.perf_counter_ns()
        rr.send_columns(entity, indexes=[times], columns=archetype_columns, recording=self.rec)
        spent = time.perf_counter_ns() - t0
        self.sends += 1
        self.send_ns_total += spent
        self.send_ns_max = max(self.send_ns_max, spent)

    def batches(self, columns: Mapping[str, np.ndarray], time_offset_s: float = 0.0) -> list[tuple[str, Any]]:
        """The work for a block of rows as small steps ``[(entity, thunk), ...]``: the first step
        builds the block's time columns, each further step builds one entity's columns and sends
        them (~0.1-0.3 ms each, so a step fits in the loop's idle time between two cycles)."""
        import rerun as rr

        time_s = np.asarray(columns["time_s"], float) + time_offset_s
        if time_s.size == 0:
            return []
        shared: dict[str, Any] = {}

        def time_columns() -> None:  # shared by every series of the block
            shared["all"] = rr.TimeColumn(TIMELINE, duration=time_s)
            shared["last"] = rr.TimeColumn(TIMELINE, duration=time_s[-1:])

        def scalars(series: Series, idx: tuple[int, ...]) -> None:
            values = np.column_stack([np.asarray(columns[series.columns[i]], float) * series.scale for i in idx])
            self._name_series(series, idx)
            self._send(series.entity, shared["all"], rr.Scalars.columns(scalars=values))

        def points(entity: str, x_name: str, scale: float) -> None:
            xy = np.column_stack(
                [np.asarray(columns[x_name], float) * scale, -np.asarray(columns["torque_hat_nm"], float)]
            )
            xy = xy[np.isfinite(xy).all(axis=1)]
            if xy.size:  # one row at the block's last time holding all its points (the view keeps the history)
                cols = rr.Points2D.columns(positions=xy, radii=np.full(len(xy), -1.5)).partition([len(xy)])
                self._send(entity, shared["last"], cols)

        out: list[tuple[str, Any]] = [("", time_columns)]
        for series, idx in present_series(list(columns)):
            out.append((series.entity, lambda s=series, i=idx: scalars(s, i)))
        if "torque_hat_nm" in columns:
            for entity, x_name, scale, _ in HYSTERESIS:
                if x_name in columns:
                    out.append((entity, lambda e=entity, x=x_name, k=scale: points(e, x, k)))
        return out

    def log_columns(self, columns: Mapping[str, np.ndarray], time_offset_s: float = 0.0) -> None:
        """Send whole columns (a finished record, e.g. a drop test) in one batch per entity."""
        for _, send in self.batches(columns, time_offset_s):
            send()

    def trip(self, time_s: float, reason: str) -> None:
        import rerun as rr

        self.rec.set_time(TIMELINE, duration=time_s)
        self.rec.log(TRIPS_ENTITY, rr.TextLog(f"{time_s:.3f} s: {reason}", level=rr.TextLogLevel.ERROR))
        self.rec.reset_time()

    def note(self, time_s: float, text: str) -> None:
        import rerun as rr

        self.rec.set_time(TIMELINE, duration=time_s)
        self.rec.log(NOTES_ENTITY, rr.TextLog(text, level=rr.TextLogLevel.INFO))
        self.rec.reset_time()

    def close(self) -> None:
        """Flush everything to the sinks and disconnect (the ``.rrd`` is complete afterwards).

        A viewer that went away (or never came up) is reported as a warning, never raised: the
        run's own records do not depend on the live view."""
        try:
            self.rec.flush(timeout_sec=FLUSH_TIMEOUT_S)
        except Exception as err:
            text = str(err).strip().splitlines()
            log.warning("live view: %s", text[0] if text else type(err).__name__)
            self.failed = True
        finally:
            self.rec.disconnect()

    def stats(self) -> dict[str, Any]:
        return {
            "sends": self.sends,
            "send_us_mean": round(self.send_ns_total / self.sends / 1e3, 1) if self.sends else None,
            "send_us_max": round(self.send_ns_max / 1e3, 1),
        }


class LiveTap:
    """The thread that feeds a :class:`RerunLog` from a running loop's recorder (module doc)."""

    def __init__(
        self,
        log: RerunLog,
        every: int = 10,
        batch_s: float = 0.25,
        band: tuple[Mapping[str, float], float] | None = None,
    ):
        if every < 1 or not batch_s > 0:
            raise ValueError("every >= 1 and batch_s > 0 required")
        self.log = log
        self.every = int(every)
        self.batch_s = float(batch_s)
        self.band = band  # (Bouc-Wen params, i_max) for the feasible band
        self.recorder: Any = None
        self.timing: Any = None
        self._next = 0
        self.rows_sent = 0
        self.rows_skipped = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None

    def start(self, recorder: Any, timing: Any = None) -> LiveTap:
        """Follow ``recorder`` (a :class:`~sashil.recording.recorder.Recorder`) and, when given,
        the loop's :class:`~sashil.runtime.timing.TimingStats` (for the lateness series)."""
        self.recorder, self.timing = recorder, timing
        self._thread = threading.Thread(target=self._run, name="sashil-rerun", daemon=True)
        self._thread.start()
        return self

    def _window_open(self) -> bool:
        window = self.recorder.window_end_ns
        return window is None or time.perf_counter_ns() + SEND_BUDGET_NS <= window

    def _collect(self) -> dict[str, np.ndarray] | None:
        rec = self.recorder
        head = rec.rows_committed
        oldest = head - rec.capacity + 64  # rows before this may be overwritten while we copy
        if self._next < oldest:
            skipped = oldest - self._next
            skipped -= skipped % self.every
            self._next += skipped
            self.rows_skipped += skipped
        rows = rec.copy_rows(self._next, head, self.every)
        if not rows:
            return None
        first = self._next
        self._next += len(rows) * self.every
        self.rows_sent += len(rows)
        block = np.asarray(rows, dtype=float)
        columns = {name: block[:, i] for i, name in enumerate(rec.columns)}
        timing = self.timing
        if timing is not None:
            lateness = np.full(len(rows), np.nan)
            for k, cycle in enumerate(range(first, first + len(rows) * self.every, self.every)):
                value = timing.value_ns("lateness", cycle)  # None once the ring moved past it
                if value is not None:
                    lateness[k] = value * 1e-3
            columns["lateness_us"] = lateness
        if self.band is not None:
            feasible_band(columns, *self.band)
        return columns

    def _run(self) -> None:
        try:
            next_batch = time.perf_counter()
            pending: list[tuple[str, Any]] = []
            while not self._stop.is_set():
                if pending:
                    if self._window_open():
                        pending.pop(0)[1]()
                        continue
                elif time.perf_counter() >= next_batch:
                    next_batch += self.batch_s
                    if self._window_open():
                        columns = self._collect()
                        if columns is not None:
                            pending = self.log.batches(columns)
                        continue
                self._stop.wait(POLL_S)
        except BaseException as err:
            self.error = err

    def close(self, trips: Sequence[Mapping[str, Any]] = (), notes: Sequence[tuple[float, str]] = ()) -> dict[str, Any]:
        """Stop the thread, send the rest of the rows, the trips and the notes (``(time_s, text)``:
        live parameter changes) on the time axis, finish the recording."""
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._thread = None
        try:
            if self.error is None and self.recorder is not None:
                while True:
                    columns = self._collect()
                    if columns is None:
                        break
                    self.log.log_columns(columns)
            for trip in trips:
                self.log.trip(float(trip.get("time_s") or 0.0), str(trip.get("reason", "trip")))
            for time_s, text in notes:
                self.log.note(time_s, text)
            self.log.close()
        except Exception as err:
            self.error = err
        return self.stats()

    def stats(self) -> dict[str, Any]:
        return {
            "rows_sent": self.rows_sent,
            "rows_skipped": self.rows_skipped,
            "every": self.every,
            "error": None if self.error is None else f"{type(self.error).__name__}: {self.error}",
            **self.log.stats(),
        }


def load_rrd(path: str | Path) -> dict[str, dict[str, list[Any]]]:
    """Read an ``.rrd`` back (``rerun.chunk.RrdReader``, the first recording in the file):
    ``{entity path: {column: values}}``, time columns (``time``, ``log_time``) in seconds.
    Used by the tests and handy for checking a recording without the viewer."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    if not Path(path).is_file():
        raise DataFileError(f"{path}: no such .rrd file")
    out: dict[str, dict[str, list[Any]]] = {}
    for chunk in RrdReader(str(path)).stream():
        batch = chunk.to_record_batch()
        entry = out.setdefault(chunk.entity_path, {})
        for name in batch.schema.names:
            column = batch.column(name)
            if pa.types.is_temporal(column.type):  # the time line and rerun's log_time: seconds
                values = (np.asarray(column.cast(pa.int64())) * 1e-9).tolist()
            else:
                values = column.to_pylist()
            entry.setdefault(name, []).extend(values)
    return out
