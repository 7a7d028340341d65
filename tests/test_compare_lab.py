"""``sashil.lab._compare.compare`` called from Python: the laws on the road of a resolved config, the
run it returns, and bad input refused before any folder exists."""

from __future__ import annotations

import math

import pytest

from sashil.engine.resolve import ConfigSource, Option, resolve
from sashil.errors import ConfigError
from sashil.lab._compare import CompareLaw, compare, laws_of, split_sets
from sashil.recording.outputs import Outputs

#: a short comparison: 3 s per law, the first 1 s left out, a 10 s road
SHORT = ("compare.settle_s=1", "road.period_s=10")


def _config(*options: Option, sets: tuple[str, ...] = SHORT):
    return resolve(
        ConfigSource(sets=sets, options=(Option("--duration", "compare.duration_s", 3.0), *options)), "compare"
    )


def test_compare_returns_the_run_with_each_laws_metrics_beside_the_references(tmp_path):
    events = []
    laws = [CompareLaw("skyhook", ("controller.c_sky=2",)), "pdd"]
    run = compare(_config(), laws, Outputs(out=tmp_path / "cmp"), events.append)
    assert run.path == tmp_path / "cmp" and run.verb == "compare"
    table = run.tables["metrics"]
    assert list(table["law"]) == ["passive 0 A", "passive 1 A", "skyhook", "pdd"]
    assert list(table["status"]) == ["ok"] * 4
    assert {"rms_accel_rad_s2", "rms_theta_deg", "peak_current_a", "coil_energy_j"} <= set(table)
    # on this rig the road-side torque k*theta + T is -J*theta2_ddot: not a second column
    assert "rms_road_torque_nm" not in table
    assert table["peak_current_a"][1] == pytest.approx(1.0, abs=0.01) and table["coil_energy_j"][0] == 0.0
    summary = run.summary
    assert summary["exit_status"] == "ok" and summary["exit_code"] == 0 and summary["driver"] == "sim"
    assert summary["road"].startswith("iso8608:C: ISO 8608 class C") and summary["duration_s"] == 3.0
    assert [law["law"] for law in summary["laws"]] == list(table["law"])
    # theta2_ddot is the simulated plant's own (its capability true_torque), not the encoders'
    assert {law["accel_source"] for law in summary["laws"]} == {"plant"}
    assert [law["rms_accel_rad_s2"] for law in summary["laws"]] == list(table["rms_accel_rad_s2"])
    assert math.isfinite(summary["optimal_bound_gain_pct"])
    # the share of the bound on one scale: the best passive run's RMS θ̈2 is 0 %, the bound's 100 %
    bound = summary["optimal_bound_rms_accel_rad_s2"]
    assert summary["share_scale_bound_rms_accel_rad_s2"] == bound  # the plant's own θ̈2: the bound's own chain
    passive = min(law["rms_accel_rad_s2"] for law in summary["laws"] if law["law"].startswith("passive"))
    for law in summary["laws"]:
        expected = 100.0 * (passive - law["rms_accel_rad_s2"]) / (passive - bound)
        assert law["share_of_bound_pct"] == pytest.approx(expected)
    assert list(table["share_of_bound_pct"]) == pytest.approx([law["share_of_bound_pct"] for law in summary["laws"]])
    assert run.config["compare"]["road"] == "iso8608:C" and run.config["controller"]["law"] == "passive"
    assert {"compare.md", "compare.png", "config.yaml", "metrics.csv", "summary.json"} <= {
        p.name for p in run.path.iterdir()
    }
    assert [e.data["law"] for e in events if "law" in e.data] == list(table["law"])
    assert [e.text for e in events if e.kind == "folder"] == [f"compare folder: {run.path}"]


def test_over_the_encoders_the_shares_scale_puts_the_bound_on_their_chain():
    from sashil.engine import assemble
    from sashil.lab._compare import READS, _header, scale_bound
    from sashil.lab.compare_metrics import LawResult
    from sashil.lab.compare_report import Scale
    from sashil.lab.hysteretic_bound import HystereticBound, model_passive
    from sashil.lab.passive_baseline import Baseline
    from sashil.models.hysteresis import BoucWenParams
    from sashil.roads.option import RoadParts, parse_road

    config = _config()
    road, _ = parse_road("iso8608:C", RoadParts.read(config))
    params = BoucWenParams.from_mapping(config["model"]["params"])
    tau, settle = float(config["rig"]["coil_tau_s"]), float(config["compare"]["settle_s"])
    model = model_passive(
        params, 1.0, tau, road, 3.0, settle, bandwidth_hz=float(config["compare"]["accel_bandwidth_hz"])
    )
    bound = HystereticBound(1.2, 1.0, 3.0, {"mid current": 1.2, "sign rule": 1.25})
    run_spec = assemble(config, reads=READS)
    floor = 1.0
    row = LawResult("passive 1 A", metrics={"rms_accel_rad_s2": math.hypot(model, floor)}, accel_source="encoders")
    baseline = Baseline(1.0, row, "listed", {1.0: row})
    # the baseline run's excess over the model's own at its current (1 A) is the chain's floor: added to the bound
    assert scale_bound(run_spec, road, 3.0, 1.2, baseline) == pytest.approx(math.hypot(1.2, floor), rel=1e-6)
    row.accel_source = "plant"  # the plant's own θ̈2: the bound as it is
    assert scale_bound(run_spec, road, 3.0, 1.2, baseline) == 1.2
    assert math.isnan(scale_bound(run_spec, road, 3.0, math.nan, baseline))
    # compare.md's header names the scale only where it is not the bound's own, and the starts' spread
    scale = Scale("passive 1 A", row.metrics["rms_accel_rad_s2"], math.hypot(1.2, floor))
    header = _header(run_spec, "iso8608:C", "C", 3.0, True, 1, 3, 1.0, bound, baseline, scale)
    assert header["share's scale"].startswith(f"the bound on the encoders' chain, RMS θ̈2 {math.hypot(1.2, floor):.4g}")
    assert "mid current 1.2, sign rule 1.25 rad/s², 0.05 apart (2.8 % of its gap)" in header["optimal bound"]
    assert header["passive baseline"].startswith("1 A, the best of the constant currents compare.passive_currents_a")
    plain = _header(run_spec, "iso8608:C", "C", 3.0, True, 1, 3, 1.0, bound, baseline, Scale("passive 1 A", 3.0, 1.2))
    assert "share's scale" not in plain and "true plant's bound" not in plain


def test_a_law_that_fails_gets_its_row_and_the_summary_names_it(tmp_path):
    fails = tmp_path / "fails.py"
    fails.write_text(
        "from sashil.control import Law\n\n\nclass Fails(Law):\n    name = 'fails'\n\n"
        "    def torque(self, state):\n        raise ValueError('gain table empty')\n"
    )
    events = []
    run = compare(_config(), [f"{fails}:Fails"], Outputs(out=tmp_path / "cmp"), events.append)
    summary = run.summary
    assert summary["exit_status"] == "error" and summary["exit_code"] == 1
    assert summary["error"].startswith("1 of 3 laws did not finish: fails: error: law 'fails'")
    assert list(run.tables["metrics"]["status"])[:2] == ["ok", "ok"]
    assert [e.text for e in events if e.kind == "warning"] == [f"sashil compare: {summary['error']}"]


@pytest.mark.parametrize(
    "laws, message",
    [
        (["nope"], "--controller nope: controller.law: unknown law 'nope'"),
        ([CompareLaw("lqr-clipped", ("controller.q_theta=-1",))], "--controller lqr-clipped: --set: controller.q_theta: expected a number >= 0"),
        (["skyhook"], "--controller skyhook: --set: controller.c_sky: law 'skyhook' needs c_sky"),
    ],
)  # fmt: skip
def test_a_law_that_cannot_run_is_refused_before_any_folder(tmp_path, laws, message):
    with pytest.raises(ConfigError) as err:
        compare(_config(), laws, Outputs(out=tmp_path / "never"))
    assert str(err.value).startswith(message) and "\n" not in str(err.value)
    assert not (tmp_path / "never").exists()


@pytest.mark.parametrize(
    "options, message",
    [
        ((Option("--road", "compare.road", "iso8608:Q"),), "--road iso8608:Q: expected an ISO 8608 road class A-H"),
        ((Option("--duration", "compare.duration_s", 1.0),), "--duration: expected more than compare.settle_s = 1 s"),
        ((Option("--jobs", "compare.jobs", 0),), "--jobs: compare.jobs: expected an integer >= 1"),
    ],
)
def test_the_compare_options_are_checked_when_the_config_is_resolved(options, message):
    with pytest.raises(ConfigError) as err:
        _config(*options)
    assert str(err.value).startswith(message)


def test_a_road_from_the_config_is_named_by_its_key():
    with pytest.raises(ConfigError, match=r"^compare.road iso8608:Q: expected an ISO 8608 road class"):
        resolve(ConfigSource(config={"compare": {"road": "iso8608:Q"}}), "compare")


def test_the_command_lines_set_items_go_to_the_laws_that_declare_them():
    sets = [
        "compare.settle_s=1",
        "controller.onoff_current_a=0.8",
        "controller.c_sky=2",
        "controller.estimator=tracking",
    ]
    base, law_sets = split_sets(sets)
    assert base == ["compare.settle_s=1", "controller.estimator=tracking"]  # a controller section key: the config's
    assert laws_of(["skyhook", "pdd", "skyhook-add", "skyhook-onoff"], law_sets) == [
        CompareLaw("skyhook", ("controller.c_sky=2",)),
        CompareLaw("pdd", ()),
        CompareLaw("skyhook-add", ("controller.onoff_current_a=0.8",)),
        CompareLaw("skyhook-onoff", ("controller.onoff_current_a=0.8",)),
    ]
    with pytest.raises(
        ConfigError,
        match=r"^--set controller.onoff_current_a=0.8: none of the compared laws \(pdd\) has a parameter onoff",
    ):
        laws_of(["pdd"], law_sets)
    with pytest.raises(
        ConfigError, match=r"^--set controller\.law=pdd: sashil compare takes its laws from --controller"
    ):
        split_sets(["controller.law=pdd"])
