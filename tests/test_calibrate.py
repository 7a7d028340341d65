"""``sashil calibrate`` on the simulated rig: the plan, the folder it writes, bad input."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from sashil.cli import main
from sashil.config import load_params
from sashil.engine.resolve import default_config
from sashil.lab.calibration.plan import plan_from_config
from sashil.plans.calibration_step import RoadChirp

SMALL_PLAN = {
    "currents_a": [0.0, 1.0],
    "small_currents_a": [],
    "road_currents_a": [],
    "validate_currents_a": [0.5],
    "drop_duration_s": 4.0,
}


def write_config(folder: Path, calibrate: dict | None = None, params: dict | None = None) -> str:
    doc: dict = {"calibrate": calibrate or {}}
    if params:
        doc["model"] = {"params": params}
    path = folder / "cal.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def test_default_plan_fits_drops_and_road_runs_and_holds_some_out():
    plan = plan_from_config(default_config())
    fit, held = plan.fit_steps(), plan.validate_steps()
    assert [(s.theta0_deg, s.current_a, s.kind) for s in fit] == [
        (-5.0, 0.0, "drop"),
        (-5.0, 0.5, "drop"),
        (-5.0, 1.0, "drop"),
        (-2.5, 0.0, "drop"),
        (-2.5, 1.0, "drop"),
        (-5.0, 0.5, "road"),
        (-5.0, 1.0, "road"),
    ]
    assert [(s.theta0_deg, s.current_a) for s in held] == [(-3.5, 0.25), (-3.5, 0.75)]
    assert plan.rig_time_s <= 180.0  # the budget: 3 minutes of rig time
    assert plan.operator_angles_deg() == [s.theta0_deg for s in plan.steps]
    assert len({s.name for s in plan.steps}) == len(plan.steps)


def test_road_chirp_speed_is_the_derivative_of_its_angle_and_it_ends_at_rest():
    chirp = RoadChirp(math.radians(1.0), 0.8, 3.0, 12.0, 1.0)
    h = 1e-6
    for t in (0.3, 0.999, 1.7, 6.0, 11.2):
        numeric = (chirp.angle(t + h) - chirp.angle(t - h)) / (2 * h)
        assert chirp.speed(t) == pytest.approx(numeric, rel=1e-5, abs=1e-9)
    assert chirp.speed(0.0) == chirp.speed(12.0) == chirp.speed(13.0) == 0.0
    # full amplitude between the ramps: the peak angle reaches A
    t = np.linspace(1.0, 11.0, 20001)
    assert max(abs(chirp.angle(x)) for x in t) == pytest.approx(math.radians(1.0), rel=1e-3)


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    out = tmp_path_factory.mktemp("cal") / "c"
    assert main(["calibrate", "--out", str(out), "-q"]) == 0
    return out


@pytest.mark.e2e  # a whole calibration or identification (seconds)
def test_calibration_folder_holds_params_report_plots_and_raw_runs(calibration):
    for name in (
        "params.yaml",
        "report.md",
        "fit.png",
        "validation.png",
        "n_profile.png",
        "summary.json",
        "config.yaml",
    ):
        assert (calibration / name).is_file(), name
    runs = sorted(p.name for p in (calibration / "runs").iterdir())
    assert len(runs) == 9 and all((calibration / "runs" / r / "data.csv").is_file() for r in runs)
    summary = json.loads((calibration / "summary.json").read_text())
    assert summary["exit_status"] == "ok" and summary["model"] == "bouc-wen"
    assert set(summary["held_out_nrmse"]) == {r for r in runs if "validate" in r}


@pytest.mark.e2e  # a whole calibration or identification (seconds)
def test_calibration_report_says_j_is_one_and_validates_on_held_out_runs(calibration):
    text = (calibration / "report.md").read_text()
    assert text.splitlines()[0].startswith("**All torques are relative to J = 1**")
    assert "## Held-out validation" in text and "n is not identifiable from this plan" in text
    summary = json.loads((calibration / "summary.json").read_text())
    # the seed damper, 4096 counts: the encoder alone costs 2.4-2.5 % NRMSE on these held-out drops
    assert all(v < 0.035 for v in summary["held_out_nrmse"].values())


@pytest.mark.e2e  # a whole calibration or identification (seconds)
def test_params_and_report_give_95_percent_intervals_of_the_lab_quantities(calibration):
    doc = yaml.safe_load((calibration / "params.yaml").read_text())
    intervals, p = doc["intervals_95"], doc["params"]
    lab = ["k", "c_0a", "c_max", "yield_0a", "yield_max"]
    assert list(intervals)[:5] == lab
    assert set(intervals) == {*lab, *(name for name in p if name != "J")}
    value = {"k": p["k"], "c_0a": p["c1"], "c_max": p["c1"] + p["c2"], "yield_0a": p["alpha1"]}
    value["yield_max"] = p["alpha1"] + p["alpha2"]  # unit z bound, i_max = 1 A
    for name, (low, high) in intervals.items():
        assert low <= value.get(name, p.get(name)) * (1 + 1e-5) and high >= value.get(name, p.get(name)) * (1 - 1e-5)
    assert doc["calibration"]["intervals"]["method"].startswith("delete-one-block jackknife")
    assert doc["calibration"]["intervals"]["fit_suspect"] is False
    text = (calibration / "report.md").read_text()
    assert "| yield torque α(i_max)·z_u [N m] |" in text and "95 % interval" in text


@pytest.mark.e2e  # a whole calibration or identification (seconds)
def test_calibrated_parameters_match_the_seed_damper(calibration):
    p = load_params(calibration / "params.yaml")["params"]
    seed = default_config()["model"]["params"]
    assert p["J"] == 1.0
    assert p["k"] == pytest.approx(seed["k"], rel=0.01)
    zu = (seed["delta"] / (seed["beta"] + seed["gamma"])) ** (1 / seed["n"])
    for i in (0.0, 1.0):
        assert p["c1"] + p["c2"] * i == pytest.approx(seed["c1"] + seed["c2"] * i, rel=0.08)
        yield_fit = p["alpha1"] + p["alpha2"] * i  # unit z bound: alpha(i) is the yield torque
        assert yield_fit == pytest.approx((seed["alpha1"] + seed["alpha2"] * i) * zu, rel=0.05)


@pytest.mark.e2e  # a whole calibration or identification (seconds)
@pytest.mark.parametrize(
    "verb",
    [
        ["drop-test", "--duration", "1"],
        ["simulate", "--theta0-deg", "-5", "--current", "0.5", "--duration", "1"],
        ["sweep", "--f-start", "1.5", "--f-stop", "1.5", "--duration", "1"],
        ["run", "--duration", "0.2", "--current", "0.5"],
        ["emulate", "--duration", "0.2"],
    ],
)
def test_every_verb_accepts_the_calibrated_parameter_file(calibration, verb, tmp_path, capsys):
    args = [*verb, "--params", str(calibration / "params.yaml")]
    if verb[0] not in ("emulate",):
        args += ["--out", str(tmp_path / "o")]
    assert main(args) == 0, capsys.readouterr().err


@pytest.mark.e2e  # a whole calibration or identification (seconds)
def test_inertia_given_scales_the_torques(tmp_path, capsys):
    truth = {"J": 1.1, "k": 120.0}
    config = write_config(tmp_path, SMALL_PLAN, truth)
    out = tmp_path / "c"
    assert main(["calibrate", "--config", config, "--inertia", "1.1", "--out", str(out), "-q", "--no-profile"]) == 0
    assert "J = 1.1" in (out / "report.md").read_text().splitlines()[0]
    p = load_params(out / "params.yaml")["params"]
    assert p["J"] == 1.1 and p["k"] == pytest.approx(120.0, rel=0.01)
    assert "relative to J = 1" not in capsys.readouterr().out


@pytest.mark.parametrize(
    "args, calibrate, needle",
    [
        (["--inertia", "0"], None, "--inertia: calibrate.inertia_kg_m2: expected a number > 0 or null, got 0.0"),
        (["--inertia", "-1.5"], None, "--inertia: calibrate.inertia_kg_m2: expected a number > 0"),
        (["--inertia", "nan"], None, "--inertia: calibrate.inertia_kg_m2"),
        (
            ["--extra-steps", "12"],
            None,
            "--extra-steps: calibrate.extra_steps: expected an integer >= 0 and <= 9, got 12",
        ),
        ([], {"currents_a": [0.5], "small_currents_a": [0.5], "road_currents_a": []}, "cannot be identified"),
        ([], {"currents_a": [0.0, 2.0]}, "calibrate.currents_a: expected currents in [0, 1] A"),
        ([], {"max_rig_time_s": 30.0}, "calibrate.max_rig_time_s"),
        ([], {"road_f_stop_hz": 0.5}, "calibrate.road_f_stop_hz"),
        ([], {"colour": "red"}, "calibrate.colour"),
        ([], {"interval_block_s": 0.01}, "calibrate.interval_block_s: expected a number >= 0.1"),
        (
            [],
            {"currents_a": [0.0, 1.0], "small_currents_a": [], "road_currents_a": [], "drop_duration_s": 0.5},
            "calibrate.drop_duration_s: the runs to fit (1 s in all) are too short to block for the intervals: "
            "16 blocks of at least 0.1 s are needed; give at least 0.8 s",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, args, calibrate, needle):
    out = tmp_path / "never"
    command = ["calibrate", "--out", str(out), *args]
    if calibrate is not None:
        command += ["--config", write_config(tmp_path, calibrate)]
    assert main(command) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err, err
    assert not out.exists()


@pytest.mark.e2e  # a whole calibration or identification (seconds)
def test_identify_takes_a_multi_current_drop_test_folder(tmp_path, capsys):
    drops = tmp_path / "drops"
    assert main(["drop-test", "--current", "0", "--current", "1", "--duration", "3", "--out", str(drops)]) == 0
    out = tmp_path / "p.yaml"
    assert main(["identify", str(drops), "--quiet", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "i0.000A" in printed and "i1.000A" in printed and "95 % intervals (delete-one-block jackknife" in printed
    assert load_params(out)["params"]["k"] == pytest.approx(109.0, rel=0.01)
    low, high = yaml.safe_load(out.read_text())["intervals_95"]["k"]
    assert low < load_params(out)["params"]["k"] < high


def test_params_with_a_config_mismatch_warns_that_it_is_applied_on_top(calibration, tmp_path):
    import argparse
    import logging

    from sashil.cli.common import resolve_config

    seen: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: seen.append(record.getMessage())  # type: ignore[method-assign]
    logger = logging.getLogger("sashil")
    logger.addHandler(handler)
    try:
        config = tmp_path / "mm.yaml"
        config.write_text("mismatch: {fraction: 0.1}\n")
        params = str(calibration / "params.yaml")
        resolve_config(argparse.Namespace(config=str(config), params=params))
        assert len(seen) == 1 and "mismatch: section is applied on top of these parameters" in seen[0]
        resolve_config(argparse.Namespace(config=None, params=params))  # no mismatch: no warning
        assert len(seen) == 1
    finally:
        logger.removeHandler(handler)


def test_a_port_that_does_not_exist_is_one_line_exit_2_and_nothing_written(tmp_path, capsys):
    out = tmp_path / "never"
    port = str(tmp_path / "no-such-tty")
    assert main(["calibrate", "--driver", "serial", "--port", port, "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no-such-tty" in err[0]
    assert not out.exists()


def _sample(seq: int, theta_deg: float, flags: int) -> object:
    from sashil.drivers.interface import RigSample

    counts = round(theta_deg * 4096 / 360)
    return RigSample(seq, seq * 1_000_000, seq * 1000, counts, 0, 0.0, flags, 4096)


@pytest.mark.parametrize("flags, held", [(0x02, True), (0x00, False)])
def test_a_drop_test_takes_a_simulated_operators_flagged_hold_wherever_it_is(flags, held):
    # the emulator with one --hold-deg holds every drop at -5 deg; a plan step asks for -2.5 deg
    from sashil.engine import assemble
    from sashil.engine.resolve import default_config
    from sashil.lab._drop_test import READS
    from sashil.plans.drop import DropTestPlan

    plan = DropTestPlan(assemble(default_config(), reads=READS), -2.5, 0.0, 1.0)
    for seq in range(1, 400):  # 0.4 s held still at -5 deg (hold_time_s is 0.2 s)
        plan.step(_sample(seq, -5.0, flags), seq * 1_000_000, 1_000_000)
    assert (plan.phase == "held") is held
    if held:  # flagged by the device: taken where it is, with the warning in held_elsewhere
        assert plan.held_elsewhere and plan.hold_angle == pytest.approx(math.radians(-5.0), abs=math.radians(0.1))


def _drop_result(step, gap_at_s: float | None):
    from sashil.lab.calibration.rig import StepResult

    t = np.arange(0.0, 3.0, 1e-3)
    theta = -0.087 * np.exp(-t) * np.cos(10 * t)  # a decaying swing: the fit would use all of it
    keep = np.ones(t.size, dtype=bool)
    if gap_at_s is not None:
        keep &= ~((t > gap_at_s) & (t < gap_at_s + 0.08))  # 80 ms of samples lost to a host pause
    columns = {"time_s": t[keep], "theta_rad": theta[keep], "current_a": np.full(keep.sum(), step.current_a)}
    return StepResult(step, columns, -5.0, True, None, {})


def test_gap_cut_finds_a_host_pause_inside_the_record_and_ignores_one_after_it():
    from sashil.lab.calibration.analysis import gap_cut

    step = plan_from_config(default_config()).fit_steps()[0]
    assert gap_cut(_drop_result(step, None), 4096) is None
    assert gap_cut(_drop_result(step, 0.42), 4096) == pytest.approx(0.42, abs=2e-3)


def test_a_step_cut_short_by_a_link_gap_is_repeated_and_the_whole_record_kept(tmp_path, monkeypatch):
    from sashil.lab.calibration import session

    calls: list[str] = []

    def run_step(config, step, data_path=None):  # the first run of each step loses samples to a host pause
        calls.append(step.name)
        return _drop_result(step, 0.42 if calls.count(step.name) == 1 else None)

    monkeypatch.setattr(session, "run_step", run_step)

    class PlanDone(Exception):
        pass

    def analyse(*args, **kwargs):  # the plan ran to its end: stop before the fit
        raise PlanDone

    monkeypatch.setattr(session, "analyse", analyse)
    said: list[str] = []
    config = default_config()
    config["calibrate"].update(SMALL_PLAN)
    with pytest.raises(PlanDone):
        session.calibrate_rig(config, tmp_path / "c", say=said.append)
    names = [s.name for s in plan_from_config(config).steps]
    assert calls == [name for name in names for _ in (1, 2)]  # each step once more, no more
    repeats = [line for line in said if "link gap" in line]
    assert len(repeats) == len(names) and "0.42 s after the release" in repeats[0] and "(1 of 2)" in repeats[0]
    for name in names:
        data = (tmp_path / "c" / "runs" / name / "data.csv").read_text().splitlines()
        assert len(data) == 3001  # the repeat's whole record, header included


def _plan_on_an_emulated_board(tmp_path, monkeypatch, console: bool, gap_step: int) -> list[tuple[str, float]]:
    """The default plan run by ``calibrate_rig`` against the emulated board's logic on simulated time:
    each attempt of a step connects (Configure) and reads the angle the board's operator holds the
    arm at; step ``gap_step``'s first attempt loses samples to a link gap, so it is repeated. With
    ``console`` the operator reads the host's prompts from a file of its console, as ``sashil
    emulate --prompts`` does; without, it plays the plan's angles in order (``--hold-deg``).
    Returns (step name, held angle [deg]) per attempt."""
    from sashil.drivers.emulator import HostConsole, Operator, build_device
    from sashil.drivers.interface import FLAG_HELD
    from sashil.drivers.messages import CMD_ENABLE, PACING_DEVICE, Command, Configure, Sample
    from sashil.lab.calibration import session

    config = default_config()
    plan = plan_from_config(config)
    screen = tmp_path / "console.txt"
    angles = plan.operator_angles_deg()
    operator = Operator(angles[0], 10.0, tuple(angles[1:]), console=HostConsole(screen) if console else None)
    board = build_device(config, operator=operator)
    held: list[tuple[str, float]] = []
    ms = 1_000_000

    def run_step(config, step, data_path=None):
        start = (len(held) + 1) * 1000 * ms  # a new connection each attempt, a second apart
        board.handle(Configure(1000, 1000, PACING_DEVICE), start)
        out = []
        for t in range(start, start + 20 * ms, ms):
            out += board.handle(Command(step.current_a, CMD_ENABLE), t) + board.tick(t)
        last = [m for _, m in out if isinstance(m, Sample) and m.flags & FLAG_HELD][-1]
        held.append((step.name, last.arm_counts * 360 / 4096))
        first_try = [name for name, _ in held].count(step.name) == 1
        return _drop_result(step, 0.42 if first_try and step.name == plan.steps[gap_step].name else None)

    class PlanDone(Exception):
        pass

    def analyse(*args, **kwargs):  # the plan ran to its end: stop before the fit
        raise PlanDone

    monkeypatch.setattr(session, "run_step", run_step)
    monkeypatch.setattr(session, "analyse", analyse)

    def to_console(line: str) -> None:  # the host's stderr in a file, one write per line as printer() does
        with screen.open("a") as out:
            out.write(f"  {line}\n")

    with pytest.raises(PlanDone):
        session.calibrate_rig(config, tmp_path / "c", say=to_console, prompt=to_console)
    return held


def test_an_emulated_operator_reading_the_prompts_holds_a_repeated_step_and_the_rest_at_their_angles(
    tmp_path, monkeypatch
):
    plan = plan_from_config(default_config())
    gap_step = 2  # the last -5 deg drop before the -2.5 deg ones: a shift would show at once
    held = _plan_on_an_emulated_board(tmp_path / "prompts", monkeypatch, True, gap_step)
    want = {s.name: s.theta0_deg for s in plan.steps}
    assert [name for name, _ in held] == [s.name for s in plan.steps for _ in range(1 + (s is plan.steps[gap_step]))]
    for name, angle in held:
        assert angle == pytest.approx(want[name], abs=360 / 4096), name
    # the operator that plays the plan's angles in order is one session ahead after the repeat
    ordered = _plan_on_an_emulated_board(tmp_path / "ordered", monkeypatch, False, gap_step)
    wrong = [name for name, angle in ordered if abs(angle - want[name]) > 360 / 4096]
    assert wrong and wrong[0] == plan.steps[gap_step].name


@pytest.mark.e2e  # a whole calibration, refitted (seconds)
def test_extra_steps_run_the_suggested_step_and_refit(tmp_path, capsys):
    out = tmp_path / "c"
    config = write_config(tmp_path, SMALL_PLAN)
    assert main(["calibrate", "--config", config, "--out", str(out), "--extra-steps", "1", "--no-profile", "-q"]) == 0
    runs = sorted(p.name for p in (out / "runs").iterdir())
    assert len(runs) == 4 and runs[-1].startswith("04-fit-") and runs[-1].endswith("-extra")
    doc = yaml.safe_load((out / "params.yaml").read_text())
    assert doc["calibration"]["widest_interval"]["quantity"] in {"k", "c_0a", "c_max", "yield_0a", "yield_max"}
    assert "## A plan that shrinks the widest interval" in (out / "report.md").read_text()
    summary = json.loads((out / "summary.json").read_text())
    assert [r["name"] for r in summary["runs"]] == runs
