"""``sashil replay`` as a library function: a recorded run's sensor stream through a law, offline
and open loop (the recorded plant did not respond to the replayed commands), into a run folder
with the law's commands beside the recorded ones.

Each recorded row becomes the :class:`~sashil.drivers.interface.RigSample` the loop read (encoder
counts back from ``theta_rad``/``theta_road_rad``, the measured ``current_a``, ``seq``, the device
time and each encoder's last edge when the run recorded them), with the
period the loop measured (``time_s`` differences) and the road speed the run commanded on the row
before (the controller's road feed-forward). The controller's estimator, observer, law and inverse
run as in the loop, on these samples; what it would have commanded (T*, i*, T̂) goes beside what
was commanded.

It is open loop: the recorded plant responded to the recorded commands, not to the replayed ones.
Replaying the run's own law and config reproduces its commands; another law's commands say what
that law would have asked for in the states the run went through, never what would have happened.
The run's last row (the shutdown's 0 A, after the last cycle), the rows read at 0 A while the
coil settled after a stop (``phase`` -1) and rows the safety supervisor changed (``trip_code`` not
0) are marked, not replayed as the controller's. A run whose law was
tuned live (``events.csv``) is replayed with the same changes at the same cycles.
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from sashil.api import Run, load_run
from sashil.config.recorded import recorded_law
from sashil.control.controller import Controller
from sashil.control.registry import make_controller
from sashil.drivers.interface import NO_EDGE, RigSample
from sashil.engine import assemble
from sashil.engine.events import Event, Listener, ignore
from sashil.errors import DataFileError
from sashil.recording.outputs import Outputs
from sashil.recording.plots import has_values, pyplot, save_figure
from sashil.runtime.loop import SETTLE_PHASE
from sashil.runtime.session import EVENTS_FILE
from sashil.runtime.tuning import EVENT_COLUMNS, LiveTuning
from sashil.writer.documents import Documents
from sashil.writer.folder_writer import FolderWriter
from sashil.writer.run_folder import RunFolder

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["REPLAY_COLUMNS", "REQUIRED", "check_columns", "differences", "recorded_config", "replay", "replay_rows"]


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
    (:func:`sashil.engine.resolve.resolve` with verb ``replay``; resolve the run's own
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
    check_columns(data, str(run.data_file))
    spec = assemble(config)
    controller = make_controller(None, spec.stage)
    folder = RunFolder.create(outputs.out, "replay")
    documents = Documents([FolderWriter(folder, "replay", {}, several=False)])
    documents.start(None, config, spec)
    started = time.perf_counter()
    # the run's live changes (sashil tune) belong to its own law: replayed with it, not with another
    own_law = controller.name == recorded_law(run.config)
    changes = recorded_changes(Path(run_folder) / EVENTS_FILE) if own_law else {}
    out = replay_rows(
        controller,
        data,
        spec.stage.counts_per_rev,
        changes,
        rate_hz=spec.loop.rate_hz,
    )
    seconds = time.perf_counter() - started
    supervised = (data["trip_code"] != 0).astype(float) if "trip_code" in data else np.zeros(data["time_s"].size)
    folder.write_data({**data, **out, "supervised": supervised})
    diff = differences(data, out)
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
    documents.summary(None, {"replay": facts})
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


#: what a replay needs of a recorded data.csv
REQUIRED = ("time_s", "theta_rad", "current_a", "seq")
#: what it writes beside the recorded columns
REPLAY_COLUMNS = ("replay_torque_cmd_nm", "replay_current_cmd_a", "replay_torque_hat_nm", "replay_z_hat")
#: the sample's integer fields a run records beside the angles (absent in older runs: no edges)
EDGE_FIELDS = ("device_time_us", "arm_edge_us", "arm_edge_dir", "road_edge_us", "road_edge_dir")
_ABSENT = {"device_time_us": 0, "arm_edge_us": NO_EDGE, "arm_edge_dir": 0, "road_edge_us": NO_EDGE, "road_edge_dir": 0}
TWO_PI = 2.0 * math.pi


def check_columns(data: dict[str, np.ndarray], where: str) -> None:
    """DataFileError naming the columns a replay needs that ``data`` lacks."""
    missing = [name for name in REQUIRED if name not in data]
    if missing:
        raise DataFileError(
            f"{where}: no column {', '.join(missing)} (a replay needs {', '.join(REQUIRED)}; "
            "runs recorded by `sashil run` have them)"
        )


def recorded_changes(path: Path) -> dict[int, tuple[dict[str, Any], float]]:
    """The live parameter changes of a run's ``events.csv`` (:mod:`sashil.runtime.tuning`) that a
    cycle applied: ``{cycle: ({param: value}, ramp_s)}``; {} when the run has none. Values are read
    as YAML, as the command line gave them. DataFileError naming the file for a malformed one."""
    if not path.is_file():
        return {}
    changes: dict[int, tuple[dict[str, Any], float]] = {}
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        missing = [name for name in EVENT_COLUMNS if name not in (reader.fieldnames or ())]
        if missing:
            raise DataFileError(f"{path}: no column {', '.join(missing)} (expected {', '.join(EVENT_COLUMNS)})")
        for line, row in enumerate(reader, start=2):
            if row["status"] != "applied":
                continue
            try:
                cycle, ramp_s, value = int(row["cycle"]), float(row["ramp_s"]), yaml.safe_load(row["new"])
            except (ValueError, yaml.YAMLError):
                raise DataFileError(f"{path}: line {line}: expected a cycle, a ramp in s and a value") from None
            values, ramp = changes.get(cycle, ({}, 0.0))
            values[row["key"]] = value
            changes[cycle] = (values, max(ramp, ramp_s))
    return changes


def replay_rows(
    controller: Controller,
    data: dict[str, np.ndarray],
    counts_per_rev: int,
    changes: Mapping[int, tuple[dict[str, Any], float]] | None = None,
    rate_hz: float = 1000.0,
) -> dict[str, np.ndarray]:
    """The controller's outputs for every recorded row (NaN on the shutdown row); ``replayed``: 1
    for a row the controller stepped on, 0 for the shutdown row. ``changes``: live parameter
    changes to re-apply at their cycles (:func:`recorded_changes`), through the same hand-off as
    the live loop (ramps at ``rate_hz``, the run's loop rate)."""
    tuning = LiveTuning(controller.law, rate_hz) if changes else None
    time_s = data["time_s"]
    n = time_s.size
    seq = data["seq"]
    fields = {
        name: np.asarray(data[name], dtype=np.int64) if name in data else np.full(n, _ABSENT[name], dtype=np.int64)
        for name in EDGE_FIELDS
    }
    device_us, arm_edge, arm_dir, road_edge, road_dir = (fields[name].tolist() for name in EDGE_FIELDS)
    scale = counts_per_rev / TWO_PI
    # the encoder counts back from the recorded angles, whole columns at once (rint: the same
    # half-to-even rounding as the counts were divided from); Python lists index fastest per row
    road_counts = np.rint(data.get("theta_road_rad", np.zeros(n)) * scale).astype(np.int64)
    arm_counts = (np.rint(data["theta_rad"] * scale).astype(np.int64) + road_counts).tolist()
    road_list = road_counts.tolist()
    current = data["current_a"].astype(float).tolist()
    seq_list = seq.astype(np.int64).tolist()
    t_ns = np.rint(time_s * 1e9).astype(np.int64).tolist()
    time_list = time_s.tolist()
    road_cmd = data.get("road_speed_cmd_rad_s")
    speeds = None if road_cmd is None else [v if math.isfinite(v) else None for v in road_cmd.tolist()]
    # the stream ends on the shutdown's safe-state row (the last sample again, at 0 A), after a stop
    # on the rows read while the coil settled at 0 A: no law ran in either
    last = n - 1 if n > 1 and seq[-1] == seq[-2] else n
    if "phase" in data:
        settling = np.flatnonzero(np.asarray(data["phase"]) == SETTLE_PHASE)
        if settling.size:
            last = int(settling[0])
    torque_cmd, current_cmd, torque_hat, z_hat = [], [], [], []
    command = controller.command
    step = controller.step
    prev_ns = 0
    for k in range(last):
        now_ns = t_ns[k]
        sample = RigSample(
            seq_list[k], now_ns, device_us[k], arm_counts[k], road_list[k], current[k], 0, counts_per_rev,
            arm_edge[k], arm_dir[k], road_edge[k], road_dir[k],
        )  # fmt: skip
        if speeds is not None and k:
            command.road_speed_rad_s = speeds[k - 1]
        if tuning is not None:
            change = changes.get(k) if changes is not None else None
            if change is not None:
                tuning.post(*change)
            if tuning.busy:
                tuning.service(time_list[k], k)
        step(sample, now_ns, now_ns - prev_ns)
        prev_ns = now_ns
        torque_cmd.append(controller.torque_cmd_nm)
        current_cmd.append(controller.current_cmd_a)
        torque_hat.append(controller.torque_hat_nm)
        z_hat.append(controller.z_hat)
    out = {}
    for name, values in zip(REPLAY_COLUMNS, (torque_cmd, current_cmd, torque_hat, z_hat), strict=True):
        column = np.full(n, np.nan)
        column[:last] = values
        out[name] = column
    replayed = np.zeros(n)
    replayed[:last] = 1.0
    out["replayed"] = replayed
    return out


def differences(data: dict[str, np.ndarray], out: dict[str, np.ndarray]) -> dict[str, Any]:
    """How the replayed commands differ from the recorded ones, over the replayed rows the safety
    supervisor did not change: RMS and largest difference of i* and T*, and the rows compared."""
    use = out["replayed"] > 0
    if "trip_code" in data:
        use &= data["trip_code"] == 0
    result: dict[str, Any] = {
        "rows_compared": int(use.sum()),
        "rows_supervised": int((out["replayed"] > 0).sum() - use.sum()),
    }
    for recorded, replayed, key in (
        ("current_cmd_a", "replay_current_cmd_a", "current_cmd_a"),
        ("torque_cmd_nm", "replay_torque_cmd_nm", "torque_cmd_nm"),
    ):
        if recorded not in data:
            continue
        diff = out[replayed][use] - data[recorded][use]
        diff = diff[np.isfinite(diff)]
        result[key] = (
            {"rms": float(np.sqrt(np.mean(diff**2))), "max_abs": float(np.max(np.abs(diff)))} if diff.size else None
        )
    return result
