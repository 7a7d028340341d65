"""Every plot kind, rendered and read back through matplotlib's artists (labels, titles, legends,
ticks, scales), not pixels: run.png, timing.png, transmissibility.png, chirp.png, simulate's
theta.png, the report's theta/hysteresis plots and report.md, calibrate's fit.png and n_profile.png."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from sashil.cli import main
from sashil.engine.resolve import default_config
from sashil.lab.report import write_report
from sashil.recording import plots
from sashil.writer.run_folder import RunFolder
from sashil.writer.summary_writer import write_config, write_summary


@pytest.fixture
def figures(monkeypatch) -> list[Any]:
    """The figures the code under test made, in order (each kept for the test to read)."""
    kept: list[Any] = []
    make = plots._Figures.subplots

    def subplots(*args: Any, **kwargs: Any) -> tuple[Any, Any]:
        fig, axes = make(*args, **kwargs)
        kept.append(fig)
        return fig, axes

    monkeypatch.setattr(plots._Figures, "subplots", staticmethod(subplots))
    return kept


def legend_texts(ax: Any) -> list[str]:
    legend = ax.get_legend()
    return [] if legend is None else [text.get_text() for text in legend.get_texts()]


def tick_labels(axis: Any) -> list[str]:
    """The major tick labels a reader sees: inside the view, not empty (drawn first, so formatters ran)."""
    axis.axes.figure.canvas.draw()
    low, high = sorted(axis.get_view_interval())
    span = high - low
    return [
        label.get_text()
        for value, label in zip(axis.get_majorticklocs(), axis.get_ticklabels(), strict=True)
        if label.get_text() and low - 1e-9 * span <= value <= high + 1e-9 * span
    ]


def loop_folder(root: Path, name: str, law: str, onoff: bool = False, **params: float) -> Path:
    """A run folder as `sashil run` writes it (config.yaml, data.csv, summary.json), 2 s at 1 kHz."""
    config = default_config()
    config["controller"].update({"law": law, **params})
    folder = RunFolder.create(root / name, "run")
    write_config(folder, config)
    t = np.arange(2000) * 1e-3
    road = math.radians(1.0) * np.sin(2 * np.pi * t)
    theta = 0.4 * road * np.cos(2 * np.pi * t)
    columns = {
        "time_s": t,
        "theta_rad": theta,
        "current_a": np.full_like(t, 0.3),
        "current_cmd_a": np.full_like(t, 0.3),
        "theta_road_rad": road,
        "theta_dot_rad_s": np.gradient(theta, t),
        "z_hat": np.tanh(50 * np.gradient(theta, t)) * 0.1,
        "torque_hat_nm": 0.2 * np.sin(2 * np.pi * t),
        "torque_cmd_nm": np.full_like(t, np.nan) if onoff else 0.25 * np.sin(2 * np.pi * t),
    }
    if law == "passive":
        for name_ in ("theta_dot_rad_s", "z_hat", "torque_hat_nm", "torque_cmd_nm"):
            del columns[name_]
    folder.write_data(columns)
    label = "passive 0 A" if law == "passive" else law
    stats = None if law == "passive" else {"clipped_cycles": 700, "passive_cycles": 0}
    timing = {"rate_hz": 1000.0, "cycles": 2000, "missed_deadlines": 0}
    write_summary(folder,
        {"verb": "run", "exit_status": "ok", "driver": "sim", "controller": label, "road": "sine 1 Hz, 1 deg",
         "controller_stats": stats, "timing": timing, "trips": []}
    )  # fmt: skip
    return folder.path


def test_readable_log_ticks_are_one_two_three_five():
    assert plots.readable_log_ticks(0.25, 5.5) == [0.3, 0.5, 1, 2, 3, 5]
    wide = plots.readable_log_ticks(0.1, 4000)
    assert len(wide) <= 8 and {1, 10, 100, 1000} <= set(wide)
    assert len(plots.readable_log_ticks(1.1, 1.3)) >= 2  # narrower than one step: its ends


def test_run_png_law_with_target_has_band_and_legends_beside_the_traces(tmp_path, figures):
    folder = loop_folder(tmp_path, "sky", "skyhook", c_sky=2.0)
    summary = json.loads((folder / "summary.json").read_text())
    plots.plot_run(folder / "run.png", folder, summary)
    (fig,) = figures
    angles, current, torque = fig.axes
    assert "skyhook (c_sky=2)" in angles.get_title("left") and "road sine 1 Hz" in angles.get_title("left")
    assert angles.get_ylabel() == "angle [deg]" and current.get_ylabel() == "coil current [A]"
    assert torque.get_ylabel() == "damper torque [N·m]" and torque.get_xlabel() == "time [s]"
    assert legend_texts(angles) == ["θ (relative angle)", "θ1 (road)", "θ2 (arm)"]
    assert legend_texts(torque) == ["feasible band, 0 A … i_max", "observer T̂", "target T*"]
    fig.canvas.draw()
    for ax in fig.axes:  # every legend sits right of its panel, over no trace
        assert ax.get_legend().get_window_extent().x0 >= ax.get_window_extent().x1


def test_run_png_of_an_on_off_law_lists_no_target_torque(tmp_path, figures):
    folder = loop_folder(tmp_path, "onoff", "skyhook-onoff", onoff=True)
    plots.plot_run(folder / "run.png", folder, json.loads((folder / "summary.json").read_text()))
    torque = figures[0].axes[2]
    assert legend_texts(torque) == ["feasible band, 0 A … i_max", "observer T̂"]


def test_run_png_of_a_passive_run_has_no_torque_panel(tmp_path, figures):
    folder = loop_folder(tmp_path, "passive", "passive")
    plots.plot_run(folder / "run.png", folder, None)
    assert len(figures[0].axes) == 2 and figures[0].axes[0].get_title("left") == "sashil run"


def test_timing_png_of_a_short_run_ends_at_its_maximum_with_readable_ticks(tmp_path, figures):
    rng = np.random.default_rng(1)
    timing = {
        "lateness_ns": np.concatenate([np.zeros(10), rng.exponential(2_000, 490)]),
        "compute_ns": rng.lognormal(np.log(5_000), 0.6, 500),
    }
    plots.plot_timing(tmp_path / "timing.png", [("skyhook (c_sky=2)", timing)])
    lateness, compute = figures[0].axes
    for ax, key in ((lateness, "lateness_ns"), (compute, "compute_ns")):
        assert tick_labels(ax.xaxis) == ["p50", "p90", "p99"]  # p99.9 would need 1000 cycles
        assert ax.get_xlim()[1] <= 500 * 2  # no empty tail past the maximum (×, at x = 500)
        assert ax.get_ylim()[1] > timing[key].max() * 1e-3 * 1.2  # the × is not cut at the top
        labels = tick_labels(ax.yaxis)
        assert len(labels) >= 3 and all("$" not in label for label in labels)
        assert legend_texts(ax) == ["skyhook (c_sky=2)"] and ax.get_xlabel().startswith("percentile")
    assert compute.get_yscale() == "log" and lateness.get_yscale() == "symlog"  # zeros need symlog
    assert "0" in tick_labels(lateness.yaxis)
    assert compute.get_ylabel() == "compute time per cycle [µs]"


def test_transmissibility_png_has_log_axes_with_readable_ticks_and_law_legends(tmp_path, figures):
    f = np.geomspace(0.5, 5.0, 12)
    curve = 1.0 / np.abs(1 - (f / 1.66) ** 2 + 0.3j * f / 1.66)
    plots.plot_transmissibility(tmp_path / "t.png", [("passive 0 A", f, curve), ("skyhook (c_sky=2)", f, curve * 0.8)])
    (ax,) = figures[0].axes
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    assert {"0.5", "1", "2", "5"} <= set(tick_labels(ax.xaxis))
    assert {"0.3", "1", "2"} <= set(tick_labels(ax.yaxis))
    assert ax.get_xlabel() == "road frequency [Hz]" and "transmissibility" in ax.get_ylabel()
    assert legend_texts(ax) == ["passive 0 A", "skyhook (c_sky=2)"]


def test_chirp_png_reads_the_instantaneous_frequency_on_a_second_axis(tmp_path, figures):
    t = np.arange(0, 11, 1e-3)
    f = plots.chirp_frequency(t, 0.5, 5.0, 10.0)
    assert f[0] == 0.5 and f[-1] == 5.0 and plots.chirp_frequency(np.array([5.0]), 0.5, 5.0, 10.0)[0] == 2.75
    road = 0.02 * np.sin(2 * np.pi * np.cumsum(f) * 1e-3)
    cols = {"time_s": t, "theta_rad": road, "theta_road_rad": road, "current_a": 0 * t, "current_cmd_a": 0 * t}
    plots.plot_chirp(tmp_path / "chirp.png", cols, "chirp 0.5-5 Hz", chirp=(0.5, 5.0, 10.0))
    angles, current = figures[0].axes
    (top,) = angles.child_axes
    assert top.get_xlabel() == "road frequency [Hz]"
    labels = tick_labels(top.xaxis)
    assert {"0.5", "1", "2", "5"} <= set(labels)
    ticks = dict(zip(labels, top.get_xticks(), strict=True))
    assert ticks["2"] == pytest.approx(10.0 * (2 - 0.5) / 4.5)  # the time the road shakes at 2 Hz
    assert angles.get_title() == "chirp 0.5-5 Hz" and current.get_xlabel() == "time [s]"


def test_simulate_plot_has_title_nrmse_residual_and_drop_metrics(tmp_path, figures, capsys):
    assert main(["simulate", "--current", "1", "--duration", "3", "--out", str(tmp_path / "a")]) == 0
    (alone,) = figures
    assert alone.axes[0].get_title() == "sashil simulate: bouc-wen on drop test theta0 -5 deg, 1 A"
    assert "damping ratio ζ" in capsys.readouterr().out
    record = tmp_path / "a" / "data.csv"
    assert main(["simulate", "--input", str(record), "--current", "1", "--out", str(tmp_path / "b")]) == 0
    top, residual = figures[1].axes
    assert "NRMSE" in top.get_title() and legend_texts(top) == ["recorded", "bouc-wen simulation"]
    assert residual.get_ylabel() == "sim − rec [deg]" and residual.get_xlabel() == "time [s]"
    assert len(tick_labels(residual.yaxis)) <= 5
    out = capsys.readouterr().out.splitlines()
    header = next(line for line in out if line.startswith("drop test"))
    assert header.split()[-2:] == ["simulated", "recorded"]
    ratio = next(line for line in out if line.startswith("damping ratio"))
    assert len(ratio.split()[-2:]) == 2
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert set(summary["drop_test"]) == {"simulated", "recorded"}


def test_report_compares_two_laws_in_one_table(tmp_path, figures):
    passive = loop_folder(tmp_path, "run-a", "passive")
    sky = loop_folder(tmp_path, "run-b", "skyhook", c_sky=2.0)
    out = tmp_path / "R"
    out.mkdir()
    write_report([passive, sky], out)
    text = (out / "report.md").read_text()
    rows = {line.split(" | ")[0].lstrip("| "): line for line in text.splitlines() if line.startswith("| ")}
    assert rows["controller"] == "| controller | passive 0 A | skyhook |"
    assert rows["parameters (set away from the defaults)"].endswith("| – | c_sky=2 |")
    assert rows["road"] == "| road | sine 1 Hz, 1 deg | sine 1 Hz, 1 deg |"
    assert rows["clipped share (cycles the inverse clipped T*)"].endswith("| – | 35.0 % (700 of 2000) |")
    assert "RMS body angle θ2 [deg]" in rows and "RMS body acceleration θ̈2 [rad/s²]" in rows
    assert rows["`c_sky`"] == "| `c_sky` | – | 2 |"
    theta = next(fig for fig in figures if fig.axes[0].get_title() == "relative angle θ(t)")
    assert legend_texts(theta.axes[0]) == ["passive 0 A", "skyhook (c_sky=2)"]  # the law, not the folder
    hysteresis = next(fig for fig in figures if fig.axes[0].get_title() == "torque against velocity")
    assert [t.get_text() for t in hysteresis.legends[0].get_texts()] == ["skyhook (c_sky=2): observer T̂, recorded"]
    timing_free = [fig for fig in figures if fig.axes[0].get_title() == "wake-up lateness"]
    assert not timing_free  # no timing.npz in these folders


def test_report_hysteresis_of_a_drop_test_says_where_its_torque_comes_from(tmp_path, figures):
    assert main(["drop-test", "--current", "1", "--duration", "3", "--out", str(tmp_path / "d"), "-q"]) == 0
    out = tmp_path / "R"
    out.mkdir()
    write_report([tmp_path / "d"], out)
    hysteresis = next(fig for fig in figures if fig.axes[0].get_title() == "torque against velocity")
    (text,) = [t.get_text() for t in hysteresis.legends[0].get_texts()]
    assert text == "passive 1 A: T_d = −kθ − Jθ̈, θ low-passed at 5.0 Hz"
    left, right = hysteresis.axes
    assert left.get_xlabel() == "θ̇ [rad/s]" and right.get_xlabel() == "θ [deg]"
    torque = left.get_lines()[0].get_ydata()
    assert np.nanmax(np.abs(np.diff(torque))) < 0.05  # smooth: no encoder steps [N m per sample]


def _record(name: str, road: bool) -> Any:
    from sashil.identify.data import record_from_columns

    t = np.arange(0, 3, 1e-3)
    theta = -0.08 * np.exp(-0.5 * t) * np.cos(10 * t)
    cols = {"time_s": t, "theta_rad": theta, "current_a": np.full_like(t, 0.5)}
    if road:
        cols["theta_road_rad"] = 0.02 * np.sin(6 * t)
    return record_from_columns(name, cols), cols


def test_calibrate_fit_png_titles_apart_residual_ticks_few_and_road_shown(tmp_path, figures):
    from sashil.lab.calibration.report import _overlay, _profile_plot

    (drop, _), (road, cols) = _record("01-fit-drop", False), _record("02-fit-road", True)
    sims = [drop.theta + 1e-4, road.theta - 1e-4]
    roads = {"02-fit-road": (cols["time_s"], cols["theta_road_rad"])}
    _overlay([drop, road], sims, tmp_path / "fit.png", "bouc-wen fit (the runs the fit saw)", roads)
    fig = figures[0]
    fig.canvas.draw()
    first = fig.axes[0]
    assert fig._suptitle.get_window_extent().y0 >= first.title.get_window_extent().y1  # no overlap
    assert legend_texts(first) == ["recorded θ", "model θ"]
    assert legend_texts(fig.axes[2]) == ["recorded θ", "model θ", "road θ1 (input)"]
    for residual in fig.axes[1::2]:
        assert len(tick_labels(residual.yaxis)) <= 4
        assert residual.get_ylabel() == "model − rec\n[deg]"
    assert fig.axes[-1].get_xlabel() == "time since release [s]"
    profile = [
        SimpleNamespace(n=n, rms_rad=r, validation_nrmse=v, fitted=f)
        for n, r, v, f in ((0.1, 1.1, 0.03, False), (0.44, 1.0, 0.025, True), (1.5, 1.3, 0.04, False))
    ]
    cal = SimpleNamespace(profile=profile, validations=[1], best=SimpleNamespace(params={"n": 0.44}))
    _profile_plot(cal, tmp_path / "n_profile.png")  # type: ignore[arg-type]
    (ax,) = figures[1].axes
    assert ax.get_ylabel() == "fit RMS / held-out NRMSE [%]" and ax.get_xscale() == "log"
    assert tick_labels(ax.xaxis) == ["0.1", "0.44", "1.5"]


def test_chirp_png_of_a_single_sine_has_no_frequency_axis(tmp_path, figures):
    t = np.arange(0, 3, 1e-3)
    road = 0.02 * np.sin(2 * np.pi * t)
    cols = {"time_s": t, "theta_rad": road, "theta_road_rad": road, "current_a": 0 * t, "current_cmd_a": 0 * t}
    plots.plot_chirp(tmp_path / "chirp.png", cols, "chirp 1-1 Hz", chirp=(1.0, 1.0, 2.0))
    assert not figures[0].axes[0].child_axes


def test_run_png_without_a_readable_config_draws_no_band(tmp_path, figures):
    folder = loop_folder(tmp_path, "sky", "skyhook", c_sky=2.0)
    (folder / "config.yaml").write_text("controller: [\n")
    plots.plot_run(folder / "run.png", folder, None)
    assert legend_texts(figures[0].axes[2]) == ["observer T̂", "target T*"]
