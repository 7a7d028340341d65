"""The bench behind the panel: one experiment at a time, started through the library, stopped by a flag.

:class:`Bench` is the panel's only link to the rig. It resolves a page's choices into an
experiment's config exactly as its verb does (:func:`sashil.engine.resolve.resolve` with verb
``run``, ``drop-test`` or ``sweep``, the verb's options named as on its command line: a bad value
is the CLI's one line and nothing starts), runs :func:`sashil.engine.sashil_run.closed_loop`,
:func:`sashil.lab.drop_test` or :func:`sashil.lab.sweep` in a worker thread with a
:class:`StreamView` reading each sub-run's stream and a :class:`~sashil.runtime.signals.StopFlag`,
tunes a run's law through the run folder's tuning socket (:func:`sashil.runtime.tune_socket.request`,
as ``sashil tune``: the same checks, the same hand-off between cycles, the same ``events.csv``
rows), and keeps the events a page shows (an operator's prompts among them). It never blocks on
the loop and never touches the law itself.
"""

from __future__ import annotations

import collections
import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sashil.config.frozen import thaw
from sashil.engine.events import Event
from sashil.errors import ConfigError, SashilError
from sashil.panel.catalog import LawChoice, laws_catalog
from sashil.panel.frames import decimation_step, encode_batch, next_window, select_columns
from sashil.recording.rest import NO_SENSE_REST, safe_state_current
from sashil.runtime.signals import StopFlag

#: after a stall, a batch reaches back at most this far on the real clock (older rows may have left
#: the stream's ring; a page wants the present)
CATCH_UP_S = 1.0
#: a page's trace window: on simulated time (a drop test or a sweep on the simulated rig runs faster
#: than the clock) a batch reaches back this far, so a short sub-run is shown whole
TRACE_WINDOW_S = 10.0
#: the experiments a page may start, each as the verb that runs it
EXPERIMENTS = ("run", "drop-test", "sweep")
#: the road specs a page may give (a profile file is named on the command line, never by a page)
PAGE_ROADS = ("sine:", "chirp:", "iso8608:", "bump:", "none")
#: the doctor's wake-up jitter measurement (seconds; the CLI's default is 5)
DOCTOR_JITTER_S = 1.0
#: the doctor's child process is given this long
DOCTOR_TIMEOUT_S = 120.0
#: events kept for pages that join late
EVENT_HISTORY = 200
#: the health counts a loop process's stream reports while it runs (``stream.health()``)
HEALTH_KEYS = ("samples_lost", "bad_frames", "watchdog", "clipped_cycles")


class FrozenRows:
    """The last ``keep`` rows of a sub-run's stream, copied when the sub-run ended (a closed stream
    gives no rows): what a page is still to be sent of it, the coil's decay after a STOP included.
    It reads as a stream does (``columns``, ``rows_committed``, ``copy_rows``)."""

    def __init__(self, stream: Any, keep: int):
        self.columns = tuple(stream.columns)
        self.rows_committed = int(stream.rows_committed)
        self.first = max(0, self.rows_committed - keep)
        self._rows = list(stream.copy_rows(self.first, self.rows_committed, 1))
        self.rows_committed = self.first + len(self._rows)

    def copy_rows(self, start: int, stop: int, step: int = 1) -> list[tuple[Any, ...]]:
        start, stop = max(start, self.first), min(stop, self.rows_committed)
        return self._rows[start - self.first : stop - self.first : step] if stop > start else []


class Segment:
    """One sub-run as a page sees it (a drop test's current, a stepped sine's frequency; a run on a
    road is one): its stream and the loop's counts while it runs, their last values once it ended."""

    def __init__(self, stream: Any, timing: Any, label: str):
        self.stream, self.timing, self.label = stream, timing, label
        self.closed = False
        self.trips: list[Any] = []
        self._final: tuple[int, int, dict[str, int] | None] | None = None

    def counts(self) -> tuple[int, int, dict[str, int] | None]:
        """Cycles, missed deadlines and the stream's health counts (None: this stream reports none)."""
        if self._final is not None:
            return self._final
        cycles = int(getattr(self.timing, "cycles", 0) or 0)
        missed = int(getattr(self.timing, "missed_deadlines", 0) or 0)
        return cycles, missed, stream_health(self.stream)

    def freeze(self, keep: int) -> None:
        """The sub-run ended: keep its counts and its last rows (its stream is closed next)."""
        self._final = self.counts()
        try:
            self.stream = FrozenRows(self.stream, keep)
        except (ValueError, OSError, BufferError):  # a stream already unmapped: its rows are gone
            self.stream = None
        self.closed = True


def stream_health(stream: Any) -> dict[str, int] | None:
    """``stream.health()`` (the loop process's link and clipping counts, updated as it runs) as
    :data:`HEALTH_KEYS` integers; None for a stream that reports none (the in-process loop's)."""
    health = getattr(stream, "health", None)
    if not callable(health):
        return None
    try:
        values = health()
    except (ValueError, OSError, BufferError):  # the stream closed under the reader
        return None
    if not isinstance(values, Mapping):
        return None
    return {key: int(values.get(key, 0) or 0) for key in HEALTH_KEYS}


class StreamView:
    """A reader of an experiment's streams (a ``views=`` entry of :func:`sashil.engine.sashil_run.closed_loop`,
    :func:`sashil.lab.drop_test` and :func:`sashil.lab.sweep`): each sub-run calls
    :meth:`start` with its fresh stream and :meth:`close` when it ends, so the view keeps one
    :class:`Segment` per sub-run, labelled from ``labels`` in order. The panel reads the newest rows
    from it at the display rate, never blocking the loop; ``keep`` rows of a sub-run are copied
    when it ends, for the page's last batches of it."""

    def __init__(
        self, labels: Sequence[str] = (), keep: int = 1, on_start: Callable[[int], None] | None = None
    ) -> None:
        self.labels = tuple(labels)
        self.keep = keep
        self.on_start = on_start
        self.segments: list[Segment] = []
        self.lock = threading.Lock()

    @property
    def stream(self) -> Any:
        """The newest sub-run's stream (None before the first starts)."""
        return self.segments[-1].stream if self.segments else None

    @property
    def timing(self) -> Any:
        return self.segments[-1].timing if self.segments else None

    @property
    def closed(self) -> bool:
        return bool(self.segments) and self.segments[-1].closed

    def start(self, stream: Any, timing: Any) -> StreamView:
        if self.segments and not self.segments[-1].closed:
            self.close()  # a sub-run that ended unannounced: its rows are kept all the same
        with self.lock:
            index = len(self.segments)
            label = self.labels[index] if index < len(self.labels) else ""
            self.segments.append(Segment(stream, timing, label))
        if self.on_start is not None:
            self.on_start(index)
        return self

    def close(self, trips: Any = (), notes: Any = ()) -> None:
        with self.lock:
            segment = self.segments[-1] if self.segments else None
        if segment is not None and not segment.closed:
            segment.trips = list(trips)
            segment.freeze(self.keep)

    def segment(self, index: int) -> Segment | None:
        with self.lock:
            return self.segments[index] if 0 <= index < len(self.segments) else None

    def count(self) -> int:
        with self.lock:
            return len(self.segments)


@dataclass
class RunState:
    """What a page is shown of the current (or last) experiment."""

    state: str = "idle"  # idle | starting | running | stopping
    run_id: int = 0
    experiment: str = "run"
    law: str = ""
    folder: str = ""
    exit_status: str = ""
    stop_reason: str = ""
    start_values: dict[str, Any] = field(default_factory=dict)
    values: dict[str, Any] = field(default_factory=dict)
    markers: list[dict[str, Any]] = field(default_factory=list)
    #: the sub-runs' labels in order (a drop test's currents, a stepped sine's frequencies)
    plan: list[str] = field(default_factory=list)
    #: the operator's newest instruction (a drop test's "press the arm ..."), while it runs
    prompt: str = ""
    #: the experiment's result lines (a drop's period and damping, a sweep's table, the timing)
    results: list[str] = field(default_factory=list)
    #: the health counts of the summary, once the run ended (a stream that reports none while it runs)
    final_health: dict[str, int] | None = None
    final_cycles: int = 0
    #: summary.json's ``safe_state`` and its line, once the run ended
    safe_state: dict[str, Any] | None = None
    safe_state_line: str = ""


def _number(value: Any, option: str, kind: type = float) -> Any:
    """A page's value of a numeric verb option, as argparse reads it (None: not given, the config's
    value stands); the option's argparse line for anything else."""
    if value is None or (isinstance(value, str) and value.strip() == ""):
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ConfigError(f"argument {option}: invalid {kind.__name__} value: {value!r}")
    if isinstance(value, float) and kind is int:
        if not value.is_integer():
            raise ConfigError(f"argument {option}: invalid int value: {value!r}")
        value = int(value)
    try:
        return kind(value.strip() if isinstance(value, str) else value)
    except ValueError:
        raise ConfigError(f"argument {option}: invalid {kind.__name__} value: {value!r}") from None


def _currents(value: Any) -> list[float] | None:
    """A drop test's currents: a list of numbers, or a text of them separated by commas or spaces
    (each ``--current A`` of the command line); None: not given."""
    if value is None:
        return None
    items = value.replace(",", " ").split() if isinstance(value, str) else value
    if not isinstance(items, (list, tuple)):
        raise ConfigError(f"argument --current: invalid float value: {value!r}")
    currents = [_number(item, "--current") for item in items]
    return [c for c in currents if c is not None] or None


def _stepped(value: Any) -> bool | None:
    if value is None or isinstance(value, bool):
        return value
    raise ConfigError(f"argument --stepped: expected true or false, got {value!r}")


class Bench:
    """One experiment at a time on the rig of ``config_file`` (None: the simulated rig, seed
    parameters), into ``runs_dir``, with the laws of the registry and of ``laws_dir``."""

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
        self._segment = 0  # the sub-run the page is being sent
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
        """The read-only config for a page's ``choice``: ``experiment`` (``run``, ``drop-test`` or
        ``sweep``), law, params, driver, port and the experiment's own values, resolved as its verb
        resolves its options (``sashil run``: road, duration_s; ``sashil drop-test``: theta0_deg,
        currents_a, duration_s; ``sashil sweep``: f_start_hz, f_stop_hz, duration_s,
        amplitude_deg, stepped, steps); ConfigError (one line) for anything refused."""
        from sashil.engine.resolve import ConfigSource, Option, resolve

        experiment = choice.get("experiment") or "run"
        if experiment not in EXPERIMENTS:
            raise ConfigError(f"experiment: expected one of {', '.join(EXPERIMENTS)}, got {experiment!r}")
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
        duration = _number(choice.get("duration_s"), "--duration")
        options: tuple[Option, ...]
        if experiment == "run":
            road = choice.get("road") or None
            if road is not None and (not isinstance(road, str) or not road.startswith(PAGE_ROADS)):
                raise ConfigError(
                    f"--road: a page chooses {', '.join(PAGE_ROADS)} (a file road is for the command line), got {road!r}"
                )
            options = (Option("--duration", "run.duration_s", duration), Option("--road", "run.road", road))
        elif experiment == "drop-test":
            options = (
                Option("--theta0-deg", "drop_test.theta0_deg", _number(choice.get("theta0_deg"), "--theta0-deg")),
                Option("--current", "drop_test.currents_a", _currents(choice.get("currents_a"))),
                Option("--duration", "drop_test.duration_s", duration),
            )
        else:
            options = (
                Option("--f-start", "sweep.f_start_hz", _number(choice.get("f_start_hz"), "--f-start")),
                Option("--f-stop", "sweep.f_stop_hz", _number(choice.get("f_stop_hz"), "--f-stop")),
                Option("--duration", "sweep.duration_s", duration),
                Option(
                    "--amplitude-deg", "sweep.amplitude_deg", _number(choice.get("amplitude_deg"), "--amplitude-deg")
                ),
                Option("--stepped", "sweep.stepped", _stepped(choice.get("stepped"))),
                Option("--steps", "sweep.steps", _number(choice.get("steps"), "--steps", int)),
            )
        source = ConfigSource(
            config=self.config_file,
            controller=self.laws[law].spec,
            sets=tuple(sets),
            options=options,
            driver=choice.get("driver") or None,
            port=choice.get("port") or None,
        )
        return resolve(source, experiment)

    def start(self, choice: Mapping[str, Any]) -> RunState:
        """Start the experiment of ``choice`` in the worker thread; ConfigError (nothing started)
        for a bad value or when one is already on."""
        with self._lock:
            if self.run.state != "idle":
                raise ConfigError(f"a run is already {self.run.state}: STOP it first")
            if self._doctoring:
                raise ConfigError("the board checks (doctor) are running: start when they end")
            config = self.resolve(choice)
            experiment = str(choice.get("experiment") or "run")
            from sashil.recording.outputs import Outputs
            from sashil.writer.run_folder import utc_stamp

            base = self.runs_dir / f"{utc_stamp()}-{experiment}"
            folder, suffix = base, 1
            while folder.exists():
                suffix += 1
                folder = base.with_name(f"{base.name}-{suffix}")
            law = self.laws[str(choice["law"])]
            declared = [p["name"] for p in law.about["parameters"]]
            from sashil.engine import assemble

            run_spec = assemble(config, reads=PANEL_READS)
            values = {name: run_spec.stage.controller.params.get(name) for name in declared}
            self.run = RunState(
                state="starting",
                run_id=self.run.run_id + 1,
                experiment=experiment,
                law=law.name,
                folder=str(folder),
                start_values=dict(values),
                values=dict(values),
                plan=sub_runs(run_spec.options, experiment),
            )
            self._config = config
            self._flag = StopFlag()
            rate = run_spec.loop.rate_hz
            self._step = decimation_step(rate)
            simulated_time = run_spec.virtual
            self._keep = max(1, int(rate * (TRACE_WINDOW_S if simulated_time else CATCH_UP_S)))
            self._segment = 0
            self._sent_row = 0
            self.view = StreamView(self.run.plan, self._keep, self._sub_run_started)
            model = run_spec.stage.model
            self._band = (model.params, run_spec.stage.current_max_a) if model.name == "bouc-wen" else None
            outputs = Outputs(out=folder)
            self._thread = threading.Thread(
                target=self._work,
                args=(experiment, config, outputs, self._flag, self.view),
                name="sashil-panel-run",
                daemon=True,
            )
            self._thread.start()
            return self.run

    def _sub_run_started(self, index: int) -> None:
        """A sub-run's loop started (the view's ``start``): the experiment runs; a new sub-run's
        operator instructions start afresh."""
        with self._lock:
            if self.run.state == "starting":
                self.run.state = "running"
            if index > 0:
                self.run.prompt = ""

    def _work(self, experiment: str, config: Any, outputs: Any, flag: StopFlag, view: StreamView) -> None:
        from sashil.engine.sashil_run import closed_loop
        from sashil.lab import drop_test, sweep

        status, reason = "error", ""
        summary: Mapping[str, Any] = {}
        try:
            if experiment == "run":
                run = closed_loop(config, outputs, self._on_event, tune=True, views=[view], stop=flag)
            elif experiment == "drop-test":
                run = drop_test(config, outputs, self._on_event, views=[view], stop=flag)
            else:
                run = sweep(config, outputs, self._on_event, views=[view], stop=flag)
            summary = run.summary
            status = str(summary.get("exit_status", "ok"))
            reason = str(summary.get("stop_reason") or "")
        except SashilError as err:
            self._on_event(Event("warning", str(err)))
            status = "stopped" if flag.requested else "error"
        except Exception as err:  # the run ended at 0 A first; the page must hear why
            self._on_event(Event("warning", f"{type(err).__name__}: {err}"))
        finally:
            if not summary:  # an experiment that raised after its folder was complete
                summary = _read_summary(outputs.out)
                status = str(summary.get("exit_status") or status)
            for line in run_health(summary):
                self._on_event(Event("result", line))
            safe = safe_state(summary)
            line = safe_state_line(safe, flag.requested) if safe is not None else ""
            if line:  # an event; the page shows it on its own line, not among the results
                self._add_event("result" if safe and safe.get("confirmed") else "warning", line)
            with self._lock:
                self.run.state = "idle"
                self.run.exit_status = status
                self.run.stop_reason = reason or (flag.signal_name or "")
                self.run.prompt = ""
                self.run.final_health = summary_health(summary)
                self.run.final_cycles = int((summary.get("timing") or {}).get("cycles") or 0)
                self.run.safe_state, self.run.safe_state_line = safe, line
            self._on_event(Event("progress", f"run ended: {status}", {"exit_status": status}))
            from sashil.runtime.loop_process import start_ahead

            start_ahead()  # the loop server, ready to fork the next run's loop before the next click

    def _on_event(self, event: Event) -> None:
        with self._lock:
            if event.kind == "progress" and event.text.startswith("sashil run:") and self.run.state == "starting":
                self.run.state = "running"
            elif event.kind == "prompt":
                self.run.prompt = event.text  # shown until the next one, the next sub-run or the end
            elif event.kind in ("result", "output") and event.text.strip() and "folder" not in event.data:
                self.run.results.append(event.text)  # the folder line is an event, not a result
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
        if self.run.experiment != "run":
            raise ConfigError(f"live tuning: a run on a road is tuned live, not a {self.run.experiment}")
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

        if self._config is None:
            raise ConfigError("save: no run yet (start one, tune it, then save)")
        config = thaw(self._config)
        for key, value in self.run.values.items():
            if value is not None:
                config["controller"][key] = value
        return str(yaml.safe_dump(_plain(config), sort_keys=False))

    # -- the stream, for pages ------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        """The experiment's state, the sub-run the page is shown, the loop's counts and health
        (live when the stream reports it, the summary's once the run ended), the operator's prompt,
        the results and the safe state's confirmation (a page's status line)."""
        view = self.view
        index = min(self._segment, view.count() - 1) if view is not None else -1
        shown = view.segment(index) if view is not None else None
        cycles, missed, health = shown.counts() if shown is not None else (0, 0, None)
        stream = shown.stream if shown is not None else None
        with self._lock:
            run = self.run
            live = health is not None
            if run.state == "idle" and run.final_health is not None:  # the summary's counts are exact
                health = {**(health or {}), **run.final_health}
                cycles, live = run.final_cycles or cycles, False
            clipped = health.get("clipped_cycles") if health is not None else None
            sub_run = None
            if shown is not None and (len(run.plan) > 1 or run.experiment != "run"):
                sub_run = {"index": index + 1, "of": max(len(run.plan), 1), "label": shown.label}
            return {
                "state": run.state,
                "run_id": run.run_id,
                "experiment": run.experiment,
                "law": run.law,
                "folder": run.folder,
                "exit_status": run.exit_status,
                "stop_reason": run.stop_reason,
                "values": dict(run.values),
                "start_values": dict(run.start_values),
                "markers": list(run.markers),
                "sub_run": sub_run,
                "cycles": cycles,
                "missed_deadlines": missed,
                "missed_share": missed / cycles if cycles else 0.0,
                "health": health,
                "health_live": live,
                "clipped_share": clipped / cycles if clipped is not None and cycles else None,
                "prompt": run.prompt,
                "results": list(run.results),
                "safe_state": run.safe_state,
                "safe_state_line": run.safe_state_line,
                "rows": int(stream.rows_committed) if stream is not None else 0,
            }

    def next_batch(self) -> bytes | None:
        """The shown sub-run's rows since the last batch (decimated, at most the trace window), as
        one binary batch; None when there is nothing new. A sub-run is sent to its end (the rows
        copied when it ended) before the next one's rows. Called once per display tick, for every page."""
        view = self.view
        if view is None:
            return None
        while True:
            segment = view.segment(self._segment)
            if segment is None or segment.stream is None:
                if view.segment(self._segment + 1) is None:
                    return None
                self._segment, self._sent_row = self._segment + 1, 0
                continue
            stream = segment.stream
            committed = int(stream.rows_committed)
            start, stop = next_window(committed, self._sent_row, self._step, self._keep)
            if stop > start or view.segment(self._segment + 1) is None:
                break
            self._segment, self._sent_row = self._segment + 1, 0  # this sub-run is sent whole: the next
        if stop <= start:
            return None
        rows = stream.copy_rows(start, stop, self._step)
        if not rows:
            return None
        self._sent_row = start + len(rows) * self._step
        return encode_batch(select_columns(rows, stream.columns, self._band))


#: what the panel reads of a run's experiment to label its sub-runs (a run's ``options``)
PANEL_READS = {
    "currents_a": "drop_test.currents_a",
    "stepped": "sweep.stepped",
    "f_start_hz": "sweep.f_start_hz",
    "f_stop_hz": "sweep.f_stop_hz",
    "steps": "sweep.steps",
    "spacing": "sweep.spacing",
    "sweep_s": "sweep.duration_s",
}


def sub_runs(options: Mapping[str, Any], experiment: str) -> list[str]:
    """The labels of an experiment's sub-runs, in the order its loops run: a drop test's currents,
    a stepped sine's frequencies, a chirp's band; a run on a road is one, unlabelled (``options``:
    a run's, :data:`PANEL_READS`)."""
    if experiment == "drop-test":
        return [f"{float(current):g} A" for current in options["currents_a"]]
    if experiment == "sweep":
        from sashil.lab._sweep import frequencies

        f0, f1 = options["f_start_hz"], options["f_stop_hz"]
        if options["stepped"]:
            return [f"{f:.3g} Hz" for f in frequencies(f0, f1, options["steps"], options["spacing"])]
        return [f"chirp {f0:g}-{f1:g} Hz over {options['sweep_s']:g} s"]
    return [""]


def _read_summary(folder: str | Path | None) -> dict[str, Any]:
    """The ``summary.json`` of ``folder`` ({} when there is none)."""
    import json

    if folder is None:
        return {}
    try:
        data = json.loads((Path(folder) / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _runs_of(summary: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    """The summary itself, then its sub-runs' entries (a drop test's, a stepped sine's), last last."""
    entries = summary.get("runs")
    subs = [entry for entry in entries if isinstance(entry, Mapping)] if isinstance(entries, list) else []
    return [summary, *subs]


def safe_state(summary: Mapping[str, Any]) -> dict[str, Any] | None:
    """``summary.json``'s ``safe_state`` (the coil's measured current once the loop, at 0 A after the
    end, read it down to the safe level, and how long after): the run's own, else its last sub-run's."""
    for entry in reversed(_runs_of(summary)):
        found = entry.get("safe_state")
        if isinstance(found, Mapping) and "current_a" in found:
            return dict(found)
    return None


def safe_state_line(safe: Mapping[str, Any], stopped: bool) -> str:
    """The one line a page shows of ``safe``: ``0 A confirmed: coil at 0.012 A 38 ms after STOP``."""
    after = f"{1e3 * float(safe.get('after_s') or 0.0):.0f} ms after {'STOP' if stopped else 'the end'}"
    current = safe_state_current(safe)
    if safe.get("sensed") is False:
        return f"{NO_SENSE_REST}: commanded {after}; the board's readback is the only confirmation"
    if safe.get("confirmed"):
        return f"0 A confirmed: {current} {after}"
    return f"0 A NOT confirmed: {current} {after}: check the rig"


def summary_health(summary: Mapping[str, Any]) -> dict[str, int] | None:
    """The health counts of a finished run's ``summary.json`` (its sub-runs' added up): samples lost
    and bad frames of the link, the clipped cycles of the law; None when it reports none of them."""
    found: dict[str, int] = {}
    runs = _runs_of(summary)
    for entry in runs[1:] if len(runs) > 1 else runs:
        link = entry.get("link")
        if isinstance(link, Mapping) and link:
            found["samples_lost"] = found.get("samples_lost", 0) + int(link.get("samples_missed", 0) or 0)
            found["bad_frames"] = found.get("bad_frames", 0) + int(link.get("bad_frames", 0) or 0)
            if "watchdog" in link:
                found["watchdog"] = found.get("watchdog", 0) + int(link.get("watchdog") or 0)
        stats = entry.get("controller_stats")
        if isinstance(stats, Mapping) and "clipped_cycles" in stats:
            found["clipped_cycles"] = found.get("clipped_cycles", 0) + int(stats["clipped_cycles"] or 0)
    return found or None


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
