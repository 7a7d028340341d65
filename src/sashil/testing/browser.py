"""Debian's Chromium under Playwright, as the panel's browser tests and ``tools/panel_figures.py``
start it: the system's browser (Playwright downloads none of its own here), headless, with the
flags a child of a test or a CI job needs.

Playwright is imported by the caller (``sync_playwright()``), not here, so importing this module
needs neither Playwright nor a browser.
"""

from __future__ import annotations

import shutil
from typing import Any

#: Chromium as a child of a test or a CI job: no sandbox (root in a container), no GPU, no network of
#: its own (no component updates, sync or first-run calls)
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
)


def chromium_path() -> str | None:
    """The system's Chromium (``chromium`` or ``chromium-browser`` on the PATH), or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def launch_chromium(playwright: Any) -> Any:
    """A headless browser of the system's Chromium with :data:`CHROMIUM_FLAGS`, from ``playwright``
    (what ``sync_playwright()`` gives); close it when done."""
    path = chromium_path()
    if path is None:
        raise RuntimeError("no system Chromium (apt-get install chromium)")
    return playwright.chromium.launch(executable_path=path, headless=True, args=list(CHROMIUM_FLAGS))
