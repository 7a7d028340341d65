"""Experiments from a script or notebook: ``sashil.run(...)`` and ``sashil.drop_test(...)``.

Each call runs the same verb as the command line (``sashil run`` / ``sashil drop-test``: one
runner, the safety supervisor, the same run folder) and returns the folder as the
:class:`~sashil.api.Run` that :func:`sashil.load_run` gives::

    run = sashil.run("skyhook", duration_s=5, set={"controller.c_sky": 2.0})
    run.data["current_cmd_a"], run.summary["timing"]["compute_us"]["p99"]

Bad input raises :class:`~sashil.errors.ConfigError` (nothing written, nothing energised); a run
that fails after it started raises the error that ended it, with the folder kept on disk.
"""

from __future__ import annotations

import inspect
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from sashil.api import Run, load_run
from sashil.errors import ConfigError, SashilError

__all__ = ["drop_test", "run"]


def law_spec(law: str | type) -> str:
    """``--controller``'s text for a law: a name or ``module:Class`` as given, or a Law class
    (as ``module:Class``, or ``file.py:Class`` for a class defined in a script run as __main__)."""
    if isinstance(law, str):
        return law
    if not isinstance(law, type):
        raise ConfigError(f"controller: expected a law name or a Law class, got {law!r}")
    if law.__module__ != "__main__":
        return f"{law.__module__}:{law.__qualname__}"
    try:
        return f"{inspect.getfile(law)}:{law.__qualname__}"
    except (TypeError, OSError):
        raise ConfigError(
            f"controller: {law.__qualname__} is defined in a notebook or console, which a run cannot re-import; "
            "put it in a .py file and pass 'path/file.py:Class'"
        ) from None


def set_items(values: Mapping[str, Any] | Iterable[str]) -> list[str]:
    """``--set`` texts from ``{"controller.c_sky": 2.0}`` (values as YAML) or ``["controller.c_sky=2"]``."""
    if isinstance(values, Mapping):
        return [
            f"{key}={yaml.safe_dump(value, default_flow_style=True).split(chr(10))[0]}" for key, value in values.items()
        ]
    return [str(item) for item in values]


def _common(
    argv: list[str],
    config: str | Path | Mapping[str, Any] | None,
    params: str | Path | None,
    overrides: list[str],
    driver: str | None,
    port: str | None,
    out: str | Path | None,
    folder: Path,
) -> list[str]:
    if isinstance(config, Mapping):
        path = folder / "config.yaml"
        path.write_text(yaml.safe_dump(dict(config), sort_keys=False))
        config = path
    if config is not None:
        argv += ["--config", str(config)]
    if params is not None:
        argv += ["--params", str(params)]
    for item in overrides:
        argv += ["--set", item]
    if driver is not None:
        argv += ["--driver", driver]
    if port is not None:
        argv += ["--port", port]
    if out is not None:
        argv += ["--out", str(out)]
    return argv


def _run_verb(verb: str, argv: Sequence[str]) -> Run:
    from sashil.cli import build_parser
    from sashil.recording.run_folder import CREATED, discard_unused

    args = build_parser().parse_args([verb, *argv])
    CREATED.clear()
    try:
        code = int(args._module.run(args) or 0)
    except SashilError as err:
        if isinstance(err, ConfigError):
            discard_unused()
        raise
    folders = [path for path, _ in CREATED]
    if not folders:
        raise SashilError(f"sashil {verb}: no run folder was written (exit code {code})")
    return load_run(folders[0])


def run(
    controller: str | type | None = None,
    *,
    duration_s: float = 10.0,
    current_a: float | None = None,
    road: str | None = None,
    rate_hz: float | None = None,
    config: str | Path | Mapping[str, Any] | None = None,
    params: str | Path | None = None,
    set: Mapping[str, Any] | Iterable[str] = (),
    driver: str | None = None,
    port: str | None = None,
    out: str | Path | None = None,
    quiet: bool = True,
) -> Run:
    """``sashil run`` from Python: ``controller`` (a law name, ``module:Class``, ``file.py:Class`` or a
    Law class), ``set`` as ``{"controller.c_sky": 2.0}`` or ``["controller.c_sky=2"]``."""
    with tempfile.TemporaryDirectory() as tmp:
        argv = _common(
            ["--duration", repr(float(duration_s))], config, params, set_items(set), driver, port, out, Path(tmp)
        )
        if controller is not None:
            argv += ["--controller", law_spec(controller)]
        if current_a is not None:
            argv += ["--current", repr(float(current_a))]
        if road is not None:
            argv += ["--road", road]
        if rate_hz is not None:
            argv += ["--rate", repr(float(rate_hz))]
        if quiet:
            argv.append("-q")
        return _run_verb("run", argv)


def drop_test(
    currents_a: Sequence[float] = (0.0,),
    *,
    theta0_deg: float = -5.0,
    duration_s: float = 10.0,
    controller: str | type | None = None,
    config: str | Path | Mapping[str, Any] | None = None,
    params: str | Path | None = None,
    set: Mapping[str, Any] | Iterable[str] = (),
    driver: str | None = None,
    port: str | None = None,
    out: str | Path | None = None,
    quiet: bool = True,
) -> Run:
    """``sashil drop-test`` from Python: one sub-run per current (``run.runs``); ``controller`` takes
    over at the release."""
    overrides = set_items(set)
    if controller is not None:
        overrides.insert(0, f"controller.law={law_spec(controller)}")
    with tempfile.TemporaryDirectory() as tmp:
        argv = ["--theta0-deg", repr(float(theta0_deg)), "--duration", repr(float(duration_s))]
        for current in currents_a:
            argv += ["--current", repr(float(current))]
        argv = _common(argv, config, params, overrides, driver, port, out, Path(tmp))
        if quiet:
            argv.append("-q")
        return _run_verb("drop-test", argv)
