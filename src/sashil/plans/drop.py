"""A drop test's plan in the loop (seed 001 section 8): hold the arm at theta0, detect the release,
record the free oscillation at a constant current, or under a stage that takes over at the release.

The plan (:class:`DropTestPlan`) is a loop stage: it commands a constant current from the start
(so the current already flows at release), waits for a steady hold near theta0, detects the
release and runs for the requested duration after it. The same plan runs on the simulated rig
(which plays the operator), the emulator and the bench (where a person does); a loop process
builds it again from the assembled run and its :meth:`DropTestPlan.spec` (:func:`drop_in_loop`).
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from sashil.control.controller import SIGNALS
from sashil.drivers.interface import FLAG_HELD, TWO_PI, RigCommand, RigInterface, RigSample, capabilities_of
from sashil.drivers.operator_prompt import hold_prompt
from sashil.errors import ConfigError, DriverTimeoutError
from sashil.plans.stages import stage_from_spec

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec, StageParts

__all__ = [
    "CONFIG_LAW",
    "CONTROLLER_COLUMNS",
    "DROP_COLUMNS",
    "EMULATED_HOLD_WAIT_S",
    "KIND",
    "DropTestPlan",
    "check_theta0",
    "controller_columns",
    "drop_in_loop",
    "plan_drop",
    "pseudo_terminal",
    "stage_controller",
]

#: the plan's kind (``RunSpec.plan["kind"]``): its values are :meth:`DropTestPlan.spec`'s, the
#: drop test's config values the run's ``options`` (``hold_tolerance_deg``, ``hold_time_s``,
#: ``release_threshold_deg``, ``hold_timeout_s``)
KIND = "drop-test"

#: columns of a drop test's data.csv (docs/architecture.md names)
DROP_COLUMNS = ("time_s", "theta_rad", "theta_road_rad", "current_a", "current_cmd_a")
#: added when a controller acts after the release (its per-cycle values, docs/architecture.md names)
CONTROLLER_COLUMNS = SIGNALS

#: how long a drop test on a pseudo-terminal (an emulated rig) waits for its operator's hold [s]:
#: an emulator started with --hold-deg holds the arm from its first sample on
EMULATED_HOLD_WAIT_S = 1.0

#: ``plan_drop(controller=CONFIG_LAW)``: the config's law takes over at the release, made where
#: the loop runs (in the loop process too)
CONFIG_LAW = "config"


def controller_columns(controller: Any) -> tuple[str, ...]:
    """The columns a drop test records of its controller: what the controller says it records
    (``signal_names``: a current law's own output, ``current_law_a``, too), else
    :data:`CONTROLLER_COLUMNS`; none without a controller."""
    if controller is None:
        return ()
    return tuple(getattr(controller, "signal_names", CONTROLLER_COLUMNS))


def pseudo_terminal(rig: Any) -> str | None:
    """The rig's port when it is a pseudo-terminal (``/dev/pts/N``, or a link to one: an emulator's),
    else None (a device, a socket, the simulated rig)."""
    port = getattr(getattr(rig, "settings", None), "port", None)
    if not isinstance(port, str) or not port.startswith("/"):
        return None
    return port if os.path.realpath(port).startswith("/dev/pts/") else None


class DropTestPlan:
    """Loop stage: constant current; wait for the hold; detect the release; run ``duration_s`` on.

    Made from the assembled ``run`` (its ``options``: the drop test's hold tolerance, hold time,
    release threshold and hold timeout in the config's units; ``stage.counts_per_rev``) and the
    drop's own ``theta0_deg``, ``current_a`` and ``duration_s``. What the rig decides
    (:attr:`known_release_after_s` when the backend plays the operator, :attr:`pseudo_terminal`) is
    set when the plan meets it (:meth:`attach_rig`).

    The plan commands and decides; it keeps no copy of the data. Its :attr:`phase_code` (an index
    of :data:`PHASES`) goes into every row of the runner's stream, and the drop test derives its
    record from that stream after the run (the release dated from the departure samples)."""

    PHASES = ("wait-hold", "held", "record", "done")

    def __init__(
        self,
        run: RunSpec,
        theta0_deg: float,
        current_a: float,
        duration_s: float,
        controller: Any = None,
        notify: Callable[[str], None] | None = None,
    ):
        drop = run.options
        self.theta0_deg = theta0_deg
        self.theta0_rad = math.radians(theta0_deg)
        self.current_a = current_a
        self.duration_s = duration_s
        self.hold_tolerance_rad = math.radians(drop["hold_tolerance_deg"])
        self.hold_time_s = drop["hold_time_s"]
        self.release_threshold_rad = math.radians(drop["release_threshold_deg"])
        self.hold_timeout_s = drop["hold_timeout_s"]
        #: after how long the backend lets go when it plays the operator [s] (None: a person does)
        self.known_release_after_s: float | None = None
        #: the rig's port when it is a pseudo-terminal (an emulator's link): no hand can hold that arm
        self.pseudo_terminal: str | None = None
        # operator prompts and what the plan detected (one line at each phase change, never per cycle)
        self.notify = notify
        # optional loop stage (sashil.control) that commands the damper after the release
        self.controller = controller
        #: the controller is the config's law (made by :func:`stage_controller`): a loop process
        #: can make its own
        self.from_config = False
        #: the controller's per-cycle values go into the stream (the loop reads them after each step,
        #: from the controller itself: the attributes below forward them too, but slower)
        self.signal_names = controller_columns(controller)
        self.signal_source = controller if controller is not None else self
        self.command = RigCommand(current_a)
        self.resolution = TWO_PI / run.stage.counts_per_rev
        self.phase = "wait-hold"
        self.phase_code = 0
        self.start_ns: int | None = None
        self._still_since: int | None = None
        self._hold_sum = 0.0
        self._hold_count = 0
        self.hold_angle = self.theta0_rad
        self.held_elsewhere = False  # a simulated operator held the arm away from theta0
        self.operator_seen = False  # a sample said a simulated operator holds the arm (FLAG_HELD)
        #: when the plan saw the arm leave the hold (host ns); the release itself is dated after the run
        self.detected_ns: int | None = None
        self._end_ns: int | None = None

    #: what the loop process sends back after the run (:meth:`facts`): what the plan saw, and what
    #: the rig decided
    FACTS = (
        "start_ns",
        "detected_ns",
        "hold_angle",
        "held_elsewhere",
        "operator_seen",
        "phase",
        "known_release_after_s",
        "pseudo_terminal",
    )

    def spec(self) -> dict[str, Any] | None:
        """What a loop process builds this drop from (:func:`drop_in_loop`, with the same assembled
        run), or None when it cannot: a controller that is neither the config's law
        (:data:`CONFIG_LAW`) nor one with a ``spec()`` of its own (a calibration step's stage)
        stays in this process."""
        controller: Any = None
        if self.from_config:
            controller = CONFIG_LAW
        elif self.controller is not None:
            controller = self.controller.spec() if hasattr(self.controller, "spec") else None
            if controller is None:
                return None
        return {
            "kind": KIND,
            "theta0_deg": self.theta0_deg,
            "current_a": self.current_a,
            "duration_s": self.duration_s,
            "controller": controller,
        }

    def attach_rig(self, rig: RigInterface) -> None:
        """Meet the rig the drop runs on, before its loop starts: a backend that plays the operator
        holds the arm now and lets go after the hold time (with the coil already at the drop's
        current when it can); a pseudo-terminal's port is noted (no hand can hold that arm)."""
        release_after = max(self.hold_time_s + 0.1, 0.3)
        if rig.operator_hold(self.theta0_rad, release_after):
            self.known_release_after_s = release_after
            if capabilities_of(rig).initial_current:
                rig.set_initial_current(self.current_a)  # type: ignore[attr-defined]  # declared by the backend
        else:
            self.pseudo_terminal = pseudo_terminal(rig)

    def facts(self) -> dict[str, Any]:
        """What the plan saw during the run, which the record is derived from, with what the
        backend decided (it plays the operator; a pseudo-terminal's port)."""
        return {name: getattr(self, name) for name in self.FACTS}

    def absorb(self, facts: dict[str, Any]) -> None:
        """Take the :meth:`facts` of the same plan run in the loop process."""
        for name in self.FACTS:
            setattr(self, name, facts[name])
        self.phase_code = self.PHASES.index(self.phase)

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
        if self.known_release_after_s is None or self.start_ns is None:
            return None
        return self.start_ns + round(self.known_release_after_s * 1e9)

    # the cycle -------------------------------------------------------------------------------
    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand | None:
        theta = sample.theta_rad
        if self.start_ns is None:
            self.start_ns = t_ns
            if self.notify is not None and self.known_release_after_s is None and self.pseudo_terminal is None:
                self.notify(
                    f"{hold_prompt(math.degrees(self.theta0_rad))} (within "
                    f"±{math.degrees(self.hold_tolerance_rad):g} deg) and hold it still; now at "
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
            if abs(theta - self.hold_angle) > self.release_threshold_rad:
                self._released(t_ns)
            elif (t_ns - self.start_ns) * 1e-9 > 2 * self.hold_timeout_s:
                raise DriverTimeoutError(
                    f"drop test: the arm was held at {math.degrees(self.hold_angle):.2f} deg but not released "
                    f"within {2 * self.hold_timeout_s:g} s"
                )
        if ctl is not None and self.phase == "record":
            return ctl
        return self.command

    def _wait_hold(self, t_ns: int, theta: float, flags: int = 0) -> None:
        target = self.theta0_rad
        if flags & FLAG_HELD:
            self.operator_seen = True
        port = self.pseudo_terminal
        assert self.start_ns is not None  # step() sets it on the first cycle
        if port is not None and not self.operator_seen and (t_ns - self.start_ns) * 1e-9 > EMULATED_HOLD_WAIT_S:
            raise ConfigError(
                f"drop test: {port} is a pseudo-terminal (an emulated rig) whose operator does not hold the arm, "
                f"and no hand can: start the emulator with --hold-deg {math.degrees(self.theta0_rad):g} "
                f"(e.g. sashil emulate --link {port} --hold-deg {math.degrees(self.theta0_rad):g} "
                "--release-after 1) to hold it at each connection and let go"
            )
        if flags & FLAG_HELD and abs(theta - target) > self.hold_tolerance_rad:
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
        if abs(theta - target) <= self.hold_tolerance_rad:
            if (
                self._still_since is None
                or abs(theta - self._hold_sum / max(self._hold_count, 1)) > 2 * self.resolution
            ):
                self._still_since, self._hold_sum, self._hold_count = t_ns, 0.0, 0
            self._hold_sum += theta
            self._hold_count += 1
            if (t_ns - self._still_since) * 1e-9 >= self.hold_time_s:
                self._enter("held")
                self.hold_angle = self._hold_sum / self._hold_count
                if self.notify is not None and self.known_release_after_s is None:
                    self.notify(
                        f"hold detected at {math.degrees(self.hold_angle):.2f} deg: release the arm when ready "
                        f"(detected when it moves {math.degrees(self.release_threshold_rad):g} deg)"
                    )
        else:
            self._still_since = None
        assert self.start_ns is not None  # step() sets it on the first cycle
        if self.phase == "wait-hold" and (t_ns - self.start_ns) * 1e-9 > self.hold_timeout_s:
            raise DriverTimeoutError(
                f"drop test: no steady hold within ±{math.degrees(self.hold_tolerance_rad):g} deg of "
                f"{math.degrees(self.theta0_rad):g} deg for {self.hold_time_s:g} s within "
                f"{self.hold_timeout_s:g} s (press the arm to theta0 and hold it still)"
            )

    def _released(self, t_ns: int) -> None:
        """The arm left the hold: record ``duration_s`` from the release (known, or at the latest now)."""
        self.detected_ns = t_ns
        known = self.known_release_ns
        self._end_ns = (t_ns if known is None else known) + round(self.duration_s * 1e9)
        self._enter("record")
        if self.notify is not None and known is None:  # a person let go (the backend knows when it did)
            self.notify(
                f"release detected: the arm left {math.degrees(self.hold_angle):.2f} deg; "
                f"recording {self.duration_s:g} s"
            )


def stage_controller(stage: StageParts) -> Any:
    """The run's controller, which takes over at the release, or None for a law that reads no
    state (such as the passive law: the drop's constant current throughout)."""
    from sashil.control.registry import law_reads_state, make_controller

    return make_controller(None, stage) if law_reads_state(stage) else None


def check_theta0(threshold: float, theta0_deg: float, option: str = "--theta0-deg") -> None:
    """Refuse a hold angle the release could not be detected from: the release is the arm moving
    ``threshold`` (``drop_test.release_threshold_deg``) from the hold, and released at |theta0|
    below it, it swings less."""
    if math.isfinite(theta0_deg) and abs(theta0_deg) < threshold:
        raise ConfigError(
            f"{option}: expected an angle at least drop_test.release_threshold_deg = {threshold:g} deg from 0 "
            f"(the release is detected when the arm moves that far from the hold), got {theta0_deg:g}"
        )


def plan_drop(
    run: RunSpec,
    theta0_deg: float,
    current_a: float,
    duration_s: float,
    notify: Callable[[str], None] | None = None,
    controller: Any = CONFIG_LAW,
) -> DropTestPlan:
    """The plan of one drop from ``theta0_deg`` at ``current_a`` for ``duration_s`` after the
    release in the assembled ``run``, not yet given its rig (:meth:`DropTestPlan.attach_rig`).
    ``controller``: the stage that takes over at the release (:data:`CONFIG_LAW`: the run's law,
    None: the constant current throughout). A hold angle the release could not be detected from is
    refused first (:func:`check_theta0`, a one-line ConfigError naming ``theta0_deg``)."""
    check_theta0(run.options["release_threshold_deg"], theta0_deg, "theta0_deg")
    from_config = isinstance(controller, str) and controller == CONFIG_LAW
    plan = DropTestPlan(
        run,
        theta0_deg,
        current_a,
        duration_s,
        stage_controller(run.stage) if from_config else controller,
        notify,
    )
    plan.from_config = from_config
    return plan


def drop_in_loop(run: RunSpec, rig: RigInterface, prompt: Callable[[str], None]) -> tuple[DropTestPlan, str, str]:
    """One drop built in a loop process (the built-in ``drop-test`` plan: ``run.plan`` as
    :meth:`DropTestPlan.spec` gives it), its operator prompts handed to ``prompt`` as they come;
    the stage that takes over at the release is the run's law, none, or a stage built from its spec
    (:func:`~sashil.plans.stages.stage_from_spec`: a built-in stage, or a ``sashil.stages`` entry)."""
    spec = run.plan
    controller = spec.get("controller", CONFIG_LAW)
    if isinstance(controller, dict):
        controller = stage_from_spec(controller)
    plan = plan_drop(run, spec["theta0_deg"], spec["current_a"], spec["duration_s"], prompt, controller)
    plan.attach_rig(rig)
    return plan, run.stage.law, "none"
