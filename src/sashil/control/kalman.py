"""A steady-state Kalman filter on the rig model over both encoders: theta, theta_dot, theta1 and its rate
and acceleration from quantised counts.

State (relative angle across the damper, road/wheel-side angle, and the part of the arm's
acceleration the model gets wrong)::

    x = [theta, theta_dot, theta1, theta1_dot, theta1_ddot, b]

Continuous model, with ``u`` the arm (body) acceleration the rig model predicts from the previous
cycle (seed 001 eq. 13: ``J*theta2_ddot = -k*theta - T_damper``, so ``u = (-k*theta - T_hat)/J``)
and ``a_cmd`` the road acceleration a plan commands (the change of the road speed it sends; 0 when it
sends none)::

    theta_ddot   = u + b - (a_cmd + theta1_ddot) + w_a     (theta = theta2 - theta1)
    theta1_dddot = w_j                                      (the road's jerk beyond the command)
    b_dot        = w_b                                      (model error, a random walk)

with white noises of spectral densities ``accel_psd`` (w_a), ``road_jerk_psd`` (w_j; the smaller
``commanded_road_jerk_psd`` while a plan commands the road) and ``bias_psd`` (w_b). Measurements
each cycle: the arm encoder ``y_arm = theta + theta1`` and the road encoder ``y_road = theta1``,
each quantised to one count ``q = 2*pi/counts_per_rev``, read in one of these ways:

* ``noise`` (the default): the angle plus white noise of variance ``q^2/12`` (plus the configured
  angle noise);
* ``cell``: a count only says that the angle lies near it. The innovation is the distance from the
  prediction to the zone of :data:`DEADZONE_COUNTS` (one count) either side of the count, 0 inside
  it: while the prediction stays there the filter follows the model alone instead of being kicked
  by every count edge. One count, not the half-count cell of one encoder: the relative angle is the
  difference of two quantised angles. The road's zone applies only while the plan commands the road.
  On an undisturbed loop this lowers the error at 4096 counts/rev (1.2 Hz sine, identified models:
  median 3.7 % against 6.6 %); but an estimate knocked off by a host stall can sit anywhere in the
  zone with nothing pulling it back (the same runs with two 34 ms stalls: 18.7 % against 7.4 %).
  Measured over the benchmark's dampers (``tools/bench_truth_chain.py``, README), the noise reading
  is the robust default;
* ``auto``: cell up to :data:`CELL_MODEL_MAX_COUNTS` counts/rev, noise above.

The period's transition ``F`` and process noise ``Q`` come from Van Loan's matrix exponential; the
gains are the steady-state ones (``scipy.linalg.solve_discrete_are``), computed once per encoder
resolution for the nominal period, so a cycle costs a few dozen float operations. The prediction uses
the measured period ``T``::

    predict:  theta1 += T*theta1_dot + T^2/2*a1,  theta1_dot += T*a1          (a1 = a_cmd + theta1_ddot)
              theta  += T*theta_dot  + T^2/2*(u + b - a1),  theta_dot += T*(u + b - a1)
    correct:  x += K @ [e_arm, e_road]        (innovations, after the cell's zone when reading cells)

The noise densities were chosen over the whole condition set (drop, chirp, stepped sines; eleven
dampers with identified and with 10 %-off models, with and without host stalls), not on one case;
see the README's control figures.

With ``edge_timing`` (``controller.edge_timing``, the default) the samples' encoder edge events are
fused too, as exact angles at their own times: the cycle is then :func:`~sashil.control.edge_kalman.edge_cycle`
with the covariance propagated (the steady-state gains above do not fit events that come at any time),
counts read weakly within their cell, and the innovation check at ``EDGE_LIMIT_SHARE`` of the limit.
Bad events (from the future, or older than the encoder's last one) are counted (``edge_rejects``) and
left out; :attr:`KalmanRigEstimator.edge_fault` says when they pass 1 %.

Innovation check: ``innovation_limit`` counts; a residual larger than that on either encoder for
:data:`PERSIST_CYCLES` cycles in a row after the first :data:`WARMUP_S` (the model cannot explain the
motion, e.g. a J 20 times too small) sets :attr:`diverged`; the controller then falls back to 0 A.
With the right model the largest residual over the benchmark's conditions is about 1 count; a J 20
times too small or too large gives 7-50 counts on drops and chirps (a J 3 times off, up to 6.7: it is
let run, worse but stable).
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

from sashil.control.edge_kalman import edge_cycle
from sashil.control.estimator import EstimatorOutputs
from sashil.drivers.interface import NO_EDGE, TWO_PI, RigSample

#: how a count is read (module docstring): "noise", "cell", or "auto" (cell up to CELL_MODEL_MAX_COUNTS)
QUANTISATION_MODELS = ("noise", "cell", "auto")
CELL_MODEL_MAX_COUNTS = 16384
DEADZONE_COUNTS = 1.0  # the cell reading's zone either side of the count

#: the innovation check: diverged after this many consecutive cycles beyond the limit, not in the first
#: WARMUP_S seconds (the filter starts at rest: a rig already moving gives large residuals at first)
PERSIST_CYCLES = 10
WARMUP_S = 0.5

#: state indices
THETA, THETA_DOT, ROAD, ROAD_DOT, ROAD_DDOT, BIAS = range(6)

#: edge events (``edge_timing``): the standard deviation of an event's time [s] (the reference board
#: stamps within +-5 us; the emulator to the microsecond); an event older than EDGE_MAX_AGE_S is not
#: fused (the model's transition over that long says less than the count)
EDGE_TIME_SIGMA_S = 3e-6
EDGE_MAX_AGE_S = 0.02
#: the standard deviation [counts] a count is read with once its encoder had events (not q/sqrt(12):
#: :mod:`sashil.control.edge_kalman` says why and what was measured)
EDGE_COUNT_SIGMA_COUNTS = math.sqrt(64.0 / 12.0)
#: with edge events the prediction's miss is measured to a fraction of a count: the innovation check
#: then uses this share of ``innovation_limit``. Measured on drops, 3 Hz sines and chirps (4 s, seed
#: damper): the right J misses by at most 0.5 count; J 3 times too large by 2 counts for at most one
#: cycle running (let run); J 20 times too large for 18-49 cycles running (falls back); J 3 times too
#: small for 33-39 (falls back: that model misses more than the old reading of counts could tell)
EDGE_LIMIT_SHARE = 1.0 / 3.0
#: bad events: once this many events were seen, a share of bad ones above EDGE_BAD_SHARE is a fault
EDGE_BAD_MIN_EVENTS = 100
EDGE_BAD_SHARE = 0.01
#: :meth:`KalmanRigEstimator._event`'s (age, boundary) for an encoder without a new event to fuse
NOTHING_NEW = (-1.0, 0.0)


def one_blas_thread() -> contextlib.AbstractContextManager[object]:
    """BLAS on one thread within the block. The filter's matrices are 6 x 6 and 12 x 12, too small for
    BLAS's worker threads to help; once woken they spin for about 0.1 s after the last call, beside
    the loop's thread: a whole core the loop's first cycles compete with on a shared machine."""
    from threadpoolctl import threadpool_limits  # loaded when a filter is built, as scipy is

    return threadpool_limits(limits=1, user_api="blas")


def discrete_model(dt: float, accel_psd: float, road_jerk_psd: float, bias_psd: float) -> tuple[np.ndarray, np.ndarray]:
    """(F, Q) of the state model (module docstring) over one period ``dt`` (Van Loan's method)."""
    from scipy.linalg import expm  # loaded when a filter is built: a passive run never pays for it

    a = np.zeros((6, 6))
    a[THETA, THETA_DOT] = 1.0
    a[THETA_DOT, ROAD_DDOT] = -1.0
    a[THETA_DOT, BIAS] = 1.0
    a[ROAD, ROAD_DOT] = 1.0
    a[ROAD_DOT, ROAD_DDOT] = 1.0
    g = np.zeros((6, 3))
    g[THETA_DOT, 0] = 1.0
    g[ROAD_DDOT, 1] = 1.0
    g[BIAS, 2] = 1.0
    qc = g @ np.diag([accel_psd, road_jerk_psd, bias_psd]) @ g.T
    m = np.zeros((12, 12))
    m[:6, :6] = -a
    m[:6, 6:] = qc
    m[6:, 6:] = a.T
    e = expm(m * dt)
    f = e[6:, 6:].T
    q = f @ e[:6, 6:]
    return f, 0.5 * (q + q.T)


def steady_state(
    dt: float, angle_var: float, accel_psd: float, road_jerk_psd: float, bias_psd: float
) -> tuple[np.ndarray, np.ndarray]:
    """The 6x2 steady-state Kalman gain for measurement noise variance ``angle_var`` on each encoder,
    and the predicted covariance it comes from."""
    from scipy.linalg import solve_discrete_are  # loaded when a filter is built

    f, q = discrete_model(dt, accel_psd, road_jerk_psd, bias_psd)
    h = np.array([[1.0, 0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]])
    r = np.eye(2) * angle_var
    p = solve_discrete_are(f.T, h.T, q, r)  # the predicted covariance
    return p @ h.T @ np.linalg.inv(h @ p @ h.T + r), p


def steady_state_gain(
    dt: float, angle_var: float, accel_psd: float, road_jerk_psd: float, bias_psd: float
) -> np.ndarray:
    """The 6x2 steady-state Kalman gain for measurement noise variance ``angle_var`` on each encoder."""
    return steady_state(dt, angle_var, accel_psd, road_jerk_psd, bias_psd)[0]


class KalmanRigEstimator(EstimatorOutputs):
    """theta, theta_dot (relative), theta1 rate/acceleration (road), theta2_dot (body): the rig model's
    steady-state Kalman filter (module docstring). Same attributes and ``update`` as
    :class:`sashil.control.estimator.RigEstimator`."""

    __slots__ = (
        "_count_vars",
        "_counts_per_rev",
        "_cycles",
        "_dt",
        "_gain",
        "_gain_commanded",
        "_last_edge_us",
        "_outside",
        "_p",
        "_p0",
        "_q",
        "_q_commanded",
        "_warmup_cycles",
        "_xa",
        "accel_psd",
        "angle_noise_rad",
        "bias_psd",
        "commanded_road_jerk_psd",
        "deadzone",
        "diverged",
        "edge_events",
        "edge_rejects",
        "edge_timing",
        "innovation_limit",
        "innovation_max_counts",
        "innovations_out",
        "quantisation",
        "road_jerk_psd",
        "started",
        "x",
    )

    def __init__(
        self,
        nominal_dt_s: float,
        accel_psd: float = 1.0e-4,
        road_jerk_psd: float = 100.0,
        bias_psd: float = 1.0e-4,
        angle_noise_rad: float = 0.0,
        innovation_limit: float = 6.0,
        commanded_road_jerk_psd: float = 1e-2,
        quantisation: str = "noise",
        edge_timing: bool = False,
    ):
        if not nominal_dt_s > 0.0:
            raise ValueError(f"Kalman estimator: nominal period must be > 0 s, got {nominal_dt_s!r}")
        for name, value in (("accel_psd", accel_psd), ("road_jerk_psd", road_jerk_psd), ("bias_psd", bias_psd)):
            if not (value > 0.0 and math.isfinite(value)):
                raise ValueError(f"Kalman estimator: {name} must be a finite number > 0, got {value!r}")
        self._dt = float(nominal_dt_s)
        self.accel_psd, self.road_jerk_psd, self.bias_psd = float(accel_psd), float(road_jerk_psd), float(bias_psd)
        self.angle_noise_rad = float(angle_noise_rad)
        self.commanded_road_jerk_psd = float(commanded_road_jerk_psd)
        if quantisation not in QUANTISATION_MODELS:
            raise ValueError(
                f"Kalman estimator: quantisation must be one of {', '.join(QUANTISATION_MODELS)}, got {quantisation!r}"
            )
        self.quantisation = quantisation
        self.deadzone = 0.0
        self._gain_commanded: tuple[tuple[float, float], ...] = ()
        self.innovation_limit = float(innovation_limit)
        self._counts_per_rev = 0
        self._gain: tuple[tuple[float, float], ...] = ()
        self.x = [0.0] * 6
        self.started = False
        self.diverged = False
        self.innovations_out = 0  # cycles with an innovation beyond the limit
        self.innovation_max_counts = 0.0  # the largest residual so far [counts]
        self._outside = 0  # consecutive cycles beyond the limit
        self._cycles = 0
        self._warmup_cycles = round(WARMUP_S / self._dt)
        #: fuse the samples' edge events (:mod:`sashil.control.edge_kalman`); False: the counts alone
        self.edge_timing = bool(edge_timing)
        self._xa = np.zeros(6)
        self._p = np.zeros((6, 6))
        self._p0 = np.zeros((6, 6))
        self._q = np.zeros((6, 6))
        self._q_commanded = np.zeros((6, 6))
        self._last_edge_us = [NO_EDGE, NO_EDGE]  # the last event taken per encoder (arm, road)
        self.edge_events = 0  # new edge events taken
        self.edge_rejects = 0  # events from the future or older than the encoder's last: left out
        super().__init__()

    def prepare(self, counts_per_rev: int) -> None:
        """Compute the gains for an encoder of ``counts_per_rev`` now (before the loop starts); a
        sample with another resolution recomputes them."""
        self._set_resolution(int(counts_per_rev))

    def _set_resolution(self, counts_per_rev: int) -> None:
        with one_blas_thread():
            self._compute_gains(counts_per_rev)

    def _compute_gains(self, counts_per_rev: int) -> None:
        q = TWO_PI / counts_per_rev
        var = q * q / 12.0 + self.angle_noise_rad**2
        cell = self.quantisation == "cell" or (self.quantisation == "auto" and counts_per_rev <= CELL_MODEL_MAX_COUNTS)
        self.deadzone = DEADZONE_COUNTS if cell else 0.0
        gain, p0 = steady_state(self._dt, var, self.accel_psd, self.road_jerk_psd, self.bias_psd)
        self._gain = tuple((float(row[0]), float(row[1])) for row in gain)
        self._p0 = p0
        self._q = discrete_model(self._dt, self.accel_psd, self.road_jerk_psd, self.bias_psd)[1]
        self._q_commanded = discrete_model(self._dt, self.accel_psd, self.commanded_road_jerk_psd, self.bias_psd)[1]
        gain = steady_state_gain(self._dt, var, self.accel_psd, self.commanded_road_jerk_psd, self.bias_psd)
        self._gain_commanded = tuple((float(row[0]), float(row[1])) for row in gain)
        self._counts_per_rev = counts_per_rev
        #: a count's variance for an encoder that had edge events (weak) and one that had none (q^2/12)
        self._count_vars = (self._count_var(EDGE_COUNT_SIGMA_COUNTS, q), self._count_var(math.sqrt(1.0 / 12.0), q))

    def update(self, sample: RigSample, dt: float, body_accel: float = 0.0, road_accel: float | None = None) -> None:
        """Take one sample ``dt`` [s] after the previous one; ``body_accel``: the model's arm acceleration;
        ``road_accel``: the road acceleration the plan commanded over the period (None: not commanded)."""
        if sample.counts_per_rev != self._counts_per_rev:
            self._set_resolution(sample.counts_per_rev)
        scale = TWO_PI / sample.counts_per_rev
        arm = sample.arm_counts * scale
        road = sample.road_counts * scale
        if self.edge_timing:
            self._update_with_edges(sample, dt, body_accel, road_accel, scale, arm, road)
            return
        x = self.x
        if not self.started:
            x[:] = [arm - road, 0.0, road, 0.0, 0.0, 0.0]
            self.started = True
        elif dt > 0.0:
            theta, v, r, rv, ra, b = x
            half = 0.5 * dt * dt
            if road_accel is None:
                g = self._gain
            else:
                g = self._gain_commanded
                ra += road_accel  # the state is then the part of the road's acceleration not commanded
            accel = body_accel + b - ra
            r_pred = r + dt * rv + half * ra
            theta_pred = theta + dt * v + half * accel
            e_arm = arm - (theta_pred + r_pred)
            e_road = road - r_pred
            dz = self.deadzone * scale  # half a count in the cell model
            if dz > 0.0:
                # a count only says the angle lies in its cell: no correction while the prediction does
                e_arm = e_arm - dz if e_arm > dz else (e_arm + dz if e_arm < -dz else 0.0)
                if road_accel is not None:  # the road's cell only where its motion is commanded
                    e_road = e_road - dz if e_road > dz else (e_road + dz if e_road < -dz else 0.0)
            self._innovation(max(abs(e_arm), abs(e_road)) / scale, self.innovation_limit)
            x[0] = theta_pred + g[0][0] * e_arm + g[0][1] * e_road
            x[1] = v + dt * accel + g[1][0] * e_arm + g[1][1] * e_road
            x[2] = r_pred + g[2][0] * e_arm + g[2][1] * e_road
            x[3] = rv + dt * ra + g[3][0] * e_arm + g[3][1] * e_road
            x[4] = ra - (road_accel or 0.0) + g[4][0] * e_arm + g[4][1] * e_road
            x[5] = b + g[5][0] * e_arm + g[5][1] * e_road
        self._publish()

    def _publish(self) -> None:
        """The state vector's estimates under the names the laws read; the arm's rate θ̇2 = θ̇ + θ̇1."""
        x = self.x
        self.theta_rad = x[0]
        self.theta_dot_rad_s = x[1]
        self.theta_road_rad = x[2]
        self.road_dot_rad_s = x[3]
        self.road_ddot_rad_s2 = x[4]
        self.body_dot_rad_s = x[1] + x[3]

    def _innovation(self, worst: float, limit: float) -> None:
        """Count a cycle's largest residual ``worst`` [counts] against ``limit``: PERSIST_CYCLES in a
        row beyond it (after the warm-up) mean the model cannot explain the motion (``diverged``)."""
        if worst > self.innovation_max_counts:
            self.innovation_max_counts = worst
        if worst > limit:
            self.innovations_out += 1
            self._outside += 1
            if self._outside >= PERSIST_CYCLES and self._cycles >= self._warmup_cycles:
                self.diverged = True
        else:
            self._outside = 0
        self._cycles += 1

    # edge events -------------------------------------------------------------------------------
    @property
    def edge_fault(self) -> bool:
        """More than EDGE_BAD_SHARE of the edge events were bad (once EDGE_BAD_MIN_EVENTS were seen)."""
        seen = self.edge_events + self.edge_rejects
        return seen >= EDGE_BAD_MIN_EVENTS and self.edge_rejects > EDGE_BAD_SHARE * seen

    def _event(
        self, k: int, edge_us: int, direction: int, counts: int, now_us: int, scale: float
    ) -> tuple[float, float]:
        """(age [s], boundary angle) of encoder ``k``'s edge event if it is new and fit to fuse, else
        (-1, 0). An event from the future or older than the last one taken is counted and left out."""
        if direction == 0 or edge_us < 0:
            return NOTHING_NEW
        last = self._last_edge_us[k]
        if edge_us == last:
            return NOTHING_NEW  # the same edge as before: nothing new
        if edge_us > now_us or (last != NO_EDGE and edge_us < last):
            self.edge_rejects += 1
            return NOTHING_NEW
        self._last_edge_us[k] = edge_us
        self.edge_events += 1
        tau = (now_us - edge_us) * 1e-6
        if not self.started or tau > EDGE_MAX_AGE_S:
            return NOTHING_NEW  # the filter starts from this sample's counts; a stale event says no more
        return tau, (counts - 0.5 * direction) * scale

    def _count_var(self, sigma_counts: float, scale: float) -> float:
        """The variance a count is read with when its error is ``sigma_counts`` counts of ``scale``
        [rad] (plus the configured angle noise)."""
        return (sigma_counts * scale) ** 2 + self.angle_noise_rad**2

    def _update_with_edges(
        self,
        sample: RigSample,
        dt: float,
        body_accel: float,
        road_accel: float | None,
        scale: float,
        arm: float,
        road: float,
    ) -> None:
        """:meth:`update` with the samples' edge events (:mod:`sashil.control.edge_kalman`); ``scale``
        is one count [rad], ``arm`` and ``road`` the encoders' angles as counted."""
        now_us = sample.device_time_us
        last = self._last_edge_us
        arm_us, road_us = sample.arm_edge_us, sample.road_edge_us
        # an edge time equal to the last one taken is the same event again: nothing new (:meth:`_event`)
        arm_tau, arm_boundary = (
            NOTHING_NEW
            if arm_us == last[0]
            else self._event(0, arm_us, sample.arm_edge_dir, sample.arm_counts, now_us, scale)
        )
        road_tau, road_boundary = (
            NOTHING_NEW
            if road_us == last[1]
            else self._event(1, road_us, sample.road_edge_dir, sample.road_counts, now_us, scale)
        )
        weak, quantised = self._count_vars
        xa = self._xa
        if not self.started:
            xa[:] = (arm - road, 0.0, road, 0.0, 0.0, 0.0)
            self._p[:, :] = self._p0
            self.started = True
        elif dt > 0.0:
            commanded = road_accel is not None
            worst = (
                edge_cycle(
                    xa,
                    self._p,
                    self._q_commanded if commanded else self._q,
                    dt / self._dt,
                    dt,
                    body_accel,
                    road_accel if road_accel is not None else 0.0,
                    arm,
                    road,
                    arm_tau,
                    arm_boundary,
                    road_tau,
                    road_boundary,
                    weak if last[0] != NO_EDGE else quantised,
                    weak if last[1] != NO_EDGE else quantised,
                    0.5 * scale,
                    EDGE_TIME_SIGMA_S * EDGE_TIME_SIGMA_S,
                    self.accel_psd,
                )
                / scale
            )
            self._innovation(worst, self.innovation_limit * EDGE_LIMIT_SHARE)
        self.x[:] = xa.tolist()
        self._publish()
