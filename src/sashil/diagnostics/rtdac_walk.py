"""The RT-DAC walk: finds the rig's wiring on an INTECO RT-DAC/USB2 with the operator at the terminal.

Nothing of the config's wiring is trusted; four steps, in order, each announced, each that drives an
output asked first (y/n) and ended with every output at rest:

1. **The arm's encoder** (nothing driven): the operator holds the arm at a marked angle
   (``--arm-deg``, the drop test's -5 deg marker by default), then lets it come to rest at 0 deg; the
   counter that moved is the arm's, its counts over the travel its counts per revolution and sign.
2. **The outputs**: every PWM channel the board has and every D/A channel, one at a time, a short
   low pulse (:data:`PULSE`, :data:`PULSE_S`) while every A/D and every counter is read. An output
   that raises an A/D and turns no counter is the coil's (the A/D its current sense); one that turns
   a counter other than the arm's steadily is the road motor's (the counter its encoder, its sense
   under a positive output theta1's). An output that moves nothing is said so. A pulse that turns
   the arm more than :data:`ARM_GUARD_DEG` or another counter more than :data:`ROAD_GUARD_DEG` ends
   at once, at rest.
3. **The road wheel's revolution**: the operator marks the wheel; the road motor turns it at the
   pulse's output until the operator says the mark is round (or the operator turns it by hand): the
   road encoder's counts per revolution; the motor's speed per output and lag from the same run.
4. **The coil's map**: the coil's output in steps of a tenth of full (0, 0.1, 0.2, ... duty, or
   0, 1, 2, ... V) while the found sense is read, to the bring-up cap: the map's points. The A/D
   reads volts, so the current needs the sense's scale: ``--sense-a-per-v``, typed at the prompt,
   or a clamp meter's reading at the first step.

Every level stays under the config's bring-up caps (:func:`~sashil.diagnostics.rtdac_findings.output_caps`),
which apply to the whole walk since nothing is confirmed while it runs. What a step finds goes into
:attr:`Walk.found`, and its wiring keys into :attr:`Walk.confirmed`; a step skipped or failed adds
neither. What the walk does not find: a PWM road motor's direction bit (it drives one way), a coil
with no current sense (no A/D moves), anything on the digital outputs, and the board's own settings
(PWM prescaler and mode, A/D gains), which stay as configured.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from sashil.config.rtdac_section import WIRING_KEYS
from sashil.diagnostics.rtdac_findings import (
    CoilFinding,
    NotFound,
    PulseEffect,
    PulseTrace,
    RoadFinding,
    coil_map,
    find_arm,
    find_coil,
    find_revolution,
    find_road,
    meter_scale,
    output_caps,
    output_name,
    pulse_effect,
    road_step,
)
from sashil.drivers.rtdac_codec import AD_BUSY_BIT, AD_GAINS, ad_volts, counter32
from sashil.drivers.rtdac_rig import RtdacRig

TWO_PI = 6.283185307179586
#: the walk reads the board every SAMPLE_S (an exchange, then a wait to the next tick)
SAMPLE_S = 0.002
#: each output's pulse: a low duty, or a low voltage, for PULSE_S (at most the bring-up caps)
PULSE = {"pwm": 0.10, "da": 0.30}
PULSE_S = 0.3
#: read at rest before a pulse (the A/Ds' level and spread) and after it (the coil decays, the road stops)
REST_S = 0.1
#: before each pulse every counter must stand still for SETTLE_S (the arm swings on after a road
#: pulse), waited for at most SETTLE_MAX_S
SETTLE_S = 0.3
SETTLE_MAX_S = 20.0
#: a pulse ends at once when the arm turns this far, or another counter this far (in the config's
#: road_counts_per_rev, the only scale known before step 3)
ARM_GUARD_DEG = 15.0
ROAD_GUARD_DEG = 45.0
#: the coil's map: steps of this much of full output, each held STEP_S; the sense read over its last half
STEP = {"pwm": 0.1, "da": 1.0}
STEP_S = 0.3
#: a step whose sensed current passes the bring-up cap by this factor ends at once
CURRENT_GUARD = 1.1
#: the road motor's revolution run stops by itself after this long
REVOLUTION_MAX_S = 120.0
#: readings averaged for a held position
HELD_SAMPLES = 25

COIL_FOUND = ("coil_output", "coil_channel", "coil_sense_ad")
ROAD_FOUND = ("road_output", "road_channel", "road_encoder", "road_reversed")
ARM_FOUND = ("arm_encoder", "arm_counts_per_rev", "arm_reversed")
MAP_FOUND = ("coil_map_current_a", "coil_map_output", "coil_sense_a_per_v")
SKIP = ("s", "skip", "n", "no", "q")


@dataclass
class WalkOptions:
    """What the operator gives on the command line."""

    #: the arm's marked angle [deg] (theta2; the arm rests at 0)
    arm_deg: float = -5.0
    #: the coil sense's scale [A/V], if known (else asked)
    sense_a_per_v: float | None = None


@dataclass
class Walk:
    """The walk (module docstring): ``ask(prompt)`` shows a prompt (``""``: none) and returns the
    operator's line, or None while none has come; ``clock``/``sleep`` pace the board's reads."""

    rig: RtdacRig
    ask: Callable[[str], str | None]
    say: Callable[[str], None]
    options: WalkOptions = field(default_factory=WalkOptions)
    clock: Callable[[], float] = time.monotonic
    sleep: Callable[[float], None] = time.sleep
    found: dict[str, Any] = field(default_factory=dict)
    confirmed: set[str] = field(default_factory=set)
    #: each step's outcome: (step, found something, what it said)
    outcomes: list[tuple[str, bool, str]] = field(default_factory=list)
    effects: list[PulseEffect] = field(default_factory=list)
    coil: CoilFinding | None = None
    road: RoadFinding | None = None
    _road_trace: PulseTrace | None = None
    _next: float = 0.0
    #: the clock when the last exchange's read frame came [s]
    read_at: float = 0.0

    # the board ------------------------------------------------------------------------------------
    @property
    def outputs(self) -> list[tuple[str, int]]:
        """Every PWM channel the board's header (else its map) has, then every D/A channel."""
        reg, header = self.rig.map, self.rig.header
        assert reg is not None
        pwm = (header.modules.get("pwm") if header else None) or reg.pwm_count
        return [("pwm", k) for k in range(pwm)] + [("da", k) for k in range(reg.da_count)]

    def _tick(self) -> tuple[int, ...]:
        """One exchange, then the wait to the next tick of SAMPLE_S."""
        words = self.rig.exchange()
        now = self.read_at = self.clock()
        self._next = max(self._next + SAMPLE_S, now)
        if self._next > now:
            self.sleep(self._next - now)
        return words

    def _counts(self, words: tuple[int, ...]) -> list[int]:
        reg = self.rig.map
        assert reg is not None
        count = (self.rig.header.modules.get("encoder_i") if self.rig.header else None) or reg.encoder_count
        return [counter32(words[lo], words[hi]) for lo, hi in (reg.counter_words(i) for i in range(count))]

    def _ads(self, words: tuple[int, ...], last: list[float] | None = None) -> list[float]:
        """Every A/D's volts at its input, at the gain the board has set for it (a conversion under
        way: its last value stands)."""
        reg = self.rig.map
        assert reg is not None
        values = []
        for i in range(reg.ad_count):
            word = words[reg.ad_value_word(i)]
            gain_word, shift = reg.ad_gain_word(i)
            gain = min((words[gain_word] >> shift) & 0x7, len(AD_GAINS) - 1)
            values.append(last[i] if last is not None and word & AD_BUSY_BIT else ad_volts(word, gain))
        return values

    def _held_counts(self) -> list[float]:
        rows = [self._counts(self._tick()) for _ in range(HELD_SAMPLES)]
        return [statistics.fmean(col) for col in zip(*rows, strict=True)]

    def rest(self) -> None:
        """Every output the walk may drive at rest (duty 0, 0 V), sent at once."""
        for kind, channel in self.outputs:
            self.rig.set_output(kind, channel, 0.0)
        self.rig.rest_outputs()
        self._tick()

    def at_rest(self) -> bool:
        """The board's readback: every output's register as :meth:`rest` wrote it (duty 0, the D/A's
        0 V word; the config's coil and road outputs at their rest)."""
        reg = self.rig.map
        assert reg is not None
        frame = self.rig.exchange_frame()
        words = self._tick()
        for kind, k in self.outputs:
            word = reg.pwm_width_word(k) if kind == "pwm" else reg.da_word(k)
            if words[word] != int.from_bytes(frame[2 * word : 2 * word + 2], "little"):
                return False
        return True

    # the operator ---------------------------------------------------------------------------------
    def _answer(self, prompt: str) -> str:
        """The operator's line (the board read while it comes)."""
        answer = self.ask(prompt)
        while answer is None:
            self._tick()
            answer = self.ask("")
        return answer.strip()

    def _yes(self, prompt: str) -> bool:
        return self._answer(prompt).lower() in ("y", "yes")

    def _outcome(self, step: str, ok: bool, text: str) -> None:
        self.outcomes.append((step, ok, text))
        self.say(f"  {text}")

    def _confirm(self, keys: Sequence[str], values: dict[str, Any]) -> None:
        self.found.update(values)
        self.confirmed.update(keys)

    # the steps ------------------------------------------------------------------------------------
    def run(self) -> None:
        """The four steps in order; every output at rest at the end, whatever happens."""
        try:
            self.rest()
            self._intro()
            self.arm()
            self.scan()
            self.revolution()
            self.coil_map()
        finally:
            self.rest()

    def _intro(self) -> None:
        reg = self.rig.map
        assert reg is not None
        caps = output_caps(self.rig.wiring)
        pwm = sum(kind == "pwm" for kind, _ in self.outputs)
        self.say(
            "the walk finds the rig's wiring on this board; it trusts none of the config's.\n"
            "Each step that drives an output asks first (y/n) and ends with every output at rest. "
            "Keep the E-stop in reach."
        )
        self.say(
            f"  the board: {pwm} PWM, {reg.da_count} D/A, {len(self._counts(self._tick()))} counters, "
            f"{reg.ad_count} A/D; every PWM at duty 0 and every D/A at 0 V"
        )
        self.say(
            f"  the walk's outputs stay under the bring-up caps (rtdac.bringup_current_max_a "
            f"{self.rig.wiring.bringup_current_max_a:g} A, rtdac.bringup_road_output "
            f"{self.rig.wiring.bringup_road_output:g}): at most duty {caps['pwm']:.2f}, {caps['da']:.2f} V"
        )

    def arm(self) -> None:
        deg = self.options.arm_deg
        self.say("\nstep 1 of 4: the arm's encoder (nothing is driven)")
        if self._answer(f"  hold the arm at the {deg:g} deg marker, then press Enter (s: skip): ").lower() in SKIP:
            self._outcome("arm", False, "skipped: the arm's keys stay unconfirmed")
            return
        marker = self._held_counts()
        if self._answer("  let the arm go; when it rests at 0 deg, press Enter (s: skip): ").lower() in SKIP:
            self._outcome("arm", False, "skipped: the arm's keys stay unconfirmed")
            return
        rest = self._held_counts()
        try:
            arm = find_arm(marker, rest, deg)
        except NotFound as err:
            self._outcome("arm", False, f"{err}: the arm's keys stay unconfirmed")
            return
        self._confirm(
            ARM_FOUND,
            {"arm_encoder": arm.encoder, "arm_counts_per_rev": arm.counts_per_rev, "arm_reversed": arm.reversed},
        )
        self._outcome(
            "arm",
            True,
            f"the arm is counter {arm.encoder}: {arm.counts:+d} counts for {arm.travel_deg:+g} deg, "
            f"{arm.counts_per_rev} counts a revolution (one count in {abs(arm.counts)}: "
            f"{100.0 / abs(arm.counts):.1f} %; a wider marker angle measures it finer)"
            + (", counting down as theta2 rises" if arm.reversed else ""),
        )

    def _pulse_levels(self) -> dict[str, float]:
        caps = output_caps(self.rig.wiring)
        return {kind: min(PULSE[kind], caps[kind]) for kind in PULSE}

    def scan(self) -> None:
        levels = self._pulse_levels()
        self.say("\nstep 2 of 4: what each output drives")
        self.say(
            f"  each of {', '.join(output_name(k, c) for k, c in self.outputs)} in turn: "
            f"duty {levels['pwm']:.2f} (PWM) or {levels['da']:.2f} V (D/A) for {PULSE_S:g} s while every A/D "
            f"and counter is read, then at rest; a pulse that turns the arm {ARM_GUARD_DEG:g} deg or another "
            f"counter {ROAD_GUARD_DEG:g} deg (at the config's rtdac.road_counts_per_rev) ends at once"
        )
        if not self._yes("  pulse each output in turn? (y/n): "):
            self._outcome("outputs", False, "skipped: the coil's and the road's channels stay unconfirmed")
            return
        arm = self.found.get("arm_encoder")
        for kind, channel in self.outputs:
            trace = self._pulse(kind, channel, levels[kind])
            effect = pulse_effect(trace, arm)
            self.effects.append(effect)
            self.say(f"    {describe_effect(effect)}")
            if effect.counter is not None:
                self._road_trace = trace
        self._classify(arm is not None)

    def _classify(self, arm_known: bool) -> None:
        try:
            coil = find_coil(self.effects)
            self.coil = coil
            self._confirm(
                COIL_FOUND, {"coil_output": coil.kind, "coil_channel": coil.channel, "coil_sense_ad": coil.sense_ad}
            )
            self._outcome(
                "coil",
                True,
                f"the coil is {output_name(coil.kind, coil.channel)}, its current sense A/D {coil.sense_ad}",
            )
        except NotFound as err:
            self._outcome("coil", False, f"{err}: the coil's channels stay unconfirmed")
        try:
            road = find_road(self.effects, arm_known)
            self.road = road
            values: dict[str, Any] = {
                "road_output": road.kind,
                "road_channel": road.channel,
                "road_encoder": road.encoder,
                "road_reversed": road.reversed,
            }
            if road.kind == "pwm":
                values["road_output_limit"] = 1.0  # a duty: the section's check for a PWM road
            self._confirm(ROAD_FOUND, values)
            self._outcome(
                "road",
                True,
                f"the road motor is {output_name(road.kind, road.channel)}, its encoder counter {road.encoder}"
                + (" (counting down as the motor turns forward)" if road.reversed else "")
                + ("; it turns one way (a direction bit is not searched)" if road.kind == "pwm" else ""),
            )
        except NotFound as err:
            self._outcome("road", False, f"{err}: the road's channels stay unconfirmed")

    def _guard(self, start: list[int], now: list[int]) -> str:
        """Why the pulse must end now ("": it may go on)."""
        w = self.rig.wiring
        arm = self.found.get("arm_encoder", w.arm_encoder)
        arm_cpr = self.found.get("arm_counts_per_rev", w.arm_counts_per_rev)
        for i, (a, b) in enumerate(zip(start, now, strict=True)):
            if i == arm and abs(b - a) > ARM_GUARD_DEG / 360.0 * arm_cpr:
                return f"the arm (counter {i}) turned {(b - a) * 360.0 / arm_cpr:+.0f} deg"
            if i != arm and abs(b - a) > ROAD_GUARD_DEG / 360.0 * w.road_counts_per_rev:
                return f"counter {i} turned {b - a:+d} counts"
        return ""

    def _settle(self) -> bool:
        """Read until no counter has changed for SETTLE_S (False: not within SETTLE_MAX_S)."""
        t0 = self.clock()
        last = self._counts(self._tick())
        still_since = t0
        while self.clock() - t0 < SETTLE_MAX_S:
            now = self._counts(self._tick())
            if now != last:
                last, still_since = now, self.clock()
            elif self.clock() - still_since >= SETTLE_S:
                return True
        return False

    def _pulse(self, kind: str, channel: int, level: float) -> PulseTrace:
        """One output at ``level`` for PULSE_S (or until a guard), read throughout; at rest after."""
        if not self._settle():
            self.say(f"    the counters did not stand still for {SETTLE_S:g} s within {SETTLE_MAX_S:g} s")
        rest_ads: list[list[float]] = []
        words = self._tick()
        for _ in range(round(REST_S / SAMPLE_S)):
            words = self._tick()
            rest_ads.append(self._ads(words, rest_ads[-1] if rest_ads else None))
        start = self._counts(words)
        trace = PulseTrace(kind, channel, level, rest_ads, start, [], [], [])
        last = rest_ads[-1]
        try:
            self.rig.set_output(kind, channel, level)
            t0 = self.clock()
            while True:
                words = self._tick()
                counts = self._counts(words)
                last = self._ads(words, last)
                trace.times.append(self.read_at - t0)
                trace.counts.append(counts)
                trace.ads.append(last)
                trace.stopped = self._guard(start, counts)
                if trace.stopped or trace.times[-1] >= PULSE_S:
                    break
        finally:
            self.rig.set_output(kind, channel, 0.0)
            self.rig.rest_outputs()
            self._tick()
        for _ in range(round(REST_S / SAMPLE_S)):
            self._tick()
        return trace

    def revolution(self) -> None:
        self.say("\nstep 3 of 4: the road wheel's counts per revolution")
        road = self.road
        arm = self.found.get("arm_encoder")
        if road is None and arm is None:
            self._outcome("revolution", False, "needs the road's or the arm's counter (steps 1-2): skipped")
            return
        choices = ["  put a mark on the road wheel against a fixed pointer, then choose:"]
        if road is not None:
            level = self._pulse_levels()[road.kind]
            choices.append(
                f"    m: {output_name(road.kind, road.channel)} turns the wheel at {level:.2f}"
                f"{' duty' if road.kind == 'pwm' else ' V'}; press Enter as the mark comes back to the pointer "
                f"(the motor stops then, or by itself after {REVOLUTION_MAX_S:g} s)"
            )
        choices.append(
            "    h: you turn the wheel by hand (the motor unpowered) one revolution, mark to mark, then Enter"
        )
        self.say("\n".join(choices))
        choice = self._answer("  m, h or s (skip): " if road is not None else "  h or s (skip): ").lower()
        run: tuple[list[float], list[int], float] | None = None
        if choice == "m" and road is not None:
            counts, run = self._motor_revolution(road)
        elif choice == "h":
            counts = self._hand_revolution(road, arm)
            trace = self._road_trace
            if road is not None and trace is not None and not trace.stopped:
                run = (
                    trace.times,
                    [c[road.encoder] - trace.start_counts[road.encoder] for c in trace.counts],
                    trace.level,
                )
        else:
            self._outcome("revolution", False, "skipped: rtdac.road_counts_per_rev stays unconfirmed")
            return
        if counts is None:
            return
        self._confirm(("road_counts_per_rev",), {"road_counts_per_rev": counts})
        how = ""
        if choice == "m" and run is not None and run[0][-1] > 0.0:
            per_s = abs(run[1][-1]) / run[0][-1]
            how = (
                f" (the motor turned {per_s:.0f} counts/s: each 0.1 s early or late at Enter is "
                f"{0.1 * per_s:.0f} counts; h, the mark lined up by hand with the wheel still, is finer)"
            )
        self._outcome("revolution", True, f"the road wheel: {counts} counts a revolution{how}")
        if run is not None:
            self._motor_step(*run, counts)

    def _motor_revolution(self, road: RoadFinding) -> tuple[int | None, tuple[list[float], list[int], float]]:
        """The motor turns the wheel until the operator's Enter: the revolution's counts, and the run."""
        level = self._pulse_levels()[road.kind]
        start = self._counts(self._tick())
        times: list[float] = []
        counts: list[int] = []
        answer: str | None = None
        try:
            self.rig.set_output(road.kind, road.channel, level)
            t0 = self.clock()
            answer = self.ask("  the wheel turns: press Enter as the mark comes back to the pointer (s: stop): ")
            while answer is None:
                now = self._counts(self._tick())
                times.append(self.read_at - t0)
                counts.append(now[road.encoder] - start[road.encoder])
                if times[-1] > REVOLUTION_MAX_S:
                    break
                answer = self.ask("")
        finally:
            self.rig.set_output(road.kind, road.channel, 0.0)
            self.rig.rest_outputs()
            self._tick()
        for _ in range(round(REST_S / SAMPLE_S)):
            self._tick()
        if answer is None or answer.strip().lower() in SKIP or not counts:
            self._outcome(
                "revolution", False, "stopped before the mark came round: rtdac.road_counts_per_rev stays unconfirmed"
            )
            return None, (times, counts, level)
        end = list(start)
        end[road.encoder] += counts[-1]
        try:
            per_rev = find_revolution(start, end, road.encoder, self.found.get("arm_encoder"))
        except NotFound as err:
            self._outcome("revolution", False, f"{err}: rtdac.road_counts_per_rev stays unconfirmed")
            return None, (times, counts, level)
        return per_rev, (times, counts, level)

    def _hand_revolution(self, road: RoadFinding | None, arm: int | None) -> int | None:
        start = self._counts(self._tick())
        if self._answer("  turn the wheel one revolution, mark to mark, then press Enter (s: skip): ").lower() in SKIP:
            self._outcome("revolution", False, "skipped: rtdac.road_counts_per_rev stays unconfirmed")
            return None
        end = self._counts(self._tick())
        try:
            return find_revolution(start, end, road.encoder if road else None, arm)
        except NotFound as err:
            self._outcome("revolution", False, f"{err}: rtdac.road_counts_per_rev stays unconfirmed")
            return None

    def _motor_step(self, times: list[float], counts: list[int], level: float, per_rev: int) -> None:
        """The road motor's speed per output and lag, from a run at ``level`` (counts from its start)."""
        if self.road is None:
            return
        sign = -1.0 if self.road.reversed else 1.0
        step = road_step(times, [sign * c * TWO_PI / per_rev for c in counts], level)
        if step is None:
            return
        gain, lag = step
        self.found.update(road_output_per_rad_s=round(1.0 / gain, 6), road_lag_s=round(lag, 4))
        unit = "unit duty" if self.road.kind == "pwm" else "V"
        self.say(
            f"  the road motor turns {gain:.3g} rad/s per {unit}, lagging {lag * 1e3:.0f} ms "
            "(rtdac.road_output_per_rad_s, rtdac.road_lag_s)"
        )

    def _scale(self) -> float | str | None:
        """The sense's scale [A/V], "meter" (read at the first step), or None (skip)."""
        if self.options.sense_a_per_v is not None:
            self.say(f"  the sense's scale: {self.options.sense_a_per_v:g} A/V (--sense-a-per-v)")
            return self.options.sense_a_per_v
        answer = self._answer(
            "  the A/D reads volts; the current needs the sense's scale in A per V (the power stage's data "
            "sheet; --sense-a-per-v gives it). Type it, or m to read a clamp meter on the coil's lead at the "
            "first step, or s to skip: "
        ).lower()
        if answer == "m":
            return "meter"
        if answer in SKIP or not answer:
            return None
        try:
            scale = float(answer)
        except ValueError:
            scale = float("nan")
        if not scale > 0.0 or scale == float("inf"):
            self.say(f"  '{answer}' is not a scale in A/V")
            return None
        return scale

    def coil_map(self) -> None:
        self.say("\nstep 4 of 4: the coil's map (current against output)")
        coil = self.coil
        if coil is None:
            self._outcome("coil map", False, "needs the coil and its sense (step 2): skipped")
            return
        scale = self._scale()
        if scale is None:
            self._outcome("coil map", False, "skipped: the coil's map and the sense's scale stay unconfirmed")
            return
        cap_a = self.rig.wiring.bringup_current_max_a
        top = output_caps(self.rig.wiring)[coil.kind]
        step = STEP[coil.kind]
        levels = [0.0] + [round(k * step, 6) for k in range(1, 1 + int(top / step + 1e-9))]
        unit = "duty" if coil.kind == "pwm" else "V"
        if len(levels) < 2:
            self._outcome("coil map", False, f"the bring-up cap allows no step of {step:g} {unit}: skipped")
            return
        if not self._yes(
            f"  drive {output_name(coil.kind, coil.channel)} at {', '.join(f'{v:g}' for v in levels)} {unit}, "
            f"{STEP_S:g} s each, reading A/D {coil.sense_ad}, up to {cap_a:g} A (the bring-up cap)? (y/n): "
        ):
            self._outcome("coil map", False, "skipped: the coil's map and the sense's scale stay unconfirmed")
            return
        try:
            done, volts, scale_a = self._steps(coil, levels, scale, cap_a)
        finally:
            self.rig.set_output(coil.kind, coil.channel, 0.0)
            self.rig.rest_outputs()
            self._tick()
        if scale_a is None:
            return
        try:
            found = coil_map(done, volts, scale_a)
        except NotFound as err:
            self._outcome("coil map", False, f"{err}: the coil's map stays unconfirmed")
            return
        self._confirm(
            MAP_FOUND,
            {
                "coil_map_current_a": list(found.currents_a),
                "coil_map_output": list(found.outputs),
                "coil_sense_a_per_v": round(found.a_per_v, 6),
                "coil_sense_offset_v": found.offset_v,
            },
        )
        points = ", ".join(f"{a:.3f} A at {o:g}" for a, o in zip(found.currents_a, found.outputs, strict=True))
        dropped = f"; left out (no rise): {', '.join(f'{v:g}' for v in found.dropped)}" if found.dropped else ""
        self._outcome(
            "coil map",
            True,
            f"the coil's map: {points} {unit}{dropped}; the sense reads {found.offset_v:+.3f} V at 0 A. Above "
            f"{found.currents_a[-1]:.3f} A the coil holds the map's top output: map further with "
            "--set rtdac.bringup_current_max_a=<A>",
        )

    def _steps(
        self, coil: CoilFinding, levels: list[float], scale: float | str, cap_a: float
    ) -> tuple[list[float], list[float], float | None]:
        """The sense's mean volts at each level (held STEP_S, the last half read), to the cap."""
        done: list[float] = []
        volts: list[float] = []
        scale_a = scale if isinstance(scale, float) else None
        for level in levels:
            if scale_a is not None and len(volts) >= 2:
                last = (volts[-1] - volts[0]) * scale_a
                before = (volts[-2] - volts[0]) * scale_a
                if 2 * last - before > cap_a * (1.0 + 1e-6):
                    self.say(f"    the next step would pass {cap_a:g} A: the steps end at {done[-1]:g}")
                    break
            self.rig.set_output(coil.kind, coil.channel, level)
            v, over = self._hold(coil.sense_ad, volts[0] if volts else None, scale_a, cap_a)
            done.append(level)
            volts.append(v)
            if over:
                self._outcome("coil map", False, f"at {level:g} the sensed current passed {cap_a:g} A: stopped")
                return done, volts, None
            shown = f", {(v - volts[0]) * scale_a:.3f} A" if scale_a is not None else ""
            self.say(f"    {level:g}: A/D {coil.sense_ad} {v:+.3f} V{shown}")
            if scale_a is None and level > 0.0:
                reading = self._answer("  the coil is held here: type the current your meter reads in A (s: skip): ")
                try:
                    scale_a = meter_scale(float(reading), v, volts[0])
                except (ValueError, NotFound) as err:
                    why = str(err) if isinstance(err, NotFound) else f"'{reading}' is not a current in A"
                    self._outcome("coil map", False, f"{why}: the coil's map stays unconfirmed")
                    return done, volts, None
                self.say(f"    the sense's scale: {scale_a:.4g} A/V")
        return done, volts, scale_a

    def _hold(self, ad: int, offset_v: float | None, scale_a: float | None, cap_a: float) -> tuple[float, bool]:
        """The sense's mean volts over the last half of STEP_S; True when the current passed the cap."""
        t0 = self.clock()
        readings: list[float] = []
        last: list[float] | None = None
        while self.clock() - t0 < STEP_S:
            last = self._ads(self._tick(), last)
            if self.clock() - t0 >= STEP_S / 2:
                readings.append(last[ad])
            if offset_v is not None and scale_a is not None and (last[ad] - offset_v) * scale_a > CURRENT_GUARD * cap_a:
                return last[ad], True
        return statistics.fmean(readings) if readings else (last[ad] if last else 0.0), False

    # the fragment ---------------------------------------------------------------------------------
    def confirmed_keys(self) -> list[str]:
        """The confirmed wiring keys, in the section's order."""
        return [key for key in WIRING_KEYS if key in self.confirmed]


def describe_effect(effect: PulseEffect) -> str:
    """One line for one output's pulse: what it moved."""
    moved = []
    if effect.ad is not None:
        moved.append(f"A/D {effect.ad} +{effect.ad_rise_v:.3f} V")
    if effect.counter is not None:
        moved.append(f"counter {effect.counter} {effect.counts:+d}")
    text = f"{effect.name}: " + (", ".join(moved) if moved else "nothing moved")
    return text + (f" (ended early: {effect.stopped})" if effect.stopped else "")
