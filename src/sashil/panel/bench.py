"""The bench behind the panel: one run at a time, started through the library, stopped by a flag.

:class:`Bench` is the panel's only link to the rig. It resolves a page's choices into a run's
config exactly as ``sashil run`` does (:func:`sashil.config.resolve.resolve` with verb ``run``:
a bad value is the CLI's one line and nothing starts), runs
:func:`sashil.lab.closed_loop` in a worker thread with a :class:`StreamView` reading the run's
stream and a :class:`~sashil.runtime.signals.StopFlag`, tunes the law through the run folder's
tuning socket (:func:`sashil.runtime.tune_socket.request`, as ``sashil tune``: the same checks,
the same hand-off between cycles, the same ``events.csv`` rows), and keeps the events a page
shows. It never blocks on the loop and never touches the law itself.
"""

from __future__ import annotations

import collections
import math
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sashil.errors import ConfigError, SashilError
from sashil.lab.events import Event
from sashil.panel.catalog import LawChoice, laws_catalog
from sashil.panel.frames import decimation_step, encode_batch, next_window, select_columns
from sashil.runtime.signals import StopFlag

#: after a stall, a batch reaches back at most this far (older rows may have left the stream's ring;
#: a page wants the present)
CATCH_UP_S = 1.0
#: the road specs a page may give (a profile file is named on the command line, never by a page)
PAGE_ROADS = ("sine:", "chirp:", "iso8608:", "bump:", "none")
#: the doctor's wake-up jitter measurement (seconds; the CLI's default is 5)
DOCTOR_JITTER_S = 1.0
#: the doctor's child process is given this long
DOCTOR_TIMEOUT_S = 120.0
#: events kept for pages that join late
EVENT_HISTORY = 200


class StreamView:
    """A reader of a run's stream (a ``views=`` entry of :func:`sashil.lab.closed_loop`): it keeps
    the stream and the loop's timing when the run starts and the trips when it ends; the panel
    reads the newest rows from it at the display rate, never blocking the loop."""

    def __init__(self) -> None:
        self.stream: Any = None
        self.timing: Any = None
        self.trips: list[Any] = []
        self.closed = False

    def start(self, stream: Any, timing: Any) -> StreamView:
        self.stream, self.timing = stream, timing
        return self

    def close(self, trips: Any = (), notes: Any = ()) -> None:
        self.trips = list(trips)
        self.closed = True


@dataclass
class RunState:
    """What a page is shown of the current (or last) run."""

    state: str = "idle"  # idle | starting | running | stopping
    run_id: int = 0
    law: str = ""
    folder: str = ""
    exit_status: str = ""
    stop_reason: str = ""
    start_values: dict[str, Any] = field(default_factory=dict)
    values: dict[str, Any] = field(default_factory=dict)
    markers: list[dict[str, Any]] = field(default_factory=list)


class Bench:
    """One run at a time on the rig of ``config_file`` (None: the simulated rig, seed parameters),
    into ``runs_dir``, with the laws of the registry and of ``laws_dir``."""

    def __init__(
        self, config_file: str | Path | None = None, runs_dir: str | Path = "runs", laws_dir: str | Path | None = None
    ):
        self.config_file = None if config_file is None else Path(config_file)
        self.runs_dir = Path(runs_dir)
        self.laws: dict[str, LawChoice] = {choice.name: choice for choice in laws_catalog(laws_dir)}
        self.run = RunState()
        self.view: StreamView | None = None
        self._config: Any = None
        self._flag: StopFlag | None = None
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._events: collections.deque[dict[str, Any]] = collections.deque(maxlen=EVENT_HISTORY)
        self._event_seq = 0
        self._sent_row = 0
        self._step = 1
        self._keep = 1
        self._band: tuple[Mapping[str, float], float] | None = None
        self._doctoring = False

    # -- choosing and starting ----------------------------------------------------------------------
    def law_table(self) -> list[dict[str, Any]]:
        """The laws as ``sashil laws --json`` describes them."""
        return [choice.about for choice in self.laws.values()]

    def resolve(self, choice: Mapping[str, Any]) -> Any:
        """The run's read-only config for a page's ``choice`` (law, params, road, duration_s,
        driver, port), resolved as ``sashil run`` resolves its options; ConfigError (one line)
        for anything refused."""
        from sashil.config.resolve import ConfigSource, Option, resolve

        law = choice.get("law")
        if law not in self.laws:
            raise ConfigError(f"controller.law: unknown law {law!r} (known: {', '.join(self.laws)})")
        params = choice.get("params") or {}
        if not isinstance(params, Mapping):
            raise ConfigError("params: expected {name: value}")
        declared = {p["name"] for p in self.laws[law].about["parameters"]}
        sets = []
        for name, text in params.items():
            if name not in declared:
                raise ConfigError(f"controller.{name}: not a parameter of {law}")
            if text is None or str(text).strip() == "":
                continue  # left blank: the config's value (or the law's default)
            sets.append(f"controller.{name}={text}")
        road = choice.get("road") or None
        if road is not None and (not isinstance(road, str) or not road.startswith(PAGE_ROADS)):
            raise ConfigError(
                f"--road: a page chooses {', '.join(PAGE_ROADS)} (a file road is for the command line), got {road!r}"
            )
        duration = choice.get("duration_s")
        if duration is not None and not isinstance(duration, (int, float)):
            raise ConfigError(f"--duration: expected seconds, got {duration!r}")
        source = ConfigSource(
            config=self.config_file,
            controller=self.laws[law].spec,
            sets=tuple(sets),
            options=(Option("--duration", "run.duration_s", duration), Option("--road", "run.road", road)),
            driver=choice.get("driver") or None,
            port=choice.get("port") or None,
        )
        return resolve(source, "run")

    def start(self, choice: Mapping[str, Any]) -> RunState:
        """Start a run of ``choice`` in the worker thread; ConfigError (nothing started) for a bad
        value or when a run is already on."""
        with self._lock:
            if self.run.state != "idle":
                raise ConfigError(f"a run is already {self.run.state}: STOP it first")
            if self._doctoring:
                raise ConfigError("the board checks (doctor) are running: start when they end")
            config = self.resolve(choice)
            from sashil.lab.outputs import Outputs
            from sashil.recording.run_folder import utc_stamp

            folder = self.runs_dir / f"{utc_stamp()}-run"
            suffix = 1
            while folder.exists():
                suffix += 1
                folder = self.runs_dir / f"{utc_stamp()}-run-{suffix}"
            law = self.laws[str(choice["law"])]
            declared = [p["name"] for p in law.about["parameters"]]
            values = {name: config["controller"].get(name) for name in declared}
            self.run = RunState(
                state="starting",
                run_id=self.run.run_id + 1,
                law=law.name,
                folder=str(folder),
                start_values=dict(values),
                values=dict(values),
            )
            self._config = config
            self._flag = StopFlag()
            self.view = StreamView()
            rate = float(config["loop"]["rate_hz"])
            self._step = decimation_step(rate)
            self._keep = max(1, int(rate * CATCH_UP_S))
            self._sent_row = 0
            model = config.get("model", {})
            self._band = (
                (model["params"], float(config["rig"]["current_max_a"])) if model.get("name") == "bouc-wen" else None
            )
            outputs = Outputs(out=folder)
            self._thread = threading.Thread(
                target=self._work, args=(config, outputs, self._flag, self.view), name="sashil-panel-run", daemon=True
            )
            self._thread.start()
            return self.run

    def _work(self, config: Any, outputs: Any, flag: StopFlag, view: StreamView) -> None:
        from sashil.lab import closed_loop

        status, reason = "error", ""
        try:
            run = closed_loop(config, outputs, self._on_event, tune=True, views=[view], stop=flag)
            status = str(run.summary.get("exit_status", "ok"))
            reason = str(run.summary.get("stop_reason") or "")
            for line in run_health(run.summary):
                self._on_event(Event("result", line))
        except SashilError as err:
            self._on_event(Event("warning", str(err)))
            status = "stopped" if flag.requested else "error"
        except Exception as err:  # the run ended at 0 A first; the page must hear why
            self._on_event(Event("warning", f"{type(err).__name__}: {err}"))
        finally:
            with self._lock:
                self.run.state = "idle"
                self.run.exit_status = status
                self.run.stop_reason = reason or (flag.signal_name or "")
            self._on_event(Event("progress", f"run ended: {status}", {"exit_status": status}))
            from sashil.runtime.loop_process import start_ahead

            start_ahead()  # the next run's loop process, ready before the next click

    def _on_event(self, event: Event) -> None:
        if event.kind == "progress" and event.text.startswith("sashil run:"):
            with self._lock:
                if self.run.state == "starting":
                    self.run.state = "running"
        self._add_event(event.kind, event.text)

    def _add_event(self, kind: str, text: str) -> None:
        with self._lock:
            self._event_seq += 1
            self._events.append({"seq": self._event_seq, "kind": kind, "text": text})

    def events_since(self, seq: int) -> list[dict[str, Any]]:
        """The events after number ``seq`` (the oldest ones kept when a page is far behind)."""
        with self._lock:
            return [event for event in self._events if event["seq"] > seq]

    # -- the board checks -------------------------------------------------------------------------------
    def doctor(self, driver: str | None = None, port: str | None = None) -> dict[str, Any]:
        """``sashil doctor --json`` for ``driver`` and ``port`` in a child process (its checks switch
        to SCHED_FIFO and trip the board's watchdog on purpose: never in this process, and only
        while the rig is idle; no run starts until they end). ConfigError (one line) when refused."""
        import json
        import subprocess
        import sys

        with self._lock:
            if self.run.state != "idle" or self._doctoring:
                raise ConfigError(
                    f"doctor: the rig is not idle ({'checks running' if self._doctoring else self.run.state})"
                )
            self._doctoring = True
        try:
            argv = [sys.executable, "-m", "sashil", "doctor", "--json", f"--jitter-s={DOCTOR_JITTER_S:g}"]
            # each value attached to its option: a value a page sends is never read as an option
            argv += [
                f"--{key}={value}"
                for key, value in (("config", self.config_file), ("driver", driver), ("port", port))
                if value
            ]
            try:
                done = subprocess.run(
                    argv, capture_output=True, text=True, timeout=DOCTOR_TIMEOUT_S, stdin=subprocess.DEVNULL
                )
            except subprocess.TimeoutExpired:
                raise ConfigError(f"doctor: no answer within {DOCTOR_TIMEOUT_S:g} s") from None
            if done.stdout.lstrip().startswith("{"):
                return dict(json.loads(done.stdout))
            lines = done.stderr.strip().splitlines()
            raise ConfigError(lines[-1] if lines else f"doctor: exit {done.returncode}")
        finally:
            with self._lock:
                self._doctoring = False

    # -- stopping ---------------------------------------------------------------------------------
    def stop(self, reason: str = "STOP (panel)") -> bool:
        """Ask the run to stop at the next cycle (0 A, the road at rest); False when none runs."""
        with self._lock:
            flag = self._flag
            running = self.run.state in ("starting", "running")
            if flag is None or not running:
                return False
            flag.request(reason)
            self.run.state = "stopping"
        self._add_event("warning", f"{reason}: stopping at the next cycle")
        return True

    def join(self, timeout: float | None = None) -> None:
        """Wait for the worker thread (the server's shutdown; the tests)."""
        thread = self._thread
        if thread is not None:
            thread.join(timeout)

    @property
    def busy(self) -> bool:
        return self.run.state != "idle"

    # -- live tuning ---------------------------------------------------------------------------------
    def tune(self, values: Mapping[str, Any], ramp_s: float | None = None) -> list[dict[str, Any]]:
        """Send ``values`` to the running law through its tuning socket, as ``sashil tune`` does;
        TuningError/ConfigError (one line, the law keeps its values) when refused."""
        from sashil.runtime.tune_socket import request

        if self.run.state not in ("running", "starting"):
            raise ConfigError("live tuning: no run is running")
        if not values:
            raise ConfigError("live tuning: no value to change")
        answer = request(self.run.folder, {"set": dict(values), "ramp_s": ramp_s})
        events = list(answer.get("events", []))
        with self._lock:
            for event in events:
                if event.get("status", "applied") == "applied" or "status" not in event:
                    self.run.values[event["key"]] = event["new"]
                self.run.markers.append(
                    {"time_s": event["time_s"], "text": f"{event['key']} {event['old']} -> {event['new']}"}
                )
        for event in events:
            self._add_event("progress", f"controller.{event['key']}: {event['old']} -> {event['new']}")
        return events

    def restore(self) -> list[dict[str, Any]]:
        """Put back the values the run started with (those changed since)."""
        changed = {
            key: value
            for key, value in self.run.start_values.items()
            if self.run.values.get(key) != value and isinstance(value, (int, float))
        }
        if not changed:
            raise ConfigError("restore: the law has its starting values")
        return self.tune(changed, 0.0)

    def saved_config(self) -> str:
        """The run's config as YAML with the law's current values: a file ``--config`` reads."""
        import yaml

        from sashil.config.frozen import thaw

        if self._config is None:
            raise ConfigError("save: no run yet (start one, tune it, then save)")
        config = thaw(self._config)
        for key, value in self.run.values.items():
            if value is not None:
                config["controller"][key] = value
        return str(yaml.safe_dump(_plain(config), sort_keys=False))

    # -- the stream, for pages ------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        """The run's state, counts and markers (a page's status line)."""
        view = self.view
        timing = view.timing if view is not None else None
        stream = view.stream if view is not None else None
        cycles = int(getattr(timing, "cycles", 0) or 0)
        missed = int(getattr(timing, "missed_deadlines", 0) or 0)
        with self._lock:
            run = self.run
            return {
                "state": run.state,
                "run_id": run.run_id,
                "law": run.law,
                "folder": run.folder,
                "exit_status": run.exit_status,
                "stop_reason": run.stop_reason,
                "values": dict(run.values),
                "start_values": dict(run.start_values),
                "markers": list(run.markers),
                "cycles": cycles,
                "missed_deadlines": missed,
                "missed_share": missed / cycles if cycles else 0.0,
                "rows": int(stream.rows_committed) if stream is not None else 0,
            }

    def next_batch(self) -> bytes | None:
        """The stream's rows since the last batch (decimated, at most the trace window), as one
        binary batch; None when there is nothing new. Called once per display tick, for every page."""
        view = self.view
        stream = view.stream if view is not None else None
        if stream is None:
            return None
        committed = int(stream.rows_committed)
        start, stop = next_window(committed, self._sent_row, self._step, self._keep)
        if stop <= start:
            return None
        rows = stream.copy_rows(start, stop, self._step)
        if not rows:
            return None
        self._sent_row = start + len(rows) * self._step
        return encode_batch(select_columns(rows, stream.columns, self._band))


def run_health(summary: Mapping[str, Any]) -> list[str]:
    """The lines a page shows when a run ends: the link's health and the board's confirmation of
    the safe state (``summary.json`` ``link``), and the share of cycles the damper clipped T*."""
    lines = []
    link = summary.get("link")
    if isinstance(link, Mapping) and link:
        lines.append(
            f"link: {link.get('samples', 0)} samples, {link.get('samples_missed', 0)} missed, "
            f"{link.get('bad_frames', 0)} bad frames, {link.get('timeouts', 0)} timeouts"
        )
        if link.get("safe_state_confirmed"):
            lines.append(f"safe state (0 A) confirmed by the board in {link.get('safe_state_ms', 0):g} ms")
        elif "safe_state_confirmed" in link:
            lines.append("safe state (0 A) NOT confirmed by the board: check the rig")
    stats = summary.get("controller_stats")
    cycles = (summary.get("timing") or {}).get("cycles") or 0
    if isinstance(stats, Mapping) and cycles and "clipped_cycles" in stats:
        share = 100.0 * stats["clipped_cycles"] / cycles
        lines.append(
            f"clipped: T* outside the feasible band in {stats['clipped_cycles']} of {cycles} cycles ({share:.0f} %)"
        )
    return lines


def _plain(value: Any) -> Any:
    """``value`` as YAML's plain types (tuples as lists; non-finite floats as null)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value
