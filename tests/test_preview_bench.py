"""``tools/bench_preview.py``'s arithmetic: the part of its exact-model gain the preview law keeps
on a plant that is not its model, the horizon of a long preview, and its ``--previews`` refused in
one line naming the option."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from tool_module import load_tool

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    return load_tool("bench_preview")


def _case(exact: float, off: float) -> dict:
    plants = {"exact": exact, "10 % off": off, "20 % off": off / 2.0, "dahl": exact}
    return {"plants": {p: {"share": {"1": s, "open-loop": s - 50.0}} for p, s in plants.items()}}


def test_the_gain_kept_is_the_share_on_the_plant_over_the_share_on_the_exact_model(bench):
    cases = [_case(80.0, 60.0), _case(90.0, 81.0), _case(40.0, 36.0)]
    kept = bench.kept_gain(cases, [1.0])
    # 10 % off: 60/80 = 75 %, 81/90 = 90 %, 36/40 = 90 %: median 90, worst 75
    assert kept["10 % off"]["1"]["median"] == pytest.approx(90.0)
    assert kept["10 % off"]["1"]["worst"] == pytest.approx(75.0)
    assert kept["20 % off"]["1"]["worst"] == pytest.approx(37.5)
    assert kept["dahl"]["1"]["median"] == pytest.approx(100.0)
    # open-loop: exact shares 30, 40, -10; the case whose exact share is not above 0 is left out
    assert kept["10 % off"]["open-loop"]["cases"] == 2
    assert kept["10 % off"]["open-loop"]["worst"] == pytest.approx(100.0 * 10.0 / 30.0)
    assert "exact" not in kept


def test_a_preview_longer_than_the_horizon_allows_lengthens_it(bench):
    assert bench.preview_keys(0.5) == ["controller.preview_s=0.5"]
    assert bench.preview_keys(1.0) == ["controller.preview_s=1"]
    assert bench.preview_keys(3.0) == ["controller.preview_s=3", "controller.horizon_s=4"]


@pytest.mark.parametrize("text", ["1,x", "0.5,-1", "nan"])
def test_bad_previews_are_refused_in_one_line_naming_the_option(text):
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "bench_preview.py"), "--curve", "--previews", text],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2
    assert "argument --previews: expected" in done.stderr.strip().splitlines()[-1]
    assert done.stdout == ""


def test_the_dahl_plant_runs_under_the_configs_controller_with_its_own_parameters(bench):
    # the Dahl plant's runs open the simulated rig on the Dahl-form parameters, whatever model the
    # config gives the controller (a run under another plant must not fail to open its rig)
    from sashil.drivers import rig_parts
    from sashil.engine.resolve import default_config
    from sashil.lab import _compare

    config = default_config()
    plant = bench.dahl_plant(config["model"]["params"])
    with bench.plant_params(plant):
        rig = _compare.open_rig(rig_parts(config, "sim"))
    assert rig.plant.params.beta == 0.0 and rig.plant.params.n == 1.0
    assert rig.plant.params.gamma == pytest.approx(plant["gamma"])
    assert _compare.open_rig(rig_parts(config, "sim")).plant.params.n == config["model"]["params"]["n"]
