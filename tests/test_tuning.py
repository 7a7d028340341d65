"""Live tuning's hand-off: a change reaches the law between two cycles, whole, checked, recorded.

A stand-in loop thread plays the control loop: each "cycle" it bumps the cycle count and, when the
hand-off is busy, calls ``service`` exactly as :class:`sashil.runtime.loop.ControlLoop` does. No
sleeps: callers wait on the hand-off's own events.
"""

from __future__ import annotations

import threading

import pytest

from sashil.control.law_api import Law, LawState, Param
from sashil.errors import ConfigError
from sashil.runtime.tuning import EVENT_COLUMNS, LiveTuning

RATE_HZ = 1000.0


class Gain(Law):
    name = "gain-law"
    gain = Param(1.0, low=0.0, doc="the gain")
    order = Param(1, low=1, high=3)
    mode = Param("soft", choices=("soft", "hard"))

    def parameters_changed(self) -> None:
        if self.gain == 13.0:
            raise ConfigError("controller.gain: 13 is refused by the law itself")
        self.changes = getattr(self, "changes", 0) + 1

    def torque(self, state: LawState) -> float:
        return self.gain * state.theta_dot_rad_s


class Timing:
    cycles = 0


class Loop:
    """Cycles until stopped; applies changes at cycle boundaries like the control loop."""

    def __init__(self, tuning: LiveTuning):
        self.tuning = tuning
        self.timing = Timing()
        tuning.timing = self.timing
        self.stop = threading.Event()
        self.values: list[float] = []  # the law's gain as each cycle's step saw it
        self.thread = threading.Thread(target=self.run)

    def run(self) -> None:
        tuning, law = self.tuning, self.tuning.law
        cycle = 0
        while not self.stop.is_set():
            self.timing.cycles = cycle
            if tuning.busy:
                tuning.service(cycle / RATE_HZ, cycle)
            self.values.append(law.gain)  # the step
            cycle += 1

    def __enter__(self) -> Loop:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join()


def make() -> tuple[Gain, LiveTuning]:
    law = Gain()
    return law, LiveTuning(law, RATE_HZ)


def test_a_change_is_applied_whole_within_two_cycles_of_arriving_and_recorded():
    law, tuning = make()
    with Loop(tuning):
        events = tuning.submit({"gain": 2.5, "order": 3})
    assert (law.gain, law.order) == (2.5, 3)
    assert [(e.key, e.old, e.new, e.status) for e in events] == [
        ("gain", 1.0, 2.5, "applied"),
        ("order", 1, 3, "applied"),
    ]
    event = events[0]
    assert event.cycle is not None and event.arrived_cycle is not None
    assert 0 <= event.cycle - event.arrived_cycle <= 2
    assert event.time_s == pytest.approx(event.cycle / RATE_HZ)
    assert events[1].cycle == event.cycle  # both parameters in one cycle
    assert tuning.summary()["applied"] == 2 and not tuning.busy
    assert tuning.rows()[0] == [event.time_s, event.cycle, "gain", 1.0, 2.5, 0.0, "applied", event.arrived_cycle]
    assert len(tuning.rows()[0]) == len(EVENT_COLUMNS)


def test_the_law_sees_old_or_new_values_only_between_steps():
    _law, tuning = make()
    with Loop(tuning) as loop:
        tuning.submit({"gain": 4.0})
    cycle = tuning.events[0].cycle
    assert set(loop.values[:cycle]) == {1.0}
    assert set(loop.values[cycle:]) == {4.0}


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"gain": -1.0}, "controller.gain: expected a number >= 0, got -1"),
        ({"order": 7}, "controller.order:"),
        ({"mode": "wild"}, "controller.mode:"),
        ({"nope": 1}, "controller.nope: law 'gain-law' has no parameter nope (its parameters: gain, order, mode)"),
        ({}, "nothing to change"),
    ],
)
def test_a_bad_value_is_refused_in_one_line_before_the_loop_sees_it(values, message):
    law, tuning = make()
    with pytest.raises(ConfigError, match="^" + message.replace("(", r"\(").replace(")", r"\)")) as err:
        tuning.submit(values)  # no loop runs: a refusal never waits for one
    assert "\n" not in str(err.value)
    assert (law.gain, law.order, law.mode) == (1.0, 1, "soft")
    assert not tuning.busy
    assert all(event.status == "refused" and event.cycle is None for event in tuning.events)


def test_a_change_the_law_itself_refuses_leaves_it_untouched_and_is_recorded():
    law, tuning = make()
    with Loop(tuning):
        with pytest.raises(ConfigError, match="13 is refused by the law itself"):
            tuning.submit({"gain": 13.0, "order": 2})
    assert (law.gain, law.order) == (1.0, 1)
    refused = [event for event in tuning.events if event.status == "refused"]
    assert {event.key for event in refused} == {"gain", "order"}
    assert all(event.cycle is not None for event in refused)


def test_a_ramp_moves_a_float_linearly_one_step_per_cycle_and_steps_the_rest():
    law, tuning = make()
    tuning.post(*tuning.check({"gain": 3.0, "order": 2}, ramp_s=0.004))  # 4 cycles at 1 kHz
    seen = []
    for cycle in range(10, 16):
        if tuning.busy:
            tuning.service(cycle / RATE_HZ, cycle)
        seen.append((law.gain, law.order))
    # from 1.0 to 3.0 in 4 steps of 0.5, the first in the cycle that applies the change
    assert seen == [(1.5, 2), (2.0, 2), (2.5, 2), (3.0, 2), (3.0, 2), (3.0, 2)]
    assert [(e.key, e.status, e.cycle, e.ramp_s) for e in tuning.events] == [
        ("gain", "applied", 10, 0.004),
        ("order", "applied", 10, 0.0),
        ("gain", "ramp_done", 13, 0.0),
    ]
    assert not tuning.busy


def test_a_new_change_restarts_a_running_ramp_from_where_it_is():
    law, tuning = make()
    tuning.post({"gain": 3.0}, 0.004)
    tuning.service(0.0, 0)  # 1.5
    tuning.service(0.001, 1)  # 2.0
    tuning.post({"gain": 0.0}, 0.002)
    tuning.service(0.002, 2)
    assert law.gain == pytest.approx(1.0)  # 2.0 -> 0.0 in two steps
    tuning.service(0.003, 3)
    assert law.gain == 0.0 and not tuning.busy


def test_a_ramp_whose_end_the_law_refuses_is_refused_at_once():
    law, tuning = make()
    with Loop(tuning):
        with pytest.raises(ConfigError, match="13 is refused"):
            tuning.submit({"gain": 13.0}, ramp_s=1.0)
    assert law.gain == 1.0 and not tuning.busy


def test_a_change_pending_when_the_run_ends_is_answered_not_applied():
    law, tuning = make()
    answers: list[BaseException] = []

    def caller() -> None:
        try:
            tuning.submit({"gain": 2.0})
        except ConfigError as err:
            answers.append(err)

    thread = threading.Thread(target=caller)
    thread.start()
    while not tuning.busy:  # the change is in the hand-off
        pass
    tuning.close()
    thread.join()
    assert str(answers[0]) == "not applied: the run has ended"
    assert law.gain == 1.0
    assert [event.status for event in tuning.events] == ["not_applied"]
    with pytest.raises(ConfigError, match="the run has ended"):
        tuning.submit({"gain": 3.0})


def test_two_changes_racing_are_applied_one_after_the_other_each_whole():
    law, tuning = make()
    start = threading.Barrier(3)
    errors: list[BaseException] = []

    def caller(gain: float, order: int) -> None:
        start.wait()
        try:
            tuning.submit({"gain": gain, "order": order})
        except BaseException as err:  # pragma: no cover - reported below
            errors.append(err)

    callers = [threading.Thread(target=caller, args=args) for args in ((2.0, 2), (5.0, 3))]
    with Loop(tuning) as loop:
        for thread in callers:
            thread.start()
        start.wait()
        for thread in callers:
            thread.join()
    assert not errors
    applied = [event for event in tuning.events if event.status == "applied"]
    assert len(applied) == 4
    first, second = applied[:2], applied[2:]
    assert first[0].cycle == first[1].cycle < second[0].cycle == second[1].cycle
    assert second[0].old == first[0].new  # the second change started from the first's values
    assert (law.gain, law.order) == (second[0].new, second[1].new)
    # every cycle saw one whole change or the other, never half of each
    assert set(loop.values) <= {1.0, 2.0, 5.0}


def test_run_png_marks_each_applied_change_on_every_panel():
    from sashil.recording.plots import _mark_live_changes, pyplot

    _law, tuning = make()
    tuning.post({"gain": 2.0}, 0.0)
    tuning.service(0.25, 250)
    with pytest.raises(ConfigError):
        tuning.submit({"gain": -1.0})
    _fig, axes = pyplot().subplots(3, 1)
    _mark_live_changes(axes, tuning.summary())
    assert [[line.get_xdata()[0] for line in ax.lines] for ax in axes] == [[0.25]] * 3  # the refusal is not drawn
    assert [text.get_text() for text in axes[0].texts] == ["gain = 2.0"]


def test_a_change_that_arrives_before_the_loop_started_is_dated_at_cycle_zero():
    _law, tuning = make()  # no loop has attached its timing yet: the socket opens before the first cycle
    tuning.post({"gain": 2.0}, 0.0)
    tuning.service(0.0, 0)
    (event,) = tuning.events
    assert (event.cycle, event.arrived_cycle, event.status) == (0, 0, "applied")
