"""The first-hour tutorial's terminal transcripts, made from the code: ``sashil doctor``'s table and
the walk's dialogue against an emulated RT-DAC/USB2, written between the page's markers.

``docs/tutorials/inteco-first-hour.md`` holds two fenced blocks between ``<!-- transcript: NAME -->``
and ``<!-- /transcript -->``:

* ``doctor``: ``sashil doctor --driver rtdac`` against ``sashil emulate --transport rtdac`` (the board
  rows; the machine's rows depend on the machine and are left out), as a lab sees it;
* ``walk``: ``sashil doctor --walk`` in this process against the emulated board wired unlike the
  config's guesses (the coil on PWM 3 with its sense on A/D 6, the road on D/A 1 with its encoder on
  counter 5 counting down at 2000 a revolution, the arm on counter 4 counting down), an emulated
  operator answering, on the board's clock: the same text every time.

    python tools/transcripts.py            # write both blocks
    python tools/transcripts.py --check    # the walk's block is what the code says now; the doctor's rows are doctor's
    python tools/transcripts.py --quick    # --check (CI): seconds
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from sashil.config.frozen import freeze_config  # noqa: E402
from sashil.diagnostics import table  # noqa: E402
from sashil.diagnostics.rtdac import walk_checks  # noqa: E402
from sashil.diagnostics.rtdac_walk import WalkOptions  # noqa: E402
from sashil.drivers import rig_parts  # noqa: E402
from sashil.drivers.emulator.board_clock import BoardClock  # noqa: E402
from sashil.drivers.emulator.rtdac_board import REWIRED_BENCH, build_board  # noqa: E402
from sashil.drivers.emulator.rtdac_operator import BenchOperator  # noqa: E402
from sashil.drivers.emulator.rtdac_usb import DirectPort, EmulatedUsbBackend  # noqa: E402
from sashil.drivers.rtdac_rig import RtdacRig  # noqa: E402
from sashil.engine.resolve import default_config  # noqa: E402

PAGE = ROOT / "docs" / "tutorials" / "inteco-first-hour.md"
#: the emulated bench's truth, unlike the config's guesses
BENCH = REWIRED_BENCH
STAGE_GAIN = 0.8  # the bench's power stage gives 0.8 of the current the config's map says
BLOCK = re.compile(r"(<!-- transcript: (\w+) -->\n```text\n)(.*?)(```\n<!-- /transcript -->)", re.S)
ROW = re.compile(r"^(OK|WARN|FAIL|SKIP)\s+(\S+/\S+(?: \S+)*?)\s{2,}")


def walk_transcript() -> str:
    """The walk's dialogue and its rows, against the emulated bench in this process."""
    clock = BoardClock()
    board = build_board(freeze_config(default_config()), stage_gain=STAGE_GAIN, wiring_changes=BENCH)
    rig = RtdacRig.from_parts(rig_parts(freeze_config(default_config()), "rtdac"))
    rig.link.backend = EmulatedUsbBackend(DirectPort(board, clock))
    rig.monotonic, rig.sleep = clock.seconds, clock.sleep
    rig.configure()
    operator = BenchOperator(board, clock.seconds, {"scale": "0.2", "revolution": "m"})
    with tempfile.TemporaryDirectory(prefix="sashil-transcript-") as tmp:
        try:
            checks = walk_checks(
                rig,
                str(Path(tmp) / "rtdac-wiring.yaml"),
                operator.ask,
                operator.say,
                WalkOptions(),
                clock.seconds,
                clock.sleep,
            )
        finally:
            rig.close()
    text = "\n".join(operator.transcript) + "\n\n" + table(checks).rstrip("\n") + "\n"
    return text.replace(str(Path(tmp) / "rtdac-wiring.yaml"), "rtdac-wiring.yaml")


def doctor_transcript() -> str:
    """``sashil doctor --driver rtdac``'s board rows against ``sashil emulate --transport rtdac``."""
    with tempfile.TemporaryDirectory(prefix="sashil-transcript-") as tmp:
        link = str(Path(tmp) / "rtdac.sock")
        sashil = [sys.executable, "-m", "sashil"]
        emulator = subprocess.Popen(
            [*sashil, "emulate", "--transport", "rtdac", "--link", link, "--duration", "120"],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        try:
            line = emulator.stdout.readline() if emulator.stdout else ""
            if "rtdac board on" not in line:
                raise SystemExit(f"transcripts: the emulator did not start: {line.strip() or 'no output'}")
            done = subprocess.run(
                [*sashil, "doctor", "--driver", "rtdac", "--port", f"emulated:{link}", "--jitter-s", "0"],
                capture_output=True,
                text=True,
                timeout=120,
            )
        finally:
            emulator.terminate()
            emulator.communicate(timeout=30)
    lines = (done.stderr + done.stdout).splitlines()
    kept: list[str] = []
    keep = True
    for text in lines:
        row = ROW.match(text)
        if row is not None:
            keep = not row.group(2).startswith("machine/")
        if keep and text.strip():
            kept.append(text.replace(f"emulated:{link}", "emulated:rtdac.sock"))
    return "\n".join(kept) + "\n"


def blocks(page: str) -> dict[str, str]:
    return {m.group(2): m.group(3) for m in BLOCK.finditer(page)}


def write(made: dict[str, str]) -> None:
    page = PAGE.read_text(encoding="utf-8")
    page = BLOCK.sub(lambda m: m.group(1) + made.get(m.group(2), m.group(3)) + m.group(4), page)
    PAGE.write_text(page, encoding="utf-8")


def check() -> list[str]:
    """What disagrees between the page's blocks and the code: the walk's block exactly, the doctor's
    rows by name (its timings are the machine's)."""
    page = blocks(PAGE.read_text(encoding="utf-8"))
    problems = []
    missing = {"walk", "doctor"} - page.keys()
    problems += [f"{PAGE.name}: no transcript block {name!r}" for name in sorted(missing)]
    if "walk" in page and page["walk"] != walk_transcript():
        problems.append(f"{PAGE.name}: the walk's transcript differs from the code's: run python tools/transcripts.py")
    if "doctor" in page:
        rows = [m.group(2) for m in map(ROW.match, page["doctor"].splitlines()) if m is not None]
        known = {"board/usb", "board/link", "board/header", "board/register map", "board/exchange", "board/rate"}
        known |= {"board/safe stop", "board/at rest"}
        if not rows or any(row not in known for row in rows):
            problems.append(f"{PAGE.name}: the doctor block's rows {rows} are not doctor's board rows {sorted(known)}")
    return problems


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="check the page's blocks against the code")
    parser.add_argument("--quick", action="store_true", help="--check (seconds)")
    args = parser.parse_args()
    if args.check or args.quick:
        problems = check()
        for line in problems:
            print(line, file=sys.stderr)
        print(f"transcripts: {'ok' if not problems else f'{len(problems)} problem(s)'}")
        return 1 if problems else 0
    write({"walk": walk_transcript(), "doctor": doctor_transcript()})
    print(f"transcripts: wrote the walk's and doctor's blocks of {PAGE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
