"""Live tuning: parameter changes for a running law, handed to the loop between two cycles.

A change comes from another thread (the tuning socket's, :mod:`sashil.runtime.tune_socket`) and
must never touch the law while it computes a cycle. :meth:`LiveTuning.submit` checks the values
with the law's own :class:`~sashil.control.law_api.Param` checks (the code a ``--set`` goes
through), posts them in a one-slot hand-off and waits; the loop, at the start of a cycle's
control step, sees :attr:`LiveTuning.busy` and calls :meth:`LiveTuning.service`, which applies
them with ``law.set_parameters`` (so ``parameters_changed()`` may still refuse, leaving the law
as it was) and answers the waiting caller. Changes are therefore applied whole, in the order
they arrive, at the first cycle after they arrive.

With a ramp (``controller.tune_ramp_s`` > 0, from the config or given with the change) a float
parameter moves linearly from its value to the new one over that time, one step per cycle; other
kinds step at once. A new change to a ramping parameter starts its ramp again from where it is.

Every applied change (and a ramp's end) is a :class:`TuneEvent`, kept for the run folder's
``events.csv`` and ``summary.json``; a refused one is kept with its reason.

Cost when nothing is pending: the loop reads one attribute per cycle (``busy``).
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from sashil.config.sections import CONTROLLER
from sashil.errors import ConfigError

#: a caller waits this long for the loop to take its change: the socket opens before the loop's
#: first cycle (the run compiles its kernels and greets the board first), and a loop at 1 Hz takes 1 s
DEFAULT_WAIT_S = 30.0
#: the controller key of a live change's ramp (seconds; 0: a step)
RAMP_KEY = "tune_ramp_s"
#: the columns of the run folder's events.csv, one row per event
EVENT_COLUMNS = ("time_s", "cycle", "key", "old", "new", "ramp_s", "status", "arrived_cycle")


def check_ramp(value: Any) -> float:
    """``controller.tune_ramp_s`` given with a change, checked by its config field (the code a config
    file's value goes through); ConfigError in one line."""
    return float(CONTROLLER.fields[RAMP_KEY].check(value, f"controller.{RAMP_KEY}"))


@dataclass
class TuneEvent:
    """One change of a running law's parameter: ``status`` is ``applied`` (a step or a ramp's
    start), ``ramp_done``, ``refused`` (with ``reason``) or ``not_applied`` (the run ended first).
    ``time_s`` and ``cycle``: when a cycle applied (or refused) it, as data.csv counts them (None:
    refused by the checks before any cycle saw it); ``arrived_cycle``: the cycles the loop had run
    when the change arrived."""

    time_s: float | None
    cycle: int | None
    key: str
    old: Any
    new: Any
    ramp_s: float
    status: str
    reason: str = ""
    arrived_cycle: int | None = None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class _Request:
    """One change in the hand-off: the checked values, the ramp, and the answer the caller waits for."""

    def __init__(self, values: dict[str, Any], ramp_s: float):
        self.values = values
        self.ramp_s = ramp_s
        self.done = threading.Event()
        self.error: str | None = None
        self.time_s: float | None = None
        self.cycle: int | None = None
        self.arrived: int | None = None


class _Ramp:
    """A float parameter moving linearly from ``start`` to ``end`` over ``cycles`` cycles."""

    __slots__ = ("cycles", "end", "key", "start", "step")

    def __init__(self, key: str, start: float, end: float, cycles: int):
        self.key, self.start, self.end, self.cycles, self.step = key, start, end, cycles, 0

    def value(self) -> float:
        return self.start + (self.end - self.start) * (self.step / self.cycles)


class LiveTuning:
    """The hand-off between a tuning caller and the loop running ``law`` at ``rate_hz``."""

    def __init__(self, law: Any, rate_hz: float, ramp_s: float = 0.0):
        self.law = law
        self.rate_hz = float(rate_hz)
        self.ramp_s = float(ramp_s)
        #: the loop calls service() while this is true: a change is pending or a ramp runs
        self.busy = False
        self.events: list[TuneEvent] = []
        self._lock = threading.Lock()  # one caller at a time in the hand-off
        self._guard = threading.Lock()  # the pending slot, between a caller withdrawing it and the loop
        self._pending: _Request | None = None
        self._ramps: dict[str, _Ramp] = {}
        self._closed: str | None = None
        #: the loop's timing statistics (their ``cycles``), set by the loop: when a change arrived
        self.timing: Any = None

    # -- the caller's side (any thread) ----------------------------------------------------------
    def check(self, values: Mapping[str, Any], ramp_s: float | None = None) -> tuple[dict[str, Any], float]:
        """The values as the law would store them and the ramp, or ConfigError in one line."""
        if not values:
            raise ConfigError("nothing to change: give controller.<param>=VALUE")
        ramp = self.ramp_s if ramp_s is None else check_ramp(ramp_s)
        return self.law.check_parameters(values), ramp

    def submit(
        self, values: Mapping[str, Any], ramp_s: float | None = None, wait_s: float = DEFAULT_WAIT_S
    ) -> list[TuneEvent]:
        """Check ``values``, hand them to the loop and wait until a cycle applied them. Returns the
        change's events (one per parameter); ConfigError (one line) when a check or the law refused it, or
        when the run ended before a cycle took it."""
        try:
            checked, ramp = self.check(values, ramp_s)
        except ConfigError as err:
            self._refused(dict(values), ramp_s or 0.0, str(err), None, None, arrived=self._cycles())
            raise
        with self._lock:
            if self._closed is not None:
                raise ConfigError(self._closed)
            request = self.post(checked, ramp)
            if not request.done.wait(wait_s):
                with_loop = self._take_pending(request)
                if with_loop:  # the loop never came to it: withdrawn
                    self._not_applied(request, "the loop took no cycle")
                    raise ConfigError(f"not applied: the loop did not reach a cycle within {wait_s:g} s")
                request.done.wait(wait_s)  # the loop has it: its answer is on the way
        if request.error is not None:
            raise ConfigError(request.error)
        return [event for event in self.events if event.cycle == request.cycle and event.status == "applied"]

    def post(self, values: Mapping[str, Any], ramp_s: float = 0.0) -> _Request:
        """Hand checked ``values`` to the loop without waiting (a replay re-applies a run's changes
        at their cycles this way); the next :meth:`service` applies them."""
        request = _Request(dict(values), float(ramp_s))
        request.arrived = self._cycles()
        with self._guard:
            self._pending = request
            self.busy = True
        return request

    def _cycles(self) -> int:
        """The cycles the loop has run (0 before it started)."""
        return 0 if self.timing is None else int(self.timing.cycles)

    def _take_pending(self, request: _Request) -> bool:
        """Withdraw ``request`` if the loop has not taken it yet (True), else False."""
        with self._guard:
            if self._pending is request:
                self._pending = None
                self.busy = bool(self._ramps)
                return True
            return False

    # -- the loop's side (between cycles) --------------------------------------------------------
    def service(self, time_s: float, cycle: int) -> None:
        """Apply a pending change and advance the ramps; the loop calls it while :attr:`busy`."""
        with self._guard:
            request, self._pending = self._pending, None
        if request is not None:
            self._apply(request, time_s, cycle)
        if self._ramps:
            self._advance(time_s, cycle)
        self.busy = self._pending is not None or bool(self._ramps)

    def _apply(self, request: _Request, time_s: float, cycle: int) -> None:
        law = self.law
        request.time_s, request.cycle = time_s, cycle
        old = {key: getattr(law, key) for key in request.values}
        ramped = {}
        if request.ramp_s > 0.0:
            ramped = {
                key: value
                for key, value in request.values.items()
                if isinstance(value, float) and isinstance(old[key], (int, float)) and not isinstance(old[key], bool)
            }
        # ramped parameters stay where they are this cycle and move from the next one
        first = {key: (old[key] if key in ramped else value) for key, value in request.values.items()}
        try:
            law.set_parameters(first)
            if ramped:  # the law must also accept where the ramp ends: checked now, then back
                law.set_parameters(ramped)
                law.set_parameters({key: old[key] for key in ramped})
        except Exception as err:
            request.error = (str(err).splitlines() or [type(err).__name__])[0]
            self._refused(request.values, request.ramp_s, request.error, time_s, cycle, old, request.arrived)
        else:
            cycles = max(1, round(request.ramp_s * self.rate_hz))
            for key, value in request.values.items():
                ramp_s = request.ramp_s if key in ramped else 0.0
                self.events.append(
                    TuneEvent(time_s, cycle, key, old[key], value, ramp_s, "applied", arrived_cycle=request.arrived)
                )
                self._ramps.pop(key, None)
                if key in ramped:
                    self._ramps[key] = _Ramp(key, float(getattr(law, key)), float(value), cycles)
        request.done.set()

    def _advance(self, time_s: float, cycle: int) -> None:
        ramps = self._ramps
        values = {}
        for ramp in ramps.values():
            ramp.step += 1
            values[ramp.key] = ramp.value()
        try:
            self.law.set_parameters(values)
        except Exception as err:  # the law refused a point on the way: it stays where it was
            reason = (str(err).splitlines() or [type(err).__name__])[0]
            for ramp in ramps.values():
                self.events.append(
                    TuneEvent(time_s, cycle, ramp.key, ramp.start, ramp.end, 0.0, "refused", f"ramp stopped: {reason}")
                )
            ramps.clear()
            return
        for key in [key for key, ramp in ramps.items() if ramp.step >= ramp.cycles]:
            ramp = ramps.pop(key)
            self.events.append(TuneEvent(time_s, cycle, key, ramp.start, ramp.end, 0.0, "ramp_done"))

    def close(self, reason: str = "the run has ended") -> None:
        """No more changes: a pending one is answered as not applied (called once the loop stopped)."""
        self._closed = reason
        with self._guard:
            request, self._pending = self._pending, None
        self.busy = False
        if request is not None:
            self._not_applied(request, reason)
            request.error = f"not applied: {reason}"
            request.done.set()

    # -- the record ------------------------------------------------------------------------------
    def _refused(
        self,
        values: Mapping[str, Any],
        ramp_s: float,
        reason: str,
        time_s: float | None,
        cycle: int | None,
        old: Mapping[str, Any] | None = None,
        arrived: int | None = None,
    ) -> None:
        for key, value in values.items():
            before = (old or {}).get(key, getattr(self.law, key, None))
            self.events.append(TuneEvent(time_s, cycle, key, before, value, ramp_s, "refused", reason, arrived))

    def _not_applied(self, request: _Request, reason: str) -> None:
        for key, value in request.values.items():
            self.events.append(
                TuneEvent(
                    None,
                    None,
                    key,
                    getattr(self.law, key, None),
                    value,
                    request.ramp_s,
                    "not_applied",
                    reason,
                    request.arrived,
                )
            )

    def summary(self) -> dict[str, Any]:
        """For summary.json: the counts and every event."""
        return {
            "applied": sum(event.status == "applied" for event in self.events),
            "refused": sum(event.status == "refused" for event in self.events),
            "events": [event.as_dict() for event in self.events],
        }

    def notes(self) -> list[tuple[float, str]]:
        """``(time_s, text)`` of every change a cycle applied or refused, for the time axis of a view."""
        out = []
        for event in self.events:
            if event.time_s is None:
                continue
            ramp = f" over {event.ramp_s:g} s" if event.ramp_s else ""
            what = {"applied": "tuned", "ramp_done": "ramp done:", "refused": "refused"}.get(event.status, event.status)
            reason = f" ({event.reason})" if event.reason else ""
            out.append((event.time_s, f"{what} controller.{event.key} {event.old} -> {event.new}{ramp}{reason}"))
        return out

    def rows(self) -> list[list[Any]]:
        """events.csv's rows (:data:`EVENT_COLUMNS`), in the order the events happened."""
        return [[getattr(event, name) for name in EVENT_COLUMNS] for event in self.events]
