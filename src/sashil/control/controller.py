"""The controller loop stage: estimator -> observer -> law -> inverse -> coil lead -> safety clamp.

``step(sample, t_ns, dt_ns) -> RigCommand`` (the loop's stage protocol). The per-cycle values
(``theta_dot_rad_s``, ``z_hat``, ``torque_hat_nm``, ``torque_cmd_nm``, the band, the currents) are
plain attributes overwritten every cycle, for a recorder to copy (:attr:`Controller.signal_names`:
the law's own output is recorded as given, ``torque_cmd_nm`` for a torque law, ``current_law_a``
for a current law, beside the ``current_cmd_a`` the loop sent); the returned command object is
reused (no allocation per cycle).

The coil-lag lead (:class:`~sashil.control.inverse.CoilLagCompensator`) drives the coil towards
the inverse's current for a torque law. A current law's output is commanded as the law gave it
(clamped to [0, i_max]) unless ``lead_current_laws``: the law chose amperes, and the lead would
command more than it asked for while the coil catches up (3.86 times the step with the 3 ms
horizon on a 10 ms coil).

The estimator's model acceleration for the next cycle comes from the rig model
(seed 001 eq. 13): ``theta2_ddot = (-k*theta - T_hat)/J`` (the relative channel subtracts theta1_ddot).

The estimator and the observer advance by the period between the samples on the device's clock
that took them (:meth:`Controller._sample_period`): over a link a late cycle reads the newest of
several samples, so the host's cycle period is not the samples' spacing.

Road feed-forward: a plan that drives the road sets ``road_speed_rad_s`` on the command this stage
returns (the sweep does); the change of that speed from one cycle to the next is the road
acceleration the estimator is given for the next period (:mod:`sashil.control.kalman`).

The law (:mod:`sashil.control.law_api`) reads a :class:`~sashil.control.law_api.LawState` the stage
fills each cycle. Its output is checked: an exception, NaN, an infinity or a non-number ends the run
with :class:`~sashil.errors.LawError`, naming the law and the first line of what went wrong; the
loop then commands 0 A and deactivates the rig like any other error.

The road ahead: a plan that commands the road calls :meth:`Controller.attach_road` before the run;
for a law that reads the road ahead (``Law.reads_road_ahead``) the commanded road is sampled there
and handed to the law once (``Law.plan_road``), and each cycle the law's state carries the window of
the next cycles (:mod:`sashil.control.preview`), its angles corrected by the estimated road angle.

Bad edge events: the Kalman estimator leaves out an edge time from the future or older than the
encoder's last one and counts it (``edge_rejects``); when more than 1 % of the events were bad (after
the first 100) the stage raises :class:`~sashil.errors.SafetyTrip`: the loop commands 0 A and the
run ends with exit 3, the counts in summary.json's ``controller_stats``.

Fallback: when the estimator reports divergence (its innovation out of bounds, e.g. a wildly wrong
J) or a non-finite estimate, the stage commands 0 A (the MR damper's passive, safe state) for the
rest of the run; :meth:`Controller.stats` reports it for summary.json.
"""

from __future__ import annotations

import math
from numbers import Real
from typing import Any

from sashil.control.estimator import RigEstimator
from sashil.control.inverse import CoilLagCompensator, HysteresisInverse
from sashil.control.kalman import KalmanRigEstimator
from sashil.control.law_api import Law, LawState
from sashil.control.observer import BoucWenObserver
from sashil.control.preview import RoadWindow, run_road
from sashil.drivers.interface import RigCommand, RigSample, clamp_current
from sashil.errors import LawError, SafetyTrip

NAN = float("nan")
INF = float("inf")
#: the docs/architecture.md data.csv columns every controller records (a current law adds current_law_a)
SIGNALS = ("theta_dot_rad_s", "z_hat", "torque_hat_nm", "torque_cmd_nm")


def signal_names(law_class: type[Law]) -> tuple[str, ...]:
    """The per-cycle values a controller of ``law_class`` records: :data:`SIGNALS`, and a current
    law's own output (``current_law_a``) beside the command."""
    return SIGNALS + (("current_law_a",) if law_class.output_kind() == "current" else ())


def _first_line(err: BaseException) -> str:
    text = (str(err).splitlines() or [""])[0]
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


class Controller:
    """One semi-active controller; see the module docstring for the cycle."""

    def __init__(
        self,
        law: Law,
        estimator: RigEstimator | KalmanRigEstimator,
        observer: BoucWenObserver,
        inverse: HysteresisInverse,
        lead: CoilLagCompensator,
        current_max_a: float,
        model_aided: bool = True,
        nominal_dt_s: float = 0.001,
        origin: str = "",
        lead_current_laws: bool = False,
    ):
        self.law = law
        #: where the law came from (built-in, a package, a file), for messages and summary.json
        self.origin = origin
        self.direct = law.output_kind() == "current"
        #: what the loop records each cycle: the law's own current beside the command for a current law
        self.signal_names = signal_names(type(law))
        #: whether the coil-lag lead acts on a current law's output (module docstring)
        self.lead_direct = bool(lead_current_laws)
        self._law_output = law.current if self.direct else law.torque
        self.state = LawState()
        self.estimator = estimator
        self.observer = observer
        self.inverse = inverse
        self.lead = lead
        self.current_max_a = float(current_max_a)
        self.model_aided = bool(model_aided)
        self.nominal_dt_s = float(nominal_dt_s)
        p = observer.params
        self._k_over_j, self._inv_j = p.k / p.J, 1.0 / p.J
        self.command = RigCommand(0.0)
        #: set by an experiment while something outside the model holds the arm (drop-test hold)
        self.held = False
        self._t0_ns: int | None = None
        self._device_us: int | None = None  # the device clock of the last sample taken
        self._accel = 0.0
        self._road_speed: float | None = None
        self._v_prev = 0.0
        self._road_window: RoadWindow | None = None
        # per-cycle values (recorded by the caller)
        self.time_s = 0.0
        self.theta_rad = 0.0
        self.theta_dot_rad_s = 0.0
        self.body_dot_rad_s = 0.0
        self.body_ddot_rad_s2 = 0.0  # model: (-k*theta - T_hat)/J
        self.road_dot_rad_s = 0.0
        self.z_hat = 0.0
        self.torque_hat_nm = 0.0
        self.torque_cmd_nm = NAN
        self.current_law_a = NAN  # a current law's output as it gave it
        self.band_lo_nm = 0.0
        self.band_hi_nm = 0.0
        self.current_target_a = 0.0
        self.current_cmd_a = 0.0
        self.cycles = 0
        self.unsafe_count = 0  # commands the safety clamp had to change (NaN or outside [0, i_max])
        self.fallback = False  # latched when the estimator fails: 0 A for the rest of the run
        self.fallback_at_s: float | None = None
        self.fallback_cycles = 0

    def attach_road(self, speed: Any, duration_s: float | None) -> None:
        """The road speed ``speed(t)`` [rad/s] a plan will command from this stage's first cycle, for
        ``duration_s`` (None: until stopped). A law that reads the road ahead gets it sampled at the
        loop's period a little beyond the duration (:func:`sashil.control.preview.run_road`)
        (``Law.plan_road``, now) and its window each cycle; any other law ignores it."""
        law = self.law
        if not law.reads_road_ahead:
            return
        cycles = int(law.preview_cycles())
        road = run_road(speed, self.nominal_dt_s, duration_s, cycles)
        law.plan_road(road)
        # a law that planned on the whole road and reads no window costs the cycle nothing more
        self._road_window = RoadWindow(road, cycles) if cycles > 0 else None

    def _fallback_step(self) -> RigCommand:
        """0 A (the safe state of an MR damper) once the estimator has failed; counted per cycle."""
        self.fallback_cycles += 1
        self.cycles += 1
        self.torque_cmd_nm = self.current_law_a = NAN  # the law was not asked
        self.current_target_a = self.current_cmd_a = 0.0
        self.command.current_a = 0.0
        return self.command

    def _edge_fault(self) -> None:
        """Too many bad edge events: stop the run (the loop then commands 0 A)."""
        est = self.estimator
        rejects, events = getattr(est, "edge_rejects", 0), getattr(est, "edge_events", 0)
        raise SafetyTrip(
            f"encoder edge times: {rejects} of {rejects + events} events were from the future or older than the "
            f"encoder's last (more than 1 %) at t = {self.time_s:.4f} s: the board's edge timing is not to be trusted"
        )

    def stats(self) -> dict[str, object]:
        """For summary.json: the law (name, origin, parameters), clipped/passive cycles, unsafe commands,
        the estimator fallback."""
        return {
            "law": {"name": self.law.name, "origin": self.origin, "parameters": self.law.parameter_values()},
            "clipped_cycles": self.inverse.clip_count,
            "passive_cycles": self.inverse.passive_count,
            "unsafe_commands": self.unsafe_count,
            "fallback": self.fallback,
            "fallback_at_s": self.fallback_at_s,
            "fallback_cycles": self.fallback_cycles,
            "innovations_out": int(getattr(self.estimator, "innovations_out", 0)),
            "edge_events": int(getattr(self.estimator, "edge_events", 0)),
            "edge_rejects": int(getattr(self.estimator, "edge_rejects", 0)),
        }

    @property
    def name(self) -> str:
        return self.law.name

    #: a law clipped in more than this share of its cycles gets one warning at the end of the run
    CLIP_WARN_SHARE = 0.5

    def clip_warning(self) -> str | None:
        """One line when the law asked for torques outside the feasible band in most cycles (more,
        or less, or another sign than the damper can give at that instant), else None."""
        clipped = self.inverse.clip_count
        if not self.cycles or clipped <= self.CLIP_WARN_SHARE * self.cycles:
            return None
        return (
            f"law {self.law.name!r} asked for a torque outside the damper's feasible band in {clipped} of "
            f"{self.cycles} cycles ({100 * clipped / self.cycles:.0f} %): the damper gave the nearest torque it "
            "could, so the run shows the band's edge more than the law (summary.json controller_stats.clipped_cycles)"
        )

    def law_failed(self, what: str) -> LawError:
        """The error that ends the run when the law fails this cycle (``what``: the exception or value)."""
        origin = f" ({self.origin})" if self.origin else ""
        return LawError(f"law {self.law.name!r}{origin} failed at t = {self.time_s:.4f} s: {what}")

    def _checked(self, value: Any) -> float:
        """A law's output as a finite float, else LawError (off the fast path: float outputs pass inline)."""
        if isinstance(value, Real) and not isinstance(value, bool):
            number = float(value)
            if math.isfinite(number):
                return number
            return self._raise(f"returned {number!r} (expected a finite number)")
        return self._raise(f"returned {value!r} of type {type(value).__name__} (expected a number)")

    def _raise(self, what: str) -> float:
        raise self.law_failed(what)

    @property
    def clip_count(self) -> int:
        """Cycles whose target torque lay outside the damper's feasible band (clipped)."""
        return self.inverse.clip_count

    def _sample_period(self, device_us: int, dt_ns: int) -> float:
        """The time [s] from the last sample to this one, on the clock that took them.

        A link hands the host its samples late by a varying amount, and a late cycle reads the
        newest of several, so the host's cycle period ``dt_ns`` is not the samples' spacing: the
        device's clock is. The host's period is taken where the device clock did not advance (a
        sample read again, or a rig without one) and where the two agree within the device clock's
        1 us (a simulated rig's device clock is the host's, truncated to whole microseconds)."""
        last, self._device_us = self._device_us, device_us
        host_s = dt_ns * 1e-9 if dt_ns > 0 else self.nominal_dt_s
        if last is None:
            return host_s
        step_us = device_us - last
        if step_us <= 0 or abs(step_us * 1000 - host_s * 1e9) <= 1000.0:
            return host_s
        return step_us * 1e-6

    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand:
        if self._t0_ns is None:
            self._t0_ns = t_ns
            self.law.reset()  # the first cycle of a run: the law starts from its own initial state
        dt = self._sample_period(sample.device_time_us, dt_ns)
        self.time_s = (t_ns - self._t0_ns) * 1e-9
        est = self.estimator
        # the road speed a plan put on last cycle's command (sweeps): its change is the road's
        # acceleration, known to the estimator instead of inferred from the road encoder alone
        speed = self.command.road_speed_rad_s
        if speed is None or speed != speed:
            road_accel = None
            self._road_speed = None
        else:
            road_accel = 0.0 if self._road_speed is None else (speed - self._road_speed) / dt
            self._road_speed = speed
        est.update(sample, dt, self._accel, road_accel)  # model body acceleration of the last cycle
        if getattr(est, "edge_fault", False):
            self._edge_fault()
        theta, v = est.theta_rad, est.theta_dot_rad_s
        if not self.fallback and (getattr(est, "diverged", False) or not math.isfinite(v) or not math.isfinite(theta)):
            # the model cannot explain the motion (innovation out of bounds) or the estimate is not a number:
            # the safe law (0 A: the damper fails passive) for the rest of the run
            self.fallback = True
            self.fallback_at_s = self.time_s
        if self.fallback:
            return self._fallback_step()
        self.theta_rad, self.theta_dot_rad_s = theta, v
        self.body_dot_rad_s, self.road_dot_rad_s = est.body_dot_rad_s, est.road_dot_rad_s
        measured = sample.current_a
        if measured != measured:  # no current sensor reading: assume the last command flows
            measured = self.current_cmd_a
        obs = self.observer
        # z-hat advances over the angle increment of the estimated rate (trapezoidal), not over the
        # filtered angle's increments: a count arriving makes the filtered angle step back and
        # forth by a fraction of a count, enough to flip z (it saturates within ~3e-4 rad)
        torque_hat = obs.update_increment(0.5 * (v + self._v_prev) * dt, v, measured)
        self._v_prev = v
        z = obs.z
        self.z_hat, self.torque_hat_nm = z, torque_hat
        body_ddot = -self._k_over_j * theta - self._inv_j * torque_hat
        self.body_ddot_rad_s2 = body_ddot
        inv = self.inverse
        at_zero, authority = inv.band(z, v)
        lo, hi = inv.band_lo_nm, inv.band_hi_nm
        self.band_lo_nm, self.band_hi_nm = lo, hi
        state = self.state
        state.time_s, state.theta_rad, state.theta_dot_rad_s = self.time_s, theta, v
        state.body_dot_rad_s, state.body_ddot_rad_s2, state.road_dot_rad_s = (
            self.body_dot_rad_s,
            body_ddot,
            self.road_dot_rad_s,
        )
        state.torque_hat_nm, state.z_hat, state.band_lo_nm, state.band_hi_nm = torque_hat, z, lo, hi
        state.current_a = measured
        road_rad = getattr(est, "theta_road_rad", 0.0)
        state.road_rad = road_rad
        if self._road_window is not None:
            self._road_window.fill(state, round(self.time_s / self.nominal_dt_s), road_rad)
        try:
            out = self._law_output(state)
        except Exception as err:
            raise self.law_failed(f"raised {_first_line(err)}") from err
        if type(out) is not float or out - out != 0.0:  # not a finite float (NaN - NaN and inf - inf are NaN)
            out = self._checked(out)
        if self.direct:
            self.torque_cmd_nm = NAN
            self.current_law_a = target = out
            cmd = self.lead.command(target, measured) if self.lead_direct else target
        else:
            self.torque_cmd_nm = out
            target = inv.solve(out, at_zero, authority, v)
            cmd = self.lead.command(target, measured)
        self.current_target_a = target
        # safety clamp: the coil only ever sees a finite current in [0, i_max]
        safe = clamp_current(cmd, self.current_max_a)
        if safe != cmd:  # outside [0, i_max], or NaN (never equal to itself)
            self.unsafe_count += 1
        cmd = safe
        self.current_cmd_a = cmd
        if self.model_aided:
            # an arm held by hand does not accelerate, whatever the model's torques say
            self._accel = 0.0 if self.held else body_ddot
        self.cycles += 1
        self.command.current_a = cmd
        return self.command
