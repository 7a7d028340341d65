"""Calibrating an emulated damper over a real link, as a lab user would (benchmarks, other tools).

``sashil emulate`` runs the plant of a config (after its ``mismatch`` section) behind a pty in its
own process and plays the operator at each Configure; ``sashil calibrate`` then runs against it
over pyserial (``transport="serial"``), python-can's slcan interface (``transport="slcan"``), or
pyusb to the emulated RT-DAC/USB2 (``transport="rtdac"``).
The host's console (its stderr) goes to a file that the emulator's operator reads
(``--prompts``): each step's attempt, a repeat after a link gap too, is held at the angle the
host's prompt for it asks, as a person at the bench would read it (``--hold-deg``: the plan's
angles in order, only before the first prompt).
"""

from __future__ import annotations

import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from sashil.config import dump_config
from sashil.config.frozen import freeze_config, thaw
from sashil.errors import DriverIOError
from sashil.lab.calibration.plan import plan_from_config

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

TRANSPORTS = {"serial": "serial", "slcan": "can", "rtdac": "rtdac"}  # emulator transport -> host driver
HOST_PRIORITY, EMULATOR_PRIORITY = 65, 70  # above other real-time tests on a shared machine
SASHIL = [sys.executable, "-m", "sashil"]
BOARDS = ("auto", "c", "python")  # sashil emulate --board


def calibrate_emulated(
    plant_config: RunConfig,
    out: str | Path,
    transport: str = "serial",
    inertia: float | None = None,
    model: str | None = None,
    truth: str | Path | None = None,
    timeout_s: float = 900.0,
    board: str = "auto",
) -> Path:
    """Calibrate the damper of ``plant_config`` emulated over ``transport``; returns params.yaml's path.

    ``plant_config``: a resolved config (``sashil.engine.resolve.load_config``/``default_config``) whose
    ``model.params`` (and ``mismatch``, ``rig``) describe the true damper; its ``calibrate``
    section is the plan. The host runs with ``driver.sample_timeout_ms`` 300 and ``link_lost_ms``
    2000, at SCHED_FIFO priority 65 (best effort) and the emulator at 70, so that a shared
    machine's pauses (100 ms seen with other real-time processes at priority 60) do not end a run. ``out``: the calibration
    folder (must not exist or be empty). ``inertia``: J given to ``--inertia`` (None: J = 1).
    ``model``: ``--model``. ``truth``: also write the emulator's ground truth CSV (``--truth``).
    ``board``: the emulator's ``--board`` (c, python, or auto: c where a C compiler is found).
    A failed calibration raises :class:`~sashil.errors.DriverIOError` with its last error line;
    the emulator process is always stopped. The host's prompts reach the emulator's operator
    through a file of the host's console (see the module docstring); nothing new goes on the wire.
    """
    if transport not in TRANSPORTS:
        raise ValueError(f"transport: expected one of {', '.join(TRANSPORTS)}, got {transport!r}")
    if board not in BOARDS:
        raise ValueError(f"board: expected one of {', '.join(BOARDS)}, got {board!r}")
    derived = thaw(plant_config)
    derived["driver"].update(sample_timeout_ms=300.0, link_lost_ms=2000.0)
    derived["loop"]["rt"]["priority"] = max(derived["loop"]["rt"]["priority"], HOST_PRIORITY)
    config = freeze_config(derived)
    angles = plan_from_config(config).operator_angles_deg()
    with tempfile.TemporaryDirectory(prefix="sashil-cal-") as tmp:
        config_path = Path(tmp) / "plant.yaml"
        config_path.write_text(dump_config(config), encoding="utf-8")
        link = str(Path(tmp) / "rig")
        console_path = Path(tmp) / "host-console.txt"  # the host's stderr: what a person at the bench reads
        console_path.touch()
        emulate = [*SASHIL, "emulate", "--config", str(config_path), "--transport", transport, "--link", link]
        emulate += ["--hold-deg", *(f"{a:g}" for a in angles), "--release-after", "1"]
        emulate += ["--prompts", str(console_path)]
        emulate += ["--priority", str(EMULATOR_PRIORITY), "--board", board]
        if truth is not None:
            emulate += ["--truth", str(truth)]
        # the emulator's log goes to a file: a pipe nobody reads fills up and stalls the device
        log = open(Path(tmp) / "emulator.log", "w", encoding="utf-8")
        emulator = subprocess.Popen(emulate, stdout=subprocess.PIPE, stderr=log, text=True)
        try:
            line = emulator.stdout.readline() if emulator.stdout else ""
            if "rig on" not in line and "board on" not in line:
                raise DriverIOError(f"sashil emulate did not start: {line.strip() or 'no output'}")
            port = f"emulated:{link}" if transport == "rtdac" else link  # the RT-DAC's emulated USB
            command = [*SASHIL, "calibrate", "--driver", TRANSPORTS[transport], "--port", port]
            command += ["--config", str(config_path), "--out", str(out), "-q"]
            if inertia is not None:
                command += ["--inertia", repr(float(inertia))]
            if model is not None:
                command += ["--model", model]
            with open(console_path, "w", encoding="utf-8") as console:
                done = subprocess.run(command, stdout=subprocess.PIPE, stderr=console, text=True, timeout=timeout_s)
            host_lines = console_path.read_text(encoding="utf-8").strip().splitlines()
        finally:
            if emulator.poll() is None:
                emulator.send_signal(signal.SIGTERM)
            try:
                emulator.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                emulator.kill()
                emulator.communicate()
            log.close()
    if done.returncode != 0:
        raise DriverIOError(f"sashil calibrate exit {done.returncode}: {host_lines[-1] if host_lines else '?'}")
    return Path(out) / "params.yaml"
