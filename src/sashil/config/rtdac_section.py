"""The ``rtdac`` section: how INTECO's RT-DAC/USB2 is found, and how the lab's rig is wired to it.

What INTECO's SAS rig wires to which counter, output and converter is not public, so nothing
here is SAS-specific: each default that guesses says so in its doc, and ``sashil doctor --driver
rtdac --walk`` finds the real wiring with the operator and writes a fragment of this section.
"""

from __future__ import annotations

import itertools
from typing import Any

from sashil.config.schema import Field, Section
from sashil.errors import ConfigError

#: the highest channel number a board can have (4-bit module counts; 16 A/D: RTDACBoard.cs)
_TOP = 15
#: the coil's wiring keys: until doctor --walk confirms them all, the coil runs under its bring-up cap
COIL_KEYS = ("coil_output", "coil_channel", "coil_map_current_a", "coil_map_output")
#: the road's wiring keys: until all are confirmed, the road motor runs under its bring-up cap
ROAD_KEYS = ("road_output", "road_channel", "road_encoder", "road_counts_per_rev", "road_reversed")
#: the arm's and the coil sense's keys, which the walk also confirms
OTHER_KEYS = ("arm_encoder", "arm_counts_per_rev", "arm_reversed", "coil_sense_ad", "coil_sense_a_per_v")
WIRING_KEYS = COIL_KEYS + ROAD_KEYS + OTHER_KEYS


def check_rtdac_section(given: Any, section: dict[str, Any], source: str, dotted: str) -> dict[str, Any]:
    """The keys that depend on each other: the coil's map, which outputs exist, distinct channels."""
    currents, outputs = section["coil_map_current_a"], section["coil_map_output"]
    if len(currents) < 2 or len(currents) != len(outputs):
        raise ConfigError(
            f"{source}: {dotted}.coil_map_output: expected as many points as coil_map_current_a "
            f"(at least 2), got {len(outputs)} and {len(currents)}"
        )
    if any(b <= a for a, b in itertools.pairwise(currents)) or any(b < a for a, b in itertools.pairwise(outputs)):
        raise ConfigError(
            f"{source}: {dotted}.coil_map_current_a: expected currents rising and outputs not falling, "
            f"got {list(currents)} -> {list(outputs)}"
        )
    if currents[0] != 0.0:
        raise ConfigError(f"{source}: {dotted}.coil_map_current_a: expected the map to start at 0 A, got {currents[0]}")
    limit = 1.0 if section["coil_output"] == "pwm" else 10.0
    if section["coil_output"] == "pwm" and (outputs[0] < 0.0 or outputs[-1] > limit):
        raise ConfigError(f"{source}: {dotted}.coil_map_output: expected duties from 0 to 1, got {list(outputs)}")
    if section["coil_output"] == "da" and (outputs[0] < -10.0 or outputs[-1] > limit):
        raise ConfigError(f"{source}: {dotted}.coil_map_output: expected volts from -10 to 10, got {list(outputs)}")
    if section["coil_output"] == "da" and section["coil_channel"] > 3:
        raise ConfigError(
            f"{source}: {dotted}.coil_channel: expected a D/A channel from 0 to 3, got {section['coil_channel']}"
        )
    if section["road_output"] == "da" and section["road_channel"] > 3:
        raise ConfigError(
            f"{source}: {dotted}.road_channel: expected a D/A channel from 0 to 3, got {section['road_channel']}"
        )
    if section["road_output"] == section["coil_output"] and section["road_channel"] == section["coil_channel"]:
        raise ConfigError(
            f"{source}: {dotted}.road_channel: the road motor and the coil on the same {section['coil_output']} "
            f"channel {section['coil_channel']}"
        )
    if section["road_encoder"] is not None and section["road_encoder"] == section["arm_encoder"]:
        raise ConfigError(
            f"{source}: {dotted}.road_encoder: the same counter as arm_encoder ({section['arm_encoder']})"
        )
    if section["heartbeat_bit"] is not None and section["heartbeat_bit"] == section["road_direction_bit"]:
        raise ConfigError(
            f"{source}: {dotted}.heartbeat_bit: the same digital output as road_direction_bit "
            f"({section['heartbeat_bit']}): the heartbeat toggles it every cycle"
        )
    if section["road_output"] == "pwm" and section["road_output_limit"] > 1.0:
        raise ConfigError(
            f"{source}: {dotted}.road_output_limit: expected a duty at most 1 for a PWM road output, "
            f"got {section['road_output_limit']}"
        )
    return section


RTDAC = Section(
    {
        # finding the board ---------------------------------------------------------------------
        "manufacturer": Field(
            "str",
            "InTeCo",
            doc="USB manufacturer string the board is matched on (the public app checks 'InTeCo')",
        ),
        "serial": Field("str?", None, doc="USB serial number of the board to open (null: the first found)"),
        "vendor_id": Field(
            "int?", None, low=0, high=0xFFFF, doc="USB vendor id to match instead of the manufacturer (null: any)"
        ),
        "product_id": Field("int?", None, low=0, high=0xFFFF, doc="USB product id to match as well (null: any)"),
        "usb_backend": Field(
            "str?",
            None,
            doc="pyusb backend: null for libusb 1.0 (the packaged one of libusb-package, else the system's); "
            "'module:callable' for the pyusb backend (usb.backend.IBackend) the callable returns, called with "
            "driver.port when it takes an argument, else with none (an emulator's, e.g. a check's own)",
        ),
        "transfer_timeout_ms": Field("float", 20.0, low=0.1, high=10_000.0, doc="one bulk transfer's timeout [ms]"),
        "application": Field(
            "str?", None, doc="application name the board's header must carry (null: any the register map serves)"
        ),
        "map_dir": Field(
            "str?", None, doc="folder of a lab's own register map files (*.yaml), beside the built-in ones"
        ),
        # the arm and the road wheel ------------------------------------------------------------
        "arm_encoder": Field(
            "int", 0, low=0, high=_TOP, doc="encoder counter of the arm angle theta2 (a guess: doctor --walk)"
        ),
        "arm_counts_per_rev": Field(
            "int", 4096, low=16, high=2**31 - 1, doc="arm encoder counts per revolution (a guess)"
        ),
        "arm_reversed": Field("bool", False, doc="the arm counter counts down when theta2 rises"),
        "road_encoder": Field(
            "int?", 1, low=0, high=_TOP, doc="encoder counter of the road wheel angle theta1 (null: none; a guess)"
        ),
        "road_counts_per_rev": Field(
            "int", 4096, low=16, high=2**31 - 1, doc="road encoder counts per revolution (a guess)"
        ),
        "road_reversed": Field("bool", False, doc="the road counter counts down when theta1 rises"),
        # the coil's power stage ----------------------------------------------------------------
        "coil_output": Field(
            "choice",
            "pwm",
            choices=("pwm", "da"),
            doc="what drives the coil's power stage: a PWM duty or a D/A voltage (a guess)",
        ),
        "coil_channel": Field("int", 0, low=0, high=_TOP, doc="the PWM or D/A channel of the coil (a guess)"),
        "coil_map_current_a": Field(
            "float_list", [0.0, 1.0], doc="coil current points of the power stage's calibration [A], from 0 A, rising"
        ),
        "coil_map_output": Field(
            "float_list",
            [0.0, 1.0],
            doc="the output at each current point: a duty 0-1 (pwm) or volts (da); between points linear (a guess: calibrate it)",
        ),
        "coil_sense_ad": Field(
            "int?",
            None,
            low=0,
            high=_TOP,
            doc="A/D channel that reads the coil current (null: none wired, current_a empty; set it once "
            "doctor --walk confirms a channel)",
        ),
        "coil_sense_a_per_v": Field("float", 0.2, low=1e-6, high=1e6, doc="coil current per A/D volt [A/V] (a guess)"),
        "coil_sense_offset_v": Field("float", 0.0, low=-10.0, high=10.0, doc="A/D volts at 0 A [V]"),
        "coil_loop_ki_per_s": Field(
            "float",
            20.0,
            low=0.0,
            high=10_000.0,
            doc="integral gain of the current loop on the sensed current [1/s] (0: the map alone)",
        ),
        # the road motor ------------------------------------------------------------------------
        "road_output": Field(
            "choice",
            "da",
            choices=("none", "pwm", "da"),
            doc="what drives the road motor: a D/A voltage, a PWM duty (one direction, or a direction bit), or none",
        ),
        "road_channel": Field("int", 0, low=0, high=_TOP, doc="the D/A or PWM channel of the road motor (a guess)"),
        "road_direction_bit": Field(
            "int?",
            None,
            low=0,
            high=25,
            doc="digital output bit that sets the road motor's direction (PWM only; null: none)",
        ),
        "road_output_per_rad_s": Field(
            "float", 0.5, low=0.0, high=100.0, doc="feed-forward of the road speed [V or duty per rad/s] (a guess)"
        ),
        "road_kp_per_rad": Field(
            "float",
            20.0,
            low=0.0,
            high=10_000.0,
            doc="gain on the road angle's error from its reference [V or duty per rad] (a guess)",
        ),
        "road_lag_s": Field(
            "float",
            0.02,
            low=0.0,
            high=10.0,
            doc="the road motor's time constant [s]: the feed-forward leads the speed by it (a guess: doctor --walk measures it)",
        ),
        "road_output_limit": Field(
            "float", 10.0, low=0.0, low_open=True, high=10.0, doc="largest road output magnitude [V, or duty]"
        ),
        "pwm_prescaler": Field(
            "int?",
            None,
            low=0,
            high=0xFFFF,
            doc="PWM prescaler written to the channels sashil drives (null: the board's own, as read, stays)",
        ),
        "pwm_mode": Field("choice", "12-bit", choices=("12-bit", "8-bit"), doc="PWM width resolution"),
        # what doctor --walk confirmed, and the limits until it has ------------------------------
        "confirmed": Field(
            "choice_list",
            [],
            choices=WIRING_KEYS,
            doc="the wiring keys doctor --walk confirmed on this rig; a group not wholly confirmed runs under "
            "its bring-up cap (the coil: " + ", ".join(COIL_KEYS) + "; the road: " + ", ".join(ROAD_KEYS) + ")",
        ),
        "bringup_current_max_a": Field(
            "float",
            0.3,
            low=0.0,
            high=10.0,
            doc="largest coil current [A] while the coil's wiring is not confirmed (a wrong channel drives "
            "at most this map's output)",
        ),
        "bringup_road_output": Field(
            "float",
            0.25,
            low=0.0,
            high=1.0,
            doc="largest road output, a fraction of road_output_limit, while the road's wiring is not confirmed",
        ),
        "coil_loop_authority": Field(
            "float",
            0.25,
            low=0.0,
            high=1.0,
            doc="largest correction of the current loop, a fraction of the map's output for the command: the "
            "coil's output stays within (1 ± this) x the map's (a dead sense cannot drive it to full duty)",
        ),
        "heartbeat_bit": Field(
            "int?",
            None,
            low=0,
            high=25,
            doc="digital output bit toggled every cycle for a retriggerable watchdog relay on the power "
            "stages (null: none); it stops when the loop stops, and the relay drops both stages",
        ),
    },
    doc="INTECO's RT-DAC/USB2 board (driver.name: rtdac): finding it, and the rig's wiring to it",
    check=check_rtdac_section,
)
