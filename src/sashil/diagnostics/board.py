"""The board's checks over its link: Hello/Version, host-paced round trips, and its watchdog.

The link is opened in host pacing (each Command answered by one Sample) and never activated:
every Command the checks send is disabled, so the board drives 0 A throughout. After the round
trips the host goes quiet; the board's watchdog must trip and report it in a Status.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil.config.frozen import freeze
from sashil.diagnostics import FAIL, OK, WARN, Check
from sashil.drivers import open_rig
from sashil.drivers.interface import FLAG_WATCHDOG
from sashil.drivers.link_rig import LinkRig
from sashil.errors import DriverError, DriverIOError, DriverTimeoutError
from sashil.runtime.clock import RealClock
from sashil.runtime.rt_setup import RealtimeSetup

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec

#: how much longer than ``driver.watchdog_ms`` the host waits for the board to report a trip
WATCHDOG_GRACE_S = 0.2


def _check(name: str, status: str, found: str, fix: str = "", data: dict[str, Any] | None = None) -> Check:
    return Check("board", name, status, found, fix, data or {})


def board_checks(run: RunSpec, rounds: int) -> list[Check]:
    """Hello/Version, ``rounds`` round trips at ``loop.rate_hz``, and the watchdog trip, the run's
    rig paced by the host."""
    if "pacing" not in run.rig.values:
        return [_check("hello", OK, f"driver {run.rig.backend}: no link to check")]
    rig = open_rig(replace(run.rig, values=freeze({**run.rig.values, "pacing": "host"}, "rig parts")))
    if not isinstance(rig, LinkRig):
        rig.close()
        return [_check("hello", OK, f"driver {run.rig.backend}: no link to check")]
    try:
        try:
            rig.configure()
        except DriverError as err:
            return [_check("hello", FAIL, str(err), "is the board powered and on this port, with this --driver?")]
        checks = [hello(rig)]
        loop = run.loop
        rt = RealtimeSetup.from_parts(loop.rt)
        rt.apply()  # the round trips run as the loop would
        try:
            checks.append(round_trips(rig, rounds, loop.rate_hz, loop.spin_margin_us))
            quiet_since = time.monotonic()  # the last Command went out; undoing the set-up takes a while
        except DriverIOError as err:
            checks.append(_check("link", FAIL, str(err), "check the cable and the adapter"))
            return checks
        finally:
            rt.restore()
        try:
            checks.append(watchdog(rig, int(run.rig.values["watchdog_ms"]), quiet_since))
        except DriverIOError as err:
            checks.append(_check("link", FAIL, str(err), "check the cable and the adapter"))
        if "low_latency" in rig.link_stats():
            checks.append(_low_latency(rig.link_stats()["low_latency"]))
        return checks
    finally:
        rig.close()


def hello(rig: LinkRig) -> Check:
    version = rig.device_version
    assert version is not None  # configure() succeeded
    s = rig.settings
    return _check(
        "hello",
        OK,
        f"protocol {version.protocol_version}, {version.counts_per_rev} counts/rev, {version.current_max_a:g} A; "
        f"Configure accepted ({s.rate_hz} Hz, watchdog {s.watchdog_ms} ms)",
    )


def round_trips(rig: LinkRig, rounds: int, rate_hz: float, spin_margin_us: float) -> Check:
    """``rounds`` Commands (disabled: 0 A) at the loop's rate, each answered by a Sample; the RTT is
    from sending the Command to decoding its Sample."""
    period_ns = round(1e9 / rate_hz)
    clock = RealClock.for_rate(spin_margin_us, rate_hz)
    rtt_ns = []
    stats = rig.stats
    deadline = clock.now_ns()
    for _ in range(rounds):
        clock.sleep_until(deadline)
        start = clock.now_ns()
        try:
            rig.read(start, period_ns)
        except DriverTimeoutError:
            pass  # counted in stats["timeouts"]
        else:
            rtt_ns.append(clock.now_ns() - start)
        deadline = max(deadline + period_ns, clock.now_ns())
    counters = rig.link_stats()
    figures = rtt_figures(
        np.asarray(rtt_ns, dtype=float) * 1e-3,
        rate_hz,
        rounds=rounds,
        lost=int(stats["samples_missed"] + stats["timeouts"]),
        bad=int(counters.get("bad_frames", 0)),
        gaps=int(stats["gaps"]),
    )
    return judge_rtt(figures)


def rtt_figures(rtt_us: np.ndarray, rate_hz: float, *, rounds: int, lost: int, bad: int, gaps: int) -> dict[str, Any]:
    """The round trips' figures (µs) :func:`judge_rtt` reads."""
    have = rtt_us.size > 0
    return {
        "rate_hz": rate_hz,
        "rounds": rounds,
        "answered": int(rtt_us.size),
        "p50_us": round(float(np.percentile(rtt_us, 50)), 1) if have else None,
        "p99_us": round(float(np.percentile(rtt_us, 99)), 1) if have else None,
        "max_us": round(float(rtt_us.max()), 1) if have else None,
        "lost": lost,
        "bad_frames": bad,
        "gaps": gaps,
    }


def judge_rtt(f: dict[str, Any]) -> Check:
    """ok: p99 within half the period, nothing lost, bad or late (a gap); warn: p99 within the period and at
    most 0.1 % of the rounds lost, bad or late; fail otherwise (a host-paced loop could not run at this rate)."""
    period_us = 1e6 / f["rate_hz"]
    if not f["answered"]:
        return _check("round_trips", FAIL, f"none of {f['rounds']} Commands answered", "check the link", f)
    found = (
        f"{f['answered']}/{f['rounds']} at {f['rate_hz']:g} Hz: RTT p50 {f['p50_us']:g} / p99 {f['p99_us']:g} / "
        f"max {f['max_us']:g} us; {f['lost']} lost, {f['bad_frames']} bad frames, {f['gaps']} gaps"
    )
    errors = f["lost"] + f["bad_frames"] + f["gaps"]  # a gap ran cycles at 0 A
    if errors == 0 and f["p99_us"] <= 0.5 * period_us:
        return _check("round_trips", OK, found, data=f)
    fix = "fix the latency timer and machine rows above, or --set loop.rate_hz lower"
    if errors <= 0.001 * f["rounds"] and f["p99_us"] <= period_us:
        return _check("round_trips", WARN, found, fix, f)
    return _check("round_trips", FAIL, found, fix, f)


def watchdog(rig: LinkRig, watchdog_ms: int, quiet_since: float) -> Check:
    """Stay quiet (since ``quiet_since``, ``time.monotonic()``) and wait for the board's Status
    reporting a watchdog trip."""
    before = rig.last_status.watchdog_trips if rig.last_status is not None else None
    quiet = quiet_since
    status = rig.wait_for_status(max(0.0, quiet + watchdog_ms * 1e-3 + WATCHDOG_GRACE_S - time.monotonic()))
    elapsed_ms = (time.monotonic() - quiet) * 1e3
    fix = "the board's firmware must cut the coil after driver.watchdog_ms without a Command"
    if status is None:
        return _check(
            "watchdog",
            FAIL,
            f"no Status within {elapsed_ms:.0f} ms of the host going quiet (watchdog {watchdog_ms} ms)",
            fix,
        )
    tripped = bool(status.flags & FLAG_WATCHDOG) and (before is None or status.watchdog_trips != before)
    found = f"Status after {elapsed_ms:.0f} ms quiet (watchdog {watchdog_ms} ms): trips {status.watchdog_trips}"
    if not tripped:
        return _check("watchdog", FAIL, found + ", watchdog flag not set", fix)
    return _check("watchdog", OK, found + ", watchdog flag set", data={"elapsed_ms": round(elapsed_ms, 1)})


def _low_latency(state: str) -> Check:
    if state == "on":
        return _check("low_latency", OK, "the serial driver's low-latency mode is on")
    status = OK if "not a local" in state or "pseudo" in state else WARN
    return _check(
        "low_latency", status, f"low-latency mode {state}", "set the adapter's latency_timer to 1 (row above)"
    )


__all__ = ["board_checks", "judge_rtt", "rtt_figures"]
