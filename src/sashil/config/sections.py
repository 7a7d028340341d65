"""The sections of a sashil config and their defaults.

The defaults *are* the default config: the simulated rig with the seed parameters of
seed 001 (Iskandarani & Karimi 2011, section 8) and a 1 kHz loop. ``configs/sim.yaml`` spells the
same values out with comments (a test keeps the two equal).

Every section lives here so that a config file has one place that says what it accepts.
"""

from __future__ import annotations

from sashil.config.rtdac_section import RTDAC
from sashil.config.schema import Field, Section
from sashil.models.registry import check_model_section
from sashil.models.seed import BOUC_WEN_SEED
from sashil.plugins import BACKENDS_GROUP, entry_point_table

#: backend name -> its entry point: the names ``driver.name`` accepts, read from the registry the
#: driver layer loads backends from (the schema names them; it imports none)
BACKENDS = entry_point_table(BACKENDS_GROUP)

MODEL = Section(
    {
        "name": Field(
            "choice",
            "bouc-wen",
            choices=("bouc-wen", "dahl", "lugre", "bingham"),
            doc="the damper model; the rig plant and the controller's observer run bouc-wen only",
        ),
        # Free-form parameter mapping: each model checks its own symbols (sashil.models.registry).
        "params": Section(
            {}, open_keys=True, doc="the model's parameters by symbol (each model checks its own; bouc-wen's below)"
        ),
    },
    doc="the rig and damper model (same shape as the parameter file `sashil identify` writes)",
    check=check_model_section,
)
#: what each Bouc-Wen symbol means, with its unit (seed 001 eqs. 9-17; z is dimensionless, J = 1 normalises
#: the others per unit of inertia)
BOUC_WEN_DOCS = {
    "J": "arm inertia J [kg m²] (redundant with the others: the seed's values are per unit inertia, J = 1)",
    "k": "spring stiffness k [N m/rad] (eq. 13: −k·θ)",
    "c1": "viscous damping at 0 A, c(i) = c1 + c2·i [N m s/rad] (eq. 11)",
    "c2": "viscous damping per ampere [N m s/(rad A)] (eq. 11)",
    "alpha1": "hysteretic torque gain at 0 A, α(i) = α1 + α2·i [N m] (eq. 12; T = α(i)·z + c(i)·θ̇)",
    "alpha2": "hysteretic torque gain per ampere [N m/A] (eq. 12)",
    "beta": "Bouc-Wen β [1/rad]: shape of the loop, the term −β·θ̇·|z|^n of ż (eq. 17)",
    "gamma": "Bouc-Wen γ [1/rad]: shape of the loop, the term −γ·|θ̇|·z·|z|^(n−1) of ż (eq. 17)",
    "delta": "Bouc-Wen δ [1/rad]: the slope δ·θ̇ of ż at z = 0 (eq. 17); z saturates at (δ/(β+γ))^(1/n)",
    "n": "Bouc-Wen exponent n [1]: sharpness of the transition to the saturated z (eq. 17)",
}
MODEL.fields["params"].fields.update(
    {key: Field("float", value, doc=BOUC_WEN_DOCS[key]) for key, value in BOUC_WEN_SEED.items()}
)

RIG = Section(
    {
        "coil_tau_s": Field("float", 0.010, low=0.0, high=1.0, doc="coil current first-order lag (assumption)"),
        "current_max_a": Field(
            "float",
            1.0,
            low=0.0,
            low_open=True,
            high=10.0,
            doc="largest coil current: commands are clamped to [0, this] A",
        ),
        "encoder_counts_per_rev": Field(
            "int", 4096, low=16, high=2**31 - 1, doc="counts per revolution of each encoder (assumption)"
        ),
        "angle_noise_rad": Field(
            "float",
            0.0,
            low=0.0,
            high=1.0,
            doc="simulated rig: standard deviation of Gaussian noise on each encoder angle",
        ),
        "current_noise_a": Field(
            "float",
            0.0,
            low=0.0,
            high=1.0,
            doc="simulated rig: standard deviation of Gaussian noise on the measured current",
        ),
        "noise_seed": Field("int", 0, low=0, doc="simulated rig: seed of the noise (the same seed, the same run)"),
        "plant_max_step_s": Field(
            "float", 0.001, low=1e-6, high=0.01, doc="simulated rig: longest integration step of the plant"
        ),
        "angle_limit_deg": Field(
            "float",
            30.0,
            low=0.0,
            low_open=True,
            high=90.0,
            doc="the arm's mechanical limit of |θ|: the safety interlock trips beyond it",
        ),
    },
    doc="the physical rig around the damper",
)

DRIVER = Section(
    {
        "name": Field(
            "choice",
            "sim",
            choices=tuple(BACKENDS),
            doc="the backend (--driver): the simulated rig, sashil's board over serial or CAN, or INTECO's RT-DAC/USB2 (rtdac)",
        ),
        "port": Field("str?", None, doc="pyserial URL or device path, or CAN channel"),
        "clock": Field(
            "choice?",
            None,
            choices=("virtual", "real"),
            doc="sim backend only; null: the verb's own (virtual for drop-test, sweep, calibrate; real for run)",
        ),
        # serial and can backends (drivers/protocol.md)
        "baud": Field("int", 1_000_000, low=1200, high=100_000_000, doc="serial line rate (ignored by ptys)"),
        "can_interface": Field(
            "str", "slcan", doc="python-can interface: socketcan, pcan, kvaser, slcan, virtual, ..."
        ),
        "can_bitrate": Field("int", 1_000_000, low=10_000, high=1_000_000, doc="CAN bus bit rate [bit/s]"),
        "can_options": Section({}, open_keys=True, doc="extra keyword arguments for python-can's can.Bus"),
        "pacing": Field("choice", "device", choices=("device", "host"), doc="who times the samples"),
        "watchdog_ms": Field("int", 50, low=1, high=60_000, doc="device cuts to 0 A without a command this long"),
        "sample_timeout_ms": Field("float", 2.5, low=0.1, high=10_000.0, doc="0 A after this long without a sample"),
        "link_lost_ms": Field(
            "float", 25.0, low=0.0, high=60_000.0, doc="the run ends after this long without a sample"
        ),
        "connect_timeout_s": Field("float", 1.0, low=0.01, high=60.0, doc="handshake answers"),
        "max_lost_fraction": Field(
            "float",
            0.25,
            low=0.0,
            high=1.0,
            doc="a run over a link that lost more than this share of its samples ends 'lossy' (exit 5), data kept",
        ),
    },
    doc="which backend talks to the rig",
)

LOOP = Section(
    {
        "rate_hz": Field(
            "float",
            1000.0,
            low=0.0,
            low_open=True,
            high=20000.0,
            doc="control rate: one cycle (read, control, write) per period",
        ),
        "spin_margin_us": Field(
            "float", 200.0, low=0.0, high=100000.0, doc="sleep to this before a deadline, then spin (0: no spin)"
        ),
        "overrun_policy": Field(
            "choice", "skip", choices=("skip", "fail"), doc="a missed deadline: skip whole periods, or stop (exit 4)"
        ),
        "warn_interval_s": Field("float", 1.0, low=0.0, doc="at most one overrun warning per this interval"),
        "process": Field(
            "bool",
            True,
            doc="run the real-clock loop in a process of its own (the recorder, views and tuning stay in the session's)",
        ),
        "max_missed_fraction": Field(
            "float",
            0.25,
            low=0.0,
            high=1.0,
            doc="a run that missed more than this share of its scheduled deadlines ends 'lossy' (exit 5), data kept",
        ),
        "rt": Section(
            {
                "priority": Field("int", 50, low=0, high=99, doc="SCHED_FIFO priority (0: leave the scheduler alone)"),
                "cpu": Field("int?", None, low=0, high=4095, doc="pin the loop thread to this CPU (null: no pinning)"),
                "mlockall": Field("bool", True, doc="lock the process memory (no page faults in the loop)"),
                "gc": Field(
                    "choice", "disable", choices=("disable", "freeze", "none"), doc="garbage collector during the run"
                ),
                "timer_slack_ns": Field(
                    "int", 1, low=0, high=10_000_000, doc="PR_SET_TIMERSLACK of the loop thread (0: leave)"
                ),
                "gil_switch_us": Field(
                    "int", 100, low=0, high=100_000, doc="interpreter thread switch interval during the run (0: leave)"
                ),
            },
            doc="best-effort real-time set-up; each step's outcome is reported, none is fatal",
        ),
    },
    doc="the real-time control loop",
)

SAFETY = Section(
    {
        "angle_interlock": Field("bool", True, doc="trip when |theta| exceeds rig.angle_limit_deg"),
        "slew_a_per_s": Field("float", 0.0, low=0.0, doc="largest current change per second (0: no slew limit)"),
        "sensor_timeout_cycles": Field(
            "int", 20, low=1, high=1_000_000, doc="trip after this many cycles without a fresh sample"
        ),
        "trip_on_device_fault": Field("bool", True, doc="trip when the device reports a fault or overcurrent flag"),
        "max_angle_rate_rad_s": Field(
            "float",
            60.0,
            low=0.0,
            low_open=True,
            doc="the fastest either encoder's angle can turn [rad/s]: a step between two samples faster than "
            "this (plus one count) is an encoder fault (an index reset, wrong counts per revolution) and trips",
        ),
        "arm_travel_deg": Field(
            "float?",
            None,
            low=0.0,
            low_open=True,
            high=360.0,
            doc="the arm's travel |theta2| from where its counter was zeroed [deg]: beyond it trips (null: off)",
        ),
        "road_error_max_rad": Field(
            "float",
            0.02,
            low=0.0,
            low_open=True,
            doc="a host-closed road loop's largest angle error from its reference [rad], held road_error_ms, trips "
            "(ten times the loop's usual largest on a rightly wired bench)",
        ),
        "road_error_ms": Field(
            "float",
            5.0,
            low=0.0,
            doc="how long the road's error may stay beyond road_error_max_rad [ms]: five periods at 1 kHz, short "
            "enough that a reversed road encoder, whose error the loop's own gain drives up, ends within 0.1 rad",
        ),
        "road_grace_ms": Field(
            "float",
            150.0,
            low=0.0,
            doc="after a host pause (a sample more than three periods after the last) the road's error and "
            "limit are not judged for this long [ms]: the board held the road's output while the host was away",
        ),
        "road_limit_ms": Field(
            "float", 50.0, low=0.0, doc="how long the road motor's output may stay at its limit [ms] before a trip"
        ),
        "coil_authority_ms": Field(
            "float",
            50.0,
            low=0.0,
            doc="how long the coil's current loop may stay at its authority limit [ms] (its sense disagrees with "
            "the command) before a trip",
        ),
    },
    doc="the host-side safety supervisor (current clamp [0, rig.current_max_a] is always on)",
)

DROP_TEST = Section(
    {
        "hold_tolerance_deg": Field(
            "float", 0.5, low=0.0, low_open=True, high=10.0, doc="the arm counts as held within this of theta0_deg"
        ),
        "hold_time_s": Field(
            "float", 0.2, low=0.0, high=60.0, doc="how long the arm must stay held before a release counts"
        ),
        "release_threshold_deg": Field(
            "float", 0.5, low=0.0, low_open=True, high=10.0, doc="a move this far from the hold angle is the release"
        ),
        "hold_timeout_s": Field(
            "float", 60.0, low=0.0, low_open=True, doc="the drop fails when the arm is not held (or released) in time"
        ),
        "settle_band_deg": Field(
            "float", 0.25, low=0.0, low_open=True, high=10.0, doc="settling time: when |θ| stays within this band"
        ),
        "theta0_deg": Field("float", -5.0, low=-30.0, high=30.0, doc="hold angle before the release (--theta0-deg)"),
        "currents_a": Field(
            "float_list", [0.0], doc="constant coil current of each drop, one sub-run each (--current)"
        ),
        "duration_s": Field("float", 10.0, low=0.0, low_open=True, doc="record length after the release (--duration)"),
    },
    doc="`sashil drop-test`: the drops, and how a drop test finds the hold and the release",
)

RUN = Section(
    {
        "duration_s": Field("float?", None, low=0.0, low_open=True, doc="seconds to run (null: until stopped)"),
        "road": Field(
            "str?", None, doc="road excitation theta1(t) (--road syntax; null: sine:1.0 on the sim backend, else none)"
        ),
    },
    doc="`sashil run`: how long, and the road (the law is controller.law, the rate loop.rate_hz)",
)

SIMULATE = Section(
    {
        "input": Field("str?", None, doc="recorded inputs (CSV or run folder); null: a drop test"),
        "theta0_deg": Field("float", -5.0, low=-90.0, high=90.0, doc="drop test: initial angle"),
        "current_a": Field("float", 0.0, low=0.0, high=10.0, doc="drop test: coil current"),
        "duration_s": Field("float", 10.0, low=0.0, low_open=True, doc="drop test: seconds"),
        "start": Field("choice", "rest", choices=("rest", "moving"), doc="the input starts at rest or moving"),
    },
    doc="`sashil simulate`: the inputs the model runs on",
)

CONTROLLER = Section(
    {
        "law": Field(
            "str",
            "passive",
            doc="the semi-active law: a registered name (sashil laws), package.module:Class or file.py:Class; "
            "its parameters are further keys of this section (or --controller)",
        ),
        "estimator": Field(
            "choice",
            "kalman",
            choices=("kalman", "tracking"),
            doc="kalman: the rig model's Kalman filter over both encoders; tracking: fixed-bandwidth filters",
        ),
        "kalman_accel_psd": Field(
            "float", 1.0e-4, low=0.0, low_open=True, high=1e12, doc="kalman: arm acceleration noise [rad^2/s^3]"
        ),
        "kalman_road_jerk_psd": Field(
            "float", 100.0, low=0.0, low_open=True, high=1e15, doc="kalman: road jerk noise [rad^2/s^5]"
        ),
        "kalman_road_jerk_psd_commanded": Field(
            "float",
            1.0e-2,
            low=0.0,
            low_open=True,
            high=1e15,
            doc="kalman: road jerk noise while a plan commands the road speed [rad^2/s^5]",
        ),
        "kalman_quantisation": Field(
            "choice",
            "noise",
            choices=("noise", "cell", "auto"),
            doc="kalman: a count as the angle plus white noise q^2/12, or as the zone of one count about it",
        ),
        "edge_timing": Field(
            "bool",
            True,
            doc="kalman: fuse the encoders' edge times (protocol 2) as exact angles at their instants; "
            "false: the counts alone",
        ),
        "kalman_bias_psd": Field(
            "float", 1.0e-4, low=0.0, low_open=True, high=1e15, doc="kalman: model-error drift [rad^2/s^5]"
        ),
        "innovation_limit_counts": Field(
            "float",
            6.0,
            low=1.0,
            high=1e6,
            doc="kalman: a residual beyond this many counts means the model is wrong: fall back to 0 A",
        ),
        "estimator_bandwidth_hz": Field(
            "float", 10.0, low=0.0, low_open=True, high=1000.0, doc="relative-angle alpha-beta filter"
        ),
        "estimator_order": Field(
            "int", 2, low=2, high=3, doc="2: alpha-beta (+model), 3: alpha-beta-gamma (+model error)"
        ),
        "road_bandwidth_hz": Field(
            "float", 30.0, low=0.0, low_open=True, high=1000.0, doc="road-angle alpha-beta-gamma filter"
        ),
        "model_aided": Field("bool", True, doc="feed the rig model's acceleration to the rate estimator"),
        "inverse": Field(
            "choice",
            "full",
            choices=("full", "rule", "viscous"),
            doc="full: the current closest to T* in the feasible band; rule: also 0 A when T*·v <= 0; "
            "viscous: alpha ignored",
        ),
        "min_authority_nm_per_a": Field(
            "float", 1e-3, low=0.0, low_open=True, doc="0 A when |alpha2*z + c2*v| is below this"
        ),
        "lead_horizon_s": Field(
            "float",
            0.003,
            low=0.0,
            high=1.0,
            doc="coil-lag compensation horizon (0: off): a torque law's current is commanded so the coil reaches it "
            "within this time",
        ),
        "lead_current_laws": Field(
            "bool",
            False,
            doc="apply the coil-lag lead to a current() law's output too (false: the current a law gives is "
            "commanded as given, clamped to [0, i_max]; data.csv records it as current_law_a either way)",
        ),
        "coil_tau_s": Field(
            "float?", None, low=0.0, high=1.0, doc="coil lag the controller assumes (null: rig.coil_tau_s)"
        ),
        "tune_ramp_s": Field(
            "float",
            0.0,
            low=0.0,
            high=3600.0,
            doc="sashil tune: seconds over which a live change moves a law's float parameter linearly (0: a step)",
        ),
    },
    open_keys=True,  # the law's own parameters, checked by sashil.control.law_config
    doc="the semi-active controller: estimator, Bouc-Wen observer, law, inverse",
)

MISMATCH = Section(
    {
        "fraction": Field(
            "float", 0.0, low=0.0, high=0.9, doc="each Bouc-Wen parameter of the simulated plant off by this fraction"
        ),
        "pattern": Field(
            "choice",
            "alternate",
            choices=("alternate", "plus", "minus", "random"),
            doc="signs of the offsets in J,k,c1,c2,alpha1,alpha2,beta,gamma,delta,n order",
        ),
        "seed": Field("int", 0, low=0, doc="pattern random: seed of the signs"),
        "params": Section({}, open_keys=True, doc="per-parameter fractions, e.g. {c1: 0.1} (override fraction)"),
        "coil_tau": Field("float", 0.0, low=-0.9, high=10.0, doc="plant coil lag = rig.coil_tau_s * (1 + this)"),
        "encoder_counts_per_rev": Field(
            "int?", None, low=16, high=2**31 - 1, doc="plant encoder quantisation (null: rig's)"
        ),
        "angle_noise_rad": Field("float?", None, low=0.0, high=1.0, doc="plant angle noise (null: rig's)"),
        "current_noise_a": Field("float?", None, low=0.0, high=1.0, doc="plant current-sensor noise (null: rig's)"),
    },
    doc="how the simulated plant differs from the model the controller uses",
)

SWEEP = Section(
    {
        "amplitude_deg": Field("float", 1.0, low=0.0, low_open=True, high=20.0, doc="road-side amplitude of theta1"),
        "ramp_s": Field("float", 1.0, low=0.0, high=60.0, doc="raised-cosine amplitude ramp at the start"),
        "settle_s": Field(
            "float", 6.0, low=0.0, high=600.0, doc="stepped sine: time before measuring at each frequency"
        ),
        "measure_s": Field(
            "float", 4.0, low=0.0, low_open=True, high=600.0, doc="stepped sine: measuring time (whole periods)"
        ),
        "steps": Field("int", 24, low=2, high=1000, doc="stepped sine: number of frequencies"),
        "spacing": Field(
            "choice", "log", choices=("linear", "log"), doc="stepped sine: how the frequencies are spaced"
        ),
        "f_start_hz": Field("float", 0.5, low=0.0, low_open=True, doc="start frequency (--f-start)"),
        "f_stop_hz": Field(
            "float", 5.0, low=0.0, low_open=True, doc="stop frequency (--f-stop; = f_start_hz: one sine)"
        ),
        "duration_s": Field("float", 30.0, low=0.0, low_open=True, doc="chirp length, ramp not included (--duration)"),
        "stepped": Field("bool", False, doc="stepped sine instead of a chirp (--stepped)"),
    },
    doc="road-side excitation: chirp and stepped sine",
)

ROAD = Section(
    {
        "lever_m": Field(
            "float", 0.5, low=0.0, low_open=True, high=10.0, doc="road height to road-wheel angle: theta1 = h / lever_m"
        ),
        "speed_m_s": Field(
            "float", 10.0, low=0.0, low_open=True, high=100.0, doc="iso8608: vehicle speed (iso8608:C:SPEED)"
        ),
        "seed": Field("int", 0, low=0, doc="iso8608: seed of the random phases (the same seed, the same road)"),
        "period_s": Field(
            "float", 120.0, low=1.0, high=3600.0, doc="iso8608: length of the synthesised road, repeated after it"
        ),
        "bump_width_s": Field("float", 0.5, low=0.0, low_open=True, high=60.0, doc="bump: its length in time"),
        "bump_start_s": Field("float", 1.0, low=0.0, high=3600.0, doc="bump: when it starts"),
    },
    doc="road profiles of --road iso8608:CLASS[:SPEED] and bump:HEIGHT_DEG: the rig's geometry and the generator",
)

COMPARE = Section(
    {
        "accel_bandwidth_hz": Field(
            "float", 20.0, low=0.0, low_open=True, high=200.0, doc="low-pass of the arm angle before its acceleration"
        ),
        "coil_resistance_ohm": Field(
            "float", 5.0, low=0.0, low_open=True, doc="coil resistance for the coil energy (ASSUMPTION)"
        ),
        "settle_s": Field("float", 2.0, low=0.0, high=600.0, doc="the start of each run the metrics leave out"),
        "rest_s": Field(
            "float", 5.0, low=0.0, high=600.0, doc="on a real rig: time at rest (0 A, road stopped) between laws"
        ),
        "max_pause_ms": Field(
            "float",
            20.0,
            low=0.0,
            low_open=True,
            high=10000.0,
            doc="on a real rig: a law whose host paused longer (its road speed held) is run again",
        ),
        "repeats": Field(
            "int", 2, low=0, high=10, doc="on a real rig: times a law is run again for a host pause (max_pause_ms)"
        ),
        "jobs": Field("int", 1, low=1, high=64, doc="simulated rig: laws run in this many processes (--jobs)"),
        "passive_currents_a": Field(
            "float_list",
            [0.0, 0.25, 0.5, 0.75, 1.0],
            doc="on a real rig: the constant currents run, the best of them the passive baseline "
            "(a simulated rig searches [0, i_max])",
        ),
        "road": Field("str", "iso8608:C", doc="the road every law runs on (--road syntax)"),
        "duration_s": Field(
            "float", 30.0, low=0.0, low_open=True, doc="seconds per law, more than settle_s (--duration)"
        ),
    },
    doc="`sashil compare`: the road, the metrics and how the laws are run",
)

CALIBRATE = Section(
    {
        "theta0_deg": Field("float", -5.0, low=-30.0, high=30.0, doc="the large drops: hold angle"),
        "currents_a": Field("float_list", [0.0, 0.5, 1.0], doc="the large drops: one per current"),
        "small_theta0_deg": Field("float", -2.5, low=-30.0, high=30.0, doc="the small drops: hold angle"),
        "small_currents_a": Field("float_list", [0.0, 1.0], doc="the small drops: one per current"),
        "drop_duration_s": Field("float", 6.0, low=0.5, high=120.0, doc="record length after each release"),
        "road_currents_a": Field(
            "float_list", [0.5, 1.0], doc="road excitation through the resonance: one per current"
        ),
        "road_amplitude_deg": Field(
            "float", 1.0, low=0.0, low_open=True, high=20.0, doc="road runs: amplitude of the road-side chirp"
        ),
        "road_f_start_hz": Field(
            "float", 0.8, low=0.0, low_open=True, high=100.0, doc="road runs: chirp start frequency"
        ),
        "road_f_stop_hz": Field(
            "float", 3.0, low=0.0, low_open=True, high=100.0, doc="road runs: chirp stop frequency"
        ),
        "road_duration_s": Field("float", 12.0, low=1.0, high=600.0, doc="record length of a road run, ramps included"),
        "road_ramp_s": Field("float", 1.0, low=0.0, high=60.0, doc="raised-cosine amplitude ramps at both ends"),
        "validate_theta0_deg": Field("float", -3.5, low=-30.0, high=30.0, doc="held-out drops: hold angle"),
        "validate_currents_a": Field("float_list", [0.25, 0.75], doc="held-out drops (the fit never sees them)"),
        "validate_road_currents_a": Field("float_list", [], doc="held-out road runs"),
        "max_rig_time_s": Field("float", 180.0, low=1.0, doc="a plan estimated to take longer is refused"),
        "model": Field(
            "choice",
            "bouc-wen",
            choices=("bouc-wen", "dahl", "lugre", "bingham", "all"),
            doc="the model fitted (all: each, compared)",
        ),
        "inertia_kg_m2": Field(
            "float?",
            None,
            low=0.0,
            low_open=True,
            doc="the arm's inertia J (--inertia; null: torques relative to J = 1)",
        ),
        "profile_n": Field("bool", True, doc="profile the Bouc-Wen exponent n after the fit (--no-profile: false)"),
        "interval_block_s": Field(
            "float", 2.0, low=0.1, high=60.0, doc="block length of the jackknife behind the 95 % intervals"
        ),
        "extra_steps": Field(
            "int", 0, low=0, high=9, doc="run this many suggested extra steps after the plan and refit (--extra-steps)"
        ),
    },
    doc="the plan of `sashil calibrate`: drops and road runs to fit, and held-out runs to validate",
)

SCHEMA = {
    "model": MODEL,
    "rig": RIG,
    "driver": DRIVER,
    "rtdac": RTDAC,
    "loop": LOOP,
    "safety": SAFETY,
    "drop_test": DROP_TEST,
    "controller": CONTROLLER,
    "mismatch": MISMATCH,
    "sweep": SWEEP,
    "calibrate": CALIBRATE,
    "run": RUN,
    "simulate": SIMULATE,
    "road": ROAD,
    "compare": COMPARE,
}
