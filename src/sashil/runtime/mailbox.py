"""What reaches the loop process from the session while it runs: stop requests and live parameter changes.

Both are words of the run's stream (:mod:`sashil.runtime.stream`) that the loop reads once per
cycle without blocking:

* :class:`LoopStop` is the loop's stop flag. It is set by a signal delivered to the loop process
  (SIGINT from the terminal reaches the whole process group), by the session's stop word (a
  signal the session caught, a page's STOP, a Python caller's flag), or by the session's death:
  the loop compares ``os.getppid()`` with the session's pid every cycle, which changes the moment
  the session is gone and the loop is re-parented (exact, one cheap system call, and unlike
  ``PR_SET_PDEATHSIG`` it follows the process rather than the thread that spawned it).
* :class:`MailboxTuning` is :class:`~sashil.runtime.tuning.LiveTuning` fed from the stream's
  mailbox: the session's tuning socket posts each request there, and the loop answers it between
  two cycles, at the first cycle after it arrived, with the same checks and events as in one
  process.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Mapping
from typing import Any

from sashil.errors import ConfigError
from sashil.runtime.signals import StopFlag
from sashil.runtime.stream import STOP_BY_CALLER, STOP_W, Stream
from sashil.runtime.tune_socket import answer
from sashil.runtime.tuning import LiveTuning, TuneEvent

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
    """The loop process's stop flag (module doc); ``flag`` takes the process's own signals."""

    __slots__ = ("_flag", "_header", "_session_pid", "orphaned")

    def __init__(self, flag: StopFlag, stream: Stream, session_pid: int):
        self._flag = flag
        self._header = stream.header
        self._session_pid = session_pid
        #: the session died: the loop is alone with the stream and the run folder
        self.orphaned = False

    @property
    def requested(self) -> bool:
        if self._flag.requested:
            return True
        code = self._header[STOP_W]
        if code:
            self._flag.request(stop_reason(int(code)))
            return True
        if os.getppid() != self._session_pid:
            self.orphaned = True
            self._flag.request(SESSION_DIED)
            return True
        return False

    @property
    def signal_name(self) -> str | None:
        return self._flag.signal_name


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
