"""What reaches the loop process from the session while it runs: stop requests and live parameter changes.

Both are words of the run's stream (:mod:`sashil.runtime.stream`) that the loop reads once per
cycle without blocking:

* :class:`LoopStop` is the loop's stop flag. It is set by a signal delivered to the loop process
  (SIGINT from the terminal reaches the whole process group), by the session's stop word (a
  signal the session caught, a page's STOP, a Python caller's flag), or by the session's death
  (:mod:`sashil.runtime.orphan`): a cycle reads the session's hold, a word of the stream that the
  kernel changes the moment the session's holding thread dies, and the job's pipe's end sets the
  flag from its ``SIGIO``. Both follow the session, whichever process is the loop's parent
  (unlike ``PR_SET_PDEATHSIG``, which follows the parent's thread). A cycle reads the flag, the
  stop word and the hold: no system call.
* :class:`MailboxTuning` is :class:`~sashil.runtime.tuning.LiveTuning` fed from the stream's
  mailbox: the session's tuning socket posts each request there, and the loop answers it between
  two cycles, at the first cycle after it arrived, with the same checks and events as in one
  process.
"""

from __future__ import annotations

import signal
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from sashil.errors import ConfigError
from sashil.runtime.signals import StopFlag
from sashil.runtime.stream import BAD_FRAMES_W, CLIPPED_W, SAMPLES_LOST_W, STOP_BY_CALLER, STOP_W, WATCHDOG_W, Stream
from sashil.runtime.tune_socket import answer
from sashil.runtime.tuning import LiveTuning, TuneEvent

if TYPE_CHECKING:
    from sashil.runtime.orphan import SessionWatch

#: the stop reason of a loop whose session process died
SESSION_DIED = "the session process died"
#: the loop's stop reason for a caller's stop (the session knows the caller's own words for it)
CALLER_STOP = "stop requested"


def stop_reason(code: int) -> str:
    """The reason a stop word gives: a signal's name, or the caller's stop."""
    if code == STOP_BY_CALLER:
        return CALLER_STOP
    try:
        return signal.Signals(code).name
    except ValueError:
        return f"stop word {code}"


class LoopStop:
    """The loop process's stop flag (module doc); ``flag`` takes the process's own signals and the
    session's death, which the loop reads every cycle from ``session``'s hold (a started
    :class:`~sashil.runtime.orphan.SessionWatch`: one word of shared memory against the holder's
    thread id) and its pipe signals. Every ``every`` cycles it also calls ``tick`` (the health's writer)."""

    __slots__ = ("_countdown", "_every", "_flag", "_header", "_hold", "_holder", "_session", "_tick")

    def __init__(
        self,
        flag: StopFlag,
        stream: Stream,
        session: SessionWatch | None = None,
        tick: Callable[[], None] | None = None,
        every: int = 100,
    ):
        self._flag = flag
        self._header = stream.header
        self._session = session
        self._hold = session.hold if session is not None else None
        self._holder = session.holder if session is not None else 0
        self._tick = tick
        self._every = max(1, int(every))
        self._countdown = 0

    @property
    def orphaned(self) -> bool:
        """The session died: the loop is alone with the stream and the run folder."""
        return self._session is not None and self._session.gone

    @property
    def requested(self) -> bool:
        if self._tick is not None:
            self._countdown -= 1
            if self._countdown <= 0:
                self._countdown = self._every
                self._tick()
        if self._flag.requested:
            return True
        code = self._header[STOP_W]
        if code:
            self._flag.request(stop_reason(int(code)))
            return True
        hold = self._hold
        if hold is not None and hold[0] != self._holder:  # the session's holding thread died (or let go)
            self._session.lost()  # type: ignore[union-attr]  # a hold comes with its watch
            return True
        return False

    @property
    def signal_name(self) -> str | None:
        return self._flag.signal_name


class HealthWriter:
    """Writes the run's health into the stream's header (:data:`~sashil.runtime.stream.HEALTH_WORDS`)
    from the rig's link counters and the controller's clip count, for the views while the run runs."""

    def __init__(self, stream: Stream, rig: Any, stage: Any):
        self._header = stream.header
        self._rig = rig if hasattr(rig, "stats") else None
        self._controller = stage if hasattr(stage, "clip_count") else getattr(stage, "controller", None)

    def __call__(self) -> None:
        header = self._header
        rig = self._rig
        if rig is not None:
            stats = rig.stats
            header[SAMPLES_LOST_W] = stats.get("samples_missed", 0)
            header[WATCHDOG_W] = stats.get("watchdog_samples", 0)
            header[BAD_FRAMES_W] = rig.codec_counters().get("bad_frames", 0)
        controller = self._controller
        if controller is not None:
            header[CLIPPED_W] = getattr(controller, "clip_count", 0)


class MailboxTuning(LiveTuning):
    """Live tuning whose requests come through ``stream``'s mailbox (module doc)."""

    def __init__(self, law: Any, rate_hz: float, ramp_s: float, stream: Stream):
        self._changing = False
        super().__init__(law, rate_hz, ramp_s)
        self.stream = stream

    @property
    def busy(self) -> bool:
        """A request in the mailbox, a change pending or a ramp running: the loop calls :meth:`service`."""
        return self._changing or self.stream.mail_pending

    @busy.setter
    def busy(self, value: bool) -> None:
        self._changing = value

    def service(self, time_s: float, cycle: int) -> None:
        request = self.stream.take_mail()
        if request is None:
            super().service(time_s, cycle)
            return
        serviced = False

        def submit(values: Mapping[str, Any], ramp_s: Any) -> list[TuneEvent]:
            nonlocal serviced
            try:
                checked, ramp = self.check(values, ramp_s)
            except ConfigError as err:
                self._refused(dict(values), float(ramp_s or 0.0), str(err), None, None, arrived=cycle)
                raise
            posted = self.post(checked, ramp)
            super(MailboxTuning, self).service(time_s, cycle)
            serviced = True
            if posted.error is not None:
                raise ConfigError(posted.error)
            return [event for event in self.events if event.cycle == posted.cycle and event.status == "applied"]

        reply = answer(self, request, submit) if isinstance(request, dict) else {"ok": False, "error": "bad request"}
        self.stream.answer(reply)
        if not serviced:
            super().service(time_s, cycle)
