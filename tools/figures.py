"""Every figure of the manual (``docs/figures/``), made by one command and checked.

Each figure NAME is kept with ``NAME.json`` beside it: the numbers its caption may state, from the
same run that drew it. The makers are the tools this one wraps: ``readme_figures.py`` (the simulated
rig's verbs: drop_test, hysteresis, compare, transmissibility, calibration, identify, timing),
``rig_figure.py`` (rig.svg, drawn by code), ``tutorial_figures.py`` (run: ``sashil run``'s run.png;
doctor: a healthy ``sashil doctor`` table against the emulated board) and ``panel_figures.py``
(panel, panel-runs: Chromium against ``sashil panel``) and ``bench_preview.py`` (preview_curve: the
preview law's share of the bound against the road it knows ahead, on simulated rigs; minutes).

    .venv/bin/python tools/figures.py                      # every figure (minutes)
    .venv/bin/python tools/figures.py --figure compare     # one figure (repeatable)
    .venv/bin/python tools/figures.py --check              # captions against the kept data, the data against the code
    .venv/bin/python tools/figures.py --check --slow       # ... and the recomputations that fit (tens of seconds each)
    .venv/bin/python tools/figures.py --quick              # CI: rig and hysteresis drawn into a temporary folder, then --check

``made.json`` records the sha256 of each figure and of its data as one run made them: ``--check``
finds a figure or a data file made again without the other.

``--check`` asserts, for every image of ``figures/`` in README.md and docs/ (its alt text and the
italic caption paragraph under it), that each number it states occurs in the figure's kept data; and
that the kept data is what the code gives now: hysteresis and rig recomputed whole, the law's
transmissibility at its peak frequency and the next (a fresh rig per frequency, so two frequencies
alone give the same values), the panel page's files unchanged since the shots; with ``--slow`` every
curve's peak, and the drop test, the comparison, the calibration and the identification run again
whole on the virtual clock. The
timing, run and doctor figures are of the machine's clock: their captions are checked against their
data, which no recomputation reproduces.

``--quick`` (CI, seconds) draws the figures made in this process (rig, hysteresis) into a temporary
folder and runs ``--check``; the makers of the others run in quick mode in their own tools' quick
modes (``readme_figures.py``, ``tutorial_figures.py``, ``panel_figures.py``), which
``tests/test_tools_quick.py`` runs.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import re
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures"
sys.path.insert(0, str(ROOT / "tools"))

import bench_preview  # noqa: E402
import panel_figures  # noqa: E402
import readme_figures  # noqa: E402
import rig_figure  # noqa: E402
import tutorial_figures  # noqa: E402


@dataclass(frozen=True)
class Figure:
    """One figure: its file in docs/figures/, the tool that makes it and what recomputes its data."""

    file: str
    tool: str
    recompute: Callable[[dict], list[str]] | None = None  # the kept data -> what disagrees
    slow: bool = False  # the recomputation takes tens of seconds (--slow)
    whole: Callable[[dict], list[str]] | None = None  # with --slow, instead of recompute: all of it


def _differ(name: str, kept: object, now: object) -> list[str]:
    """Each leaf where ``kept`` and ``now`` differ, as ``name.key: kept -> now``."""
    if isinstance(kept, dict) and isinstance(now, dict):
        return [
            line
            for key in sorted(kept.keys() | now.keys())
            for line in _differ(f"{name}.{key}", kept.get(key), now.get(key))
        ]
    return [] if kept == now else [f"{name}: kept {kept!r}, the code gives {now!r}"]


def _without_command(data: dict) -> dict:
    return {key: value for key, value in data.items() if key != "command"}


def recompute_hysteresis(kept: dict) -> list[str]:
    return _differ("hysteresis", _without_command(kept), readme_figures.hysteresis_numbers())


def recompute_rig(kept: dict) -> list[str]:
    drawn = (OUT / "rig.svg").read_text(encoding="utf-8")
    stale = [] if drawn == rig_figure.svg() else ["rig.svg differs from what tools/rig_figure.py draws now"]
    return stale + _differ("rig", _without_command(kept), rig_figure.numbers())


def recompute_transmissibility(kept: dict, curves: tuple[str, ...] | None = None) -> list[str]:
    """Each curve's (of ``curves``; default all) peak and the frequency after it again, those two
    alone (a stepped sine runs each frequency on a fresh rig, so a point does not depend on the
    frequencies around it)."""
    import sashil
    from sashil.cli import main

    wrong = []
    with tempfile.TemporaryDirectory(prefix="figures-check-") as tmp:
        for name, curve in kept["curves"].items():
            if curves is not None and name not in curves:
                continue
            values = curve["transmissibility"]
            peak = max(range(len(values) - 1), key=values.__getitem__)
            pair = curve["frequency_hz"][peak : peak + 2]
            folder = Path(tmp) / name
            setting = readme_figures.SWEEP_CURVES[name]
            span = ["--f-start", repr(pair[0]), "--f-stop", repr(pair[1]), "--steps", "2"]
            code = main(["sweep", "--stepped", *setting, *span, "--out", str(folder), "-q"])
            if code:
                wrong.append(f"transmissibility.{name}: sashil sweep {' '.join(span)}: exit {code}")
                continue
            table = sashil.load_run(folder).tables["transmissibility"]
            for f, now, was in zip(
                table["frequency_hz"], table["transmissibility"], values[peak : peak + 2], strict=True
            ):
                if not math.isclose(float(now), was, rel_tol=1e-9):
                    wrong.append(f"transmissibility.{name} at {f:.3f} Hz: kept {was!r}, the code gives {float(now)!r}")
    return wrong


def recompute_panel(kept: dict) -> list[str]:
    changed = sorted(n for n in kept["static"].keys() | panel_figures.static_hashes().keys()
                     if kept["static"].get(n) != panel_figures.static_hashes().get(n))  # fmt: skip
    return [f"panel: src/sashil/panel/static/{name} changed since the shots" for name in changed]


def _recompute_verb(name: str) -> Callable[[dict], list[str]]:
    """A figure's maker run again whole, on the virtual clock, into a temporary folder."""

    def recompute(kept: dict) -> list[str]:
        with tempfile.TemporaryDirectory(prefix="figures-check-") as tmp:
            now = readme_figures.figures(Path(tmp) / "out", quick=False, chosen=(name,), in_process=True)[name]
        return _differ(name, kept, now)

    return recompute


FIGURES = {
    "rig": Figure("rig.svg", "rig_figure.py", recompute_rig),
    "drop_test": Figure("drop_test.png", "readme_figures.py", _recompute_verb("drop_test"), slow=True),
    "hysteresis": Figure("hysteresis.png", "readme_figures.py", recompute_hysteresis),
    "compare": Figure("compare.png", "readme_figures.py", _recompute_verb("compare"), slow=True),
    "transmissibility": Figure(
        "transmissibility.png",
        "readme_figures.py",
        lambda kept: recompute_transmissibility(kept, ("skyhook-add",)),
        whole=recompute_transmissibility,
    ),
    "calibration": Figure("calibration.png", "readme_figures.py", _recompute_verb("calibration"), slow=True),
    "identify": Figure("identify.png", "readme_figures.py", _recompute_verb("identify"), slow=True),
    "timing": Figure("timing.png", "readme_figures.py"),
    "run": Figure("run.png", "tutorial_figures.py"),
    "doctor": Figure("doctor.svg", "tutorial_figures.py"),
    "panel": Figure("panel.png", "panel_figures.py", recompute_panel),
    "panel-runs": Figure("panel-runs.png", "panel_figures.py"),
    "preview_curve": Figure("preview_curve.png", "bench_preview.py"),
}
#: the figures ``--quick`` draws (in this process, in seconds)
QUICK = ("rig", "hysteresis")
#: the figure whose data file holds another's (the panel's two shots share panel.json)
DATA_OF = {"panel-runs": "panel"}

#: a number as a caption states it: not part of a name (θ2, T1, eq9) nor of a longer number
CAPTION_NUMBER = re.compile(r"(?<![\w\u0300-\u036f.])[+±−-]?\d+(?:\.\d+)?")
#: a number anywhere in the kept data (also inside a word: iso8608)
DATA_NUMBER = re.compile(r"\d+(?:\.\d+)?")
IMAGE = re.compile(r"!\[(?P<alt>[^\]]*)\]\((?P<path>[^)\s]*figures/(?P<file>[\w.-]+))\)")


#: the record of which figure file and data file each run made together
MADE = "made.json"


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def pair(name: str, out: Path = OUT) -> dict[str, str]:
    """The sha256 of a figure's file and of its data file in ``out``."""
    data = out / f"{DATA_OF.get(name, name)}.json"
    return {"figure": _sha256(out / FIGURES[name].file), "data": _sha256(data)}


def record_made(names: tuple[str, ...], out: Path = OUT) -> None:
    """Note in ``made.json`` that the figure and the data of each of ``names`` were made together."""
    path = out / MADE
    made = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    made.update({name: pair(name, out) for name in names})
    path.write_text(json.dumps(dict(sorted(made.items())), indent=2) + "\n", encoding="utf-8")


def check_made(names: tuple[str, ...], out: Path = OUT) -> list[str]:
    """Each figure whose file or data is not the pair tools/figures.py made together (one of the two
    made again alone, or by another tool)."""
    path = out / MADE
    made = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    wrong = []
    for name in names:
        if made.get(name) != pair(name, out):
            wrong.append(f"{name}: {FIGURES[name].file} and its data are not the pair tools/figures.py made together")
    return wrong


def kept_data(name: str) -> dict:
    return json.loads((OUT / f"{DATA_OF.get(name, name)}.json").read_text(encoding="utf-8"))


def _leaves(value: object) -> Iterator[str]:
    if isinstance(value, dict):
        for key, item in value.items():
            yield str(key)
            yield from _leaves(item)
    elif isinstance(value, list):
        for item in value:
            yield from _leaves(item)
    else:
        yield str(value)


def data_numbers(data: dict) -> set[float]:
    """Every number the kept data holds, as values (0.060 and 0.06 are one)."""
    return {float(match) for leaf in _leaves(data) for match in DATA_NUMBER.findall(leaf)}


def captions(root: Path = ROOT) -> Iterator[tuple[str, str, str]]:
    """(page, figure file, alt text and caption) of every image of ``figures/`` in README.md and docs/:
    the caption is the italic paragraph right under the image, if any."""
    pages = [root / "README.md", *sorted((root / "docs").rglob("*.md"))]
    for page in pages:
        lines = page.read_text(encoding="utf-8").splitlines()
        for index, line in enumerate(lines):
            for match in IMAGE.finditer(line):
                text = [match["alt"]]
                after = index + 1
                while after < len(lines) and not lines[after].strip():
                    after += 1
                if (
                    after < len(lines)
                    and lines[after].lstrip().startswith("*")
                    and not lines[after].lstrip().startswith("**")
                ):
                    while after < len(lines) and lines[after].strip():
                        text.append(lines[after])
                        after += 1
                yield str(page.relative_to(root)), match["file"], "\n".join(text)


def check_captions(root: Path = ROOT) -> list[str]:
    """Each caption number that the figure's kept data does not hold; a figure with no kept data."""
    wrong = []
    by_file = {figure.file: name for name, figure in FIGURES.items()}
    for page, file, text in captions(root):
        name = by_file.get(file)
        if name is None:
            wrong.append(f"{page}: figures/{file} is made by no entry of tools/figures.py")
            continue
        if not (OUT / f"{DATA_OF.get(name, name)}.json").is_file():
            wrong.append(f"{page}: figures/{file} has no kept data: run tools/figures.py --figure {name}")
            continue
        known = data_numbers(kept_data(name))
        for number in CAPTION_NUMBER.findall(text):
            if float(number.lstrip("+±−-")) not in known:
                wrong.append(
                    f"{page}: the caption of figures/{file} states {number}, which {name}'s data does not hold"
                )
    return wrong


def check_data(names: tuple[str, ...], slow: bool) -> list[str]:
    """What disagrees between each figure's kept data and the code's output now."""
    wrong = []
    for name in names:
        figure = FIGURES[name]
        if figure.recompute is None or (figure.slow and not slow):
            continue
        started = time.monotonic()
        found = (figure.whole if slow and figure.whole else figure.recompute)(kept_data(name))
        print(f"  {name}: {'ok' if not found else 'DIFFERS'} ({time.monotonic() - started:.1f} s)")
        wrong += found
    return wrong


def make(names: tuple[str, ...], out: Path, quick: bool) -> None:
    """Run each chosen figure's maker into ``out``."""
    verbs = tuple(name for name in names if name in readme_figures.FIGURES)
    if verbs:
        readme_figures.figures(out, quick=quick, chosen=verbs)
    if "rig" in names:
        rig_figure.write(out)
    tutorial = tuple(name for name in names if name in tutorial_figures.FIGURES)
    if tutorial:
        tutorial_figures.figures(out, quick=quick, chosen=tutorial)
    if "preview_curve" in names:
        if quick:
            names = tuple(name for name in names if name != "preview_curve")
        else:
            bench_preview.figure(out)
    if {"panel", "panel-runs"} & set(names):
        lacking = panel_figures.missing()
        if lacking is None:
            panel_figures.figures(out, quick=quick)
            names = (*names, *({"panel", "panel-runs"} - set(names)))  # one run takes both shots
        elif quick:
            print(f"panel figures: skipped: {lacking}")
            names = tuple(name for name in names if name not in ("panel", "panel-runs"))
        else:
            raise SystemExit(f"panel figures: {lacking}")
    record_made(names, out)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figure", action="append", choices=sorted(FIGURES), help="only this figure (repeatable)")
    parser.add_argument("--check", action="store_true", help="check the captions and the kept data; make nothing")
    parser.add_argument("--slow", action="store_true", help="with --check: also the whole recomputations")
    parser.add_argument(
        "--quick", action="store_true", help="rig and hysteresis into a temporary folder, then --check (seconds)"
    )
    args = parser.parse_args()
    names = tuple(args.figure or FIGURES)
    started = time.monotonic()
    if args.quick:
        drawn = tuple(name for name in names if name in QUICK)
        with tempfile.TemporaryDirectory(prefix="figures-quick-") as tmp:
            make(drawn, Path(tmp), quick=True)
            print(f"drew {', '.join(drawn)} in quick mode: {time.monotonic() - started:.1f} s")
    elif not args.check:
        make(names, OUT, quick=False)
        print(f"made {len(names)} figure(s) into docs/figures/: {time.monotonic() - started:.1f} s")
        return 0
    wrong = check_made(names) + check_captions() + check_data(names, args.slow)
    for line in wrong:
        print(line)
    print(f"figures check: {len(wrong)} disagreement(s), {time.monotonic() - started:.1f} s")
    return 1 if wrong else 0


if __name__ == "__main__":
    raise SystemExit(main())
