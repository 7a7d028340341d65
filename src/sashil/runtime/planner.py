"""A preview law's planner beside the loop: a process of its own that makes each re-plan
(:class:`sashil.control.preview_horizon.HorizonPlanner`) and hands the loop its latest plan through
shared memory, so the loop's cycle never waits for an optimisation nor for the planner's hold of
its interpreter.

One memory-mapped file in ``/dev/shm`` per run (as the run's stream, :mod:`sashil.runtime.stream`),
a header of int64 words and the float64 areas after it:

* the request: the loop writes the cycle, the estimated state (θ, θ̇2, ẑ, i) and the road speeds
  of the preview, then raises the request count and writes one byte to a pipe that wakes the
  planner (a request the planner has not begun is overwritten by the next: it plans the newest);
* the plan: the planner writes the start cycle and the slots' commands between two raises of the
  plan count (odd while it writes: a seqlock), and the loop takes a plan whose count is even and
  unchanged after its copy, into the one of its two buffers not in force (no allocation).

The loop's side costs a request (a few copies and one ``write``) every re-plan period and one read
of the plan count each cycle. The planner is a fresh interpreter (``python -m
sashil.runtime.planner``) given the model and the horizon as JSON, never a fork of the loop; it
ends when the loop sets the stop word, or when its parent is gone. On simulated time the law plans
in its own cycle instead (:class:`~sashil.control.preview_horizon.InlinePlanner`), so results are
deterministic.
"""

from __future__ import annotations

import json
import mmap
import os
import secrets
import select
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from sashil.control.law_api import Law
from sashil.control.preview_horizon import HorizonPlan, HorizonPlanner, HorizonSpec, InlinePlanner
from sashil.models.hysteresis import BoucWenParams

__all__ = ["PlannerProcess", "end_beside_loop", "plan_beside_loop"]

REQUEST_W, CYCLE_W, PLAN_W, START_W, STOP_W, READY_W, MADE_W = range(7)
HEADER_WORDS = 8
#: the planner's numeric libraries on one thread: a BLAS thread pool spinning beside the loop's core
#: slows both (L-BFGS-B's small factorisations took ten times as long with it on a busy machine)
ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
SHM_DIR = Path("/dev/shm") if Path("/dev/shm").is_dir() else Path("/tmp")


class _Shared:
    """The file's views: the header, the request's state and road, the plan's commands."""

    def __init__(self, path: Path, spec: HorizonSpec, create: bool):
        self.path = path
        floats = 4 + spec.preview_cycles + spec.slots
        size = 8 * (HEADER_WORDS + floats)
        if create:
            with open(path, "wb") as f:
                f.truncate(size)
        with open(path, "r+b") as f:
            self._map = mmap.mmap(f.fileno(), size)
        self.header = np.frombuffer(self._map, dtype=np.int64, count=HEADER_WORDS)
        body = np.frombuffer(self._map, dtype=np.float64, offset=8 * HEADER_WORDS)
        self.state = body[:4]
        self.road = body[4 : 4 + spec.preview_cycles]
        self.plan = body[4 + spec.preview_cycles :]

    def close(self) -> None:
        del self.header, self.state, self.road, self.plan
        self._map.close()


class PlannerProcess:
    """The loop's side of the planner process: :class:`InlinePlanner`'s calls, the plan made beside."""

    def __init__(self, inline: InlinePlanner, first: HorizonPlan):
        planner = inline.planner
        spec = planner.spec
        self.spec = spec
        path = SHM_DIR / f"sashil-planner-{os.getpid()}-{secrets.token_hex(4)}"
        self.shared = _Shared(path, spec, create=True)
        self.shared.plan[:] = first.command_a
        self.shared.header[START_W] = first.start
        self._bufs = (np.array(first.command_a, dtype=float), np.empty(spec.slots))
        self._in_force = 0
        self._current = HorizonPlan(first.start, spec.slot_cycles, self._bufs[0])
        self._seen = 0
        read_fd, self._wake = os.pipe()
        os.set_blocking(self._wake, False)
        job = {
            "path": str(path),
            "wake_fd": read_fd,
            "params": asdict(planner.params),
            "coil_tau_s": planner.coil_tau_s,
            "i_max": planner.i_max,
            "spec": asdict(spec),
        }
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "sashil.runtime.planner", json.dumps(job)],
                pass_fds=(read_fd,),
                env={**os.environ, **ONE_THREAD},
            )
        finally:
            os.close(read_fd)

    def wait_ready(self, timeout_s: float = 60.0) -> bool:
        """Whether the planner answers requests (its kernels loaded) within ``timeout_s``."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self.shared.header[READY_W]:
                return True
            if self.process.poll() is not None:
                return False
            time.sleep(0.01)
        return False

    def start(self, plan: HorizonPlan) -> None:
        """The plan in force from the run's first cycle (the planner starts from it too)."""
        self._current = plan

    def request(self, cycle: int, state: tuple[float, float, float, float], road_ahead: np.ndarray) -> None:
        """Post the request of ``cycle`` and wake the planner; the loop goes on at once."""
        shared = self.shared
        shared.header[CYCLE_W] = cycle
        shared.state[0], shared.state[1], shared.state[2], shared.state[3] = state
        n = min(road_ahead.size, shared.road.size)
        shared.road[:n] = road_ahead[:n]
        shared.road[n:] = 0.0
        shared.header[REQUEST_W] += 1
        try:
            os.write(self._wake, b"r")
        except BlockingIOError:  # the planner has wake-ups enough queued: it reads the newest request
            pass

    def latest(self, cycle: int) -> HorizonPlan | None:
        """The newest plan the planner has handed over (its count even and unchanged over the copy)."""
        header = self.shared.header
        count = int(header[PLAN_W])
        if count != self._seen and not count & 1:
            spare = self._bufs[1 - self._in_force]
            start = int(header[START_W])
            np.copyto(spare, self.shared.plan)
            if int(header[PLAN_W]) == count:
                self._in_force = 1 - self._in_force
                self._current = HorizonPlan(start, self.spec.slot_cycles, spare)
                self._seen = count
        return self._current

    @property
    def plans_made(self) -> int:
        return int(self.shared.header[MADE_W])

    def close(self) -> None:
        """Stop the planner, wait for it, remove the file."""
        self.shared.header[STOP_W] = 1
        try:
            os.write(self._wake, b"s")
        except OSError:
            pass
        try:
            self.process.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        os.close(self._wake)
        self.shared.close()
        self.shared.path.unlink(missing_ok=True)


def _law_of(stage: Any) -> Any:
    """The law inside a loop stage (a road stage around a controller, the controller, or the law), or None."""
    for _ in range(4):
        if stage is None:
            return None
        if isinstance(stage, Law):
            return stage
        law = getattr(stage, "law", None)
        if law is not None:
            return law
        own = getattr(stage, "__dict__", {})  # its own attributes: a wrapper's delegation is not followed
        stage = own.get("stage") or own.get("controller")
    return None


def plan_beside_loop(stage: Any, virtual: bool) -> PlannerProcess | None:
    """On the real clock, a law that plans inline (``law.planner`` an :class:`InlinePlanner`) is
    given a :class:`PlannerProcess` in its place, ready before this returns (its interpreter
    started and its kernels loaded: about a second); on simulated time it keeps planning inline."""
    law = _law_of(stage)
    inline = getattr(law, "planner", None)
    if virtual or not isinstance(inline, InlinePlanner):
        return None
    first = inline.latest(0)
    if first is None:
        return None
    beside = PlannerProcess(inline, first)
    law.planner = beside
    beside.wait_ready()  # before the first deadline, as the loop's own kernels are warmed
    return beside


def end_beside_loop(stage: Any) -> None:
    """Stop the planner process of the stage's law, if it has one."""
    planner = getattr(_law_of(stage), "planner", None)
    if isinstance(planner, PlannerProcess):
        planner.close()


def serve(job: dict[str, Any]) -> int:
    """The planner process: answer each request with a plan until stopped or orphaned."""
    spec = HorizonSpec(**job["spec"])
    planner = HorizonPlanner(BoucWenParams(**job["params"]), float(job["coil_tau_s"]), float(job["i_max"]), spec)
    shared = _Shared(Path(job["path"]), spec, create=False)
    wake = int(job["wake_fd"])
    parent = os.getppid()
    header = shared.header
    planner.last = HorizonPlan(int(header[START_W]), spec.slot_cycles, shared.plan.copy())
    planner.plan(0, (0.0, 0.0, 0.0, 0.0), np.zeros(spec.preview_cycles))  # compile and load before the run
    planner.last = HorizonPlan(int(header[START_W]), spec.slot_cycles, shared.plan.copy())
    header[READY_W] = 1
    done = 0
    while not header[STOP_W] and os.getppid() == parent:
        ready, _, _ = select.select([wake], [], [], 0.5)
        if ready:
            os.read(wake, 4096)
        count = int(header[REQUEST_W])
        if count == done or header[STOP_W]:
            continue
        cycle = int(header[CYCLE_W])
        state = (float(shared.state[0]), float(shared.state[1]), float(shared.state[2]), float(shared.state[3]))
        plan = planner.plan(cycle, state, shared.road.copy())
        done = count
        header[PLAN_W] += 1  # odd: writing
        shared.plan[:] = plan.command_a
        header[START_W] = plan.start
        header[PLAN_W] += 1
        header[MADE_W] += 1
    del header  # the map closes only with no view of it left
    shared.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(serve(json.loads(sys.argv[1])))
