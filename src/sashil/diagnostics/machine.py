"""The machine's real-time readiness, from facts read out of sysfs and procfs.

:func:`read_facts` gathers what the checks need (``sys_root``/``proc_root`` replaceable, so tests
feed fixture trees); :func:`machine_checks` judges them against the config's ``loop`` section.
Nothing here changes the machine.
"""

from __future__ import annotations

import os
import resource
from dataclasses import dataclass, field
from pathlib import Path

from sashil.config.section_parts import LoopRtPart
from sashil.diagnostics import FAIL, OK, WARN, Check

CAP_IPC_LOCK = 14
CAP_SYS_NICE = 23
#: the timer slack a thread starts with (ns)
DEFAULT_TIMER_SLACK_NS = 50_000
LIMITS_FILE = "/etc/security/limits.d/99-sashil.conf"


@dataclass
class MachineFacts:
    """What the machine checks look at (every field may be unknown: None)."""

    kernel_version: str = ""  # ``uname -v``: "#1 SMP PREEMPT_RT ..."
    realtime_flag: str | None = None  # /sys/kernel/realtime ("1" on a PREEMPT_RT kernel)
    preempt_mode: str | None = None  # /sys/kernel/debug/sched/preempt: "none voluntary (full)"
    uid: int = -1
    cap_eff: int = 0  # CapEff of /proc/self/status
    rtprio: tuple[int, int] = (0, 0)  # RLIMIT_RTPRIO soft, hard
    memlock: tuple[int, int] = (0, 0)  # RLIMIT_MEMLOCK soft, hard (bytes; RLIM_INFINITY: unlimited)
    vm_size_bytes: int | None = None  # VmSize of /proc/self/status (what mlockall locks)
    governors: dict[int, str] = field(default_factory=dict)  # cpu -> scaling_governor
    isolated: list[int] | None = None  # /sys/devices/system/cpu/isolated
    timer_slack_ns: int | None = None  # /proc/self/timerslack_ns


def _read(path: Path) -> str | None:
    try:
        return path.read_text().strip()
    except OSError:
        return None


def parse_cpu_list(text: str) -> list[int]:
    """A kernel CPU list ("0-2,5") as CPU numbers; "" is none."""
    cpus: list[int] = []
    for part in text.replace("\n", ",").split(","):
        part = part.strip()
        if not part:
            continue
        low, _, high = part.partition("-")
        cpus.extend(range(int(low), int(high or low) + 1))
    return cpus


def parse_status(text: str) -> dict[str, str]:
    """/proc/<pid>/status as key -> value."""
    out = {}
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep:
            out[key.strip()] = value.strip()
    return out


def read_facts(sys_root: Path = Path("/sys"), proc_root: Path = Path("/proc"), self_dir: str = "self") -> MachineFacts:
    """The facts of this machine and process (see :class:`MachineFacts`)."""
    status = parse_status(_read(proc_root / self_dir / "status") or "")
    vm_size = status.get("VmSize", "").split()
    governors = {}
    cpu_dir = sys_root / "devices" / "system" / "cpu"
    if cpu_dir.is_dir():
        for entry in sorted(cpu_dir.glob("cpu[0-9]*")):
            governor = _read(entry / "cpufreq" / "scaling_governor")
            if governor is not None:
                governors[int(entry.name[3:])] = governor
    isolated = _read(cpu_dir / "isolated")
    slack = _read(proc_root / self_dir / "timerslack_ns")
    return MachineFacts(
        kernel_version=os.uname().version,
        realtime_flag=_read(sys_root / "kernel" / "realtime"),
        preempt_mode=_read(sys_root / "kernel" / "debug" / "sched" / "preempt"),
        uid=os.geteuid(),
        cap_eff=int(status.get("CapEff", "0"), 16),
        rtprio=resource.getrlimit(resource.RLIMIT_RTPRIO),
        memlock=resource.getrlimit(resource.RLIMIT_MEMLOCK),
        vm_size_bytes=int(vm_size[0]) * 1024 if vm_size and vm_size[0].isdigit() else None,
        governors=governors,
        isolated=parse_cpu_list(isolated) if isolated is not None else None,
        timer_slack_ns=int(slack) if slack and slack.isdigit() else None,
    )


def _check(name: str, status: str, found: str, fix: str = "") -> Check:
    return Check("machine", name, status, found, fix)


def preemption(facts: MachineFacts) -> Check:
    version = facts.kernel_version
    if facts.realtime_flag == "1" or "PREEMPT_RT" in version:
        return _check("preemption", OK, "PREEMPT_RT kernel")
    fix = "a PREEMPT_RT kernel (Debian: linux-image-rt-amd64; Ubuntu: `sudo pro enable realtime-kernel`)"
    if facts.preempt_mode:  # the selected mode is the one in parentheses
        chosen = facts.preempt_mode.partition("(")[2].partition(")")[0] or facts.preempt_mode
        if chosen == "full":
            return _check("preemption", WARN, "PREEMPT_DYNAMIC in full preemption (not PREEMPT_RT)", fix)
        return _check(
            "preemption", WARN, f"PREEMPT_DYNAMIC in {chosen} preemption", "boot with preempt=full, or " + fix
        )
    if "PREEMPT_DYNAMIC" in version:
        found = (
            "PREEMPT_DYNAMIC kernel, not PREEMPT_RT (its mode is in /sys/kernel/debug/sched/preempt, not readable here)"
        )
    elif "PREEMPT" in version:
        found = "PREEMPT (low-latency desktop) kernel, not PREEMPT_RT"
    else:
        found = "no kernel preemption (server kernel), not PREEMPT_RT"
    return _check("preemption", WARN, found, fix)


def sched_fifo(facts: MachineFacts, priority: int) -> Check:
    if priority == 0:
        return _check("sched_fifo", OK, "loop.rt.priority is 0: the loop leaves the scheduler alone")
    soft, hard = facts.rtprio
    if facts.uid == 0 or facts.cap_eff >> CAP_SYS_NICE & 1:
        who = "root" if facts.uid == 0 else "CAP_SYS_NICE"
        return _check("sched_fifo", OK, f"priority {priority} allowed ({who})")
    if soft == resource.RLIM_INFINITY or soft >= priority:
        return _check("sched_fifo", OK, f"priority {priority} allowed (RLIMIT_RTPRIO {soft})")
    fix = f'`echo "$USER - rtprio 99" | sudo tee -a {LIMITS_FILE}`, then log in again'
    if hard == resource.RLIM_INFINITY or hard >= priority:
        fix = f"`ulimit -r {priority}` in the shell that runs sashil (the hard limit allows it)"
    return _check(
        "sched_fifo",
        WARN,
        f"priority {priority} not allowed (RLIMIT_RTPRIO {soft}, no CAP_SYS_NICE): the loop runs as an ordinary thread",
        fix,
    )


def _mib(value: int) -> str:
    return "unlimited" if value == resource.RLIM_INFINITY else f"{value / 2**20:.0f} MiB"


def memlock(facts: MachineFacts, wanted: bool) -> Check:
    if not wanted:
        return _check("memlock", OK, "loop.rt.mlockall is false: memory is not locked")
    soft, _ = facts.memlock
    if facts.uid == 0 or facts.cap_eff >> CAP_IPC_LOCK & 1:
        who = "root" if facts.uid == 0 else "CAP_IPC_LOCK"
        return _check("memlock", OK, f"mlockall allowed ({who}; RLIMIT_MEMLOCK {_mib(soft)})")
    need = facts.vm_size_bytes
    if soft == resource.RLIM_INFINITY or (need is not None and soft >= need):
        return _check("memlock", OK, f"RLIMIT_MEMLOCK {_mib(soft)} holds this process ({_mib(need or 0)})")
    need_text = f"this process maps {_mib(need)}" if need is not None else "the process size is unknown"
    return _check(
        "memlock",
        WARN,
        f"RLIMIT_MEMLOCK {_mib(soft)}; {need_text}: mlockall fails and the loop can page-fault",
        f'`echo "$USER - memlock unlimited" | sudo tee -a {LIMITS_FILE}`, then log in again',
    )


def governor(facts: MachineFacts, cpu: int | None) -> Check:
    if not facts.governors:
        return _check("cpu_governor", OK, "no cpufreq in sysfs (a fixed clock, or a virtual machine)")
    watched = {cpu: facts.governors[cpu]} if cpu is not None and cpu in facts.governors else facts.governors
    slow = {c: g for c, g in watched.items() if g != "performance"}
    if not slow:
        return _check("cpu_governor", OK, "performance")
    names = sorted(set(slow.values()))
    cpus = ",".join(str(c) for c in sorted(slow))
    return _check(
        "cpu_governor",
        WARN,
        f"{'/'.join(names)} on CPU {cpus}: the clock ramps up after each wake-up",
        "`sudo cpupower frequency-set -g performance`",
    )


def isolated_cpus(facts: MachineFacts, cpu: int | None) -> Check:
    isolated = facts.isolated
    if isolated is None:
        return _check("isolated_cpus", WARN, "cannot read /sys/devices/system/cpu/isolated")
    listed = ",".join(map(str, isolated))
    if cpu is not None:
        if cpu in isolated:
            return _check("isolated_cpus", OK, f"loop.rt.cpu {cpu} is isolated ({listed})")
        return _check(
            "isolated_cpus",
            WARN,
            f"loop.rt.cpu {cpu} is not isolated (isolated: {listed or 'none'}): other work shares it",
            f"boot with isolcpus={cpu} nohz_full={cpu} rcu_nocbs={cpu}",
        )
    if isolated:
        return _check(
            "isolated_cpus",
            WARN,
            f"CPU {listed} isolated but the loop is not pinned (loop.rt.cpu null)",
            f"--set loop.rt.cpu={isolated[-1]}",
        )
    return _check(
        "isolated_cpus",
        WARN,
        "no CPU isolated and the loop is not pinned: it shares every CPU",
        "boot with isolcpus=1 nohz_full=1 rcu_nocbs=1 and set loop.rt.cpu: 1",
    )


def timer_slack(facts: MachineFacts, configured_ns: int) -> Check:
    now = facts.timer_slack_ns
    now_text = "unknown" if now is None else f"{now} ns"
    if configured_ns:
        return _check("timer_slack", OK, f"{now_text} now; the loop sets {configured_ns} ns (loop.rt.timer_slack_ns)")
    if now is not None and now <= 1000:
        return _check("timer_slack", OK, f"{now_text} (loop.rt.timer_slack_ns 0: left as it is)")
    return _check(
        "timer_slack",
        WARN,
        f"{now_text}, left as it is (loop.rt.timer_slack_ns 0): each sleep may end that much late",
        "--set loop.rt.timer_slack_ns=1",
    )


def machine_checks(facts: MachineFacts, rt: LoopRtPart) -> list[Check]:
    """Every machine check for the config's ``loop.rt`` set-up."""
    return [
        preemption(facts),
        sched_fifo(facts, rt.priority),
        memlock(facts, rt.mlockall),
        governor(facts, rt.cpu),
        isolated_cpus(facts, rt.cpu),
        timer_slack(facts, rt.timer_slack_ns),
    ]


__all__ = ["FAIL", "MachineFacts", "machine_checks", "parse_cpu_list", "read_facts"]
