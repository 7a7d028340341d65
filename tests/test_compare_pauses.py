"""A compared law is run again when its host paused longer than ``compare.max_pause_ms``: the
decision on each run's summary, the runs kept, the rig's rest between them, and what compare.md says."""

from __future__ import annotations

import math

from sashil.lab import _compare
from sashil.lab.compare_metrics import LawResult
from sashil.lab.compare_pauses import PausePolicy, pause_ms, paused_note, run_unpaused

POLICY = PausePolicy(max_pause_ms=10.0, repeats=2)


def result(label: str, late_ms: float | None, status: str = "ok") -> LawResult:
    summary = {} if late_ms is None else {"timing": {"lateness_us": {"max": late_ms * 1e3}}}
    return LawResult(label, status=status, summary=summary)


class Runs:
    """A law's runs in turn, each with its host's longest pause [ms], and the rests between them."""

    def __init__(self, label: str, pauses: list[float | None], status: str = "ok"):
        self.queue = [result(label, p, status) for p in pauses]
        self.runs = self.rests = 0

    def run(self) -> LawResult:
        self.runs += 1
        return self.queue.pop(0)

    def rest(self) -> None:
        self.rests += 1


def test_a_run_s_pause_is_its_loop_s_longest_lateness():
    assert pause_ms(result("x", 43.5).summary) == 43.5
    assert math.isnan(pause_ms({})) and math.isnan(pause_ms({"timing": None}))


def test_a_law_whose_host_paused_longer_is_run_again_after_a_rest_and_the_unpaused_run_kept():
    law, events = Runs("passive 0 A", [43.0, 3.0]), []
    kept = run_unpaused(law.run, law.rest, POLICY, events.append)
    assert (law.runs, law.rests) == (2, 1)
    assert kept.pauses_ms == [43.0, 3.0] and kept.summary["timing"]["lateness_us"]["max"] == 3000.0
    assert [e.data for e in events] == [{"law": "passive 0 A", "pause_ms": 43.0}]
    assert "the host paused 43 ms (compare.max_pause_ms 10)" in events[0].text and "(1 of 2)" in events[0].text
    assert paused_note([kept], POLICY) == (
        "Run again, the host having paused longer than 10 ms: passive 0 A: 43, 3 ms. "
        "compare.max_pause_ms and compare.repeats set this."
    )


def test_a_law_paused_in_every_run_stops_after_the_repeats_and_the_comparison_says_so():
    law = Runs("skyhook", [43.0, 30.0, 25.0, 1.0])
    kept = run_unpaused(law.run, law.rest, POLICY, lambda _: None)
    assert (law.runs, law.rests) == (3, 2) and kept.pauses_ms == [43.0, 30.0, 25.0]
    note = paused_note([kept, result("passive 1 A", 2.0)], POLICY)
    assert note is not None and "Not the others' road: skyhook," in note and "passive 1 A" not in note


def test_a_law_runs_once_unpaused_at_the_limit_without_a_timing_when_it_failed_or_with_no_repeats():
    cases = [
        (Runs("a", [10.0]), POLICY),  # at the limit: not longer
        (Runs("b", [None]), POLICY),  # no timing: nothing to judge
        (Runs("c", [99.0], status="tripped: over-current"), POLICY),  # its status already says why
        (Runs("d", [99.0]), PausePolicy(10.0, 0)),
    ]
    for law, policy in cases:
        kept = run_unpaused(law.run, law.rest, policy, lambda _: None)
        assert (law.runs, law.rests, len(kept.pauses_ms)) == (1, 0, 1), kept.label
    assert paused_note([result("a", 10.0)], POLICY) is None


def test_compare_runs_each_law_again_on_a_real_clock_and_never_on_the_virtual_one(monkeypatch):
    pauses = {"passive 0 A": [0.2], "passive 1 A": [55.0, 0.4], "law": [0.3]}
    ran: list[str] = []

    def run_job(job):
        ran.append(job.label)
        return result(job.label, pauses[job.label].pop(0))

    monkeypatch.setattr(_compare, "run_job", run_job)
    jobs = [_compare.LawJob(label, {}, "iso8608:C", 1.0) for label in pauses]
    results = _compare._run_jobs(jobs, 1, 0.0, False, lambda _: None, POLICY)
    assert ran == ["passive 0 A", "passive 1 A", "passive 1 A", "law"]
    assert [r.pauses_ms for r in results] == [[0.2], [55.0, 0.4], [0.3]]
    ran.clear()
    pauses.update({"passive 0 A": [0.0], "passive 1 A": [55.0], "law": [0.0]})
    results = _compare._run_jobs(jobs, 1, 0.0, True, lambda _: None, POLICY)
    assert ran == ["passive 0 A", "passive 1 A", "law"] and all(r.pauses_ms == [] for r in results)
