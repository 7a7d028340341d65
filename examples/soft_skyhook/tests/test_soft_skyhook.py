"""The soft skyhook's own tests, on sashil's simulated rig (the plugin sashil.testing gives sashil_rig)."""

from soft_skyhook import SoftSkyhook

from sashil.testing import assert_law_contract, compare_with_passive


def test_ten_seconds_on_a_class_c_road(sashil_rig):
    run = sashil_rig.run(SoftSkyhook, road="iso8608:C", duration_s=10, c_sky=2.0)
    assert run.summary["exit_status"] == "ok"
    assert run.data["time_s"][-2] >= 9.99
    assert 0.0 <= run.data["current_cmd_a"].min() and run.data["current_cmd_a"].max() <= 1.0
    assert run.metrics["rms_theta_deg"] < 2.0


def test_meets_the_law_contract(sashil_rig):
    assert_law_contract(SoftSkyhook, rig=sashil_rig, params={"c_sky": 2.0, "dead_band_rad_s": 0.05})


def test_against_the_best_constant_current(sashil_rig):
    comparison = compare_with_passive(sashil_rig.run(SoftSkyhook, c_sky=2.0))
    # on the seed's damper the soft start and the skyhook's passive half cost comfort against 1 A:
    # this guards the figure, so a change to the law that makes it worse fails here
    assert comparison.comfort_gain_pct > -30.0
    assert comparison.share_of_bound_pct > -150.0
