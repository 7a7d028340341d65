"""The contract check of a law class: what a lab asserts before its law meets the bench.

:func:`check_law` returns a :class:`ContractReport` whose ``faults`` are one line each, naming the
law and the fault (``soft-skyhook: raised ZeroDivisionError: float division by zero at t = 0.0000 s``):

* **declared**: the class is a :class:`~sashil.control.Law` with a ``name`` and exactly one output
  (``torque`` or ``current``); every parameter is a :class:`~sashil.control.Param` with a ``doc``,
  and a numeric one has a bound (``low`` or ``high``); the law builds with its defaults and the
  parameters given, through the config's own checks;
* **finite**: its output is a finite number at the edge states a run can reach (at rest at t = 0,
  fast in either direction, an empty feasible band) and in every cycle of a run on the simulated rig;
  a run whose law raises or returns NaN or an infinity ends at 0 A (the controller's check, the
  same as on the bench), and the check confirms the last command was 0 A;
* **deterministic**: a second run under the same noise seed commands the same current, row for row
  (a law that keeps state in its class, or draws from an unseeded random generator, does not);
* **within budget**: the law's own compute per cycle (each call of its output, on the clock
  ``timer`` reads, integer ns) has its 99th percentile within ``budget_us``;
* **in range**: a current law's output stays in [0, rig.current_max_a]; a torque law's T* stays
  within ``torque_reach`` times the largest torque the damper can give in the run,
  α(i_max)·z_bound + c(i_max)·max|θ̇| (seed 001 eqs. 9, 11-12; z_bound the Bouc-Wen bound of |z|):
  beyond that the law's scale or units are wrong.

The runs go through :func:`sashil.testing.run_law` with the law wrapped in a subclass that times
each call of its output; the subclass keeps the law's module and name, so the law registry treats it
as the law itself.
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from sashil.api import Run
from sashil.control.law_api import Law, LawState
from sashil.control.law_config import build_law
from sashil.control.law_registry import find_law
from sashil.engine import assemble
from sashil.errors import ConfigError
from sashil.models.hysteresis import BoucWenParams
from sashil.plugins import check_not_importing
from sashil.testing.rig import DEFAULT_ROAD, SimRig, run_law

__all__ = ["ContractReport", "assert_law_contract", "check_law"]

#: the numeric parameter kinds, which need a bound
_NUMERIC = ("float", "float?", "int", "int?")
#: the timed subclasses made so far (each a distinct attribute of this module, for its spec)
_serial = itertools.count(1)


@dataclass(frozen=True)
class ContractReport:
    """What :func:`check_law` found: ``faults`` (one line each, naming the law), the law's compute
    per cycle in µs (``p50``, ``p99``, ``max``) and the run it measured (None when none ran)."""

    law: str
    faults: tuple[str, ...] = ()
    compute_us: Mapping[str, float] = field(default_factory=dict)
    run: Run | None = None

    @property
    def ok(self) -> bool:
        return not self.faults

    def __str__(self) -> str:
        if self.ok:
            return f"{self.law}: meets the contract (compute p99 {self.compute_us.get('p99', math.nan):.1f} µs)"
        return "\n".join(self.faults)


def check_law(
    law: type,
    *,
    params: Mapping[str, Any] | None = None,
    rig: SimRig | None = None,
    road: str = DEFAULT_ROAD,
    duration_s: float = 3.0,
    budget_us: float = 100.0,
    torque_reach: float = 10.0,
    timer: Callable[[], int] = time.perf_counter_ns,
) -> ContractReport:
    """Check ``law`` (a Law class) with ``params`` against the contract of the module docstring, on
    ``rig`` (the default :class:`SimRig` when None) on ``road`` for ``duration_s`` per run (two runs);
    the first second of each run is left out of its metrics. ``timer``: the clock the compute budget
    is measured on (integer ns; a test may pass one the law advances)."""
    check_not_importing("sashil.testing.check_law")  # a script's law file imported for its class runs nothing
    name = str(getattr(law, "name", "") or getattr(law, "__qualname__", repr(law)))
    faults = _declaration_faults(law)
    if faults:
        return ContractReport(name, tuple(f"{name}: {fault}" for fault in faults))
    rig = rig if rig is not None else SimRig()
    rig = replace(rig, sets={"compare.settle_s": min(1.0, duration_s / 2), **dict(rig.sets)})
    params = dict(params or {})
    try:
        stage = assemble(rig.config(law, road=road, duration_s=duration_s, params=params)).stage
        instance = build_law(find_law(stage.law), stage, params)
    except ConfigError as err:
        return ContractReport(name, (f"{name}: parameters: {err}",))
    except Exception as err:  # the constructor or parameters_changed() of the law itself
        return ContractReport(name, (f"{name}: cannot be built with {params or 'its defaults'}: {_first_line(err)}",))
    i_max = stage.current_max_a
    faults = _probe_faults(instance, i_max)
    times: list[int] = []
    spec = _timed_spec(law, timer, times)
    first = run_law(spec, road=road, duration_s=duration_s, params=params, rig=rig)
    compute = _quantiles_us(times)
    found = _run_faults(first, instance, i_max, BoucWenParams.from_mapping(stage.model.params), torque_reach)
    if found and found[0].startswith("failed at "):  # one fault, one line: the run's, which says when
        what = found[0].partition(": ")[2].removesuffix(" (the run ended at 0 A)")
        faults = [fault for fault in faults if not fault.startswith(what)]
    faults += found
    if first.summary.get("exit_status") == "ok":
        second = run_law(spec, road=road, duration_s=duration_s, params=params, rig=rig)
        faults += _determinism_faults(first, second, rig.seed)
    if compute and compute["p99"] > budget_us:
        faults.append(
            f"compute per cycle p99 {compute['p99']:.1f} µs (max {compute['max']:.1f} µs) is over the budget of "
            f"{budget_us:g} µs"
        )
    return ContractReport(name, tuple(f"{name}: {fault}" for fault in faults), compute, first)


def assert_law_contract(law: type, **kwargs: Any) -> ContractReport:
    """:func:`check_law`, raising AssertionError with one line per fault; the report when none."""
    report = check_law(law, **kwargs)
    if not report.ok:
        raise AssertionError("\n" + str(report))
    return report


def _declaration_faults(law: Any) -> list[str]:
    if not (isinstance(law, type) and issubclass(law, Law)):
        return [f"not a subclass of sashil.control.Law ({law!r})"]
    faults = []
    if not law.name:
        faults.append("has no name (the class attribute name that controller.law selects it by)")
    if not law.output_kind():
        faults.append("must implement exactly one of torque(state) and current(state)")
    for key, param in law.params().items():
        if not param.doc:
            faults.append(f"parameter {key} has no doc (what it means, for `sashil laws` and the config reference)")
        if param.field.kind in _NUMERIC and param.low is None and param.high is None:
            faults.append(f"parameter {key} has no bound (low= or high=): any number would be accepted")
    return faults


def _edge_states(i_max: float) -> list[tuple[str, LawState]]:
    """States a run can reach that a law's arithmetic may not expect."""
    states = []
    for label, values in (
        ("at rest at t = 0 s", {}),
        ("moving fast upward (20 rad/s)", {"theta_dot_rad_s": 20.0, "body_dot_rad_s": 20.0, "band_hi_nm": 44.0}),
        ("moving fast downward (-20 rad/s)", {"theta_dot_rad_s": -20.0, "road_dot_rad_s": 20.0, "band_lo_nm": -44.0}),
        ("with an empty feasible band", {"time_s": 1.0, "theta_rad": 0.01, "current_a": i_max}),
    ):
        state = LawState()
        for key, value in values.items():
            setattr(state, key, value)
        states.append((label, state))
    return states


def _probe_faults(law: Law, i_max: float) -> list[str]:
    output = law.current if law.output_kind() == "current" else law.torque
    faults = []
    for label, state in _edge_states(i_max):
        law.reset()
        try:
            value = output(state)
        except Exception as err:
            faults.append(f"raised {_first_line(err)} {label}")
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            faults.append(f"returned {value!r} of type {type(value).__name__} {label} (expected a number)")
        elif not math.isfinite(value):
            faults.append(f"returned {value!r} {label} (expected a finite number)")
        elif law.output_kind() == "current" and not 0.0 <= value <= i_max:
            faults.append(f"returned {value:g} A {label}, outside [0, {i_max:g}] A")
    return faults


def _run_faults(run: Run, law: Law, i_max: float, model: BoucWenParams, reach: float) -> list[str]:
    faults = []
    summary, data = run.summary, run.data
    if summary.get("exit_status") != "ok":
        error = str(summary.get("error") or summary.get("status") or summary.get("exit_status"))
        faults.append(_law_error_text(error))
    current = np.asarray(data.get("current_cmd_a", ()), dtype=float)
    if current.size and current[-1] != 0.0:
        faults.append(f"the run did not end at 0 A (last command {current[-1]:g} A)")
    if law.output_kind() == "current":
        asked = np.asarray(data.get("current_law_a", ()), dtype=float)
        asked = asked[np.isfinite(asked)]
        outside = asked[(asked < 0.0) | (asked > i_max)]
        if outside.size:
            faults.append(
                f"asked for currents outside [0, {i_max:g}] A in {outside.size} cycles "
                f"(from {asked.min():g} to {asked.max():g} A; the safety clamp cut them)"
            )
    else:
        torque = np.asarray(data.get("torque_cmd_nm", ()), dtype=float)
        torque = torque[np.isfinite(torque)]
        rate = np.asarray(data.get("theta_dot_rad_s", ()), dtype=float)
        rate = rate[np.isfinite(rate)]
        if torque.size and rate.size:
            most = model.hysteretic_gain(i_max) * model.z_bound + model.damping(i_max) * float(np.max(np.abs(rate)))
            worst = float(np.max(np.abs(torque)))
            if worst > reach * most:
                faults.append(
                    f"asked for {worst:.4g} N m, more than {reach:g} times the most the damper can give in this run "
                    f"({most:.4g} N m): a scale or unit error"
                )
    return faults


def _determinism_faults(first: Run, second: Run, seed: int) -> list[str]:
    for column in ("current_cmd_a", "torque_cmd_nm", "current_law_a"):
        a = np.asarray(first.data.get(column, ()), dtype=float)
        b = np.asarray(second.data.get(column, ()), dtype=float)
        if a.shape != b.shape:
            return [f"not deterministic under seed {seed}: {column} has {a.size} rows, then {b.size}"]
        differ = np.flatnonzero(~((a == b) | (np.isnan(a) & np.isnan(b))))
        if differ.size:
            t = float(first.data["time_s"][differ[0]])
            return [
                f"not deterministic under seed {seed}: {column} differs between two runs from t = {t:.3f} s "
                f"({differ.size} rows; state kept in the class, or an unseeded random generator?)"
            ]
    if second.summary.get("exit_status") != "ok":
        return [f"not deterministic under seed {seed}: the second run ended {second.summary.get('exit_status')}"]
    return []


def _timed_spec(law: type[Law], timer: Callable[[], int], sink: list[int]) -> str:
    """The spec of a subclass of ``law`` that appends the ns each call of its output takes (on
    ``timer``) to ``sink``. It keeps the law's module, qualified name and ``name``, so the registry
    takes it for the law (an installed law's entry point included)."""
    method = "current" if law.output_kind() == "current" else "torque"
    inner = getattr(law, method)

    def timed(self: Any, state: LawState) -> Any:
        start = timer()
        try:
            return inner(self, state)
        finally:
            sink.append(timer() - start)

    attribute = f"_Timed{next(_serial)}"
    timed_law = type(law.__name__, (law,), {method: timed, "__module__": law.__module__})
    timed_law.__qualname__ = law.__qualname__
    setattr(sys.modules[__name__], attribute, timed_law)
    return f"{__name__}:{attribute}"


def _quantiles_us(times_ns: list[int]) -> dict[str, float]:
    if not times_ns:
        return {}
    values = np.asarray(times_ns, dtype=float) * 1e-3
    return {
        "p50": float(np.percentile(values, 50)),
        "p99": float(np.percentile(values, 99)),
        "max": float(values.max()),
    }


def _law_error_text(error: str) -> str:
    """The controller's LawError text without the law's name and origin, which the fault line starts with."""
    _, found, rest = error.partition(" failed at ")
    return f"failed at {rest} (the run ended at 0 A)" if found else error


def _first_line(err: BaseException) -> str:
    text = (str(err).splitlines() or [""])[0]
    return f"{type(err).__name__}: {text}" if text else type(err).__name__
