"""The stop path's retry loop (:func:`rest_until_confirmed`) on a fake clock: scripted exchanges, checks
and recoveries; every count and time exact."""

from __future__ import annotations

import pytest

from sashil.drivers.rtdac_rest import RETRY_PAUSE_S, RestOutcome, rest_until_confirmed
from sashil.errors import DriverIOError


class Script:
    """A fake board: each try takes ``step_s`` of the fake clock and yields the next scripted outcome
    (an exception is raised, a value is the readback); the last outcome repeats."""

    def __init__(self, outcomes: list, step_s: float = 0.001, recover_outcomes: list | None = None):
        self.outcomes = outcomes
        self.step_s = step_s
        self.t = 0.0
        self.tries = 0
        self.recover_outcomes = recover_outcomes or [None]
        self.recovers = 0
        self.sleeps: list[float] = []

    def clock(self) -> float:
        return self.t

    def send(self) -> str:
        outcome = self.outcomes[min(self.tries, len(self.outcomes) - 1)]
        self.tries += 1
        self.t += self.step_s
        if isinstance(outcome, BaseException):
            raise outcome
        return outcome

    def recover(self) -> None:
        outcome = self.recover_outcomes[min(self.recovers, len(self.recover_outcomes) - 1)]
        self.recovers += 1
        if outcome is not None:
            raise outcome

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.t += seconds

    def run(self, deadline_s: float = 0.3, pause_s: float = RETRY_PAUSE_S) -> RestOutcome:
        return rest_until_confirmed(
            self.send, lambda words: words == "rest", self.recover, self.clock, deadline_s, self.sleep, pause_s
        )


def test_a_rest_confirmed_at_the_first_try_needs_no_recovery():
    script = Script(["rest"])
    assert script.run() == RestOutcome(True, 1, 0.001, None)
    assert script.recovers == 0


def test_each_failed_exchange_is_followed_by_a_recovery_and_the_rest_then_confirmed():
    halted, gone = DriverIOError("halted"), DriverIOError("stuck")
    script = Script([halted, gone, "rest"])
    outcome = script.run()
    assert outcome.confirmed and outcome.attempts == 3 and script.recovers == 2
    assert outcome.last_error is gone and outcome.elapsed_s == pytest.approx(0.003)
    assert script.sleeps == []  # the recoveries succeeded: no pause


def test_a_readback_not_yet_at_rest_is_tried_again_without_a_recovery_until_the_deadline():
    script = Script(["driven"], step_s=1 / 1024)  # binary fractions: the fake clock's sums are exact
    outcome = script.run(deadline_s=10 / 1024)
    # the tries end at 1/1024 s, 2/1024 s, ...; the tenth reaches the deadline
    assert outcome == RestOutcome(False, 10, 10 / 1024, None)
    assert script.recovers == 0


def test_a_recovery_that_fails_pauses_before_the_next_try_and_is_the_last_error():
    failed = DriverIOError("reopen failed")
    script = Script([DriverIOError("gone")], step_s=0.0, recover_outcomes=[failed])
    outcome = script.run(deadline_s=4 / 64, pause_s=1 / 64)
    assert not outcome.confirmed and outcome.attempts == 4 and script.recovers == 4
    assert outcome.last_error is failed and script.sleeps == [1 / 64] * 4 and outcome.elapsed_s == 4 / 64


def test_no_recovery_is_started_once_the_deadline_has_passed():
    script = Script([DriverIOError("slow")], step_s=0.25)
    outcome = script.run(deadline_s=0.375)
    # the first try ends at 0.25 s (recovered), the second at 0.5 s: past the deadline, not recovered
    assert outcome.attempts == 2 and script.recovers == 1 and not outcome.confirmed
    assert str(outcome.last_error) == "slow"


def test_a_check_that_raises_counts_as_a_failed_try():
    calls = []

    def check(words: str) -> bool:
        calls.append(words)
        if len(calls) == 1:
            raise ValueError("a read frame of 502 bytes")
        return True

    script = Script(["rest"])
    outcome = rest_until_confirmed(script.send, check, script.recover, script.clock, 0.3)
    assert outcome.confirmed and outcome.attempts == 2 and script.recovers == 1
    assert isinstance(outcome.last_error, ValueError)


def test_an_interrupt_is_not_swallowed():
    script = Script([KeyboardInterrupt()])
    with pytest.raises(KeyboardInterrupt):
        script.run()
