"""Options shared by the verbs, and turning them into the library's inputs.

Everything here at module level is argparse and the standard library only, so that ``sashil VERB
--help`` loads no numerics: :func:`config_source` and :func:`outputs_of` turn parsed options into
the :class:`~sashil.engine.resolve.ConfigSource` and :class:`~sashil.recording.outputs.Outputs` the
experiments take; the config itself is resolved by :func:`sashil.engine.resolve.resolve`.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.errors import ConfigError
from sashil.recording.formats import FORMATS
from sashil.recording.formats import HELP as FORMAT_HELP
from sashil.recording.outputs import IN_RUN_FOLDER, Outputs

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig
    from sashil.engine.resolve import ConfigSource, Option

Config = dict[str, Any]


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """``--config``, ``--params`` and ``--set`` (every verb that reads a config)."""
    parser.add_argument("--config", metavar="FILE", help="YAML config (default: simulated rig, seed parameters)")
    parser.add_argument("--params", metavar="FILE", help="parameter file from `sashil identify` (replaces the model)")
    add_set_option(parser)


def add_set_option(parser: argparse.ArgumentParser) -> None:
    """``--set section.key=value`` (repeatable), applied by :func:`sashil.engine.resolve.resolve`."""
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
    parser.add_argument(
        "--driver", metavar="NAME", help="override driver.name: sim, serial, can, rtdac, or an installed backend's name"
    )
    parser.add_argument(
        "--port", metavar="PORT", help="pyserial URL/device path, or CAN channel (override driver.port)"
    )


def add_output_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", metavar="DIR", help="run folder (default runs/<UTC timestamp>-<verb>/)")


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


def outputs_of(args: argparse.Namespace) -> Outputs:
    """The :class:`~sashil.recording.outputs.Outputs` the options ask for (folder, formats, live view)."""
    return Outputs(
        out=getattr(args, "out", None),
        formats=formats(args),
        rerun_viewer=bool(getattr(args, "rerun", False)),
        rerun_bind=getattr(args, "rerun_bind", "127.0.0.1"),
        rerun_connect=getattr(args, "rerun_connect", None),
        rerun_save=getattr(args, "rerun_save", None),
    )


def formats(args: argparse.Namespace) -> tuple[str, ...]:
    """The ``--format`` values, each once (checked against the driver by :meth:`Outputs.check`)."""
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


def config_source(args: argparse.Namespace, options: Sequence[Option] = ()) -> ConfigSource:
    """The :class:`~sashil.engine.resolve.ConfigSource` of the common options (``--config``,
    ``--params``, ``--controller``, ``--set``, ``--driver``, ``--port``) and the verb's own ``options``."""
    from sashil.engine.resolve import ConfigSource

    return ConfigSource(
        config=getattr(args, "config", None),
        params=getattr(args, "params", None),
        controller=getattr(args, "controller", None) or None,
        sets=tuple(getattr(args, "overrides", None) or ()),
        options=tuple(options),
        driver=getattr(args, "driver", None),
        port=getattr(args, "port", None),
    )


def resolve_config(args: argparse.Namespace, models: Sequence[str] | None = None) -> RunConfig:
    """The config of the common options, resolved and checked (:func:`~sashil.engine.resolve.resolve`,
    read-only), and the ``--format`` values checked against its driver: for the verbs whose own
    options set no config key (``doctor``, ``emulate``)."""
    from sashil.config.parts import RigParts
    from sashil.engine.resolve import resolve

    if getattr(args, "current", None) is not None and getattr(args, "controller", None) not in (None, "passive"):
        raise ConfigError(f"--current: only for --controller passive (got --controller {args.controller})")
    config = resolve(config_source(args), getattr(args, "verb", None), models)
    outputs_of(args).check(RigParts.backend_of(config))
    return config


def law_help() -> str:
    """``--controller``'s help: what names a law (the installed ones are listed by ``sashil laws``, so
    that ``--help`` scans no installed distributions)."""
    return "a registered law's name (sashil laws lists them with their parameters), or package.module:Class or path/file.py:Class"


def positive_seconds(option: str, value: float) -> float:
    """Check a duration argument: a finite number > 0."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ConfigError(f"{option}: expected a duration in seconds > 0, got {value:g}")
    return float(value)
