"""Regenerate the manual's panel figures in ``docs/figures/``: ``panel.png`` (the Bench view during a
skyhook run, tuned once live) and ``panel-runs.png`` (the Runs view: the runs list, that run and a
passive one overlaid), with Playwright driving Debian's Chromium
against ``sashil panel`` on the simulated rig, as ``tests/test_panel_browser.py`` does.

* A clean folder, as a lab's: the panel is started in a fresh temporary folder holding only
  ``bench.yaml`` and ``runs/``, with ``--config bench.yaml --runs runs``. The page shows the runs
  folder as it was given, so every path in the shots (the header's run folder, the events'
  ``sashil tune runs/...``) reads ``runs/<UTC stamp>-run``: no temporary path.
* The real clock: the Bench view shows a run live and its law tuned while it runs, which a run on the
  virtual clock (over before the page sees it) cannot show. The runs are short: a 4 s passive run,
  then a skyhook run stopped after about 8 s.
* No overrun warnings: ``bench.yaml`` sets ``loop.rate_hz: 250`` (:data:`RATE_HZ`) for the figures'
  runs, not the default 1 kHz. A 1 kHz Python loop on a loaded machine (the project's shared 2-core
  one) misses deadlines, and the page would show red ``loop overrun`` lines and a red missed count
  that belong to the machine, not to the panel. Nothing on the page is cleared or edited: the shots
  show what the page showed. The captions in ``docs/how-to/panel.md`` state the rate. When a run
  misses a deadline anyway, the tool takes the shots again from a fresh folder (:data:`ATTEMPTS` in
  all), then fails; ``--quick``, whose shots nobody keeps, only notes it.

Beside the PNGs, ``panel.json``: the sha256 of every file in ``src/sashil/panel/static/`` (the page
the figures show) and of the two PNGs. ``tests/test_panel_figures.py`` fails when the page's files
are not the ones the committed figures were taken of: change the page, then run this tool.

    .venv/bin/python tools/panel_figures.py
    .venv/bin/python tools/panel_figures.py --quick   # 0.5 s runs; PNGs to a temporary folder

Needs Playwright (the ``test`` extra) and the system's Chromium (``apt-get install chromium``), started
as the browser tests start it (:mod:`sashil.testing.browser`); ``--quick`` says in one line which is
missing and exits 0.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from sashil.testing.browser import chromium_path, launch_chromium, panel_server

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures"
STATIC = ROOT / "src" / "sashil" / "panel" / "static"
FIGURES = ("panel.png", "panel-runs.png")
RECORD = "panel.json"
#: the figures' loop rate (see the module's docstring: no overruns on a loaded machine)
RATE_HZ = 250.0
#: the skyhook run's c_sky at its start and as tuned live; the two runs' lengths [s] (full mode)
C_SKY_START, C_SKY_TUNED = "1.5", "3"
PASSIVE_S, SKYHOOK_S = 4.0, 8.0
#: shots taken again from a fresh folder when a run missed a deadline
ATTEMPTS = 3
#: the Bench view's window, as tests/test_panel_browser.py opens it
WIDTH, HEIGHT = 1400, 1000
#: a first run on a machine compiles the loop's kernels (cached after): the page waits for it
FIRST_TRACE_MS = 120_000


def static_hashes(static: Path = STATIC) -> dict[str, str]:
    """The sha256 of each file of the page (``src/sashil/panel/static/*``), by name."""
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(static.iterdir()) if p.is_file()}


def missing() -> str | None:
    """What this machine lacks to take the shots (one line), or None."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "playwright is not installed (pip install -e '.[test]')"
    if chromium_path() is None:
        return "no system Chromium (apt-get install chromium)"
    return None


@contextlib.contextmanager
def serve_panel(lab: Path) -> Iterator[str]:
    """``sashil panel --port 0 --config bench.yaml --runs runs`` started in ``lab``; its printed URL;
    SIGINT at the end (the server stops any run at 0 A and exits)."""
    (lab / "runs").mkdir(parents=True)
    (lab / "bench.yaml").write_text(
        f"# the manual's panel figures: a loop rate a loaded machine keeps\nloop:\n  rate_hz: {RATE_HZ:g}\n",
        encoding="utf-8",
    )
    with panel_server(["--config", "bench.yaml", "--runs", "runs"], cwd=lab) as url:
        yield url


def start(page: Any, law: str, params: dict[str, str], duration: str = "") -> None:
    """Start a run on the config's road from the Bench form."""
    page.select_option("#experiment", "run")
    page.select_option("#law", law)
    for name, value in params.items():
        page.locator(f'#params input[data-param="{name}"]').fill(value)
    page.fill("#duration", duration)
    page.click("#start")
    page.wait_for_function("window.panel.status.state === 'running'", timeout=30_000)


class Missed(Exception):
    """A figure's run missed a deadline: the page shows it in red."""


def check_no_misses(status: dict[str, Any], quick: bool) -> None:
    """Missed (full mode) or a note (``--quick``, whose shots nobody keeps) when the run of
    ``status`` missed a deadline."""
    if status.get("missed_deadlines"):
        line = f"{status.get('folder')}: {status['missed_deadlines']} missed deadline(s) at {RATE_HZ:g} Hz"
        if not quick:
            raise Missed(line)
        print(f"note: {line}")


def shoot(out: Path, quick: bool) -> list[str]:
    """Take the two shots into ``out``; the run folders the page shows."""
    from playwright.sync_api import sync_playwright

    seconds = 0.5 if quick else SKYHOOK_S
    with tempfile.TemporaryDirectory(prefix="sashil-panel-figures-") as tmp, serve_panel(Path(tmp)) as url:
        with sync_playwright() as playwright:
            browser = launch_chromium(playwright)
            try:
                page = browser.new_page(viewport={"width": WIDTH, "height": HEIGHT})
                page.goto(url)
                page.wait_for_function("window.panel && window.panel.laws.length > 0 && window.panel.client")

                # a passive run at 0 A to overlay the skyhook run on
                start(page, "passive", {}, duration="0.5" if quick else f"{PASSIVE_S:g}")
                page.wait_for_function("window.panel.status.state === 'idle'", timeout=FIRST_TRACE_MS)
                passive = page.evaluate("window.panel.status")
                check_no_misses(passive, quick)

                # the skyhook run, tuned once live: c_sky 1.5 -> 3 through the slider's field and Enter
                start(page, "skyhook", {"c_sky": C_SKY_START})
                page.wait_for_function(
                    f"window.panel.data.time_s.length > 0 && window.panel.data.time_s.at(-1) > {seconds / 2}",
                    timeout=FIRST_TRACE_MS,
                )
                page.locator('#sliders input[type=number][data-param="c_sky"]').fill(C_SKY_TUNED)
                page.locator('#sliders input[type=number][data-param="c_sky"]').press("Enter")
                page.wait_for_function("window.panel.markers.length === 1")
                page.wait_for_function(f"window.panel.data.time_s.at(-1) > {seconds}", timeout=FIRST_TRACE_MS)
                page.wait_for_function("window.panel.status.health_live === true")
                check_no_misses(page.evaluate("window.panel.status"), quick)
                page.mouse.move(0, HEIGHT - 1)  # no hover on a plot: its legend shows no values
                (out / "panel.png").write_bytes(page.screenshot())
                page.click("#stop")
                page.wait_for_function("window.panel.status.state === 'idle'", timeout=30_000)
                skyhook = page.evaluate("window.panel.status")
                check_no_misses(skyhook, quick)  # the Runs view shows its summary's count

                # Runs: the two overlaid
                names = [Path(status["folder"]).name for status in (skyhook, passive)]
                for name in names:
                    page.wait_for_selector(f'#run-table input[data-run="{name}"]')
                    page.check(f'#run-table input[data-run="{name}"]')
                page.click("#overlay")
                page.wait_for_function("window.panel.overlay && window.panel.overlay.names.length === 2")
                page.locator("#runs").scroll_into_view_if_needed()
                page.mouse.move(0, 0)
                (out / "panel-runs.png").write_bytes(page.locator("#runs").screenshot())
                shown = page.evaluate("document.body.innerText")
            finally:
                browser.close()
    if tmp in shown or "/tmp/" in shown:
        raise SystemExit("the page shows a temporary path: the figures would too")
    return [skyhook["folder"], passive["folder"]]


def record(out: Path) -> dict[str, Any]:
    """``panel.json``: what the figures were taken of (the page's files) and the figures' own hashes."""
    return {
        "tool": "tools/panel_figures.py",
        "loop_rate_hz": RATE_HZ,
        "default_loop_rate": "1 kHz",
        "c_sky": {"start": C_SKY_START, "tuned_live": C_SKY_TUNED},
        "runs_s": {"passive_0A": f"{PASSIVE_S:g}", "skyhook": f"{SKYHOOK_S:g}"},
        "static": static_hashes(),
        "figures": {name: hashlib.sha256((out / name).read_bytes()).hexdigest() for name in FIGURES},
    }


def figures(out: Path, quick: bool, attempts: int = ATTEMPTS) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for attempt in range(1, attempts + 1):
        try:
            folders = shoot(out, quick)
            break
        except Missed as missed:
            print(f"attempt {attempt} of {attempts}: {missed}: {'again' if attempt < attempts else 'giving up'}")
    else:
        raise SystemExit(
            f"every attempt missed a deadline at {RATE_HZ:g} Hz: the machine is too loaded for a clean figure; "
            "run again when it is quieter"
        )
    (out / RECORD).write_text(json.dumps(record(out), indent=2) + "\n", encoding="utf-8")
    print(f"runs shown as {', '.join(folders)}")
    for name in (*FIGURES, RECORD):
        path = out / name
        print(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}  {path.stat().st_size / 1e3:.0f} kB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="0.5 s runs; PNGs to a temporary folder")
    args = parser.parse_args()
    lacking = missing()
    if lacking is not None:
        if args.quick:
            print(f"panel_figures --quick: skipped: {lacking}")
            return
        raise SystemExit(f"panel_figures: {lacking}")
    if args.quick:
        with tempfile.TemporaryDirectory(prefix="panel_figures-") as tmp:
            figures(Path(tmp), quick=True)
    else:
        figures(OUT, quick=False)


if __name__ == "__main__":
    main()
