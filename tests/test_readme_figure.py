"""The README's figure (docs/figures/drop_test.png) shows what the quick start prints: the values of
its legend, which tools/readme_figures.py writes beside it as drop_test.json, are those of a fresh
simulated drop test from the quick start's command."""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

from doc_blocks import fenced_blocks, section

import sashil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import readme_figures  # noqa: E402


def test_the_figure_is_of_the_quick_starts_drop_test():
    shown = json.loads((ROOT / "docs" / "figures" / "drop_test.json").read_text(encoding="utf-8"))
    first = fenced_blocks(section((ROOT / "README.md").read_text(encoding="utf-8"), "## Quick start"))[0]
    command = first.body.splitlines()[0].rpartition("&& .venv/bin/")[2]
    assert shlex.split(command) == shlex.split(shown["command"]) == ["sashil", *readme_figures.DROP_COMMAND]


def test_the_figures_legend_matches_a_fresh_drop_test(tmp_path):
    shown = json.loads((ROOT / "docs" / "figures" / "drop_test.json").read_text(encoding="utf-8"))
    currents = [float(value) for value in readme_figures.DROP_COMMAND[2::2]]
    run = sashil.drop_test(currents, out=tmp_path / "drop")  # the quick start's defaults: -5 deg, 10 s
    assert readme_figures.legend(run.summary) == shown, (
        "docs/figures/drop_test.png no longer shows what the quick start prints: "
        "run .venv/bin/python tools/readme_figures.py --figure drop_test"
    )
