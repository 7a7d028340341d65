"""``sashil replay`` on a simulated run (virtual clock): its own law reproduces the recorded
commands exactly; another law's commands are written beside them; bad input is one line, exit 2."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from sashil.api import load_run
from sashil.cli import main
from sashil.runtime.clock import VirtualClock


class _VirtualClock:
    """``sashil run``'s clock made virtual (the verb always takes the real one), so no deadline is missed."""

    @staticmethod
    def for_rate(spin_margin_us: float, rate_hz: float) -> VirtualClock:
        return VirtualClock()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A run as ``sashil run`` records it: the loop process on the real clock, the session's recorder."""
    out = tmp_path_factory.mktemp("replay") / "run"
    code = main(
        ["run", "-q", "--duration", "1", "--controller", "skyhook", "--set", "controller.c_sky=2", "--out", str(out)]
    )
    assert code == 0
    return out


def test_replay_with_the_runs_own_law_reproduces_its_commands(recorded, tmp_path):
    # the run's estimator fused encoder edge events, and data.csv kept them for the replay
    run = load_run(recorded)
    assert np.any(run.data["road_edge_dir"] != 0) and np.any(run.data["arm_edge_dir"] != 0)
    assert json.loads((recorded / "summary.json").read_text())["controller_stats"]["edge_events"] > 0
    out = tmp_path / "same"
    assert main(["replay", str(recorded), "-q", "--out", str(out)]) == 0
    data = load_run(out).data
    rows = data["replayed"] > 0
    assert rows.sum() == data["time_s"].size - 1  # all but the shutdown's 0 A row
    assert np.array_equal(data["replay_current_cmd_a"][rows], data["current_cmd_a"][rows])
    assert np.array_equal(data["replay_torque_cmd_nm"][rows], data["torque_cmd_nm"][rows])
    diff = json.loads((out / "summary.json").read_text())["replay"]["differences"]
    assert diff["current_cmd_a"] == {"rms": 0.0, "max_abs": 0.0}
    assert (out / "replay.png").stat().st_size > 0


def test_replay_with_another_law_writes_its_commands_beside_the_recorded(recorded, tmp_path):
    out = tmp_path / "other"
    code = main(
        [
            "replay",
            str(recorded),
            "-q",
            "--controller",
            "groundhook",
            "--set",
            "controller.c_ground=2",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())["replay"]
    assert summary["law"]["name"] == "groundhook" and summary["law"]["parameters"] == {"c_ground": 2.0}
    assert summary["differences"]["current_cmd_a"]["rms"] > 0
    data = load_run(out).data
    for name in ("theta_rad", "current_cmd_a", "replay_current_cmd_a", "replay_torque_cmd_nm", "replay_torque_hat_nm"):
        assert name in data
    recorded_data = load_run(recorded).data
    assert np.array_equal(data["current_cmd_a"], recorded_data["current_cmd_a"])  # the recorded columns kept


def _one_line_error(capsys, *words):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(word in err for word in words), err


def test_replay_of_a_folder_that_is_not_a_run(tmp_path, capsys):
    assert main(["replay", str(tmp_path), "--out", str(tmp_path / "x")]) == 2
    _one_line_error(capsys, "not a sashil run folder")
    assert not (tmp_path / "x").exists()


def test_replay_of_a_run_without_the_columns_it_needs(recorded, tmp_path, capsys):
    folder = tmp_path / "cut"
    folder.mkdir()
    (folder / "config.yaml").write_text((recorded / "config.yaml").read_text())
    with open(recorded / "data.csv") as src, open(folder / "data.csv", "w", newline="") as dst:
        rows = list(csv.reader(src))
        keep = [i for i, name in enumerate(rows[0]) if name != "seq"]
        csv.writer(dst).writerows([[row[i] for i in keep] for row in rows])
    assert main(["replay", str(folder), "--out", str(tmp_path / "x")]) == 2
    _one_line_error(capsys, "no column seq")


def test_replay_with_a_bad_parameter(recorded, tmp_path, capsys):
    out = tmp_path / "x"
    assert main(["replay", str(recorded), "--set", "controller.c_sky=-1", "--out", str(out)]) == 2
    _one_line_error(capsys, "controller.c_sky")
    assert not out.exists()
