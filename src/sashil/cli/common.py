"""Options shared by the verbs, and turning them into a resolved config."""

from __future__ import annotations

import argparse
import logging
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sashil.config import Config, apply_params, check_controller, load_config
from sashil.config.overrides import apply_overrides
from sashil.drivers import BACKENDS, declared_capabilities
from sashil.errors import ConfigError
from sashil.models.registry import MODEL_PARAMS, RIG_MODELS
from sashil.recording.formats import FORMATS, check_formats
from sashil.recording.formats import HELP as FORMAT_HELP


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """``--config``, ``--params`` and ``--set`` (every verb that reads a config)."""
    parser.add_argument("--config", metavar="FILE", help="YAML config (default: simulated rig, seed parameters)")
    parser.add_argument("--params", metavar="FILE", help="parameter file from `sashil identify` (replaces the model)")
    add_set_option(parser)


def add_set_option(parser: argparse.ArgumentParser) -> None:
    """``--set section.key=value`` (repeatable), applied by :func:`resolve_config`."""
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        dest="overrides",
        metavar="SECTION.KEY=VALUE",
        help="change one config value, checked like the config file (YAML value; repeatable), "
        "e.g. --set loop.rate_hz=500 --set controller.law=skyhook --set controller.c_sky=2",
    )


def add_driver_options(parser: argparse.ArgumentParser) -> None:
    """``--driver`` and ``--port`` (every verb that talks to a rig)."""
    parser.add_argument("--driver", choices=tuple(BACKENDS), help="override driver.name")
    parser.add_argument(
        "--port", metavar="PORT", help="pyserial URL/device path, or CAN channel (override driver.port)"
    )


def add_output_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", metavar="DIR", help="run folder (default runs/<UTC timestamp>-<verb>/)")


#: ``--rerun-save`` without a file name: ``live.rrd`` in the run folder (a marker no path can equal)
IN_RUN_FOLDER = "{run folder}/live.rrd"


def rrd_path(text: str) -> str:
    """``--rerun-save FILE``: checked when the command line is read, before anything is written."""
    if text == IN_RUN_FOLDER:  # argparse passes the const through here too
        return text
    path = Path(text)
    if path.suffix != ".rrd":
        raise argparse.ArgumentTypeError(f"expected a file name ending .rrd, got {text!r}")
    if not path.parent.is_dir():
        raise argparse.ArgumentTypeError(f"folder {str(path.parent)!r} of {text!r} does not exist")
    return text


def add_recording_options(parser: argparse.ArgumentParser, formats: bool = True) -> None:
    """``--rerun``, ``--rerun-connect``, ``--rerun-save`` (live view / recording) and ``--format``."""
    group = parser.add_argument_group("live view and output formats")
    group.add_argument("--rerun", action="store_true", help="spawn the rerun viewer and stream the run to it live")
    group.add_argument(
        "--rerun-bind",
        metavar="ADDR",
        default="127.0.0.1",
        help="address the spawned viewer listens on (default 127.0.0.1: this machine only; 0.0.0.0: every interface)",
    )
    group.add_argument(
        "--rerun-connect",
        metavar="URL",
        help="stream to a running rerun viewer (e.g. rerun+http://127.0.0.1:9876/proxy)",
    )
    group.add_argument(
        "--rerun-save",
        nargs="?",
        const=IN_RUN_FOLDER,
        type=rrd_path,
        metavar="FILE.rrd",
        help="record the live view to an .rrd file, no viewer needed (no FILE: live.rrd in the run folder)",
    )
    if formats:
        group.add_argument("--format", action="append", choices=FORMATS, metavar="FMT", help=FORMAT_HELP)


def wants_rerun(args: argparse.Namespace) -> bool:
    return bool(
        getattr(args, "rerun", False) or getattr(args, "rerun_connect", None) or getattr(args, "rerun_save", None)
    )


def open_rerun(args: argparse.Namespace, columns: Sequence[str], name: str, folder: Path) -> Any:
    """The :class:`~sashil.recording.rerun_log.RerunLog` the options ask for, or None
    (``folder``: the run folder, for ``--rerun-save`` without a file name)."""
    if not wants_rerun(args):
        return None
    from sashil.recording.rerun_log import RerunLog

    save = args.rerun_save
    if save == IN_RUN_FOLDER:
        save = Path(folder) / "live.rrd"
    return RerunLog.open(
        columns,
        save=save,
        viewer=bool(args.rerun),
        connect=getattr(args, "rerun_connect", None),
        name=name,
        bind=getattr(args, "rerun_bind", "127.0.0.1"),
    )


def open_live_tap(args: argparse.Namespace, config: Config, columns: Sequence[str], name: str, folder: Path) -> Any:
    """A :class:`~sashil.recording.rerun_log.LiveTap` for a loop run (``run_session(live=...)``),
    or None without a rerun option. The feasible torque band is added for the Bouc-Wen model."""
    if not wants_rerun(args):
        return None
    from sashil.recording.rerun_log import LiveTap

    model = config.get("model", {})
    band = None
    if model.get("name") == "bouc-wen" and "z_hat" in columns and "theta_dot_rad_s" in columns:
        band = (model["params"], float(config["rig"]["current_max_a"]))
    extra = ("lateness_us",) + (("band_lo_nm", "band_hi_nm") if band is not None else ())
    return LiveTap(open_rerun(args, tuple(columns) + extra, name, folder), band=band)


def formats(args: argparse.Namespace) -> tuple[str, ...]:
    """The ``--format`` values, each once (checked by :func:`resolve_config`)."""
    return tuple(dict.fromkeys(getattr(args, "format", None) or ()))


def add_verbosity_options(parser: argparse.ArgumentParser) -> None:
    """``--quiet`` / ``--verbose`` (every verb; set up by :func:`setup_logging`)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors, no progress")
    group.add_argument("-v", "--verbose", action="store_true", help="debug messages too")


def setup_logging(args: argparse.Namespace) -> int:
    """Configure the ``sashil`` logger from ``--quiet``/``--verbose``; returns the level."""
    level = (
        logging.WARNING
        if getattr(args, "quiet", False)
        else logging.DEBUG
        if getattr(args, "verbose", False)
        else logging.INFO
    )
    logger = logging.getLogger("sashil")
    logger.setLevel(level)
    for existing in logger.handlers:
        if getattr(existing, "_sashil", False) and isinstance(existing, logging.StreamHandler):
            existing.stream = sys.stderr  # main() again in one process: the stderr of now, not of the first call
    if not any(getattr(h, "_sashil", False) for h in logger.handlers):
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(message)s"))
        handler._sashil = True  # type: ignore[attr-defined]
        logger.addHandler(handler)
        logger.propagate = False
    return level


def say(args: argparse.Namespace, message: str) -> None:
    """A progress/status line on stderr unless ``--quiet``."""
    if not getattr(args, "quiet", False):
        print(message, file=sys.stderr, flush=True)


def resolve_config(args: argparse.Namespace, models: Sequence[str] = RIG_MODELS) -> Config:
    """The config the verb runs with: file (or defaults), then --params, then each --set, then
    --driver/--port. Every step is validated before anything is opened or written; a model the
    verb cannot run (not in ``models``) is refused."""
    config = load_config(getattr(args, "config", None))
    if getattr(args, "params", None):
        config = apply_params(config, args.params)
        check_controller(config, args.params)  # the law's checks against the new model
    overrides = list(getattr(args, "overrides", None) or ())
    law = getattr(args, "controller", None)
    if law:  # --controller LAW is controller.law=LAW, applied before the law's --set keys
        if getattr(args, "current", None) is not None and law != "passive":
            raise ConfigError(f"--current: only for --controller passive (got --controller {law})")
        config = apply_overrides(
            config, [f"controller.law={law}", *overrides], "--set" if overrides else "--controller"
        )
    else:
        config = apply_overrides(config, overrides)
    check_runnable_model(config, args, models)
    if getattr(args, "params", None) and _mismatched(config.get("mismatch") or {}):
        logging.getLogger("sashil").warning(
            "--params %s: the config's mismatch: section is applied on top of these parameters "
            "(the simulated plant differs from them)",
            args.params,
        )
    if getattr(args, "driver", None):
        config["driver"]["name"] = args.driver
    if getattr(args, "port", None):
        config["driver"]["port"] = args.port
        if not declared_capabilities(config).link:
            raise ConfigError(
                f"--port {args.port}: the driver is {config['driver']['name']}, which has no port; "
                "add --driver serial or --driver can"
            )
    check_formats(getattr(args, "format", None), config["driver"]["name"])  # before anything runs
    return config


def check_runnable_model(config: Config, args: argparse.Namespace, models: Sequence[str]) -> None:
    """ConfigError, one line naming where the model came from (``--set model.name``, ``--params``
    or ``--config``), when the verb cannot run the config's model."""
    name = config["model"]["name"]
    if name in models:
        return
    sets = [item for item in getattr(args, "overrides", None) or () if item.partition("=")[0].strip() == "model.name"]
    if sets:
        where = f"--set {sets[-1]}"
    elif getattr(args, "params", None):
        where = f"--params {args.params}"
    else:
        where = f"--config {getattr(args, 'config', None)}"
    verb = f"sashil {args.verb}" if getattr(args, "verb", None) else "this verb"
    raise ConfigError(
        f"{where}: a {name} model; {verb} runs {' or '.join(models)} models only (the rig plant and the "
        f"controller's observer are Bouc-Wen); sashil simulate runs {', '.join(MODEL_PARAMS)}"
    )


def _mismatched(section: dict[str, Any]) -> bool:
    """Whether a ``mismatch`` section changes the simulated plant at all."""
    return bool(
        section.get("fraction")
        or any(section.get("params", {}).values())
        or section.get("coil_tau")
        or any(section.get(key) is not None for key in ("encoder_counts_per_rev", "angle_noise_rad", "current_noise_a"))
    )


def select_law(config: Config, name: str | None) -> str:
    """``--controller NAME``: the law the run uses, written into ``config['controller']`` (the
    previous law's parameters dropped) and checked with its parameters; returns the law's name."""
    section = config["controller"]
    if name is not None and name != section["law"]:
        from sashil.control.law_config import switch_law

        switch_law(section, name)
        check_controller(config, "--controller")
    return str(section["law"])


def law_help() -> str:
    """The registered law names for ``--controller``'s help (``sashil laws`` lists their parameters)."""
    from sashil.control.law_registry import law_names

    try:
        names = ", ".join(law_names())
    except ConfigError as err:
        return f"(the laws cannot be listed: {err})"
    return f"{names}; or package.module:Class or path/file.py:Class (sashil laws lists their parameters)"


def option_or_config(value: Any, option: str, config: Config, key: str) -> tuple[Any, str]:
    """``(value, option)`` when the option was given, else the config's dotted ``key`` and its name:
    the value a verb runs with, and what to name in a message about it."""
    if value is not None:
        return value, option
    section, name = key.split(".")
    return config[section][name], key


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
