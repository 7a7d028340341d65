"""Options shared by the verbs, and turning them into a resolved config."""

from __future__ import annotations

import argparse
import math
from typing import Any

from sashil.config import Config, apply_params, load_config
from sashil.errors import ConfigError


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """``--config`` and ``--params`` (every verb)."""
    parser.add_argument("--config", metavar="FILE", help="YAML config (default: simulated rig, seed parameters)")
    parser.add_argument("--params", metavar="FILE", help="parameter file from `sashil identify` (replaces the model)")


def add_driver_options(parser: argparse.ArgumentParser) -> None:
    """``--driver`` and ``--port`` (every verb that talks to a rig)."""
    parser.add_argument("--driver", choices=("sim", "serial", "can"), help="override driver.name")
    parser.add_argument("--port", metavar="PORT", help="pyserial URL/device path, or CAN channel (override driver.port)")


def add_output_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", metavar="DIR", help="run folder (default runs/<UTC timestamp>-<verb>/)")


def resolve_config(args: argparse.Namespace) -> Config:
    """The config the verb runs with: file (or defaults), then --params, then --driver/--port."""
    config = load_config(getattr(args, "config", None))
    if getattr(args, "params", None):
        config = apply_params(config, args.params)
    if getattr(args, "driver", None):
        config["driver"]["name"] = args.driver
    if getattr(args, "port", None):
        config["driver"]["port"] = args.port
    return config


def positive_seconds(option: str, value: float) -> float:
    """Check a duration argument: a finite number > 0."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ConfigError(f"{option}: expected a duration in seconds > 0, got {value:g}")
    return float(value)


def current_in_range(option: str, value: float, config: dict[str, Any]) -> float:
    """Check a coil current argument against [0, rig.current_max_a]."""
    i_max = config["rig"]["current_max_a"]
    if not (math.isfinite(value) and 0.0 <= value <= i_max):
        raise ConfigError(f"{option}: expected a current in [0, {i_max:g}] A (rig.current_max_a), got {value:g}")
    return float(value)
