"""``sashil replay`` as a library function: a recorded run's sensor stream through a law, offline
and open loop (the recorded plant did not respond to the replayed commands), into a run folder
with the law's commands beside the recorded ones."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil.api import Run, load_run
from sashil.config.parts import StageParts
from sashil.control.registry import make_controller
from sashil.errors import DataFileError
from sashil.experiments import replay as offline
from sashil.lab.events import Event, Listener, ignore
from sashil.recording.outputs import Outputs
from sashil.recording.plots import has_values, pyplot, save_figure
from sashil.recording.run_folder import RunFolder
from sashil.runtime.session import EVENTS_FILE

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["recorded_config", "replay"]


def recorded_config(run_folder: str | Path) -> Path:
    """The config file of a recorded run (its ``config.yaml``: what a replay runs with unless
    another is given). DataFileError, one line, when ``run_folder`` is not a run folder with a data
    file and a config."""
    run = load_run(run_folder)
    if run.data_file is None:
        subs = [sub for sub in run.runs if sub is not run and sub.data_file is not None]
        if subs:  # a folder of several runs (a drop test's currents, a compare's laws): each replays alone
            names = ", ".join(f"{sub.name}/" for sub in subs[:6]) + (", …" if len(subs) > 6 else "")
            raise DataFileError(
                f"{run_folder}: holds {len(subs)} runs ({names}), each with its own data.csv: replay one, "
                f"e.g. sashil replay {Path(run_folder) / subs[0].name}"
            )
        raise DataFileError(f"{run_folder}: no data.csv: nothing to replay")
    config_file = Path(run_folder) / "config.yaml"
    if not config_file.exists():
        raise DataFileError(f"{config_file}: no such file (a replay runs on the run's own config)")
    return config_file


def replay(
    config: RunConfig, run_folder: str | Path, outputs: Outputs | None = None, on_event: Listener = ignore
) -> Run:
    """Replay the recorded run in ``run_folder`` through the law of a resolved ``config``
    (:func:`sashil.config.resolve.resolve` with verb ``replay``; resolve the run's own
    :func:`recorded_config` to replay it with its own law) into a new run folder.

    The run's live parameter changes (``events.csv``) are applied when the law is the run's own.
    Returns the folder as a :class:`~sashil.api.Run`: ``data.csv`` (the recorded columns, the
    ``replay_*`` columns, ``replayed``, ``supervised``), ``replay.png`` and ``summary.json``
    (``replay``: the law, rows, the differences from the recorded commands, speed). Bad input (not
    a run folder, a data file without the columns a replay needs, a law's bad parameter) raises
    ConfigError before any folder exists."""

    outputs = outputs if outputs is not None else Outputs()
    outputs.check_folder_only("replay")
    recorded_config(run_folder)
    run = load_run(run_folder)
    data = run.data
    offline.check_columns(data, str(run.data_file))
    controller = make_controller(None, StageParts.read(config))
    folder = RunFolder.create(outputs.out, "replay")
    folder.write_config(config)
    started = time.perf_counter()
    # the run's live changes (sashil tune) belong to its own law: replayed with it, not with another
    own_law = controller.name == (run.config.get("controller") or {}).get("law", "passive")
    changes = offline.recorded_changes(Path(run_folder) / EVENTS_FILE) if own_law else {}
    out = offline.replay(
        controller,
        data,
        int(config["rig"]["encoder_counts_per_rev"]),
        changes,
        rate_hz=float(config["loop"]["rate_hz"]),
    )
    seconds = time.perf_counter() - started
    supervised = (data["trip_code"] != 0).astype(float) if "trip_code" in data else np.zeros(data["time_s"].size)
    folder.write_data({**data, **out, "supervised": supervised})
    diff = offline.differences(data, out)
    span = float(data["time_s"][-1] - data["time_s"][0])
    facts: dict[str, Any] = {
        "source": str(Path(run_folder)),
        "law": controller.stats()["law"],
        "rows": int(data["time_s"].size),
        "rows_replayed": int(out["replayed"].sum()),
        "live_changes": sum(len(values) for values, _ in changes.values()),
        "differences": diff,
        "seconds": round(seconds, 4),
        "times_real_time": round(span / seconds, 1) if seconds > 0 else None,
        "open_loop": True,
    }
    folder.write_summary({"replay": facts})
    _plot(folder.file("replay.png"), data, out, controller.name)
    current = diff.get("current_cmd_a")
    change = f"i* differs by RMS {current['rms']:.4g} A (max {current['max_abs']:.4g} A)" if current else ""
    text = f"replayed {facts['rows_replayed']} rows with {controller.name} {change}".rstrip()
    on_event(Event("result", text, {"rows_replayed": facts["rows_replayed"], "differences": diff}))
    on_event(Event("folder", f"run folder: {folder.path}", {"folder": str(folder.path)}))
    return load_run(folder.path)


def _plot(path: Path, data: dict[str, np.ndarray], out: dict[str, np.ndarray], law: str) -> None:
    """``replay.png``: the recorded and the replayed current command (and torque command, when
    either has one) against time."""

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
