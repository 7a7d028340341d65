"""Experiments from a script or notebook: ``sashil.run(...)`` and ``sashil.drop_test(...)``.

Each call resolves its config (:func:`sashil.engine.resolve.resolve`) and calls the experiment's
library function (:mod:`sashil.lab`), as the command line does (one runner, the safety supervisor,
the same run folder), and returns the folder as the :class:`~sashil.api.Run` that
:func:`sashil.load_run` gives::

    run = sashil.run("skyhook", duration_s=5, set={"controller.c_sky": 2.0})
    run.data["current_cmd_a"], run.summary["timing"]["compute_us"]["p99"]

Bad input raises :class:`~sashil.errors.ConfigError` (nothing written, nothing energised); a run
that fails after it started raises the error that ended it, with the folder kept on disk.
"""

from __future__ import annotations

import inspect
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from sashil.api import Run
from sashil.engine.events import Listener, printer
from sashil.engine.resolve import ConfigSource, Option, resolve
from sashil.engine.sashil_run import closed_loop
from sashil.errors import ConfigError
from sashil.lab._drop_test import drop_test as run_drops
from sashil.plugins import check_not_importing
from sashil.recording.outputs import Outputs

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


def _source(
    config: str | Path | Mapping[str, Any] | None,
    params: str | Path | None,
    sets: Mapping[str, Any] | Iterable[str],
    controller: str | type | None,
    driver: str | None,
    port: str | None,
    options: Sequence[Option],
) -> ConfigSource:
    return ConfigSource(
        config=config,
        params=params,
        controller=law_spec(controller) if controller is not None else None,
        sets=tuple(set_items(sets)),
        options=tuple(options),
        driver=driver,
        port=port,
    )


def _listener(quiet: bool, on_event: Listener | None) -> Listener:
    """The caller's listener, else printed lines: all of them, or with ``quiet`` only the operator's
    prompts and warnings."""
    if on_event is not None:
        return on_event
    show = printer(quiet=True)
    if not quiet:
        return printer(quiet=False)
    return lambda event: show(event) if event.kind in ("prompt", "warning") else None


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
    on_event: Listener | None = None,
) -> Run:
    """``sashil run`` from Python: ``controller`` (a law name, ``module:Class``, ``file.py:Class`` or a
    Law class), ``set`` as ``{"controller.c_sky": 2.0}`` or ``["controller.c_sky=2"]``. ``on_event``
    receives the run's :class:`~sashil.engine.events.Event` messages (default: printed unless ``quiet``)."""
    check_not_importing("sashil.run")
    if current_a is not None:
        if controller not in (None, "passive"):
            raise ConfigError(f"current_a: only for the passive law (got controller={controller!r})")
        controller = "passive"
    options = (
        Option("duration_s", "run.duration_s", float(duration_s)),
        Option("rate_hz", "loop.rate_hz", None if rate_hz is None else float(rate_hz)),
        Option("current_a", "controller.current_a", None if current_a is None else float(current_a)),
        Option("road", "run.road", road),
    )
    resolved = resolve(_source(config, params, set, controller, driver, port, options), "run")
    return closed_loop(resolved, Outputs(out=out), _listener(quiet, on_event), progress=not quiet)


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
    on_event: Listener | None = None,
) -> Run:
    """``sashil drop-test`` from Python: one sub-run per current (``run.runs``); ``controller`` takes
    over at the release. ``on_event`` receives the operator's prompts and each drop's result."""
    check_not_importing("sashil.drop_test")
    options = (
        Option("theta0_deg", "drop_test.theta0_deg", float(theta0_deg)),
        Option("currents_a", "drop_test.currents_a", [float(current) for current in currents_a]),
        Option("duration_s", "drop_test.duration_s", float(duration_s)),
    )
    resolved = resolve(_source(config, params, set, controller, driver, port, options), "drop-test")
    return run_drops(resolved, Outputs(out=out), _listener(quiet, on_event))
