"""The passive baseline: the best constant current found one way (a bounded search on a simulated rig,
the listed currents on a real one) and used by every figure that says "passive": compare's table,
header and summary, and ``sashil.testing.compare_with_passive``; shares above the bound flagged."""

from __future__ import annotations

import csv
import math

import pytest

from sashil.engine import assemble
from sashil.engine.resolve import ConfigSource, Option, resolve
from sashil.errors import ConfigError
from sashil.lab._compare import READS, CompareLaw, compare, reference_currents
from sashil.lab.compare_metrics import LawResult
from sashil.lab.compare_report import BOUND_TOLERANCE_PTS, Scale, above_bound, write_compare_md, write_metrics_csv
from sashil.lab.passive_baseline import XATOL_SHARE, best_constant_current
from sashil.recording.outputs import Outputs

SHORT = ("compare.settle_s=1", "road.period_s=10")


def _config(duration: float = 3.0, sets: tuple[str, ...] = SHORT):
    return resolve(ConfigSource(sets=sets, options=(Option("--duration", "compare.duration_s", duration),)), "compare")


def _fake(rms_of):
    """A run of the passive damper whose RMS θ̈2 is ``rms_of(current)``, and the currents it ran."""
    ran: list[float] = []

    def run_current(current: float) -> LawResult:
        ran.append(current)
        return LawResult(f"passive {current:g} A", metrics={"rms_accel_rad_s2": rms_of(current), "rms_theta_deg": 1.0})

    return run_current, ran


def test_the_search_finds_an_inner_best_current_within_its_tolerance_and_runs_each_current_once():
    run_current, ran = _fake(lambda i: 2.0 + (i - 0.742) ** 2)
    baseline = best_constant_current(run_current, 1.0)
    assert baseline.method == "search" and baseline.xatol_a == XATOL_SHARE
    assert abs(baseline.current_a - 0.742) <= XATOL_SHARE
    assert baseline.rms_accel == pytest.approx(2.0, abs=XATOL_SHARE**2)
    assert {0.0, 1.0} <= set(ran) and len(ran) == len(set(ran)) == len(baseline.evaluated)
    # every current run is a whole milliampere: its label and config.yaml rerun it
    assert all(round(c, 3) == c for c in ran)
    assert baseline.label == f"passive {baseline.current_a:g} A"


def test_the_search_keeps_an_end_the_interval_never_reaches_and_reuses_known_runs():
    run_current, ran = _fake(lambda i: 3.0 - i)  # the stiffer the better: the best is i_max itself
    known = {0.0: _fake(lambda i: 3.0)[0](0.0), 1.0: _fake(lambda i: 2.0)[0](1.0)}
    baseline = best_constant_current(run_current, 1.0, known=known)
    assert baseline.current_a == 1.0 and baseline.rms_accel == 2.0
    assert 0.0 not in ran and 1.0 not in ran  # the reference rows are not run again


def test_listed_currents_are_each_run_once_and_the_best_kept():
    run_current, ran = _fake(lambda i: {0.0: 3.0, 0.5: 2.2, 1.0: 2.5}[i])
    baseline = best_constant_current(run_current, 1.0, listed=[0.0, 0.5, 1.0])
    assert ran == [0.0, 0.5, 1.0] and baseline.current_a == 0.5 and baseline.method == "listed"
    assert "compare.passive_currents_a lists (0, 0.5, 1 A)" in baseline.describe(1.0)


def test_no_finished_current_is_an_error_naming_each():
    def fails(current: float) -> LawResult:
        return LawResult(f"passive {current:g} A", status="tripped: overcurrent")

    with pytest.raises(RuntimeError, match="0 A: tripped: overcurrent; 1 A: tripped"):
        best_constant_current(fails, 1.0, listed=[0.0, 1.0])


def test_on_a_stiff_hysteretic_damper_at_speed_an_inner_current_beats_both_ends():
    """n 1 at 20 m/s on class C: the two-current rule (0 A or i_max) misses the best constant
    current; the search, each candidate a simulated run, finds one that beats both."""
    from sashil.lab._compare import passive_baseline

    config = _config(8.0, (*SHORT, "model.params.n=1.0", "road.speed_m_s=20"))
    run = assemble(config, reads=READS)
    baseline = passive_baseline(config, run, "iso8608:C", 8.0)
    ends = {c: baseline.evaluated[c].metrics["rms_accel_rad_s2"] for c in (0.0, 1.0)}
    # measured: 0.788 A, RMS θ̈2 3.324 against 3.349 at 1 A and 4.184 at 0 A (0.7 % below the better end;
    # 2.4 % on 30 s of the 120 s road, at 0.635 A)
    assert 0.6 < baseline.current_a < 0.95
    assert baseline.rms_accel < 0.995 * min(ends.values())
    # the run at the current found, made again, gives the search's own metrics (the same road and seed)
    again = passive_baseline(config, run, "iso8608:C", 8.0)
    assert again.current_a == baseline.current_a and again.rms_accel == baseline.rms_accel


def test_a_real_rigs_listed_currents_must_lie_in_the_coils_range():
    config = _config(sets=(*SHORT, "driver.clock=real", "compare.passive_currents_a=[0.0, 1.5]"))
    with pytest.raises(ConfigError, match=r"compare.passive_currents_a: 1.5 A is outside \[0, rig.current_max_a"):
        reference_currents(assemble(config, reads=READS))
    listed = _config(sets=(*SHORT, "driver.clock=real", "compare.passive_currents_a=[0.0, 0.5]"))
    assert reference_currents(assemble(listed, reads=READS)) == [0.0, 0.5]
    assert reference_currents(assemble(_config(), reads=READS)) == [0.0, 1.0]  # simulated: the search's ends


def test_a_share_beyond_the_tolerance_is_flagged_in_the_table_and_the_csv(tmp_path):
    passive, bound = 3.0, 2.0
    inside = passive - (1.0 + 0.01 * (BOUND_TOLERANCE_PTS - 1.0)) * (passive - bound)  # 100 % + tol - 1
    beyond = passive - (1.0 + 0.01 * (BOUND_TOLERANCE_PTS + 1.0)) * (passive - bound)  # 100 % + tol + 1
    rest = {"rms_theta_deg": 1.0, "peak_current_a": 0.5, "coil_energy_j": 1.0}
    results = [
        LawResult("passive 0.5 A", metrics={"rms_accel_rad_s2": passive, **rest}),
        LawResult("inside", metrics={"rms_accel_rad_s2": inside, **rest}),
        LawResult("beyond", metrics={"rms_accel_rad_s2": beyond, **rest}),
    ]
    assert above_bound(100.0 + BOUND_TOLERANCE_PTS + 0.1) and not above_bound(100.0 + BOUND_TOLERANCE_PTS)
    scale = Scale("passive 0.5 A", passive, bound)
    rows = {r["law"]: r for r in csv.DictReader(open(write_metrics_csv(tmp_path / "m.csv", results, scale)))}
    assert [rows[k]["above_bound"] for k in ("passive 0.5 A", "inside", "beyond")] == ["False", "False", "True"]
    assert float(rows["beyond"]["share_of_bound_pct"]) == pytest.approx(100.0 + BOUND_TOLERANCE_PTS + 1.0)
    text = write_compare_md(tmp_path / "c.md", results, {}, [], scale).read_text()
    lines = {line.split(" | ")[0].strip("| *").split("**")[0]: line for line in text.splitlines()}
    assert "⚠ above the bound" in lines["beyond"] and "⚠" not in lines["inside"]
    assert "| passive 0.5 A (baseline) |" in text


def test_compare_with_passive_gives_compares_own_figures_for_the_same_run(tmp_path):
    """The law's own run folder from a comparison, given to sashil.testing: the same baseline, bound
    and share, to the last bit (each a run of the same road and seed, the bound the same search)."""
    from sashil.api import load_run
    from sashil.testing import compare_with_passive

    config = _config(8.0, (*SHORT, "model.params.n=1.0", "road.speed_m_s=20"))
    run = compare(config, [CompareLaw("skyhook", ("controller.c_sky=2",))], Outputs(out=tmp_path / "cmp"))
    summary = run.summary
    law = next(entry for entry in summary["laws"] if entry["law"] == "skyhook")
    comparison = compare_with_passive(load_run(tmp_path / "cmp" / "skyhook"))
    baseline = summary["passive_baseline"]
    assert baseline["method"] == comparison.baseline_method == "search"
    assert comparison.comfort_current_a == baseline["current_a"]
    assert comparison.comfort_rms_accel_rad_s2 == baseline["rms_accel_rad_s2"]
    assert comparison.bound_rms_accel_rad_s2 == summary["share_scale_bound_rms_accel_rad_s2"]
    assert comparison.bound_gain_pct == summary["optimal_bound_gain_pct"]
    assert comparison.share_of_bound_pct == law["share_of_bound_pct"]
    assert comparison.comfort_gain_pct == pytest.approx(
        100.0 * (1.0 - law["rms_accel_rad_s2"] / baseline["rms_accel_rad_s2"]), rel=1e-12
    )
    # the searched current is a row of the table with its own run folder, the baseline marked
    table = run.tables["metrics"]
    row = list(table["law"]).index(f"passive {baseline['current_a']:g} A")
    assert table["rms_accel_rad_s2"][row] == baseline["rms_accel_rad_s2"] and table["share_of_bound_pct"][row] == 0.0
    assert f"passive {baseline['current_a']:g} A** (best) (baseline)" in (run.path / "compare.md").read_text() or (
        f"passive {baseline['current_a']:g} A (baseline)" in (run.path / "compare.md").read_text()
    )
    assert not math.isnan(summary["optimal_bound"]["spread_rad_s2"])
    assert set(summary["optimal_bound"]["starts"]) == {"mid current", "best constant", "sign rule", "random smooth"}


def test_on_a_mismatched_simulated_rig_compare_reports_the_share_of_the_true_plants_bound(tmp_path):
    config = _config(3.0, (*SHORT, "mismatch.fraction=0.1", "mismatch.coil_tau=0.1"))
    run = compare(config, [CompareLaw("skyhook", ("controller.c_sky=2",))], Outputs(out=tmp_path / "cmp"))
    summary = run.summary
    plant = summary["plant_bound"]["rms_accel_rad_s2"]
    assert plant != summary["optimal_bound_rms_accel_rad_s2"]
    passive = summary["passive_baseline"]["rms_accel_rad_s2"]
    for law in summary["laws"]:
        expected = 100.0 * (passive - law["rms_accel_rad_s2"]) / (passive - plant)
        assert law["share_of_plant_bound_pct"] == pytest.approx(expected)
    assert "true plant's bound" in (run.path / "compare.md").read_text()
    assert "share_of_plant_bound_pct" in run.tables["metrics"]
