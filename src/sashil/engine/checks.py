"""What each verb checks of its own keys beyond the schema, before anything runs.

:func:`sashil.engine.resolve.resolve` calls a verb's check (``VERB_CHECKS``) with the config it has
just validated and ``named(key)``, the option that set a key (``--road``, ``--current``) or the key
itself, so each refusal is one line naming what the user typed. These are cheap: nothing is opened,
built or written.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.errors import ConfigError
from sashil.plans.drop import check_theta0

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = [
    "THETA0_LIMIT_DEG",
    "check_compare",
    "check_drops",
    "check_road_ahead",
    "check_run",
    "check_simulate",
    "check_sweep",
    "input_file",
]

#: the largest hold angle a drop test accepts [deg]
THETA0_LIMIT_DEG = 30.0

Named = Callable[[str], str]


def check_drops(config: RunConfig, named: Named) -> None:
    """The ``drop_test`` keys a run can honour: a hold angle within ±THETA0_LIMIT_DEG and far enough
    from 0 for the release to be seen, and each current once, within [0, rig.current_max_a]."""
    section = config["drop_test"]
    theta0 = section["theta0_deg"]
    if not (math.isfinite(theta0) and abs(theta0) <= THETA0_LIMIT_DEG):
        raise ConfigError(
            f"{named('drop_test.theta0_deg')}: expected an angle within ±{THETA0_LIMIT_DEG:g} deg, got {theta0:g}"
        )
    check_theta0(section["release_threshold_deg"], theta0, named("drop_test.theta0_deg"))
    currents = list(section["currents_a"])
    where = named("drop_test.currents_a")
    if not currents:
        raise ConfigError(f"{where}: expected at least one current, got []")
    i_max = config["rig"]["current_max_a"]
    for value in currents:
        if not (math.isfinite(value) and 0.0 <= value <= i_max):
            raise ConfigError(f"{where}: expected a current in [0, {i_max:g}] A (rig.current_max_a), got {value:g}")
    if len(set(currents)) != len(currents):
        raise ConfigError(f"{where}: each current once, got {currents}")


def _road_parses(config: RunConfig, text: str | None, key: str, named: Named) -> None:
    """ConfigError naming ``named(key)`` when the road ``text`` does not parse."""
    from sashil.roads.option import RoadParts, parse_road  # numpy and the road profiles: only for a road

    try:
        parse_road(text, RoadParts.read(config))
    except ConfigError as err:
        where = named(key)
        raise ConfigError(str(err).replace("--road", where, 1) if where != "--road" else str(err)) from None


def check_run(config: RunConfig, named: Named) -> None:
    """The ``run`` keys a run can honour: the road parses."""
    _road_parses(config, config["run"]["road"], "run.road", named)


def check_compare(config: RunConfig, named: Named) -> None:
    """The ``compare`` keys a run can honour: the road parses, and each law runs longer than the
    start its metrics leave out (``compare.settle_s``)."""
    section = config["compare"]
    _road_parses(config, section["road"], "compare.road", named)
    duration, settle = float(section["duration_s"]), float(section["settle_s"])
    if duration <= settle:
        raise ConfigError(
            f"{named('compare.duration_s')}: expected more than compare.settle_s = {settle:g} s (the start of each "
            f"law's run the metrics leave out), got {duration:g}"
        )


def check_sweep(config: RunConfig, named: Named) -> None:
    """The ``sweep`` keys a run can honour: each frequency in (0, loop.rate_hz / 10], the stop at or
    above the start, and above it for a stepped sine."""
    section = config["sweep"]
    f_start, f_stop = section["f_start_hz"], section["f_stop_hz"]
    start_name, stop_name = named("sweep.f_start_hz"), named("sweep.f_stop_hz")
    top = config["loop"]["rate_hz"] / 10
    for option, value in ((start_name, f_start), (stop_name, f_stop)):
        if not (math.isfinite(value) and 0.0 < value <= top):
            raise ConfigError(f"{option}: expected a frequency in (0, {top:g}] Hz, got {value:g}")
    if f_stop < f_start:
        raise ConfigError(
            f"{stop_name}: expected a frequency at or above {start_name} ({f_start:g} Hz), got {f_stop:g}"
        )
    if section["stepped"] and f_stop == f_start:
        raise ConfigError(
            f"{stop_name}: a stepped sine needs a frequency above {start_name} ({f_start:g} Hz), got {f_stop:g}"
        )


def input_file(value: str, where: str = "--input") -> Path:
    """The data file of ``simulate.input`` (``where``: the option or key that gave it): the file
    itself, or a run folder's ``data.csv``; a folder of several runs is refused, naming them."""
    path = Path(value)
    if not path.is_dir():
        return path
    if (path / "data.csv").is_file():
        return path / "data.csv"
    runs = sorted(found.parent.name for found in path.glob("*/data.csv"))
    if runs:
        example = f"--input {path / runs[0]}" if where == "--input" else f"{where}: {path / runs[0]}"
        raise ConfigError(
            f"{where} {path}: a folder of {len(runs)} runs ({', '.join(runs[:4])}{', ...' if len(runs) > 4 else ''}); "
            f"simulate takes one, e.g. {example}"
        )
    raise ConfigError(f"{where} {path}: a folder without data.csv (expected a data.csv or a run folder)")


def check_simulate(config: RunConfig, named: Named) -> None:
    """The ``simulate`` keys a run can honour: an input that is a data file or one run's folder."""
    value = config["simulate"]["input"]
    if value:
        input_file(value, named("simulate.input"))


#: the verbs whose plan commands a road, so the road ahead is known, and the key that names the road
#: (None: the plan always commands one, a sweep's chirp or sine)
ROAD_PLANS: dict[str, str | None] = {"run": "run.road", "compare": "compare.road", "sweep": None}


def _road_of(config: RunConfig, key: str) -> str:
    """The road a verb's key names (``run.road``, ``compare.road``), ``none`` when unset."""
    road = config["run"]["road"] if key == "run.road" else config["compare"]["road"]
    return str(road or "none").strip()


#: the verbs whose plans drive the road motor, and the key of their road (None: the verb's own roads)
ROAD_DRIVERS: dict[str, str | None] = {"run": "run.road", "compare": "compare.road", "sweep": None, "calibrate": None}


def check_road_reverses(config: Any, verb: str | None, reverses: bool, named: Named) -> None:
    """Refuse, before anything is energised, a plan that drives the road on wiring that turns the road
    motor one way only: every road sashil plays (a sine, a chirp, ISO 8608, a bump) reverses it, and a
    one-way output cannot brake."""
    if reverses or verb not in ROAD_DRIVERS:
        return
    key = ROAD_DRIVERS[verb]
    if key is not None and str(config[key.split(".")[0]]["road"] or "none").strip() == "none":
        return
    road = f"{named(key)} {config[key.split('.')[0]]['road']}: " if key is not None else f"sashil {verb}: "
    raise ConfigError(
        f"{road}the road motor's wiring drives it one way only (rtdac.road_output pwm with no "
        "rtdac.road_direction_bit), and this road reverses it: set rtdac.road_direction_bit to the motor's "
        "direction output, or drive the road from a D/A (rtdac.road_output: da)"
    )


def check_road_ahead(config: RunConfig, verb: str | None, named: Named, spec: str, reads_ahead: bool) -> None:
    """Refuse a law that reads the road ahead (``spec``, the law as given; ``reads_ahead``: its
    class's ``Law.reads_road_ahead``) under a plan that commands no road: a drop test, a replay, a
    calibration, ``--road none``."""
    if not reads_ahead:
        return
    if verb in ROAD_PLANS:
        key = ROAD_PLANS[verb]
        if key is None:
            return
        if _road_of(config, key) != "none":
            return
        raise ConfigError(
            f"{named(key)} none: law {spec!r} reads the road ahead, which only a plan that commands a road "
            "has: give a road (--road iso8608:C)"
        )
    raise ConfigError(
        f"controller.law {spec}: law {spec!r} reads the road ahead, and {verb or 'this verb'} commands no road "
        "(run it with sashil run --road, sashil compare or sashil sweep)"
    )
