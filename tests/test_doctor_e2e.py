"""``sashil doctor`` against the emulated board over serial and SLCAN, and a board that does not
answer (a pty with nobody on the other end). Real processes on the real clock: the figures are
not judged (they depend on the machine), only that every check ran and what it found."""

from __future__ import annotations

import json
import os
import pty

import pytest

from tests.test_link_e2e import DRIVERS, Emulator, _warm_sashil, sashil  # noqa: F401 - the fixture

pytestmark = pytest.mark.e2e


def _rows(done) -> dict[str, dict]:
    return {f"{r['group']}/{r['name']}": r for r in json.loads(done.stdout)["checks"]}


@pytest.mark.parametrize("transport, driver", DRIVERS)
def test_doctor_against_the_emulated_board(transport, driver, tmp_path):
    emu = Emulator(tmp_path, transport, "python")
    try:
        done = sashil(
            "doctor", "--json", "--jitter-s", "0.2", "--round-trips", "200", "--driver", driver, "--port", emu.link
        )
    finally:
        emu.stop()
    assert done.returncode in (0, 1), done.stderr
    rows = _rows(done)
    assert json.loads(done.stdout)["exit_code"] == done.returncode
    assert rows["port/exists"]["status"] == "ok" and "/dev/pts/" in rows["port/exists"]["found"]
    assert rows["port/latency_timer"]["status"] == "ok"
    assert rows["board/hello"]["status"] == "ok" and "protocol 2" in rows["board/hello"]["found"]
    trips = rows["board/round_trips"]["data"]
    assert trips["rounds"] == 200 and trips["answered"] > 0 and trips["p50_us"] <= trips["p99_us"] <= trips["max_us"]
    assert rows["board/watchdog"]["status"] == "ok" and "watchdog flag set" in rows["board/watchdog"]["found"]
    assert rows["machine/jitter"]["data"]["cycles"] == 200
    if driver == "serial":
        assert rows["board/low_latency"]["found"] == "low-latency mode not available on a pseudo-terminal"


@pytest.mark.parametrize("driver", ["serial", "can"])
def test_doctor_on_a_board_that_does_not_answer(driver):
    master, slave = pty.openpty()
    try:
        done = sashil(
            "doctor",
            "--json",
            "--jitter-s",
            "0",
            "--driver",
            driver,
            "--port",
            os.ttyname(slave),
            "--set",
            "driver.connect_timeout_s=0.2",
        )
    finally:
        os.close(slave)
        os.close(master)
    assert done.returncode == 1, done.stderr
    hello = _rows(done)["board/hello"]
    assert hello["status"] == "fail" and "within 0.2 s" in hello["found"], hello
