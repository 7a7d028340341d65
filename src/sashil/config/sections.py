"""The sections of a sashil config and their defaults.

The defaults *are* the default config: the simulated rig with the seed parameters of
seed 001 (Iskandarani & Karimi 2011, section 8) and a 1 kHz loop. ``configs/sim.yaml`` spells the
same values out with comments (a test keeps the two equal).

Each issue's section lives here so that a config file has one place that says what it accepts.
"""

from __future__ import annotations

from sashil.config.schema import Field, Section

#: Bouc-Wen rig model parameters (DESIGN.md; seed 001 eqs. 9-17, section 8 tables).
BOUC_WEN_SEED = {
    "J": 1.0,
    "k": 109.0,
    "c1": 0.7,
    "c2": 1.5,
    "alpha1": 1.0,
    "alpha2": 1.0,
    "beta": 873.0,
    "gamma": 1.0,
    "delta": 700.0,
    "n": 0.099,
}

MODEL = Section(
    {
        "name": Field("choice", "bouc-wen", choices=("bouc-wen", "dahl", "lugre", "bingham")),
        # Free-form parameter mapping: each model checks its own symbols (sashil.models.registry).
        "params": Section({}, open_keys=True),
    },
    doc="the rig and damper model (same shape as the parameter file `sashil identify` writes)",
)
MODEL.fields["params"].fields.update(
    {key: Field("float", value) for key, value in BOUC_WEN_SEED.items()}
)

RIG = Section(
    {
        "coil_tau_s": Field("float", 0.010, low=0.0, high=1.0, doc="coil current first-order lag (assumption)"),
        "current_max_a": Field("float", 1.0, low=0.0, low_open=True, high=10.0),
        "encoder_counts_per_rev": Field("int", 4096, low=16, high=2**31 - 1, doc="(assumption)"),
        "angle_noise_rad": Field("float", 0.0, low=0.0, high=1.0),
        "current_noise_a": Field("float", 0.0, low=0.0, high=1.0),
        "noise_seed": Field("int", 0, low=0),
        "plant_max_step_s": Field("float", 0.001, low=1e-6, high=0.01),
        "angle_limit_deg": Field("float", 30.0, low=0.0, low_open=True, high=90.0),
    },
    doc="the physical rig around the damper",
)

DRIVER = Section(
    {
        "name": Field("choice", "sim", choices=("sim", "serial", "can")),
        "port": Field("str?", None, doc="pyserial URL or device path, or CAN channel"),
        "clock": Field("choice", "virtual", choices=("virtual", "real"), doc="sim backend only"),
    },
    doc="which backend talks to the rig",
)

LOOP = Section(
    {
        "rate_hz": Field("float", 1000.0, low=0.0, low_open=True, high=20000.0),
    },
    doc="the real-time control loop",
)

DROP_TEST = Section(
    {
        "hold_tolerance_deg": Field("float", 0.5, low=0.0, low_open=True, high=10.0),
        "hold_time_s": Field("float", 0.2, low=0.0, high=60.0),
        "release_threshold_deg": Field("float", 0.1, low=0.0, low_open=True, high=10.0),
        "hold_timeout_s": Field("float", 60.0, low=0.0, low_open=True),
        "settle_band_deg": Field("float", 0.25, low=0.0, low_open=True, high=10.0),
    },
    doc="how a drop test finds the hold and the release",
)

SCHEMA = {
    "model": MODEL,
    "rig": RIG,
    "driver": DRIVER,
    "loop": LOOP,
    "drop_test": DROP_TEST,
}
