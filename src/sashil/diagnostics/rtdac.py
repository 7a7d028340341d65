"""``sashil doctor --driver rtdac``: find the RT-DAC/USB2, read its header, time the exchange, and
(``--walk``) name the rig's channels with the operator.

The walk asks the operator at the terminal, one step at a time, each ended with both outputs at
rest: move the arm by hand through a known angle (which counter moved, counts per degree and
sign); a short low-duty coil pulse (which A/D rose); the road motor at a low output (which other
counter moved). Between the answers the board is read continuously. What it finds becomes a
fragment of the ``rtdac`` section for the lab to review.
"""

from __future__ import annotations

import math
import select
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TextIO

import yaml

from sashil.diagnostics import FAIL, OK, WARN, Check
from sashil.drivers.rtdac_bus import LOOP_SHARE, highest_rate_hz
from sashil.drivers.rtdac_codec import ad_volts, counter32
from sashil.drivers.rtdac_rig import RtdacRig
from sashil.drivers.rtdac_usb import UDEV_FILE, UDEV_RULE, BoardLink, describe_device
from sashil.errors import DriverError, SashilError

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec

#: what the walk's pulses drive: a low duty, or a low voltage
PULSE_DUTY = 0.1
PULSE_VOLTS = 1.0
PULSE_S = 0.3
ROAD_S = 1.0

NO_WATCHDOG = (
    "the RT-DAC/USB2 has no watchdog: it keeps its last outputs when the host goes quiet. sashil rests the coil "
    "and the road motor and checks the board's readback on every stop it runs (a signal, a fault, a law that "
    "raises, the loop process killed); it cannot when both of its processes die or the cable is pulled"
)
E_STOP = "wire the rig's hardware E-stop to cut the coil's and the road motor's power; keep it in reach"


def exchange_times(rig: RtdacRig, n: int) -> list[float]:
    """``n`` exchanges (write frame, read request, read frame) with the outputs at rest, each timed [s]."""
    times = []
    for _ in range(n):
        start = time.perf_counter()
        rig.exchange()
        times.append(time.perf_counter() - start)
    return times


def exchange_checks(rig: RtdacRig, n: int, rate_hz: float) -> list[Check]:
    """The exchange's round trip (median, p99) and the highest loop rate it leaves room for."""
    times = sorted(exchange_times(rig, n))
    median = statistics.median(times)
    p99 = times[min(len(times) - 1, math.ceil(0.99 * len(times)) - 1)]
    data = {
        "n": n,
        "median_us": round(median * 1e6, 1),
        "p99_us": round(p99 * 1e6, 1),
        "max_us": round(times[-1] * 1e6, 1),
    }
    highest = highest_rate_hz(p99)
    data["highest_rate_hz"] = highest
    round_trip = Check(
        "board", "exchange", OK, f"{n} exchanges: median {data['median_us']:g} us, p99 {data['p99_us']:g} us", data=data
    )
    ok = highest >= rate_hz
    rate = Check(
        "board",
        "rate",
        OK if ok else WARN,
        f"the exchange leaves room for {highest} Hz (p99 and {LOOP_SHARE:.0%} of a period for the loop); "
        f"loop.rate_hz is {rate_hz:g}",
        "" if ok else f"--set loop.rate_hz={highest} (or a faster USB port: no hub, a USB 2 port of its own)",
    )
    return [round_trip, rate]


def board_checks(run: RunSpec, round_trips: int) -> tuple[list[Check], RtdacRig | None]:
    """Find and open the board, read its header and map, time the exchange; the rig is left open
    (outputs at rest) for the walk, or None when it could not be opened."""
    rig = RtdacRig.from_parts(run.rig.values)
    checks: list[Check] = []
    try:
        rig.configure()
    except SashilError as err:
        text = str(err)
        fix = ""
        if "permission denied" in text:
            fix = f"echo '{UDEV_RULE}' | sudo tee {UDEV_FILE} && sudo udevadm control --reload, then replug"
        elif "another program holds" in text:
            fix = "close the other program (MATLAB/Simulink, INTECO's toolbox, another sashil)"
        elif "no RT-DAC/USB2 found" in text:
            fix = "plug the board in and power it; lsusb lists it"
        elif "USB link" in text:
            fix = "plug the board into a high-speed (USB 2.0) port with no USB 1.1 hub between; lsusb -t shows 480M"
        checks.append(Check("board", "usb", FAIL, text, fix))
        rig.close()
        return checks, None
    assert rig.header is not None and rig.map is not None
    where = describe_device(rig.link.dev)
    checks.append(Check("board", "usb", OK, f"RT-DAC/USB2 at {where}"))
    checks.append(link_check(rig.link, run.loop.rate_hz))
    checks.append(
        Check(
            "board",
            "header",
            OK,
            rig.header.describe(),
            data={"logic": rig.header.logic, "application": rig.header.application},
        )
    )
    checks.append(Check("board", "register map", OK, rig.map.describe()))
    checks += exchange_checks(rig, round_trips, run.loop.rate_hz)
    checks.append(Check("board", "safe stop", WARN, NO_WATCHDOG, E_STOP))
    return checks, rig


def link_check(link: BoardLink, rate_hz: float) -> Check:
    """What the board said of itself at open (ids, strings, speed, stale frames) and whether its bus
    carries ``rate_hz``."""
    limit = link.max_rate_hz
    ok = limit is None or rate_hz <= limit
    fix = "" if ok else f"a high-speed (USB 2.0) port with no USB 1.1 hub between, or --set loop.rate_hz={limit}"
    return Check("board", "link", OK if ok else WARN, link.summary(), fix, data=link.facts())


# the walk ------------------------------------------------------------------------------------------
@dataclass
class Walk:
    """The operator's walk through the channels (module docstring)."""

    rig: RtdacRig
    ask: Callable[[str], str | None]
    say: Callable[[str], None]
    found: dict[str, Any] = field(default_factory=dict)

    def _words(self) -> tuple[int, ...]:
        return self.rig.exchange()

    def _counters(self, words: tuple[int, ...]) -> list[int]:
        reg = self.rig.map
        assert reg is not None
        count = (self.rig.header.modules.get("encoder_i") if self.rig.header else None) or reg.encoder_count
        return [counter32(words[lo], words[hi]) for lo, hi in (reg.counter_words(i) for i in range(count))]

    def _ads(self, words: tuple[int, ...]) -> list[float]:
        reg = self.rig.map
        assert reg is not None
        return [ad_volts(words[reg.ad_value_word(i)]) for i in range(reg.ad_count)]

    def _rest(self) -> None:
        self.rig.rest_outputs()
        self._words()

    def _set(self, kind: str, channel: int, value: float) -> None:
        self.rig.set_output(kind, channel, value)

    def arm(self) -> None:
        answer = self.ask(
            "move the arm by hand through a known angle and hold it there; then type that angle in degrees "
            "(positive: the way theta2 rises) and press Enter, or s to skip: "
        )
        start = self._counters(self._words())
        end, answer = self._watch(start, answer)
        if answer is None:
            return
        try:
            angle = float(answer)
        except ValueError:
            self.say(f"  '{answer}' is not an angle in degrees: the arm step is skipped")
            return
        moved = [e - s for s, e in zip(start, end, strict=True)]
        channel = max(range(len(moved)), key=lambda i: abs(moved[i]))
        if moved[channel] == 0 or angle == 0.0:
            self.say("  no counter moved: the arm step found nothing")
            return
        per_degree = moved[channel] / angle
        self.found.update(
            arm_encoder=channel,
            arm_counts_per_rev=round(abs(per_degree) * 360.0),
            arm_reversed=per_degree < 0,
        )
        self.say(
            f"  the arm is counter {channel}: {moved[channel]:+d} counts for {angle:g} deg, "
            f"{abs(per_degree):.3f} counts/deg ({self.found['arm_counts_per_rev']} a revolution)"
            + (", counting down" if per_degree < 0 else "")
        )

    def _watch(self, start: list[int], answer: str | None) -> tuple[list[int], str | None]:
        """Read the board until the operator's answer (the ask returned None: still waiting)."""
        end = start
        while answer is None:
            end = self._counters(self._words())
            answer = self.ask("")
        if answer.strip().lower() in ("s", "skip", "q"):
            return end, None
        return self._counters(self._words()), answer.strip()

    def coil(self) -> None:
        rig = self.rig
        kind, channel = rig.wiring.coil_output, rig.wiring.coil_channel
        level = PULSE_DUTY if kind == "pwm" else PULSE_VOLTS
        shown = f"duty {level:.0%}" if kind == "pwm" else f"{level:g} V"
        if not self._confirm(
            f"press Enter to pulse the coil ({kind} {channel}) at {shown} for {PULSE_S:g} s, or s to skip: "
        ):
            return
        before = self._ads(self._words())
        peak = list(before)
        try:
            self._set(kind, channel, level)
            end = time.monotonic() + PULSE_S
            while time.monotonic() < end:
                peak = [max(p, v) for p, v in zip(peak, self._ads(self._words()), strict=True)]
        finally:
            self._rest()
        rise = [p - b for p, b in zip(peak, before, strict=True)]
        channel_ad = max(range(len(rise)), key=lambda i: rise[i])
        if rise[channel_ad] < 0.05:
            self.say("  no A/D rose by 50 mV: no coil current sense found (rtdac.coil_sense_ad: null)")
            self.found["coil_sense_ad"] = None
            return
        self.found["coil_sense_ad"] = channel_ad
        self.say(f"  the coil current is A/D {channel_ad}: it rose {rise[channel_ad]:.3f} V (coil at rest again)")

    def road(self) -> None:
        rig = self.rig
        kind, channel = rig.wiring.road_output, rig.wiring.road_channel
        if kind == "none":
            return
        level = PULSE_DUTY if kind == "pwm" else PULSE_VOLTS
        shown = f"duty {level:.0%}" if kind == "pwm" else f"{level:g} V"
        if not self._confirm(
            f"press Enter to run the road motor ({kind} {channel}) at {shown} for {ROAD_S:g} s, or s to skip: "
        ):
            return
        start = self._counters(self._words())
        trace: list[tuple[float, list[int]]] = []
        try:
            self._set(kind, channel, level)
            t0 = time.monotonic()
            while time.monotonic() < t0 + ROAD_S:
                trace.append((time.monotonic() - t0, self._counters(self._words())))
        finally:
            self._rest()
        moved = [e - s for s, e in zip(start, self._counters(self._words()), strict=True)]
        arm = self.found.get("arm_encoder", rig.wiring.arm_encoder)
        others = [i for i in range(len(moved)) if i != arm]
        channel_enc = max(others, key=lambda i: abs(moved[i]))
        if moved[channel_enc] == 0:
            self.say("  no counter but the arm's moved: no road encoder found")
            return
        self.found.update(road_encoder=channel_enc, road_reversed=moved[channel_enc] * level < 0)
        self.say(f"  the road wheel is counter {channel_enc}: {moved[channel_enc]:+d} counts (motor at rest again)")
        per_rev = self.found.get("road_counts_per_rev", rig.wiring.road_counts_per_rev)
        step = road_step(trace, channel_enc, start[channel_enc], per_rev, level)
        if step is not None:
            gain, lag = step
            self.found.update(road_output_per_rad_s=round(1.0 / gain, 6), road_lag_s=round(lag, 4))
            self.say(
                f"  the road motor turns {gain:.3g} rad/s per {'unit duty' if kind == 'pwm' else 'V'}, "
                f"with a lag of {lag * 1e3:.0f} ms (road_output_per_rad_s, road_lag_s; counts per revolution "
                f"taken as {per_rev})"
            )

    def _confirm(self, prompt: str) -> bool:
        answer = self.ask(prompt)
        while answer is None:
            self._words()
            answer = self.ask("")
        return answer.strip().lower() not in ("s", "skip", "q")


def road_step(
    trace: list[tuple[float, list[int]]], channel: int, start: int, counts_per_rev: int, level: float
) -> tuple[float, float] | None:
    """The road motor's step response from the walk's trace: its steady speed per unit of output
    (the mean over the trace's last 40 %) and its time constant (where the angle's path meets the
    first-order response's: at steady speed it runs ``lag`` behind a motor with none)."""
    if len(trace) < 10 or level == 0.0:
        return None
    times = [t for t, _ in trace]
    angles = [(counts[channel] - start) * 2.0 * math.pi / counts_per_rev for _, counts in trace]
    tail = int(0.6 * len(trace))
    if times[-1] - times[tail] <= 0.0:
        return None
    speed = (angles[-1] - angles[tail]) / (times[-1] - times[tail])
    if abs(speed) < 1e-6:
        return None
    # a first-order motor's angle at steady speed: speed * (t - lag); the line through the tail's points
    lag = times[-1] - angles[-1] / speed
    return abs(speed / level), max(lag, 0.0)


def terminal_asker(stream: TextIO = sys.stdin, out: TextIO = sys.stdout) -> Callable[[str], str | None]:
    """An ask that prints its prompt once and returns the operator's line, or None while none has come
    (so the walk keeps reading the board between the operator's keys)."""

    def ask(prompt: str) -> str | None:
        if prompt:
            out.write(prompt)
            out.flush()
        ready, _, _ = select.select([stream], [], [], 0.002)
        if not ready:
            return None
        line = stream.readline()
        if not line:
            return "s"  # the input ended: skip what is left
        if not stream.isatty():
            out.write(line)  # a scripted answer: shown where a terminal would echo it
        return line.rstrip("\n")

    return ask


def walk_checks(
    rig: RtdacRig, fragment_path: str, ask: Callable[[str], str | None], say: Callable[[str], None]
) -> list[Check]:
    """The operator's walk, then the fragment written for review; both outputs at rest at the end."""
    walk = Walk(rig, ask, say)
    try:
        walk.arm()
        walk.coil()
        walk.road()
    finally:
        walk._rest()
    if not walk.found:
        return [Check("walk", "channels", WARN, "the walk found nothing (every step skipped or nothing moved)")]
    fragment = {"driver": {"name": "rtdac"}, "rtdac": walk.found}
    text = "# the RT-DAC wiring sashil doctor --walk found: review it before a run\n" + yaml.safe_dump(
        fragment, sort_keys=False
    )
    try:
        with open(fragment_path, "w", encoding="utf-8") as handle:
            handle.write(text)
    except OSError as err:
        raise DriverError(f"--fragment {fragment_path}: cannot write ({err.strerror})") from None
    found = ", ".join(f"{k}={v}" for k, v in walk.found.items())
    return [Check("walk", "channels", OK, f"{found}; written to {fragment_path}", data=dict(walk.found))]


def rtdac_checks(
    run: RunSpec,
    round_trips: int,
    walk: bool = False,
    fragment_path: str = "rtdac-wiring.yaml",
    ask: Callable[[str], str | None] | None = None,
    say: Callable[[str], None] | None = None,
) -> list[Check]:
    """The board's checks, and the walk on request; the board is left with both outputs at rest."""
    checks, rig = board_checks(run, round_trips)
    if rig is None:
        return checks
    try:
        if walk:
            checks += walk_checks(rig, fragment_path, ask or terminal_asker(), say or print)
    finally:
        rig.deactivate()
        confirmed = rig.safe_state.get("safe_state_confirmed")
        rig.close()
    checks.append(
        Check(
            "board",
            "at rest",
            OK if confirmed else FAIL,
            "both outputs at rest, confirmed by the board's readback"
            if confirmed
            else "the readback did not confirm both outputs at rest",
            "" if confirmed else E_STOP,
        )
    )
    return checks
