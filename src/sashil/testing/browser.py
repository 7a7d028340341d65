"""Debian's Chromium under Playwright, and ``sashil panel`` for it to load, as the panel's browser
tests and ``tools/panel_figures.py`` start them: the system's browser (Playwright downloads none of
its own here), headless, with the flags a child of a test or a CI job needs; the panel in a child
process on a free port.

Playwright is imported by the caller (``sync_playwright()``), not here, so importing this module
needs neither Playwright nor a browser.
"""

from __future__ import annotations

import contextlib
import re
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
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


@contextlib.contextmanager
def panel_server(options: Sequence[str] = (), cwd: Path | None = None) -> Iterator[str]:
    """``sashil panel --port 0 [options]`` in a child process (in ``cwd``); the URL it prints, with
    its token; SIGINT at the end (the server stops any run at 0 A and exits). RuntimeError when the
    panel prints no URL."""
    child = subprocess.Popen(
        [sys.executable, "-m", "sashil", "panel", "--port", "0", *options],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    try:
        line = child.stdout.readline() if child.stdout else ""
        match = re.search(r"(http://127\.0\.0\.1:\d+/\?token=[0-9a-f]+)", line)
        if not match:
            raise RuntimeError(f"sashil panel printed no URL: {line!r} {child.stderr.read() if child.stderr else ''}")
        yield match.group(1)
    finally:
        child.send_signal(signal.SIGINT)
        try:
            child.wait(timeout=30)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()
        for stream in (child.stdout, child.stderr):
            if stream is not None:
                stream.close()
