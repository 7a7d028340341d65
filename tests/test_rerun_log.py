"""rerun live view: recordings written by drop-test and by a loop run load back with their entities
and values (rerun.chunk.RrdReader via sashil.recording.rerun_log.load_rrd)."""

from __future__ import annotations

import numpy as np
import pytest

from sashil.cli import main
from sashil.config.parts import StageParts
from sashil.control.registry import make_controller
from sashil.drivers import open_rig
from sashil.engine import assemble
from sashil.recording.data_file import read_data_csv
from sashil.recording.rerun_log import LiveTap, RerunLog, feasible_band, load_rrd
from sashil.runtime.clock import VirtualClock
from sashil.runtime.loop import record_columns
from sashil.runtime.session import InProcessLoop, run_session
from sashil.writer.run_folder import RunFolder


def _series(doc, entity):
    """(time_s, values per row) of a Scalars entity, sorted by time."""
    entry = doc[f"/{entity}"]
    times = np.asarray(entry["time"])
    values = np.asarray(entry["Scalars:scalars"], dtype=float)
    order = np.argsort(times, kind="stable")
    return times[order], values[order]


def test_feasible_band_is_the_torque_at_zero_and_at_max_current():
    params = {"alpha1": 1.0, "alpha2": 2.0, "c1": 0.7, "c2": 1.5}
    cols = {"z_hat": np.array([0.5, -1.0]), "theta_dot_rad_s": np.array([2.0, 0.0])}
    feasible_band(cols, params, 0.8)
    # T(i) = (a1 + a2 i) z + (c1 + c2 i) v: row 0: T(0) = 0.5 + 1.4, T(0.8) = (1 + 1.6) 0.5 + (0.7 + 1.2) 2
    assert cols["band_lo_nm"] == pytest.approx([1.9, -1.0])
    assert cols["band_hi_nm"] == pytest.approx([1.3 + 3.8, -2.6])


def test_drop_test_rerun_save_loads_back_with_the_logged_entities(tmp_path):
    out, rrd = tmp_path / "D", tmp_path / "drop.rrd"
    assert (
        main(
            [
                "drop-test",
                "--current",
                "0",
                "--current",
                "1",
                "--duration",
                "2",
                "--out",
                str(out),
                "--rerun-save",
                str(rrd),
            ]
        )
        == 0
    )
    doc = load_rrd(rrd)
    assert {"/signals/angle_deg", "/signals/current_a", "/events/notes"} <= set(doc)
    times, angle = _series(doc, "signals/angle_deg")
    first = read_data_csv(out / "i0.000A" / "data.csv")
    second = read_data_csv(out / "i1.000A" / "data.csv")
    n0, n1 = first["time_s"].size, second["time_s"].size
    assert angle.shape == (n0 + n1, 2)  # θ and θ1 per row
    assert angle[:n0, 0] == pytest.approx(np.degrees(first["theta_rad"]), abs=1e-12)
    # the second drop test follows the first on the time line (its duration + 1 s later)
    assert times[n0] == pytest.approx(3.0)
    assert angle[n0:, 0] == pytest.approx(np.degrees(second["theta_rad"]), abs=1e-12)
    _, current = _series(doc, "signals/current_a")
    assert current[n0:, 0] == pytest.approx(1.0)  # commanded
    notes = [text for row in doc["/events/notes"]["TextLog:text"] for text in row]
    assert any("at 1 A" in text for text in notes)
    assert doc["/signals/angle_deg"]["SeriesLines:names"][0] == ["θ (relative)", "θ1 (road)"]
    from rerun.chunk import RrdReader

    assert len(RrdReader(str(rrd)).blueprints()) == 1  # the panel layout travels with the recording


def test_rerun_save_into_a_missing_folder_is_a_usage_error_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "D"
    with pytest.raises(SystemExit) as exit_info:
        main(["drop-test", "--out", str(out), "--rerun-save", str(tmp_path / "no" / "x.rrd")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "--rerun-save" in err and "does not exist" in err and "\n" not in err
    assert not out.exists()


def test_rerun_save_without_a_file_records_into_the_run_folder(tmp_path):
    out = tmp_path / "D"
    assert main(["drop-test", "--duration", "1", "--out", str(out), "--rerun-save", "-q"]) == 0
    doc = load_rrd(out / "live.rrd")
    _, angle = _series(doc, "signals/angle_deg")
    assert angle[:, 0] == pytest.approx(np.degrees(read_data_csv(out / "data.csv")["theta_rad"]), abs=1e-12)


def test_live_tap_follows_a_loop_run_decimated(tmp_path, config):
    config["controller"]["law"] = "target-damping"
    config["controller"]["zeta"] = 0.08
    stage = make_controller("target-damping", StageParts.read(config))
    columns = record_columns(stage)
    rrd = tmp_path / "run.rrd"
    params = config["model"]["params"]
    tap = LiveTap(RerunLog.open((*columns, "lateness_us"), save=rrd), every=10, band=(params, 1.0))
    folder = RunFolder.create(tmp_path / "R", "run")
    outcome = run_session(
        InProcessLoop(assemble(config), open_rig(assemble(config).rig), stage, VirtualClock(), realtime=False),
        config,
        folder,
        1.5,
        controller="t",
        live=tap,
        say=lambda _: None,
    )
    assert outcome.exit_code == 0
    stats = outcome.summary["live_view"]
    assert stats["rows_sent"] == 150 + 1 and stats["rows_skipped"] == 0 and stats["error"] is None  # + the 0 A row
    data = read_data_csv(folder.file("data.csv"))
    doc = load_rrd(rrd)
    times, torque = _series(doc, "signals/torque_nm")
    assert times == pytest.approx(data["time_s"][::10], abs=1e-9)
    assert torque[:, 0] == pytest.approx(data["torque_hat_nm"][::10])
    z, v = data["z_hat"][::10], data["theta_dot_rad_s"][::10]
    lo = params["alpha1"] * z + params["c1"] * v
    assert torque[:, 2] == pytest.approx(lo)
    assert torque[:, 3] == pytest.approx(lo + params["alpha2"] * z + params["c2"] * v)
    _, lateness = _series(doc, "timing/lateness_us")
    assert lateness[:-1, 0] == pytest.approx(0.0)  # the virtual clock is never late
    assert np.isnan(lateness[-1, 0])  # the shutdown's safe-state row is no cycle: no lateness
    # hysteresis views: every sent row as a point (θ̇ in deg/s, −T̂)
    points = [p for row in doc["/hysteresis/torque_vs_velocity"]["Points2D:positions"] for p in row]
    assert len(points) == 150 + 1
    xs = sorted(round(p[0], 3) for p in points)
    assert xs == pytest.approx(sorted(np.round(np.degrees(v).astype(np.float32), 3)), abs=2e-3)


def test_live_tap_logs_trips_at_close(tmp_path):
    rrd = tmp_path / "t.rrd"
    tap = LiveTap(RerunLog.open(("time_s", "theta_rad"), save=rrd))
    tap.close([{"time_s": 1.25, "reason": "angle 31 deg beyond the interlock"}])
    doc = load_rrd(rrd)
    ((text,),) = doc["/events/trips"]["TextLog:text"]
    assert text == "1.250 s: angle 31 deg beyond the interlock"
    assert doc["/events/trips"]["time"] == [1.25]
    stats = tap.stats()
    assert stats["rows_sent"] == 0 and stats["sends"] == 0 and stats["error"] is None  # no recorder attached
