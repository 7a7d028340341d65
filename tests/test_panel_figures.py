"""The manual's panel figures (docs/figures/panel.png, panel-runs.png) show the page as it is: the
page's files (``src/sashil/panel/static/*``) are those tools/panel_figures.py took them of, whose
sha256 it writes beside them in panel.json, with the figures' own."""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import panel_figures  # noqa: E402

RECORD = ROOT / "docs" / "figures" / panel_figures.RECORD
AGAIN = "run .venv/bin/python tools/panel_figures.py (Chromium: apt-get install chromium)"


def test_the_panel_figures_are_of_the_current_page():
    taken = json.loads(RECORD.read_text(encoding="utf-8"))["static"]
    now = panel_figures.static_hashes()
    changed = sorted(name for name in taken.keys() | now.keys() if taken.get(name) != now.get(name))
    assert not changed, (
        f"docs/figures/panel.png and panel-runs.png predate src/sashil/panel/static/ ({', '.join(changed)}): {AGAIN}"
    )


def test_the_record_is_of_the_committed_figures():
    figures = json.loads(RECORD.read_text(encoding="utf-8"))["figures"]
    assert sorted(figures) == sorted(panel_figures.FIGURES)
    for name, digest in figures.items():
        png = (ROOT / "docs" / "figures" / name).read_bytes()
        assert hashlib.sha256(png).hexdigest() == digest, (
            f"docs/figures/{name} is not the one panel.json records: {AGAIN}"
        )
