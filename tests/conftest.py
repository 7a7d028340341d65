"""Shared fixtures: the default config, a guard that fails any test that leaks a resource, and how the
tests are shared out between pytest-xdist's workers.

The guard (autouse) compares what is open after a test with what was open before it: python-can
buses not shut down, threads still alive, pseudo-terminal fds still open, child processes still
running (or not waited for), and the process's scheduling (SCHED_FIFO, priority, CPU affinity) or
SIGINT/SIGTERM handlers not restored after a run (every child started later would inherit the
scheduling; a stale handler stops a run that is long gone). A leaked bus or pty keeps a channel busy for the tests that follow; a
leaked thread or child keeps driving an emulated rig. Threads and children get a short grace to end
on their own (a join, not a sleep).
"""

from __future__ import annotations

import copy
import functools
import os
import re
import signal
import threading
import time
import weakref
from collections.abc import Iterator
from pathlib import Path

import can
import pytest
from warm_sashil import WarmSashil

from sashil.engine.resolve import default_config
from sashil.runtime import loop_server

#: how long a thread or child that is on its way out may take to end after the test
GRACE_S = 2.0

_buses: weakref.WeakSet[can.BusABC] = weakref.WeakSet()
_bus_init = can.BusABC.__init__


def _tracking_init(self: can.BusABC, *args: object, **kwargs: object) -> None:
    _bus_init(self, *args, **kwargs)
    _buses.add(self)


can.BusABC.__init__ = _tracking_init  # type: ignore[method-assign]


#: a fixture made once for a whole module (or class): a calibration, a firmware build, a QEMU session, a fit
_SHARED_FIXTURE = re.compile(r"""scope\s*=\s*["'](module|class|package)["']""")


@functools.cache
def _module_shares_a_fixture(path: str) -> bool:
    try:
        return bool(_SHARED_FIXTURE.search(Path(path).read_text(encoding="utf-8")))
    except OSError:
        return True  # unknown: keep its tests together, as a serial run would


@pytest.hookimpl(tryfirst=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object | None:
    """``--dist loadscope`` (pyproject's addopts), one work unit per test, except that the tests of a
    module that makes a fixture for all its tests run together on one worker, which makes it once.

    Plain loadscope keeps every module on one worker, and the longest module (each tool's quick mode,
    one after another) then sets the suite's time; one test per unit would make each worker compute
    a module's calibration or firmware image again."""
    if config.getoption("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ModuleWhenShared(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return module if _module_shares_a_fixture(str(config.rootpath / module)) else nodeid

    return ModuleWhenShared(config, log)


@pytest.fixture(scope="session")
def warm_sashil(tmp_path_factory: pytest.TempPathFactory) -> Iterator[WarmSashil]:
    """A ``sashil`` whose commands fork one warm interpreter (tests/warm_sashil.py): for the tests that
    run many commands and signal them only by SIGINT, SIGTERM or SIGHUP."""
    warm = WarmSashil(tmp_path_factory.mktemp("warm-sashil"))
    try:
        yield warm
    finally:
        warm.close()


@pytest.fixture
def config():
    """A fresh copy of the default config (simulated rig, seed parameters, 1 kHz)."""
    return copy.deepcopy(default_config())


def _open_buses() -> set[int]:
    return {id(bus) for bus in list(_buses) if not getattr(bus, "_is_shutdown", True)}


def _pty_fds() -> set[tuple[int, str]]:
    """This process's open fds on the pty master/slave devices (``/dev/ptmx``, ``/dev/pts/N``)."""
    out = set()
    for name in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{name}")
        except OSError:
            continue  # closed while listing (the listing's own fd)
        if target == "/dev/ptmx" or target.startswith("/dev/pts/"):
            out.add((int(name), target))
    return out


def _children() -> set[int]:
    """Pids whose parent is this process (running or zombie: a zombie was never waited for), the
    loop processes its loop server forked counted as its own and the server, kept for the worker's
    later runs (sashil.runtime.loop_server), not counted."""
    server = loop_server.running()
    parents = {os.getpid()} if server is None else {os.getpid(), server.pid}
    out = set()
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as stat:
                fields = stat.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) in parents:
            out.add(int(entry))
    return out - ({server.pid} if server is not None else set())


def _settle(check, before, deadline: float):
    """What ``check()`` finds beyond ``before``, once it is empty or the deadline has passed."""
    extra = check() - before
    while extra and time.monotonic() < deadline:
        time.sleep(0.01)  # polling for the leak to clear up, not timing a test
        extra = check() - before
    return extra


def _process_state() -> tuple[object, ...]:
    """This thread's scheduling policy, priority and CPU affinity (the loop's real-time set-up), and
    the SIGINT/SIGTERM handlers (a verb's clean-stop handlers)."""
    return (
        os.sched_getscheduler(0),
        os.sched_getparam(0).sched_priority,
        sorted(os.sched_getaffinity(0)),
        signal.getsignal(signal.SIGINT),
        signal.getsignal(signal.SIGTERM),
    )


def _threads() -> set[threading.Thread]:
    return {t for t in threading.enumerate() if t.is_alive()}


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail a test that leaves a CAN bus, a thread, a pty fd, a child process, real-time scheduling or
    signal handlers behind."""
    buses, threads, ptys, children, state = _open_buses(), _threads(), _pty_fds(), _children(), _process_state()
    yield
    deadline = time.monotonic() + GRACE_S
    for thread in _threads() - threads:
        thread.join(max(0.0, deadline - time.monotonic()))
    leaks = []
    if left := _open_buses() - buses:
        leaks.append(f"{len(left)} python-can bus(es) not shut down")
    if left := _threads() - threads:
        leaks.append("threads still running: " + ", ".join(sorted(t.name for t in left)))
    if left := _settle(_pty_fds, ptys, deadline):
        leaks.append("pty fds still open: " + ", ".join(f"{fd} -> {path}" for fd, path in sorted(left)))
    if left := _settle(_children, children, deadline):
        leaks.append(f"child processes still running or not waited for: pids {sorted(left)}")
    if (now := _process_state()) != state:
        leaks.append(
            f"real-time set-up or signal handlers not restored (policy, priority, cpus, SIGINT, SIGTERM): {state} -> {now}"
        )
    if leaks:
        pytest.fail("leaked: " + "; ".join(leaks), pytrace=False)
