"""The drop test of seed 001 section 8, as a library function: hold the arm at θ0 (−5°), release,
record the free oscillation at each constant current, one sub-run per current.

The plan (:class:`DropTestPlan`) is a loop stage: it commands a constant current from the start
(so the current already flows at release), waits for a steady hold near theta0, detects the
release and records the free oscillation for the requested duration. The same plan runs on the
simulated rig (which plays the operator), the emulator and the bench (where a person does).

Release time. When the backend plays the operator it knows the instant it lets go. Otherwise the
plan estimates it from the departure: just after release the arm leaves the hold angle with
constant acceleration, ``|theta - theta_hold| = a/2 * (t - t_r)^2``, so ``sqrt|dtheta|`` is linear
in t and its zero is t_r (a least-squares line through the departure samples between two encoder
counts and the release threshold).
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil import engine
from sashil.api import Run, load_run
from sashil.config.overrides import set_values
from sashil.config.parts import RunSpec, StageParts
from sashil.control.law_registry import law_label
from sashil.control.registry import stage_signals
from sashil.drivers.interface import FLAG_HELD, TWO_PI, RigCommand, RigInterface, RigSample, capabilities_of
from sashil.drivers.operator_prompt import hold_prompt
from sashil.engine import assemble, assembled
from sashil.engine.checks import check_theta0
from sashil.engine.events import Event, Listener, ignore
from sashil.errors import ConfigError, DriverTimeoutError, SashilError
from sashil.lab.compare_metrics import sample_times
from sashil.lab.metrics import DropMetrics, damping_text, drop_metrics, settling_text
from sashil.plugins import STAGES_GROUP, entry_point_table, load_class
from sashil.recording.documents import Documents
from sashil.recording.outputs import Outputs
from sashil.recording.plots import plot_drop_test
from sashil.recording.run_folder import RunFolder
from sashil.recording.run_progress import SessionHooks
from sashil.runtime.clock import Clock
from sashil.runtime.runner import CYCLES_FILE, RunOutcome
from sashil.runtime.signals import StopFlag
from sashil.writer.folder_writer import FolderWriter

if TYPE_CHECKING:
    from sashil.config.parts import StageParts
    from sashil.config.typed import RunConfig

__all__ = ["READS", "DropRecord", "DropTestPlan", "drop_test", "result_line", "run_drop_test"]

#: the drop test's own values (``{name: config key}``), read once by the engine into its run's
#: ``options`` (:func:`sashil.engine.assemble`)
READS = {
    "theta0_deg": "drop_test.theta0_deg",
    "currents_a": "drop_test.currents_a",
    "duration_s": "drop_test.duration_s",
    "settle_band_deg": "drop_test.settle_band_deg",
    "hold_tolerance_deg": "drop_test.hold_tolerance_deg",
    "hold_time_s": "drop_test.hold_time_s",
    "release_threshold_deg": "drop_test.release_threshold_deg",
    "hold_timeout_s": "drop_test.hold_timeout_s",
    "port": "driver.port",
}


def _label(current: float) -> str:
    return f"i{current:.3f}A"


def result_line(metrics: DropMetrics, duration_s: float) -> str:
    """One drop's period, first peaks, damping ratio and settling, as reported after it."""
    period = "-" if metrics.period_s is None else f"{metrics.period_s:.3f} s"
    peaks = ", ".join(f"{p:.2f}" for p in metrics.peaks_deg[:4])
    return f"period {period}, peaks [{peaks}] deg, {damping_text(metrics)}, {settling_text(metrics, duration_s)}"


def result_warnings(metrics: DropMetrics) -> list[str]:
    """What the operator should know about a drop's figures: no peaks, or a damping ratio the record cut short."""
    if metrics.peaks_note is not None:
        return [f"no peaks: {metrics.peaks_note}"]
    if metrics.damping_note is not None and (metrics.damping_ratio is None or metrics.damping_record_short):
        return [metrics.damping_note]
    return []


def drop_test(
    config: RunConfig,
    outputs: Outputs | None = None,
    on_event: Listener = ignore,
    *,
    views: Sequence[Any] = (),
    stop: StopFlag | None = None,
) -> Run:
    """Run the drop tests of a resolved ``config`` (:func:`sashil.engine.resolve.resolve` with verb
    ``drop-test``: ``drop_test.theta0_deg``, ``currents_a``, ``duration_s``) into a new run folder.

    Each current is a sub-run (``i0.000A/``, ...) when there are several. The law in
    ``controller.law`` takes over at the release (``passive``: the constant current throughout).
    On the real clock each drop runs in a loop process of its own (``loop.process``). ``views``:
    readers of each drop's stream, as :func:`sashil.engine.sashil_run.closed_loop` takes them (each gets
    ``start(stream, timing)`` and ``close(trips, notes)`` once per drop, with that drop's stream).
    ``stop``: a flag another thread may set to end the current drop at 0 A and the test.
    Returns the folder as a :class:`~sashil.api.Run`. Bad input raises ConfigError before any folder
    exists; a run that fails after it started raises the error that ended it, after the folder is
    complete (its data up to the failure, its plot and summary)."""
    outputs = outputs if outputs is not None else Outputs()
    run = assemble(config, reads=READS)
    drop = run.options
    theta0_deg, duration = float(drop["theta0_deg"]), float(drop["duration_s"])
    currents = [float(value) for value in drop["currents_a"]]
    # each drop of several records the config that reruns it alone: the resolved one at its current
    own = {c: set_values(config, [(["drop_test", "currents_a"], [c])], "--current")[0] for c in currents}
    outputs.check(run.rig.backend)
    # the law and its parameters were checked in the resolution; its controller is built where each drop's loop runs
    signals = stage_signals(run.stage)
    closed = bool(signals)
    folder = RunFolder.create(outputs.out, "drop-test")
    law, origin = law_label(run.stage.law)
    live = outputs.open_rerun(DROP_COLUMNS + signals, "sashil drop-test", folder.path)
    live_offset_s = 0.0
    several = len(currents) > 1
    writer = _writer(run, folder, law if closed else f"{law} (constant current per run)", origin, several, outputs)
    documents = Documents([writer])
    documents.start(None, config, run)
    overlay = []
    prompt = lambda line: on_event(Event("prompt", line))  # noqa: E731
    for current in currents:
        label = f"{law} (from {current:g} A until the release)" if closed else f"{law} {current:g} A"
        on_event(Event("progress", f"drop test from {theta0_deg:g} deg, {label} ...", {"current_a": current}))
        target = writer.folder_for(_label(current))
        settings = DropTestSettings.of(run, theta0_deg, current, duration)
        record = run_drop(
            run,
            plan_drop(run, settings, prompt, CONFIG_LAW if closed else None),
            data_path=target.file(CYCLES_FILE),  # every cycle streamed as it runs (the hold too)
            live=SessionHooks(*views) if views else None,
            stop=stop,
            trace=outputs.can_trace(target.path, drop["port"]),
            documents=documents,
            name=_label(current),
            recorded_config=own[current] if several else None,
            describe=functools.partial(_described, current, label, theta0_deg),
        )
        assert record.metrics is not None and record.run  # run_drop sets both
        if live is not None:
            live.note(
                live_offset_s,
                f"drop test from {theta0_deg:g} deg at {current:g} A (release at t = {live_offset_s:g} s)",
            )
            live.log_columns(record.columns, live_offset_s)
            live_offset_s += duration + 1.0
        entry = writer.entries[-1]
        if writer.failed:
            overlay.append({**entry, **record.columns, "label": f"{label} (stopped)"})
            break
        overlay.append({**entry, **record.columns, "label": label})
        on_event(Event("result", result_line(record.metrics, duration), {"current_a": current}))
        for note in result_warnings(record.metrics):
            on_event(Event("warning", f"drop test at {current:g} A: {note}", {"current_a": current}))
    under = f", under {law}" if closed else ""
    title = f"Drop test from {theta0_deg:g}°{under} ({run.rig.backend} rig)"
    return _finish(folder, writer, documents, overlay, title, drop["settle_band_deg"], live, on_event)


def _finish(
    folder: RunFolder,
    writer: FolderWriter,
    documents: Documents,
    overlay: list[dict[str, Any]],
    title: str,
    band_deg: float,
    live: Any,
    on_event: Listener,
) -> Run:
    """The drop test's plot and summary; the folder discarded when bad input stopped the first drop
    before it began, and the error that ended a drop raised after the folder is complete."""
    plot = plot_drop_test(folder.file("drop_test.png"), overlay, title, band_deg=band_deg)
    if live is not None:
        live.close()
    if writer.error is not None and getattr(writer.error, "exit_code", 1) == 2:
        # bad input found on opening the rig (a port that cannot be opened) or before the drop began
        # (an emulated rig whose operator holds nothing): the drop never started, no folder
        folder.discard()
        raise writer.error
    documents.end()
    on_event(Event("folder", f"run folder: {folder.path} (plot {plot.name})", {"folder": str(folder.path)}))
    if writer.error is not None:
        raise writer.error  # the data up to it is on disk
    return load_run(Path(folder.path))


def _writer(
    run: RunSpec, folder: RunFolder, controller: str, origin: str, several: bool, outputs: Outputs
) -> FolderWriter:
    """The writer of the drop test's folder, with the keys its summaries share."""
    common = {
        "driver": run.rig.backend,
        "controller": controller,
        "controller_origin": origin,
        "clock": "virtual" if run.virtual else "real",  # timing is simulated on the virtual clock
    }
    return FolderWriter(folder, "drop-test", common, several=several, outputs=outputs)


def _described(current: float, label: str, theta0_deg: float, record: DropRecord) -> dict[str, Any]:
    """One drop's analysis for its stop document: its row of the summary, its data and what its
    --format files are labelled with."""
    entry = _drop_row(record, current, label, theta0_deg)
    return {"entry": entry, "data": record.columns, "formats": {"current_a": current, "controller": label}}


def _drop_row(record: Any, current: float, label: str, theta0_deg: float) -> dict[str, Any]:
    """One drop's row of the folder's summary: what ran, its figures, its timing and facts."""
    return {
        "current_a": current,
        "controller": label,
        "theta0_deg": theta0_deg,
        "hold_angle_deg": math.degrees(record.hold_angle_rad),
        "release_estimated": record.release_estimated,
        **record.metrics.as_dict(),
        "timing": record.run["timing"],
        "trips": record.run["trips"],
        "safe_state": record.run.get("safe_state"),
        "link": record.extra.get("link"),
        "realtime": record.extra.get("realtime"),
        "can_trace": record.extra.get("can_trace"),
        "loop_process": record.extra.get("loop_process"),
    }


#: columns of a drop test's data.csv (docs/architecture.md names)
DROP_COLUMNS = ("time_s", "theta_rad", "theta_road_rad", "current_a", "current_cmd_a")
#: added when a controller acts after the release (its per-cycle values, docs/architecture.md names)
CONTROLLER_COLUMNS = ("theta_dot_rad_s", "z_hat", "torque_hat_nm", "torque_cmd_nm")


def controller_columns(controller: Any) -> tuple[str, ...]:
    """The columns a drop test records of its controller: what the controller says it records
    (``signal_names``: a current law's own output, ``current_law_a``, too), else
    :data:`CONTROLLER_COLUMNS`; none without a controller."""
    if controller is None:
        return ()
    return tuple(getattr(controller, "signal_names", CONTROLLER_COLUMNS))


#: how long a drop test on a pseudo-terminal (an emulated rig) waits for its operator's hold [s]:
#: an emulator started with --hold-deg holds the arm from its first sample on
EMULATED_HOLD_WAIT_S = 1.0


def pseudo_terminal(rig: Any) -> str | None:
    """The rig's port when it is a pseudo-terminal (``/dev/pts/N``, or a link to one: an emulator's),
    else None (a device, a socket, the simulated rig)."""
    import os

    port = getattr(getattr(rig, "settings", None), "port", None)
    if not isinstance(port, str) or not port.startswith("/"):
        return None
    return port if os.path.realpath(port).startswith("/dev/pts/") else None


@dataclass
class DropTestSettings:
    theta0_rad: float
    current_a: float
    duration_s: float
    rate_hz: float
    hold_tolerance_rad: float
    hold_time_s: float
    release_threshold_rad: float
    hold_timeout_s: float
    known_release_after_s: float | None = None  # set when the backend plays the operator
    #: the rig's port when it is a pseudo-terminal (an emulator's link): no hand can hold that arm
    pseudo_terminal: str | None = None

    def values(self) -> dict[str, Any]:
        """The settings a loop process builds the same drop from (what the backend decides, the
        operator's release and a pseudo-terminal's port, is decided there again)."""
        return {name: value for name, value in vars(self).items() if name not in self.DECIDED}

    #: the settings the rig decides (:meth:`DropTestPlan.attach_rig`), not the config
    DECIDED = ("known_release_after_s", "pseudo_terminal")

    @classmethod
    def from_config(cls, config: RunConfig, theta0_deg: float, current_a: float, duration_s: float) -> DropTestSettings:
        """One drop's settings in a resolved config (:meth:`of` its assembled run)."""
        return cls.of(assemble(config, reads=READS), theta0_deg, current_a, duration_s)

    @classmethod
    def of(cls, run: RunSpec, theta0_deg: float, current_a: float, duration_s: float) -> DropTestSettings:
        """One drop's settings in the assembled ``run`` (its ``options``: the drop test's :data:`READS`)."""
        drop = run.options
        check_theta0(drop["release_threshold_deg"], theta0_deg, "theta0_deg")
        return cls(
            theta0_rad=math.radians(theta0_deg),
            current_a=current_a,
            duration_s=duration_s,
            rate_hz=run.loop.rate_hz,
            hold_tolerance_rad=math.radians(drop["hold_tolerance_deg"]),
            hold_time_s=drop["hold_time_s"],
            release_threshold_rad=math.radians(drop["release_threshold_deg"]),
            hold_timeout_s=drop["hold_timeout_s"],
        )


@dataclass
class DropRecord:
    """The recorded free oscillation, time zero at the release."""

    columns: dict[str, np.ndarray]
    release_time_ns: int
    release_estimated: bool
    hold_angle_rad: float
    #: the loop run's summary.json keys (:func:`~sashil.runtime.runner.loop_summary`): how it ended, its
    #: timing, trips and safe state
    run: dict[str, Any] = field(default_factory=dict)
    metrics: DropMetrics | None = None
    error: SashilError | None = None  # what ended the test early (the data up to it is kept)
    extra: dict[str, Any] = field(default_factory=dict)
    #: every stream column of the record's rows (time zero at the release)
    stream: dict[str, np.ndarray] = field(default_factory=dict)
    #: the device's clock at the release [s] (between the samples around it)
    device_release_s: float | None = None


def estimate_release_ns(times_ns: list[int], angles: list[float], hold_angle: float, resolution: float) -> int:
    """Release instant from departure samples: zero of the line through ``sqrt|theta - hold|``."""
    ts, roots = [], []
    for t, angle in zip(times_ns, angles, strict=True):
        moved = abs(angle - hold_angle)
        if moved >= 1.5 * resolution:
            ts.append(t)
            roots.append(math.sqrt(moved))
    if len(ts) >= 2:
        t_rel = np.asarray(ts, dtype=float) - ts[0]
        slope, intercept = np.polyfit(t_rel, np.asarray(roots), 1)
        if slope > 0:
            estimate = ts[0] + int(round(-intercept / slope))
            last_still = max(
                (t for t, a in zip(times_ns, angles, strict=True) if abs(a - hold_angle) < 0.5 * resolution),
                default=None,
            )
            if last_still is None or estimate >= last_still:
                return min(estimate, ts[0])
            return last_still
    still = [t for t, a in zip(times_ns, angles, strict=True) if abs(a - hold_angle) < resolution]
    return still[-1] if still else times_ns[0]


class DropTestPlan:
    """Loop stage: constant current; wait for the hold; detect the release; run ``duration_s`` on.

    The plan commands and decides; it keeps no copy of the data. Its :attr:`phase_code` (an index
    of :data:`PHASES`) goes into every row of the runner's stream, and :func:`drop_record` derives
    the record from that stream after the run (the release dated from the departure samples)."""

    PHASES = ("wait-hold", "held", "record", "done")

    def __init__(
        self,
        settings: DropTestSettings,
        counts_per_rev: int,
        controller: Any = None,
        notify: Callable[[str], None] | None = None,
    ):
        self.s = settings
        # operator prompts and what the plan detected (one line at each phase change, never per cycle)
        self.notify = notify
        # optional loop stage (sashil.control) that commands the damper after the release
        self.controller = controller
        #: the controller is the config's law (made by :func:`config_controller`): a loop process
        #: can make its own
        self.from_config = False
        #: the controller's per-cycle values go into the stream (the loop reads them after each step,
        #: from the controller itself: the attributes below forward them too, but slower)
        self.signal_names = controller_columns(controller)
        self.signal_source = controller if controller is not None else self
        self.command = RigCommand(settings.current_a)
        self.resolution = TWO_PI / counts_per_rev
        self.phase = "wait-hold"
        self.phase_code = 0
        self.start_ns: int | None = None
        self._still_since: int | None = None
        self._hold_sum = 0.0
        self._hold_count = 0
        self.hold_angle = settings.theta0_rad
        self.held_elsewhere = False  # a simulated operator held the arm away from theta0
        self.operator_seen = False  # a sample said a simulated operator holds the arm (FLAG_HELD)
        #: when the plan saw the arm leave the hold (host ns); the release itself is dated after the run
        self.detected_ns: int | None = None
        self._end_ns: int | None = None

    #: what the loop process sends back after the run (:meth:`facts`): what the plan saw
    FACTS = ("start_ns", "detected_ns", "hold_angle", "held_elsewhere", "operator_seen", "phase")

    def spec(self) -> dict[str, Any] | None:
        """What a loop process builds this drop from (:func:`drop_in_loop`), or None when it cannot: a
        controller that is neither the config's law (:data:`CONFIG_LAW`) nor one with a ``spec()``
        of its own (a calibration step's stage) stays in this process."""
        controller: Any = None
        if self.from_config:
            controller = CONFIG_LAW
        elif self.controller is not None:
            controller = self.controller.spec() if hasattr(self.controller, "spec") else None
            if controller is None:
                return None
        return {
            "kind": "drop-test",
            "theta0_deg": math.degrees(self.s.theta0_rad),
            "current_a": self.s.current_a,
            "duration_s": self.s.duration_s,
            "settings": self.s.values(),
            "controller": controller,
        }

    def attach_rig(self, rig: RigInterface) -> None:
        """Meet the rig the drop runs on, before its loop starts: a backend that plays the operator
        holds the arm now and lets go after the hold time (with the coil already at the drop's
        current when it can); a pseudo-terminal's port is noted (no hand can hold that arm)."""
        settings = self.s
        release_after = max(settings.hold_time_s + 0.1, 0.3)
        if rig.operator_hold(settings.theta0_rad, release_after):
            settings.known_release_after_s = release_after
            if capabilities_of(rig).initial_current:
                rig.set_initial_current(settings.current_a)  # type: ignore[attr-defined]  # declared by the backend
        else:
            settings.pseudo_terminal = pseudo_terminal(rig)

    def facts(self) -> dict[str, Any]:
        """What the plan saw during the run, which the record is derived from (:func:`drop_record`),
        with the settings the backend decided (it plays the operator; a pseudo-terminal's port)."""
        return {
            **{name: getattr(self, name) for name in self.FACTS},
            "known_release_after_s": self.s.known_release_after_s,
            "pseudo_terminal": self.s.pseudo_terminal,
        }

    def absorb(self, facts: dict[str, Any]) -> None:
        """Take the :meth:`facts` of the same plan run in the loop process."""
        for name in self.FACTS:
            setattr(self, name, facts[name])
        self.phase_code = self.PHASES.index(self.phase)
        self.s.known_release_after_s = facts["known_release_after_s"]
        self.s.pseudo_terminal = facts["pseudo_terminal"]

    def __getattr__(self, name: str) -> Any:  # the controller's per-cycle signals (signal_names)
        if name in self.__dict__.get("signal_names", ()) and self.__dict__.get("controller") is not None:
            return getattr(self.controller, name)
        raise AttributeError(name)

    def _enter(self, phase: str) -> None:
        self.phase = phase
        self.phase_code = self.PHASES.index(phase)

    @property
    def known_release_ns(self) -> int | None:
        """The release instant when the backend plays the operator (it knows when it lets go)."""
        if self.s.known_release_after_s is None or self.start_ns is None:
            return None
        return self.start_ns + round(self.s.known_release_after_s * 1e9)

    # the cycle -------------------------------------------------------------------------------
    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand | None:
        theta = sample.theta_rad
        if self.start_ns is None:
            self.start_ns = t_ns
            if self.notify is not None and self.s.known_release_after_s is None and self.s.pseudo_terminal is None:
                self.notify(
                    f"{hold_prompt(math.degrees(self.s.theta0_rad))} (within "
                    f"±{math.degrees(self.s.hold_tolerance_rad):g} deg) and hold it still; now at "
                    f"{math.degrees(theta):.2f} deg"
                )
        ctl = None
        if self.controller is not None:
            self.controller.held = self.phase != "record"  # the operator's hand is outside the model
            ctl = self.controller.step(sample, t_ns, dt_ns)
        if self.phase == "record":
            assert self._end_ns is not None  # set at the release
            if t_ns > self._end_ns:
                self._enter("done")
                return None
            return self.command if ctl is None else ctl
        if self.phase == "wait-hold":
            self._wait_hold(t_ns, theta, sample.flags)
        elif self.phase == "held":
            if abs(theta - self.hold_angle) > self.s.release_threshold_rad:
                self._released(t_ns)
            elif (t_ns - self.start_ns) * 1e-9 > 2 * self.s.hold_timeout_s:
                raise DriverTimeoutError(
                    f"drop test: the arm was held at {math.degrees(self.hold_angle):.2f} deg but not released "
                    f"within {2 * self.s.hold_timeout_s:g} s"
                )
        if ctl is not None and self.phase == "record":
            return ctl
        return self.command

    def _wait_hold(self, t_ns: int, theta: float, flags: int = 0) -> None:
        target = self.s.theta0_rad
        if flags & FLAG_HELD:
            self.operator_seen = True
        port = self.s.pseudo_terminal
        assert self.start_ns is not None  # step() sets it on the first cycle
        if port is not None and not self.operator_seen and (t_ns - self.start_ns) * 1e-9 > EMULATED_HOLD_WAIT_S:
            raise ConfigError(
                f"drop test: {port} is a pseudo-terminal (an emulated rig) whose operator does not hold the arm, "
                f"and no hand can: start the emulator with --hold-deg {math.degrees(self.s.theta0_rad):g} "
                f"(e.g. sashil emulate --link {port} --hold-deg {math.degrees(self.s.theta0_rad):g} "
                "--release-after 1) to hold it at each connection and let go"
            )
        if flags & FLAG_HELD and abs(theta - target) > self.s.hold_tolerance_rad:
            # a simulated operator (the emulator's --hold-deg) says it holds the arm: take the hold
            # where it is rather than wait for an angle it will never press to
            if not self.held_elsewhere:
                logging.getLogger("sashil").warning(
                    "drop test: the rig's operator holds the arm at %.2f deg, not at theta0 = %.2f deg; "
                    "the drop starts from there",
                    math.degrees(theta),
                    math.degrees(target),
                )
            self.held_elsewhere = True
            target = theta
        if abs(theta - target) <= self.s.hold_tolerance_rad:
            if (
                self._still_since is None
                or abs(theta - self._hold_sum / max(self._hold_count, 1)) > 2 * self.resolution
            ):
                self._still_since, self._hold_sum, self._hold_count = t_ns, 0.0, 0
            self._hold_sum += theta
            self._hold_count += 1
            if (t_ns - self._still_since) * 1e-9 >= self.s.hold_time_s:
                self._enter("held")
                self.hold_angle = self._hold_sum / self._hold_count
                if self.notify is not None and self.s.known_release_after_s is None:
                    self.notify(
                        f"hold detected at {math.degrees(self.hold_angle):.2f} deg: release the arm when ready "
                        f"(detected when it moves {math.degrees(self.s.release_threshold_rad):g} deg)"
                    )
        else:
            self._still_since = None
        assert self.start_ns is not None  # step() sets it on the first cycle
        if self.phase == "wait-hold" and (t_ns - self.start_ns) * 1e-9 > self.s.hold_timeout_s:
            raise DriverTimeoutError(
                f"drop test: no steady hold within ±{math.degrees(self.s.hold_tolerance_rad):g} deg of "
                f"{math.degrees(self.s.theta0_rad):g} deg for {self.s.hold_time_s:g} s within "
                f"{self.s.hold_timeout_s:g} s (press the arm to theta0 and hold it still)"
            )

    def _released(self, t_ns: int) -> None:
        """The arm left the hold: record ``duration_s`` from the release (known, or at the latest now)."""
        self.detected_ns = t_ns
        known = self.known_release_ns
        self._end_ns = (t_ns if known is None else known) + round(self.s.duration_s * 1e9)
        self._enter("record")
        if self.notify is not None and known is None:  # a person let go (the backend knows when it did)
            self.notify(
                f"release detected: the arm left {math.degrees(self.hold_angle):.2f} deg; "
                f"recording {self.s.duration_s:g} s"
            )


#: how far before its detection the release is looked for in the stream (the departure samples)
RELEASE_WINDOW_S = 1.0


def drop_record(stream: dict[str, np.ndarray], plan: DropTestPlan, loop_start_ns: int) -> DropRecord:
    """The record from the release on, derived from the runner's stream of every cycle.

    The release is the backend's known instant, else the zero of the departure (see the module
    docstring) in the stream's rows of the last :data:`RELEASE_WINDOW_S` before the detection.
    Columns: :data:`DROP_COLUMNS` (+ :func:`controller_columns` under a controller) and ``seq``,
    time zero at the release; rows up to ``duration_s`` after it (the shutdown's 0 A row included
    when the run ended earlier). ``stream`` keeps every stream column of those rows (device time,
    road speed commanded) for a caller that needs them."""
    names = DROP_COLUMNS + controller_columns(plan.controller) + ("seq",)
    empty = {name: np.zeros(0, dtype=np.int64 if name == "seq" else float) for name in names}
    if plan.detected_ns is None or not stream or stream["time_s"].size == 0:
        return DropRecord(empty, 0, False, plan.hold_angle)
    t_ns = loop_start_ns + np.round(stream["time_s"] * 1e9).astype(np.int64)
    release_ns = plan.known_release_ns
    estimated = release_ns is None
    if release_ns is None:
        window = (t_ns >= plan.detected_ns - round(RELEASE_WINDOW_S * 1e9)) & (t_ns < plan.detected_ns)
        release_ns = (
            estimate_release_ns(
                t_ns[window].tolist(), stream["theta_rad"][window].tolist(), plan.hold_angle, plan.resolution
            )
            if window.any()
            else plan.detected_ns
        )
    rows = (t_ns >= release_ns) & (t_ns - release_ns <= round(plan.s.duration_s * 1e9))
    columns = {name: stream[name][rows] for name in names}
    columns["time_s"] = (t_ns[rows] - release_ns) * 1e-9
    columns["seq"] = columns["seq"].astype(np.int64)
    record = DropRecord(columns, release_ns, estimated, plan.hold_angle)
    record.stream = {name: values[rows] for name, values in stream.items()}
    record.stream["time_s"] = columns["time_s"]
    if "device_time_us" in stream:  # the device's clock at the release (between two samples)
        record.device_release_s = float(np.interp(release_ns, t_ns, stream["device_time_us"] * 1e-6))
    return record


#: ``run_drop_test(controller=CONFIG_LAW)``: the config's law takes over at the release, made where
#: the loop runs (in the loop process too)
CONFIG_LAW = "config"


def stage_controller(stage: StageParts) -> Any:
    """The run's controller, which takes over at the release, or None for a law that reads no
    state (such as the passive law: the drop's constant current throughout)."""
    from sashil.control.registry import law_reads_state, make_controller

    return make_controller(None, stage) if law_reads_state(stage) else None


def plan_drop(
    run: RunSpec,
    settings: DropTestSettings,
    notify: Callable[[str], None] | None = None,
    controller: Any = CONFIG_LAW,
) -> DropTestPlan:
    """The plan of one drop of ``settings`` in the assembled ``run``, not yet given its rig
    (:meth:`DropTestPlan.attach_rig`). ``controller``: the stage that takes over at the release
    (:data:`CONFIG_LAW`: the run's law, None: the constant current throughout)."""
    from_config = isinstance(controller, str) and controller == CONFIG_LAW
    plan = DropTestPlan(
        settings,
        run.stage.counts_per_rev,
        stage_controller(run.stage) if from_config else controller,
        notify,
    )
    plan.from_config = from_config
    return plan


def drop_in_loop(run: RunSpec, rig: RigInterface, prompt: Callable[[str], None]) -> tuple[DropTestPlan, str, str]:
    """One drop built in a loop process (the ``drop-test`` plan of ``sashil.plans``: ``run.plan``
    as :meth:`DropTestPlan.spec` gives it), its operator prompts handed to ``prompt`` as they come;
    the stage that takes over at the release is the run's law, none, or a stage built from its spec
    (``kind``: a ``sashil.stages`` entry)."""
    spec = run.plan
    controller = spec.get("controller", CONFIG_LAW)
    if isinstance(controller, dict):
        kind = str(controller.get("kind"))
        stage_class = load_class(_registered(STAGES_GROUP, kind, "stage"), f"stage {kind!r}")
        controller = stage_class.from_spec(controller)  # type: ignore[attr-defined]  # the stage's own constructor
    plan = plan_drop(run, DropTestSettings(**spec["settings"]), prompt, controller)
    plan.attach_rig(rig)
    return plan, run.stage.law, "none"


def _registered(group: str, kind: str, what: str) -> str:
    """The target registered as ``kind`` in ``group`` (a one-line ConfigError naming the known ones)."""
    table = entry_point_table(group)
    if kind not in table:
        raise ConfigError(f"no {what} of kind {kind!r} is registered (known: {', '.join(table)})")
    return table[kind].target


def run_drop_test(
    config: RunConfig | RunSpec,
    theta0_deg: float = -5.0,
    current_a: float = 0.0,
    duration_s: float = 10.0,
    rig: RigInterface | None = None,
    clock: Clock | None = None,
    controller: Any = None,
    notify: Callable[[str], None] | None = None,
    data_path: str | Path | None = None,
    *,
    live: Any = None,
    stop: Any = None,
    trace: Any = None,
    documents: Documents | None = None,
    name: str | None = None,
    recorded_config: Mapping[str, Any] | None = None,
    describe: Callable[[DropRecord], Mapping[str, Any]] | None = None,
) -> DropRecord:
    """One drop test of a resolved ``config`` or of the drop test's assembled run (its ``options``:
    :data:`READS`) at a constant current (or, after the release, under ``controller``: a stage, or :data:`CONFIG_LAW`
    for the config's law).

    On the real clock with ``loop.process`` (the default) the drop runs in a loop process of its
    own (:mod:`sashil.runtime.loop_process`), which opens the rig, plays or waits for the operator
    and runs the plan; its prompts reach ``notify`` as they come. A controller crosses to it as the
    config's law or as its own ``spec()`` (a calibration step's stage); any other runs its drop in
    this process. ``rig``: the rig for a run in
    this process (default: the config's). ``data_path``: where every cycle of the loop is streamed
    as it runs (the hold included, time from the loop's start); the record returned is the part
    from the release. ``live``: views of the stream (``start(stream, timing)``, ``close(trips,
    notes)``); ``stop``: a :class:`~sashil.runtime.signals.StopFlag` another thread may set;
    ``trace``: a :class:`~sashil.recording.can_trace.CanTrace` (not started) fed the run's CAN
    frames, closed after the run (its statistics in ``record.extra["can_trace"]``). ``documents``:
    the verb's documents, this drop as run ``name`` recording ``recorded_config`` (None: none of its own),
    its stop document the drop's analysis as ``describe(record)`` gives it.

    Returns the record from the release on. An error that ends the test early (a driver error, a
    safety trip, no hold) does not raise: the rig is already safe, and the record carries the data
    up to it and the error in ``record.error``.
    """
    run = assembled(config, READS)
    plan = plan_drop(run, DropTestSettings.of(run, theta0_deg, current_a, duration_s), notify, controller)
    return run_drop(
        run,
        plan,
        rig=rig,
        clock=clock,
        data_path=data_path,
        live=live,
        stop=stop,
        trace=trace,
        documents=documents,
        name=name,
        recorded_config=recorded_config,
        describe=describe,
    )


def run_drop(
    run: RunSpec,
    plan: DropTestPlan,
    *,
    rig: RigInterface | None = None,
    clock: Clock | None = None,
    data_path: str | Path | None = None,
    live: Any = None,
    stop: Any = None,
    trace: Any = None,
    documents: Documents | None = None,
    name: str | None = None,
    recorded_config: Mapping[str, Any] | None = None,
    describe: Callable[[DropRecord], Mapping[str, Any]] | None = None,
) -> DropRecord:
    """The drop ``plan`` of the drop test's assembled ``run`` through the engine, and its record
    (the arguments as :func:`run_drop_test` takes them)."""
    records: list[DropRecord] = []

    def analyse(outcome: RunOutcome) -> dict[str, Any]:
        if live is not None:
            live.close(outcome.trips, ())
        # whatever ended the test early, the rig is at 0 A, deactivated and closed
        error = outcome.error if outcome.error is not None else outcome.stop_error()
        if error is not None and not isinstance(error, SashilError):
            raise error
        records.append(_record(run, outcome, plan, error))
        return {"error": error, **(describe(records[0]) if describe is not None else {})}

    engine.run(
        run,
        plan,
        clock=clock,
        rig=(lambda: rig) if rig is not None else None,
        data_path=data_path,
        live=live,
        stop=stop,
        trace=trace,
        documents=documents,
        name=name,
        config=recorded_config,
        analyse=analyse,
    )
    return records[0]


def _record(run: RunSpec, outcome: RunOutcome, plan: DropTestPlan, error: SashilError | None) -> DropRecord:
    """The drop's record from the release on, from the run's stream: its columns, the run's summary
    keys and facts, its metrics."""
    record = drop_record(outcome.stream, plan, outcome.start_ns)
    record.run = outcome.summary
    record.error = error
    if outcome.can_trace is not None:
        record.extra["can_trace"] = outcome.can_trace
    if outcome.loop_process is not None:
        record.extra["loop_process"] = outcome.loop_process
    if outcome.link is not None:
        record.extra["link"] = outcome.link
    if outcome.realtime:
        record.extra["realtime"] = outcome.realtime
    if outcome.recording is not None:
        record.extra["recording"] = outcome.recording
    time_s, theta = sampled_angle(record)
    record.metrics = drop_metrics(
        time_s, theta, settle_band_deg=run.options["settle_band_deg"], resolution_rad=plan.resolution
    )
    return record


def sampled_angle(record: DropRecord) -> tuple[np.ndarray, np.ndarray]:
    """The drop's angle against the clock that sampled it, time zero at the release: the device's
    (each distinct sample once, at its own device time) when the rig's samples carry one, else the
    loop's. Over a link the loop reads a sample a round trip after the device took it, and on a
    busy host a late cycle later still: peaks and the period on the loop's clock would carry that
    lateness, which is the host's, not the arm's. A device clock that only restates the loop's (a
    simulated rig's: the loop's time in whole µs, :data:`SAME_CLOCK_S`) gives way to the loop's,
    which is finer."""
    loop_time, theta = record.columns["time_s"], record.columns["theta_rad"]
    sampled = sample_times(record.stream) if record.device_release_s is not None else None
    if sampled is None:
        return loop_time, theta
    times, rows = sampled
    device_time = times - record.device_release_s
    if rows.size == loop_time.size and np.all(np.abs(device_time - loop_time) <= SAME_CLOCK_S):
        return loop_time, theta
    return device_time, theta[rows]


#: the largest difference between a device's sample times and the loop's at which the device's clock
#: is the loop's restated (whole µs, and the release's instant read between two samples) [s]
SAME_CLOCK_S = 2e-6
