"""Best-effort real-time set-up of the loop thread: timer slack, CPU, SCHED_FIFO, mlockall, GC,
and the interpreter's thread switch interval.

Every step is tried on its own and its outcome recorded (``ok``, ``failed`` with the reason, or
``skipped``); none is fatal, as in ros2_control's "try SCHED_FIFO on any kernel" (see
research/architecture_anchors.md §5). ``RealtimeSetup.apply()`` runs the steps in the order the
research note gives (affinity before the scheduler; GC last, after start-up allocations), and
``restore()`` undoes them after the run so that writing the results runs as an ordinary thread.

Linux specifics: ``os.sched_setscheduler(0, ...)`` and ``sched_setaffinity(0, ...)`` act on the
calling thread; ``mlockall`` and ``prctl(PR_SET_TIMERSLACK)`` are called through ``ctypes``.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
import sys
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sashil.config.section_parts import LoopRtPart

MCL_CURRENT = 1
MCL_FUTURE = 2
PR_SET_TIMERSLACK = 29
PR_GET_TIMERSLACK = 30


@dataclass
class StepOutcome:
    status: str  # "ok" | "failed" | "skipped"
    detail: str

    def as_dict(self) -> dict[str, str]:
        return {"status": self.status, "detail": self.detail}


def _libc() -> ctypes.CDLL | None:
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name or "libc.so.6", use_errno=True)
    except OSError:
        return None


def _errno_text() -> str:
    err = ctypes.get_errno()
    return f"{os.strerror(err)} (errno {err})" if err else "unknown error"


@dataclass
class RealtimeSetup:
    """The real-time settings of ``loop.rt`` and, after ``apply()``, what each step achieved."""

    priority: int = 50
    cpu: int | None = None
    mlockall: bool = True
    gc_mode: str = "disable"  # "disable" | "freeze" | "none"
    timer_slack_ns: int = 1
    gil_switch_us: int = 100
    current_only: bool = False  # mlockall without MCL_FUTURE (set when an allocating thread runs beside the loop)
    outcomes: dict[str, StepOutcome] = field(default_factory=dict)
    _saved: dict[str, Any] = field(default_factory=dict, repr=False)

    @classmethod
    def from_parts(cls, rt: LoopRtPart) -> RealtimeSetup:
        """The set-up of the ``loop.rt`` values."""
        return cls(rt.priority, rt.cpu, rt.mlockall, rt.gc, rt.timer_slack_ns, rt.gil_switch_us)

    # the steps --------------------------------------------------------------------------------
    def apply(self) -> dict[str, StepOutcome]:
        libc = _libc()
        self.outcomes = {
            "timer_slack": self._timer_slack(libc),
            "cpu_affinity": self._affinity(),
            "sched_fifo": self._sched_fifo(),
            "mlockall": self._mlockall(libc),
            "gc": self._gc(),
            "gil_switch": self._gil_switch(),
        }
        return self.outcomes

    def _gil_switch(self) -> StepOutcome:
        # A background thread (recorder writer, live view) holding the interpreter when the loop
        # wakes would keep it for up to the switch interval (5 ms by default); shorten it.
        if not self.gil_switch_us:
            return StepOutcome("skipped", "loop.rt.gil_switch_us is 0")
        self._saved["switch_interval"] = sys.getswitchinterval()
        sys.setswitchinterval(self.gil_switch_us * 1e-6)
        return StepOutcome(
            "ok", f"{sys.getswitchinterval() * 1e6:.0f} us (was {self._saved['switch_interval'] * 1e6:.0f} us)"
        )

    def _timer_slack(self, libc: ctypes.CDLL | None) -> StepOutcome:
        if not self.timer_slack_ns:
            return StepOutcome("skipped", "loop.rt.timer_slack_ns is 0")
        if libc is None:
            return StepOutcome("failed", "libc not found")
        before = libc.prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0)
        if libc.prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(self.timer_slack_ns), 0, 0, 0) != 0:
            return StepOutcome("failed", "prctl(PR_SET_TIMERSLACK): " + _errno_text())
        self._saved["timer_slack"] = before
        return StepOutcome("ok", f"{self.timer_slack_ns} ns (was {before} ns)")

    def _affinity(self) -> StepOutcome:
        if self.cpu is None:
            return StepOutcome("skipped", "loop.rt.cpu is null")
        if not hasattr(os, "sched_setaffinity"):
            return StepOutcome("failed", "os.sched_setaffinity is not available on this platform")
        try:
            before = os.sched_getaffinity(0)
            os.sched_setaffinity(0, {self.cpu})
        except OSError as err:
            return StepOutcome("failed", f"CPU {self.cpu}: {err.strerror} (errno {err.errno})")
        self._saved["affinity"] = before
        return StepOutcome("ok", f"CPU {self.cpu}")

    def _sched_fifo(self) -> StepOutcome:
        if not hasattr(os, "sched_setscheduler"):
            return StepOutcome("failed", "os.sched_setscheduler is not available on this platform")
        policy = os.sched_getscheduler(0)
        current = os.sched_getparam(0).sched_priority
        if not self.priority:
            if policy == os.SCHED_FIFO:
                return StepOutcome("ok", f"already SCHED_FIFO priority {current} (inherited; loop.rt.priority is 0)")
            return StepOutcome("skipped", "loop.rt.priority is 0")
        if policy == os.SCHED_FIFO and current >= self.priority:
            return StepOutcome("ok", f"already SCHED_FIFO priority {current} (inherited)")
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.priority))
        except OSError as err:
            hint = " (needs CAP_SYS_NICE or an rtprio limit, e.g. `ulimit -r 99`)" if err.errno == 1 else ""
            return StepOutcome("failed", f"priority {self.priority}: {err.strerror} (errno {err.errno}){hint}")
        self._saved["sched"] = (policy, current)
        return StepOutcome("ok", f"priority {self.priority}")

    def _mlockall(self, libc: ctypes.CDLL | None) -> StepOutcome:
        if not self.mlockall:
            return StepOutcome("skipped", "loop.rt.mlockall is false")
        if libc is None:
            return StepOutcome("failed", "libc not found")
        # MCL_FUTURE makes every later allocation fault its pages in at once, under the process's
        # memory-map lock: with a busy allocating thread beside the loop (the rerun live view's
        # native threads) that stalled the loop for milliseconds (measured: 10 missed deadlines
        # in 20 s with it, 0-1 without), so such runs lock only what is mapped now.
        flags, text = (
            (MCL_CURRENT, "MCL_CURRENT") if self.current_only else (MCL_CURRENT | MCL_FUTURE, "MCL_CURRENT|MCL_FUTURE")
        )
        if libc.mlockall(flags) != 0:
            return StepOutcome("failed", "mlockall: " + _errno_text() + " (memlock limit: `ulimit -l`)")
        self._saved["mlock"] = libc
        return StepOutcome("ok", text)

    def _gc(self) -> StepOutcome:
        if self.gc_mode == "none":
            return StepOutcome("skipped", "loop.rt.gc is none")
        self._saved["gc_enabled"] = gc.isenabled()
        gc.collect()
        gc.freeze()
        if self.gc_mode == "disable":
            gc.disable()
            return StepOutcome("ok", f"collected, froze {gc.get_freeze_count()} objects, disabled during the run")
        return StepOutcome("ok", f"collected, froze {gc.get_freeze_count()} objects")

    # undo -------------------------------------------------------------------------------------
    def restore(self) -> None:
        """Undo what ``apply`` changed (never raises)."""
        saved, self._saved = self._saved, {}
        if "switch_interval" in saved:
            sys.setswitchinterval(saved["switch_interval"])
        if "gc_enabled" in saved:
            gc.unfreeze()
            if saved["gc_enabled"]:
                gc.enable()
        if "mlock" in saved:
            saved["mlock"].munlockall()
        if "sched" in saved:
            policy, priority = saved["sched"]
            try:
                os.sched_setscheduler(0, policy, os.sched_param(priority))
            except OSError:
                pass
        if "affinity" in saved:
            try:
                os.sched_setaffinity(0, saved["affinity"])
            except OSError:
                pass
        if "timer_slack" in saved:
            libc = _libc()
            if libc is not None:
                libc.prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(saved["timer_slack"]), 0, 0, 0)

    def report(self) -> dict[str, dict[str, str]]:
        """The outcomes as JSON-ready dicts (``summary.json`` key ``realtime``)."""
        return {name: outcome.as_dict() for name, outcome in self.outcomes.items()}

    def lines(self) -> list[str]:
        """One line per step, printed at the start of a run."""
        return [f"realtime: {name}: {o.status} ({o.detail})" for name, o in self.outcomes.items()]
