"""``sashil replay``: a recorded run's sensor stream through a law, offline (open loop)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from sashil.cli.common import add_config_options, add_output_options, law_help, resolve_config, say
from sashil.errors import DataFileError

EXAMPLE = "sashil replay runs/bench-skyhook --controller groundhook --set controller.c_ground=2"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_folder", metavar="RUN_FOLDER", help="a run folder with data.csv (from sashil run)")
    parser.add_argument("--controller", metavar="LAW", help=f"the law to replay ({law_help()}); default: the run's")
    add_config_options(parser)
    add_output_options(parser)
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines")


def _load(folder: str) -> tuple[dict[str, np.ndarray], Path]:
    from sashil.api import load_run
    from sashil.experiments.replay import check_columns

    run = load_run(folder)
    data_file = run.data_file
    if data_file is None:
        raise DataFileError(f"{folder}: no data.csv: nothing to replay")
    data = run.data
    check_columns(data, str(data_file))
    config_file = Path(folder) / "config.yaml"
    if not config_file.exists():
        raise DataFileError(f"{config_file}: no such file (a replay runs on the run's own config)")
    return data, config_file


def _plot(path: Path, data: dict[str, np.ndarray], out: dict[str, np.ndarray], law: str) -> None:
    from sashil.recording.plots import has_values, pyplot, save_figure

    plt = pyplot()
    torque = has_values(data, "torque_cmd_nm") or has_values(out, "replay_torque_cmd_nm")
    fig, axes = plt.subplots(2 if torque else 1, 1, sharex=True, figsize=(9, 5 if torque else 3), squeeze=False)
    t = data["time_s"]
    ax = axes[0][0]
    ax.plot(t, data.get("current_cmd_a", data["current_a"]), lw=0.8, label="i* recorded")
    ax.plot(t, out["replay_current_cmd_a"], lw=0.8, label=f"i* {law} (replay)")
    ax.set_ylabel("current [A]")
    ax.legend(fontsize=8, loc="upper right")
    if torque:
        ax = axes[1][0]
        if has_values(data, "torque_cmd_nm"):
            ax.plot(t, data["torque_cmd_nm"], lw=0.8, label="T* recorded")
        ax.plot(t, out["replay_torque_cmd_nm"], lw=0.8, label=f"T* {law} (replay)")
        ax.set_ylabel("torque [N m]")
        ax.legend(fontsize=8, loc="upper right")
    axes[-1][0].set_xlabel("time [s]")
    fig.suptitle("replay (open loop: the recorded plant did not respond to the replayed commands)", fontsize=9)
    save_figure(fig, path)


def run(args: argparse.Namespace) -> int:
    data, config_file = _load(args.run_folder)
    args.config = args.config or str(config_file)
    config = resolve_config(args)
    from sashil.config import load_config
    from sashil.control.registry import make_controller
    from sashil.experiments.replay import differences, recorded_changes, replay
    from sashil.runtime.session import EVENTS_FILE

    run_config = load_config(config_file)
    from sashil.recording.run_folder import RunFolder

    controller = make_controller(None, config)
    folder = RunFolder.create(args.out, "replay")
    folder.write_config(config)
    started = time.perf_counter()
    # the run's live changes (sashil tune) belong to its own law: replayed with it, not with another
    own_law = controller.name == (run_config.get("controller") or {}).get("law", "passive")
    changes = recorded_changes(Path(args.run_folder) / EVENTS_FILE) if own_law else {}
    out = replay(
        controller,
        data,
        int(config["rig"]["encoder_counts_per_rev"]),
        changes,
        rate_hz=float(config["loop"]["rate_hz"]),
    )
    seconds = time.perf_counter() - started
    supervised = (data["trip_code"] != 0).astype(float) if "trip_code" in data else np.zeros(data["time_s"].size)
    folder.write_data({**data, **out, "supervised": supervised})
    diff = differences(data, out)
    span = float(data["time_s"][-1] - data["time_s"][0])
    summary: dict[str, Any] = {
        "exit_status": "ok",
        "replay": {
            "source": str(Path(args.run_folder)),
            "law": controller.stats()["law"],
            "rows": int(data["time_s"].size),
            "rows_replayed": int(out["replayed"].sum()),
            "live_changes": sum(len(values) for values, _ in changes.values()),
            "differences": diff,
            "seconds": round(seconds, 4),
            "times_real_time": round(span / seconds, 1) if seconds > 0 else None,
            "open_loop": True,
        },
    }
    folder.write_summary(summary)
    _plot(folder.file("replay.png"), data, out, controller.name)
    current = diff.get("current_cmd_a")
    change = f"i* differs by RMS {current['rms']:.4g} A (max {current['max_abs']:.4g} A)" if current else ""
    say(args, f"replayed {summary['replay']['rows_replayed']} rows with {controller.name} {change}".rstrip())
    say(args, f"run folder: {folder.path}")
    return 0
