"""The tutorials' figures of what a reader should see, in ``docs/figures/``:

* ``run.png``: the ``run.png`` of the your-own-law tutorial's step 3, ``sashil run --controller
  soft-skyhook --set controller.c_sky=2 --road sine:1.2:1 --duration 2`` (the real clock), and beside
  it ``run.json``: the command, the loop's cycles and missed deadlines, the cycles the law's torque
  was clipped to the damper's band;
* ``doctor.svg``: the table of the emulated-board tutorial's step 2, ``sashil doctor --driver serial
  --port rig --jitter-s 1 --round-trips 200`` against ``sashil emulate --transport serial --link
  rig``, drawn as SVG text (a terminal's monospace lines), and ``doctor.txt`` (the output itself)
  and ``doctor.json`` (the command and each row's verdict).

    .venv/bin/python tools/tutorial_figures.py
    .venv/bin/python tools/tutorial_figures.py --quick    # a 0.5 s run, a short doctor; to a temporary folder
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from html import escape
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures"
FIGURES = ("run", "doctor")
#: the your-own-law tutorial's step 3
RUN_COMMAND = (
    "run", "--controller", "soft-skyhook", "--set", "controller.c_sky=2", "--road", "sine:1.2:1", "--duration", "2",
)  # fmt: skip
#: the emulated-board tutorial's step 2 (the emulator's link is ``rig`` in the working folder)
EMULATE_COMMAND = ("emulate", "--transport", "serial", "--link", "rig")
DOCTOR_COMMAND = ("doctor", "--driver", "serial", "--port", "rig", "--jitter-s", "1", "--round-trips", "200")
VERDICTS = ("OK", "WARN", "FAIL")
#: doctor runs again (a fresh emulator) while a row fails: on a loaded machine the emulator, an
#: ordinary process, may miss the round trips' deadlines; the figure shows the last attempt
ATTEMPTS = 3


def sashil_command() -> list[str]:
    """How to start sashil: $SASHIL_COMMAND (the tests' warm interpreter) or this interpreter's."""
    given = os.environ.get("SASHIL_COMMAND")
    if given:
        return given.split()
    return [sys.executable, "-c", "import sys; from sashil.cli import main; sys.exit(main(sys.argv[1:]))"]


def make_run(out: Path, tmp: Path, quick: bool) -> dict:
    command = list(RUN_COMMAND)
    if quick:
        command[command.index("--duration") + 1] = "0.5"
    subprocess.run([*sashil_command(), *command, "--out", str(tmp / "run"), "-q"], check=True)
    shutil.copy(tmp / "run" / "run.png", out / "run.png")
    summary = json.loads((tmp / "run" / "summary.json").read_text(encoding="utf-8"))
    timing, stats = summary["timing"], summary["controller_stats"]
    return {
        "command": "sashil " + " ".join(command),
        "rate_hz": f"{timing['rate_hz']:g}",
        "cycles": str(timing["cycles"]),
        "missed_deadlines": str(timing["missed_deadlines"]),
        "clipped_cycles": str(stats["clipped_cycles"]),
        "clipped_pct": f"{100 * stats['clipped_cycles'] / max(timing['cycles'], 1):.0f}",
        "law": stats["law"],
    }


@contextlib.contextmanager
def emulator(folder: Path) -> Iterator[None]:
    """``sashil emulate --transport serial --link rig`` in ``folder`` until its link appears; SIGINT after."""
    process = subprocess.Popen(
        [*sashil_command(), *EMULATE_COMMAND], cwd=folder, start_new_session=True,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while not (folder / "rig").exists():
            if process.poll() is not None or time.monotonic() > deadline:
                raise SystemExit(f"sashil emulate did not link rig: {process.communicate()[1][-2000:]}")
            time.sleep(0.1)
        yield
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def rows(text: str) -> dict[str, dict[str, str]]:
    """Each row of a doctor table that starts with a verdict: its check's name -> the verdict and
    what was found."""
    found = {}
    for line in text.splitlines():
        words = line.split(maxsplit=2)
        if len(words) >= 2 and words[0] in VERDICTS:
            found[words[1]] = {"verdict": words[0], "found": words[2] if len(words) > 2 else ""}
    return found


def terminal_svg(command: str, text: str) -> str:
    """Lines of a terminal as SVG text: the prompt and command, then the output, in a monospace font."""
    lines = [f"$ {command}", *text.rstrip("\n").splitlines()]
    width = 14 + 7.8 * max(len(line) for line in lines)
    height = 20 + 17 * len(lines)
    colours = {"OK": "#2a9d3a", "WARN": "#b7791f", "FAIL": "#d62728"}
    body = []
    for index, line in enumerate(lines):
        first = line.split()[0] if line.split() else ""
        colour = colours.get(first, "#9fe870" if index == 0 else "#e8e8e8")
        body.append(f'<text x="10" y="{22 + 17 * index}" fill="{colour}" xml:space="preserve">{escape(line)}</text>')
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height}" '
        f'viewBox="0 0 {width:.0f} {height}" font-family="DejaVu Sans Mono, Menlo, Consolas, monospace" font-size="13">\n'
        f'<rect width="100%" height="100%" rx="6" fill="#1e1e1e"/>\n' + "\n".join(body) + "\n</svg>\n"
    )


def make_doctor(out: Path, tmp: Path, quick: bool) -> dict:
    command = list(DOCTOR_COMMAND)
    if quick:
        command[command.index("--jitter-s") + 1] = "0.2"
        command[command.index("--round-trips") + 1] = "20"
    attempts = 1 if quick else ATTEMPTS  # a quick table nobody keeps is taken once
    for attempt in range(1, attempts + 1):
        folder = tmp / f"doctor-{attempt}"
        folder.mkdir()
        with emulator(folder):
            done = subprocess.run(
                [*sashil_command(), *command], cwd=folder, capture_output=True, text=True, timeout=300
            )
        failed = [name for name, row in rows(done.stdout).items() if row["verdict"] == "FAIL"]
        if not failed:
            break
        print(f"doctor attempt {attempt} of {attempts}: {', '.join(failed)} failed (a loaded machine)")
    text = done.stdout
    (out / "doctor.txt").write_text(text, encoding="utf-8")
    shown = "sashil " + " ".join(command)
    (out / "doctor.svg").write_text(terminal_svg(shown, text), encoding="utf-8")
    verdicts = rows(text)
    if not verdicts:
        raise SystemExit(f"sashil doctor printed no table (exit {done.returncode}): {done.stderr[-2000:]}")
    lines = [line for line in text.splitlines() if line.strip()]
    return {"command": shown, "exit_code": str(done.returncode), "rows": verdicts, "summary": lines[-1]}


MAKERS = {"run": make_run, "doctor": make_doctor}


def figures(out: Path, quick: bool, chosen: tuple[str, ...] = FIGURES) -> dict[str, dict]:
    """Make the chosen figures into ``out``, each with NAME.json beside it; the data."""
    out.mkdir(parents=True, exist_ok=True)
    made = {}
    with tempfile.TemporaryDirectory(prefix="sashil-tutorial-figures-") as name:
        for figure in chosen:
            made[figure] = MAKERS[figure](out, Path(name), quick)
            (out / f"{figure}.json").write_text(json.dumps(made[figure], indent=2) + "\n", encoding="utf-8")
            print(f"{figure}: {json.dumps(made[figure])}")
    return made


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a 0.5 s run, a short doctor; to a temporary folder")
    parser.add_argument("--figure", action="append", choices=FIGURES, help="only this figure (repeatable)")
    args = parser.parse_args()
    chosen = tuple(args.figure or FIGURES)
    if args.quick:
        with tempfile.TemporaryDirectory(prefix="tutorial_figures-") as tmp:
            figures(Path(tmp), quick=True, chosen=chosen)
    else:
        figures(OUT, quick=False, chosen=chosen)


if __name__ == "__main__":
    main()
