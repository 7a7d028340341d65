"""``sashil doctor``'s checks on fixture sysfs/procfs trees and given figures (no real clock)."""

from __future__ import annotations

import json
import os
import resource
from pathlib import Path

import numpy as np
import pytest
import serial

from sashil.cli import main
from sashil.config.section_parts import LoopRtPart
from sashil.diagnostics import FAIL, OK, WARN, exit_code, table
from sashil.diagnostics.board import judge_rtt, rtt_figures
from sashil.diagnostics.jitter import judge, summarise
from sashil.diagnostics.machine import (
    MachineFacts,
    governor,
    isolated_cpus,
    machine_checks,
    memlock,
    parse_cpu_list,
    preemption,
    read_facts,
    sched_fifo,
    timer_slack,
)
from sashil.diagnostics.port import latency_timer, permission, port_checks, socketcan
from sashil.drivers.serial_rig import request_low_latency

INF = resource.RLIM_INFINITY


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


@pytest.fixture
def trees(tmp_path):
    sys_root, proc_root = tmp_path / "sys", tmp_path / "proc"
    cpu = sys_root / "devices/system/cpu"
    _write(cpu / "cpu0/cpufreq/scaling_governor", "powersave\n")
    _write(cpu / "cpu1/cpufreq/scaling_governor", "performance\n")
    _write(cpu / "isolated", "1-2,5\n")
    _write(sys_root / "kernel/realtime", "1\n")
    _write(proc_root / "self/status", "Name:\tpython\nVmSize:\t  204800 kB\nCapEff:\t0000000000800000\n")
    _write(proc_root / "self/timerslack_ns", "50000\n")
    return sys_root, proc_root


def test_read_facts_parses_the_trees(trees):
    facts = read_facts(*trees)
    assert facts.governors == {0: "powersave", 1: "performance"}
    assert facts.isolated == [1, 2, 5]
    assert facts.realtime_flag == "1"
    assert facts.vm_size_bytes == 204800 * 1024
    assert facts.cap_eff >> 23 & 1  # CAP_SYS_NICE
    assert facts.timer_slack_ns == 50000
    assert preemption(facts).status == OK


def test_parse_cpu_list():
    assert parse_cpu_list("") == []
    assert parse_cpu_list("0-2,7\n") == [0, 1, 2, 7]


@pytest.mark.parametrize(
    "version, mode, status, word",
    [
        ("#1 SMP PREEMPT_RT Tue", None, OK, "PREEMPT_RT"),
        ("#1 SMP PREEMPT_DYNAMIC", None, WARN, "PREEMPT_DYNAMIC"),
        ("#1 SMP PREEMPT_DYNAMIC", "none voluntary (full)", WARN, "full"),
        ("#1 SMP PREEMPT_DYNAMIC", "none (voluntary) full", WARN, "voluntary"),
        ("#1 SMP Tue", None, WARN, "no kernel preemption"),
    ],
)
def test_preemption(version, mode, status, word):
    check = preemption(MachineFacts(kernel_version=version, preempt_mode=mode))
    assert check.status == status and word in check.found
    assert check.status == OK or "PREEMPT_RT" in check.fix


def test_sched_fifo_by_limit_capability_or_root():
    user = MachineFacts(uid=1000, rtprio=(0, 0))
    check = sched_fifo(user, 50)
    assert check.status == WARN and "RLIMIT_RTPRIO 0" in check.found and "rtprio 99" in check.fix
    assert "ulimit -r 50" in sched_fifo(MachineFacts(uid=1000, rtprio=(0, 99)), 50).fix
    assert sched_fifo(MachineFacts(uid=1000, rtprio=(50, 50)), 50).status == OK
    assert sched_fifo(MachineFacts(uid=1000, cap_eff=1 << 23), 50).status == OK
    assert sched_fifo(MachineFacts(uid=0), 50).status == OK
    assert sched_fifo(user, 0).status == OK  # priority 0: nothing asked


def test_memlock_against_the_process_size():
    small = MachineFacts(uid=1000, memlock=(8 << 20, 8 << 20), vm_size_bytes=300 << 20)
    check = memlock(small, True)
    assert check.status == WARN and "8 MiB" in check.found and "memlock unlimited" in check.fix
    assert memlock(MachineFacts(uid=1000, memlock=(INF, INF), vm_size_bytes=300 << 20), True).status == OK
    assert memlock(MachineFacts(uid=1000, cap_eff=1 << 14), True).status == OK
    assert memlock(small, False).status == OK


def test_governor_and_isolated_cpus():
    facts = MachineFacts(governors={0: "powersave", 1: "performance"}, isolated=[1])
    check = governor(facts, None)
    assert check.status == WARN and "powersave" in check.found and "cpupower frequency-set -g performance" in check.fix
    assert governor(facts, 1).status == OK  # the pinned CPU runs at full speed
    assert governor(MachineFacts(), None).status == OK  # no cpufreq (a VM)
    assert isolated_cpus(facts, 1).status == OK
    assert "isolcpus=0" in isolated_cpus(facts, 0).fix
    assert isolated_cpus(facts, None).fix == "--set loop.rt.cpu=1"
    assert "isolcpus" in isolated_cpus(MachineFacts(isolated=[]), None).fix


def test_timer_slack():
    facts = MachineFacts(timer_slack_ns=50_000)
    assert timer_slack(facts, 1).status == OK
    check = timer_slack(facts, 0)
    assert check.status == WARN and check.fix == "--set loop.rt.timer_slack_ns=1"


def test_machine_checks_cover_the_loop_section(config):
    names = [c.name for c in machine_checks(MachineFacts(), LoopRtPart.read(config["loop"]["rt"]))]
    assert names == ["preemption", "sched_fifo", "memlock", "cpu_governor", "isolated_cpus", "timer_slack"]


def test_latency_timer_of_a_usb_serial_adapter(tmp_path):
    sys_root = tmp_path / "sys"
    timer = sys_root / "bus/usb-serial/devices/ttyUSB0/latency_timer"
    _write(timer, "16\n")
    check = latency_timer("/dev/ttyUSB0", 1000.0, sys_root)
    assert check.status == FAIL and "16 ms" in check.found
    assert check.fix.startswith(f"`echo 1 | sudo tee {timer}`")
    timer.write_text("1\n")
    assert latency_timer("/dev/ttyUSB0", 1000.0, sys_root).status == OK
    assert latency_timer("/dev/ttyACM0", 1000.0, sys_root).status == OK  # CDC-ACM: no timer


def test_permission_names_the_group_to_join(tmp_path):
    port = tmp_path / "ttyUSB0"
    port.write_text("")
    port.chmod(0o660)
    check = permission(str(port), access=lambda path, mode: False)
    assert check.status == FAIL and "no read/write permission" in check.found
    assert "usermod -aG" in check.fix or "log out and in" in check.fix
    port.chmod(0o600)
    assert "chmod g+rw" in permission(str(port), access=lambda path, mode: False).fix


@pytest.mark.skipif(os.geteuid() == 0, reason="root opens a file of mode 000 all the same")
def test_permission_of_a_mode_000_file(tmp_path):
    port = tmp_path / "tty"
    port.write_text("")
    port.chmod(0)
    assert permission(str(port)).status == FAIL


def _ip(bitrate: int, state: str) -> str:
    info = {"state": state, "berr_counter": {"tx": 3, "rx": 0}, "bittiming": {"bitrate": bitrate}}
    return json.dumps([{"ifname": "can0", "linkinfo": {"info_kind": "can", "info_data": info}}])


def test_socketcan_interface(tmp_path):
    sys_root = tmp_path / "sys"
    [missing] = socketcan("can0", 1_000_000, sys_root, lambda name: None)
    assert missing.status == FAIL and "no network interface can0" in missing.found
    _write(sys_root / "class/net/can0/flags", "0x80\n")
    [down] = socketcan("can0", 1_000_000, sys_root, lambda name: None)
    assert down.status == FAIL and "bitrate 1000000" in down.fix
    _write(sys_root / "class/net/can0/flags", "0x81\n")
    up, rate, errors = socketcan("can0", 1_000_000, sys_root, lambda name: _ip(500_000, "BUS-OFF"))
    assert up.status == OK
    assert rate.status == FAIL and "500000" in rate.found and "bitrate 1000000" in rate.fix
    assert errors.status == FAIL and "tx 3" in errors.found
    _, rate, errors = socketcan("can0", 1_000_000, sys_root, lambda name: _ip(1_000_000, "ERROR-ACTIVE"))
    assert (rate.status, errors.status) == (OK, OK)


def test_port_checks_route_by_driver(config):
    driver = dict(config["driver"], name="serial", port="loop://")
    assert [c.status for c in port_checks(driver, 1000.0)] == [OK]
    driver = dict(config["driver"], name="can", can_interface="virtual", port="x")
    assert [c.name for c in port_checks(driver, 1000.0)] == ["can_interface"]


def test_jitter_verdicts_from_figures():
    quiet = summarise(np.full(1000, 20.0), 1000.0)
    assert quiet["histogram_us"][">=20"] == 1000
    assert judge(quiet).status == OK
    busy = summarise(np.r_[np.full(999, 300.0), 5000.0], 1000.0)
    assert busy["misses"] == 1 and judge(busy).status == WARN
    assert judge(summarise(np.full(100, 2000.0), 1000.0)).status == FAIL


def test_round_trip_verdicts_from_figures():
    def fig(rtt, lost=0, bad=0):
        return rtt_figures(np.asarray(rtt, dtype=float), 1000.0, rounds=1000, lost=lost, bad=bad, gaps=0)

    assert judge_rtt(fig([200.0] * 1000)).status == OK
    assert judge_rtt(fig([200.0] * 980 + [800.0] * 20)).status == WARN
    assert judge_rtt(fig([200.0] * 1000, lost=5)).status == FAIL
    assert judge_rtt(fig([])).status == FAIL


def test_table_and_exit_code():
    checks = judge(summarise(np.full(10, 2000.0), 1000.0)), judge(summarise(np.full(10, 1.0), 1000.0))
    assert exit_code(list(checks)) == 1 and exit_code(list(checks[1:])) == 0
    text = table(list(checks))
    assert text.startswith("FAIL  machine/jitter") and "fix: " in text


def test_low_latency_is_reported_when_not_available():
    port = serial.serial_for_url("loop://")
    try:
        assert request_low_latency(port).startswith("not available")
    finally:
        port.close()


def test_doctor_on_a_port_that_does_not_exist(tmp_path, capsys):
    missing = str(tmp_path / "ttyUSB9")
    code = main(["doctor", "--json", "--jitter-s", "0", "--driver", "serial", "--port", missing])
    assert code == 1
    rows = {(r["group"], r["name"]): r for r in json.loads(capsys.readouterr().out)["checks"]}
    assert rows["port", "exists"]["status"] == FAIL and "does not exist" in rows["port", "exists"]["found"]
    assert rows["board", "hello"]["status"] == FAIL and "not checked" in rows["board", "hello"]["found"]


def test_doctor_reads_the_given_sysfs(trees, capsys):
    assert main(["doctor", "--jitter-s", "0", "--sys-root", str(trees[0])]) == 0
    out = capsys.readouterr().out
    assert "WARN  machine/cpu_governor" in out and "PREEMPT_RT kernel" in out


@pytest.mark.parametrize("option", [["--jitter-s", "-1"], ["--round-trips", "0"]])
def test_doctor_bad_options(option, capsys):
    assert main(["doctor", *option]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and option[0] in err
