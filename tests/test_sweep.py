"""Road profiles, stepped-sine transmissibility, the ``sashil sweep`` verb."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from sashil.cli import main
from sashil.config.parts import StageParts
from sashil.control.registry import make_controller
from sashil.engine.resolve import default_config
from sashil.lab._sweep import chirp_profile, sine_profile, stepped_sine


@pytest.mark.parametrize(
    "profile",
    [chirp_profile(0.01, 0.5, 5.0, 10.0, 1.0), sine_profile(0.01, 2.0, 1.0), sine_profile(0.01, 2.0, 1.0, stop_s=7.0)],
)
def test_profiles_are_consistent_with_their_derivatives(profile):
    h = 1e-5
    for t in (0.3, 0.9, 2.0, 6.9, 7.2, 7.5, 7.95, 11.0):
        (x0, v0, _), (x1, v1, _) = profile(t - h), profile(t + h)
        _x, v, a = profile(t)
        assert v == pytest.approx((x1 - x0) / (2 * h), abs=1e-6)
        assert a == pytest.approx((v1 - v0) / (2 * h), abs=1e-4)


def test_the_stepped_sine_road_ramps_down_to_rest_after_its_stop_time():
    road = sine_profile(0.01, 2.0, 1.0, stop_s=7.0)
    assert road(6.875) == pytest.approx(sine_profile(0.01, 2.0, 1.0)(6.875))  # untouched before the stop
    x, _v, _a = road(7.5)  # half-way down the raised cosine: half the amplitude
    assert x == pytest.approx(0.005 * math.sin(2 * math.pi * 2.0 * 7.5), abs=1e-12)
    assert road(8.0) == (0.0, 0.0, 0.0) and road(9.3) == (0.0, 0.0, 0.0)  # at rest from stop + ramp on


def test_chirp_is_a_sine_of_the_linear_frequency_ramp():
    road = chirp_profile(0.02, 0.5, 5.0, 10.0, ramp_s=0.0)
    for t in (0.5, 4.0, 9.9):
        phase = 2 * math.pi * (0.5 * t + 0.5 * 0.45 * t * t)
        x, v, _ = road(t)
        assert x == pytest.approx(0.02 * math.sin(phase), abs=1e-12)
        assert v == pytest.approx(0.02 * math.cos(phase) * 2 * math.pi * (0.5 + 0.45 * t), abs=1e-12)
    # held at f_stop after the ramp: one period later the angle repeats
    assert road(12.0)[0] == pytest.approx(road(12.2)[0], abs=1e-9)


def test_stepped_sine_transmissibility_is_one_below_and_small_above_resonance():
    config = default_config()
    config["sweep"].update(settle_s=3.0, measure_s=2.0, ramp_s=0.5)
    soft = stepped_sine(config, lambda: make_controller("passive", StageParts.read(config)), [0.3, 1.66, 5.0])
    assert soft[0].transmissibility == pytest.approx(1.0, abs=0.05)
    assert soft[1].transmissibility > 3.0  # resonance sqrt(109)/(2 pi) = 1.66 Hz, light damping
    assert soft[2].transmissibility < 0.3
    config["controller"]["current_a"] = 1.0
    hard = stepped_sine(config, lambda: make_controller("passive", StageParts.read(config)), [1.66])
    assert hard[0].transmissibility < 0.6 * soft[1].transmissibility


def test_sweep_cli_stepped_writes_table_and_plot(tmp_path):
    out = tmp_path / "run"
    rc = main(
        ["sweep", "--stepped", "--steps", "2", "--f-start", "1", "--f-stop", "3", "--current", "0.5", "--out", str(out)]
    )
    assert rc == 0
    lines = (out / "transmissibility.csv").read_text().splitlines()
    assert lines[0].startswith("frequency_hz,body_rms_rad") and len(lines) == 3
    assert (out / "transmissibility.png").stat().st_size > 1000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "ok"
    # each frequency's time series is kept in a sub-folder, a run folder of its own
    import sashil

    run = sashil.load_run(out)
    assert [r.name for r in run.runs] == ["f1.000Hz", "f3.000Hz"]
    assert run.run("f3.000Hz").metrics["transmissibility"] == summary["points"][1]["transmissibility"]
    assert run.runs[0].data["time_s"][-1] > 10.0 and run.runs[0].config["controller"]["current_a"] == 0.5
    assert list(run.tables["transmissibility"]["frequency_hz"]) == [1.0, 3.0]


def test_sweep_cli_at_one_frequency_records_seq_and_the_sine(tmp_path):
    # --f-stop = --f-start: a sine at that frequency; data.csv carries the sample seq (join with emulate --truth)
    out = tmp_path / "sine"
    rc = main(
        [
            "sweep",
            "--f-start",
            "1.25",
            "--f-stop",
            "1.25",
            "--duration",
            "2",
            "--amplitude-deg",
            "1",
            "--current",
            "0",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    lines = (out / "data.csv").read_text().splitlines()
    header = lines[0].split(",")
    # seq: the sample of each cycle, then the shutdown's 0 A row on the last sample
    assert header[-1] == "seq" and lines[1].split(",")[-1] == "1" and lines[-2].split(",")[-1] == str(len(lines) - 2)
    assert lines[-1].split(",")[-1] == str(len(lines) - 2) and float(lines[-1].split(",")[4]) == 0.0
    rows = [dict(zip(header, map(float, line.split(",")), strict=True)) for line in lines[1:]]
    late = [r for r in rows if r["time_s"] >= 1.0]  # after the 1 s ramp: theta1 = sin(2 pi 1.25 t), 1 deg
    assert max(abs(math.degrees(r["theta_road_rad"]) - math.sin(2 * math.pi * 1.25 * r["time_s"])) for r in late) < 0.1
    assert (out / "chirp.png").stat().st_size > 20_000  # road, body and current against time


@pytest.mark.parametrize("mode", [[], ["--stepped", "--steps", "2"]])
def test_a_sweep_that_trips_the_angle_interlock_ends_at_zero_amps_and_keeps_its_data(tmp_path, capsys, mode):
    # at the 1.6 Hz resonance and 0 A the arm swings past a 3 deg interlock (rig.angle_limit_deg)
    config = tmp_path / "tight.yaml"
    config.write_text("rig:\n  angle_limit_deg: 3.0\n")
    out = tmp_path / "tripped"
    rc = main(
        [
            "sweep",
            *mode,
            "--f-start",
            "1.6",
            "--f-stop",
            "2.0",
            "--duration",
            "20",
            "--current",
            "0.5",
            "--config",
            str(config),
            "--out",
            str(out),
        ]
    )
    err = capsys.readouterr().err
    assert rc != 0 and "angle" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "safety_trip" and "angle" in summary["error"]  # the one schema's status
    if not mode:  # the chirp's rows up to the trip are on disk; the last command is 0 A
        lines = (out / "data.csv").read_text().splitlines()
        header = lines[0].split(",")
        before, last = (dict(zip(header, line.split(","), strict=True)) for line in lines[-2:])
        assert len(lines) > 500 and float(before["current_cmd_a"]) == pytest.approx(0.5)
        assert float(last["current_cmd_a"]) == 0.0  # the stream ends on the 0 A the trip sent
        assert abs(math.degrees(float(last["theta_rad"]))) > 2.5
    else:
        assert summary["points"] == []  # the first frequency tripped: nothing measured, nothing invented


def test_a_safety_trip_in_a_sweep_leaves_the_damper_at_zero_amps():
    from sashil.drivers import open_rig
    from sashil.errors import SafetyTrip
    from sashil.lab._sweep import run_profile

    config = default_config()
    config["rig"]["angle_limit_deg"] = 3.0
    rigs, kept = [], []

    def factory(run, road):
        rigs.append(open_rig(run.rig))
        return rigs[-1]

    with pytest.raises(SafetyTrip):
        run_profile(
            config,
            make_controller(
                "passive", StageParts.read({**config, "controller": {**config["controller"], "current_a": 0.5}})
            ),
            sine_profile(math.radians(1.0), 1.6, 1.0),
            20.0,
            factory,
            keep=kept.append,
        )
    assert rigs[0]._command == 0.0 and rigs[0].plant.state.current_a < 0.5
    assert len(kept) == 1 and kept[0]["current_cmd_a"][-2] == pytest.approx(0.5) and len(kept[0]["time_s"]) > 500
    assert kept[0]["current_cmd_a"][-1] == 0.0  # the data ends on the safe state


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--controller", "nope"], "--controller: controller.law: unknown law 'nope'"),
        (["--controller", "skyhook"], "controller.c_sky"),
        (["--f-start", "3", "--f-stop", "1"], "--f-stop: expected a frequency at or above --f-start (3 Hz)"),
        (["--stepped", "--f-start", "2", "--f-stop", "2"], "--f-stop: a stepped sine needs a frequency above"),
        (["--current", "5"], "--current: controller.current_a: expected a current in [0, 1]"),
    ],
)
def test_sweep_cli_bad_input_is_one_line(tmp_path, capsys, argv, message):
    rc = main(["sweep", *argv, "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and err.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_skyhook_add_is_no_worse_than_the_better_passive_setting_with_mismatch():
    # shortened: 10 % plant mismatch, coil lag +10 %, 4096 counts/rev
    config = default_config()
    config["mismatch"].update(fraction=0.1, coil_tau=0.1)
    config["sweep"].update(settle_s=4.0, measure_s=2.0, ramp_s=1.0)
    config["controller"]["crossover_hz"] = 3.5
    freqs = [1.0, 1.5, 2.5, 4.5]

    def body(name, current=None):
        cfg = copy.deepcopy(config)
        if current is not None:
            cfg["controller"]["current_a"] = current
        return [p.body_rms_rad for p in stepped_sine(cfg, lambda: make_controller(name, StageParts.read(cfg)), freqs)]

    soft, hard, law = body("passive", 0.0), body("passive", 1.0), body("skyhook-add")
    ratios = [x / min(a, b) for x, a, b in zip(law, soft, hard, strict=True)]
    assert max(ratios) <= 1.03, ratios
    assert soft[1] > 2 * hard[1] and hard[3] > soft[3]  # the two passive settings each lose somewhere


# the library function, called from Python ------------------------------------------------------
def _resolved(*options, **source):
    from sashil.engine.resolve import ConfigSource, resolve

    return resolve(ConfigSource(options=options, **source), "sweep")


def test_the_sweep_function_runs_a_chirp_into_the_run_it_returns(tmp_path):
    from sashil.engine.resolve import Option
    from sashil.lab._sweep import SWEEP_COLUMNS, sweep
    from sashil.recording.outputs import Outputs

    config = _resolved(
        Option("--f-start", "sweep.f_start_hz", 1.5),
        Option("--f-stop", "sweep.f_stop_hz", 2.5),
        Option("--duration", "sweep.duration_s", 1.0),
        sets=("sweep.ramp_s=0.5", "controller.current_a=0.4"),
    )
    events = []
    run = sweep(config, Outputs(out=tmp_path / "chirp"), events.append)
    assert run.path == tmp_path / "chirp" and run.verb == "sweep"
    data = run.data
    assert list(data) == [*SWEEP_COLUMNS, "current_law_a", "seq"]  # the passive law gives a current
    assert set(data["current_law_a"][:-1]) == {0.4}
    assert len(data["time_s"]) == 1500 + 1  # 1 s chirp + 0.5 s ramp at 1 kHz, then the 0 A row
    # the simulated rig reports its plant's true torque (capability true_torque): no NaN in the record
    assert np.all(np.isfinite(data["torque_true_nm"][:-1])) and np.any(data["torque_true_nm"] != 0.0)
    summary = run.summary
    assert summary["exit_status"] == "ok" and summary["mode"] == "chirp" and summary["controller"] == "passive 0.4 A"
    assert {"road", "body_rms_rad", "road_rms_rad", "body_peak_rad", "observer_nrmse", "clipped_cycles"} <= set(summary)
    body = data["theta_rad"] + data["theta_road_rad"]  # the arm angle theta2 = theta + theta1
    assert summary["body_rms_rad"] == pytest.approx(float(np.std(body)), rel=1e-12)
    assert summary["road"] == "chirp 1.5-2.5 Hz over 1 s, 1 deg"
    assert run.config["sweep"]["duration_s"] == 1.0 and run.config["controller"]["current_a"] == 0.4
    outputs = [e.text for e in events if e.kind == "output"]
    assert outputs[0].startswith("chirp 1.5-2.5 Hz over 1 s (passive 0.4 A): body RMS ")
    assert outputs[-1] == f"run folder: {run.path}"


def test_the_sweep_function_runs_a_stepped_sine_a_sub_run_per_frequency(tmp_path):
    from sashil.engine.resolve import Option
    from sashil.lab._sweep import TRANSMISSIBILITY_COLUMNS, sweep
    from sashil.recording.outputs import Outputs

    config = _resolved(
        Option("--stepped", "sweep.stepped", True),
        Option("--steps", "sweep.steps", 2),
        Option("--f-start", "sweep.f_start_hz", 0.3),
        Option("--f-stop", "sweep.f_stop_hz", 5.0),
        sets=("sweep.settle_s=3", "sweep.measure_s=2", "sweep.ramp_s=0.5", "sweep.spacing=linear"),
    )
    events = []
    run = sweep(config, Outputs(out=tmp_path / "stepped"), events.append)
    assert [r.name for r in run.runs] == ["f0.300Hz", "f5.000Hz"]
    table = run.tables["transmissibility"]
    assert list(table) == list(TRANSMISSIBILITY_COLUMNS) and list(table["frequency_hz"]) == [0.3, 5.0]
    # far below the 1.66 Hz resonance the arm follows the road; far above it, it stays behind
    assert table["transmissibility"][0] == pytest.approx(1.0, abs=0.05) and table["transmissibility"][1] < 0.3
    assert [p["transmissibility"] for p in run.summary["points"]] == list(table["transmissibility"])
    assert run.summary["integrated_body_rms_rad"] == pytest.approx(
        math.sqrt(np.mean(table["body_rms_rad"] ** 2)), rel=1e-12
    )
    assert [e.data["frequency_hz"] for e in events if e.kind == "progress"] == [0.3, 5.0]
    assert len([e for e in events if e.kind == "output"]) == 1 + 2 + 1 + 1  # header, rows, integrated, folder


def test_a_stepped_sines_views_see_each_frequency_and_a_stop_ends_the_sweep_at_0_a(tmp_path):
    from sashil.engine.resolve import Option
    from sashil.errors import Stopped
    from sashil.lab._sweep import sweep
    from sashil.recording.outputs import Outputs
    from sashil.runtime.signals import StopFlag

    config = _resolved(
        Option("--stepped", "sweep.stepped", True),
        Option("--steps", "sweep.steps", 3),
        Option("--f-start", "sweep.f_start_hz", 1.0),
        Option("--f-stop", "sweep.f_stop_hz", 3.0),
        sets=("sweep.settle_s=1", "sweep.measure_s=1", "sweep.ramp_s=0.5", "controller.current_a=0.3"),
    )
    flag = StopFlag()
    seen: list[tuple[str, int]] = []

    class StopOnTheSecond:
        """A page's view: it watches each frequency's stream and presses STOP as the second starts."""

        def start(self, stream, timing):
            self.stream = stream
            seen.append(("start", stream.rows_committed))
            if len(seen) == 3:
                flag.request("STOP (test)")

        def close(self, trips, notes):
            seen.append(("close", self.stream.rows_committed))

    with pytest.raises(Stopped):
        sweep(config, Outputs(out=tmp_path / "stepped"), views=[StopOnTheSecond()], stop=flag)
    assert [kind for kind, _ in seen] == ["start", "close", "start", "close"]
    assert (
        seen[1][1] == 3000 + 1
    )  # the first frequency whole (ramp 0.5, settle 1, measure 1, ramp down 0.5 s), the 0 A row
    summary = json.loads((tmp_path / "stepped" / "summary.json").read_text())
    assert summary["exit_status"] == "stopped" and [r["exit_status"] for r in summary["runs"]] == ["ok", "stopped"]
    assert summary["runs"][1]["safe_state"] is None  # stopped before its first cycle: nothing to settle
    stopped = (tmp_path / "stepped" / "f1.732Hz" / "cycles.csv").read_text().splitlines()  # log spacing
    assert len(stopped) - 1 == seen[3][1] == 0  # stopped before its first cycle: nothing energised


@pytest.mark.parametrize(
    "options, sets, message",
    [
        ((("--f-start", "sweep.f_start_hz", 3.0), ("--f-stop", "sweep.f_stop_hz", 1.0)), (), "--f-stop: expected a frequency at or above --f-start (3 Hz), got 1"),
        ((("--f-start", "sweep.f_start_hz", 150.0),), (), "--f-start: expected a frequency in (0, 100] Hz, got 150"),
        ((), ("sweep.stepped=true", "sweep.f_start_hz=2", "sweep.f_stop_hz=2"), "sweep.f_stop_hz: a stepped sine needs a frequency above sweep.f_start_hz"),
        ((("--amplitude-deg", "sweep.amplitude_deg", 30.0),), (), "--amplitude-deg: sweep.amplitude_deg: expected a number > 0 and <= 20"),
    ],
)  # fmt: skip
def test_the_sweep_options_are_checked_when_the_config_is_resolved(options, sets, message):
    from sashil.engine.resolve import Option
    from sashil.errors import ConfigError

    with pytest.raises(ConfigError) as err:
        _resolved(*(Option(*option) for option in options), sets=sets)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_the_sweep_function_leaves_no_folder_on_bad_input(tmp_path):
    import re

    from sashil.config.frozen import freeze, thaw
    from sashil.errors import ConfigError, DriverError
    from sashil.lab._sweep import sweep
    from sashil.recording.outputs import Outputs

    port = tmp_path / "no-port"
    config = _resolved(driver="serial", port=str(port), sets=("sweep.f_start_hz=1", "sweep.f_stop_hz=1"))
    with pytest.raises(DriverError, match=re.escape(f"serial port {port}: cannot open")) as err:
        sweep(config, Outputs(out=tmp_path / "x"))
    assert err.value.exit_code == ConfigError.exit_code and not (tmp_path / "x").exists()  # bad input: exit 2
    skyhook = thaw(_resolved())
    skyhook["controller"]["law"] = "skyhook"  # a config that did not go through resolve: no c_sky
    with pytest.raises(ConfigError, match=r"controller\.c_sky"):
        sweep(freeze(skyhook), Outputs(out=tmp_path / "y"))
    assert not (tmp_path / "y").exists()
    with pytest.raises(ConfigError, match="--format asc: a CAN frame trace needs the can driver"):
        sweep(_resolved(), Outputs(out=tmp_path / "z", formats=("asc",)))
    assert not (tmp_path / "z").exists()
