"""The panel in a real browser: Debian's Chromium driven by Playwright (no browser download), against
``sashil panel`` started as a user starts it, on the simulated rig.

Set ``SASHIL_PANEL_SCREENSHOTS=DIR`` to keep the screenshots of the Bench and Runs views the test
takes, as ``DIR/panel.png`` and ``DIR/panel-runs.png`` (the manual's how-to page shows them).
"""

from __future__ import annotations

import csv
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_panel import fake_run

sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install -e '.[test]')")

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = [
    pytest.mark.e2e,
    pytest.mark.skipif(CHROMIUM is None, reason="no system Chromium (apt-get install chromium; .ci/run does)"),
]
#: a first run on a machine compiles the loop's kernels (cached after): the page waits for it
FIRST_TRACE_MS = 90_000


@pytest.fixture
def panel_url(tmp_path):
    """``sashil panel --port 0`` in a child process, with one earlier run in its runs folder; its
    printed URL; SIGINT at the end (the server stops any run at 0 A and exits)."""
    fake_run(tmp_path / "runs", "20261126T100000Z-run")
    child = subprocess.Popen(
        [sys.executable, "-m", "sashil", "panel", "--port", "0", "--runs", str(tmp_path / "runs")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = child.stdout.readline() if child.stdout else ""
        match = re.search(r"(http://127\.0\.0\.1:\d+/\?token=[0-9a-f]+)", line)
        assert match, f"no URL printed: {line!r} {child.stderr.read() if child.stderr else ''}"
        yield match.group(1), tmp_path / "runs"
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


def read_csv(path: Path) -> dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    return {key: np.array([float(row[key]) if row[key] != "" else np.nan for row in rows]) for key in rows[0]}


def test_bench_in_chromium_start_tune_space_bar_stop(panel_url, tmp_path):
    url, runs = panel_url
    frames = {"binary": 0, "text": 0}

    def count(payload: str | bytes) -> None:
        frames["binary" if isinstance(payload, bytes) else "text"] += 1

    with sync_api.sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.on("websocket", lambda ws: ws.on("framereceived", count))
            page.goto(url)
            assert "token=" not in page.url  # the token left the address bar for a cookie
            page.wait_for_function("window.panel && window.panel.laws.length > 0 && window.panel.client")
            page.select_option("#law", "skyhook")
            c_sky = page.locator('#params input[data-param="c_sky"]')
            c_sky.fill("1.5")

            # the space bar on a focused Start is STOP, never a click on Start
            requests: list[str] = []
            page.on("request", lambda request: requests.append(request.url))
            page.focus("#start")
            with page.expect_response("**/api/stop") as stopped:
                page.keyboard.press("Space")
            assert stopped.value.json() == {"stopping": False}  # STOP, with no run to stop
            assert not [url for url in requests if url.endswith("/api/start")]
            assert [p.name for p in runs.iterdir()] == ["20261126T100000Z-run"]

            # a refused value: the CLI's one line, and nothing starts
            c_sky.fill("-1")
            page.click("#start")
            sync_api.expect(page.locator("#refusal")).to_have_text(
                "--set: controller.c_sky: expected a number > 0, got -1"
            )
            assert [p.name for p in runs.iterdir()] == ["20261126T100000Z-run"]  # no new run folder

            c_sky.fill("1.5")
            page.evaluate("window.panelClick = performance.now()")
            page.click("#start")
            page.wait_for_function("window.panel.data.time_s.length > 100", timeout=FIRST_TRACE_MS)
            assert frames["binary"] > 0  # the traces came as binary batches
            page.wait_for_function("window.panel.charts[0].data[0].length > 100")  # and were drawn

            # the c_sky slider, dragged with the mouse and released: one change, sent on release
            slider = page.locator('#sliders input[type=range][data-param="c_sky"]')
            box = slider.bounding_box()
            assert box is not None
            y = box["y"] + box["height"] / 2
            page.mouse.move(box["x"] + box["width"] * 0.375, y)
            page.mouse.down()
            for step in range(1, 11):  # a drag over many pixels ...
                page.mouse.move(box["x"] + box["width"] * (0.375 + 0.025 * step), y)
            page.mouse.up()  # ... sends once, here
            page.wait_for_function("window.panel.status.values.c_sky !== 1.5")
            tuned = page.evaluate("window.panel.status.values.c_sky")
            assert tuned > 1.5
            page.wait_for_function("window.panel.markers.length === 1")

            shoot(page.screenshot(), "panel.png", tmp_path)
            with page.expect_download() as saved:  # Save YAML: a config --config reads, with the tuned value
                page.click("#save")
            saved_yaml = Path(saved.value.path()).read_text()
            page.check("#pause")  # the plots freeze; the CSV is of what they show
            with page.expect_download() as visible:
                page.click("#csv")
            visible_csv = Path(visible.value.path()).read_text()
            frozen = page.evaluate("window.panel.frozen.time_s.length")
            page.uncheck("#pause")

            # the space bar is STOP, wherever the focus is (here, a number input)
            page.focus("#ramp")
            page.keyboard.press("Space")
            page.wait_for_function("window.panel.status.state === 'idle'", timeout=30_000)
            status = page.evaluate("window.panel.status")
            assert (status["exit_status"], status["stop_reason"]) == ("stopped", "STOP (panel)")
            shown = page.evaluate("window.panel.data")
            drawn = page.evaluate("window.panel.charts[0].data")

            # Runs: the new run and an older one, overlaid on one time axis
            name = Path(status["folder"]).name
            page.wait_for_selector(f'#run-table input[data-run="{name}"]')
            page.check(f'#run-table input[data-run="{name}"]')
            page.check('#run-table input[data-run="20261126T100000Z-run"]')
            page.click("#overlay")
            page.wait_for_function("window.panel.overlay && window.panel.overlay.names.length === 2")
            overlaid = page.evaluate("window.panel.overlay.data")
            page.click("#report")  # sashil report's tables of the two runs
            page.wait_for_function(
                "window.panel.report && window.panel.report.includes('## Controllers compared')", timeout=120_000
            )
            page.locator("#runs").scroll_into_view_if_needed()
            shoot(page.locator("#runs").screenshot(), "panel-runs.png", tmp_path)
        finally:
            browser.close()

    folder = Path(status["folder"])
    data = read_csv(folder / "data.csv")
    saved_config = tmp_path / "tuned.yaml"
    saved_config.write_text(saved_yaml)
    from sashil.config.resolve import ConfigSource, resolve

    assert resolve(ConfigSource(config=saved_config), "run")["controller"]["c_sky"] == pytest.approx(tuned)
    csv_path = tmp_path / "visible.csv"
    csv_path.write_text(visible_csv)
    on_screen = read_csv(csv_path)
    from sashil.panel.frames import PLOT_COLUMNS

    assert tuple(on_screen) == PLOT_COLUMNS
    assert 0 < len(on_screen["time_s"]) <= frozen
    rows = np.searchsorted(data["time_s"], on_screen["time_s"])
    np.testing.assert_array_equal(data["time_s"][rows], on_screen["time_s"])
    np.testing.assert_allclose(on_screen["current_a"], data["current_a"][rows], rtol=1e-9, atol=1e-12)
    assert data["current_cmd_a"][-1] == 0.0
    with (folder / "events.csv").open() as f:
        changes = [row for row in csv.DictReader(f) if row["key"] == "c_sky" and row["status"] == "applied"]
    assert len(changes) == 1 and float(changes[0]["new"]) == pytest.approx(tuned)
    # the plot's series hold rows of data.csv: same times, same values
    times = np.array(shown["time_s"], dtype=float)
    index = np.searchsorted(data["time_s"], times)
    np.testing.assert_array_equal(data["time_s"][index], times)
    for name in ("theta_rad", "current_a", "torque_cmd_nm", "theta_road_rad"):
        np.testing.assert_allclose(np.array(shown[name], dtype=float), data[name][index], rtol=1e-9, atol=1e-12)
    assert drawn[0] == shown["time_s"]  # the plot draws exactly the rows the page holds
    # the overlay: the older run's three rows, and the new run's angle at its own times
    times = np.array(overlaid[0], dtype=float)
    new_run, old_run = (np.array([np.nan if v is None else v for v in series], dtype=float) for series in overlaid[1:])
    np.testing.assert_array_equal(old_run[np.isin(times, [0.0, 0.001, 0.002])][:3], [0.1, 0.2, 0.3])
    at = np.isfinite(new_run)
    index = np.searchsorted(data["time_s"], times[at])
    np.testing.assert_allclose(new_run[at], data["theta_rad"][index], rtol=1e-9, atol=1e-12)


def shoot(png: bytes, name: str, tmp_path: Path) -> None:
    """Keep a screenshot in ``tmp_path``, and in ``$SASHIL_PANEL_SCREENSHOTS`` when set."""
    (tmp_path / name).write_bytes(png)
    if os.environ.get("SASHIL_PANEL_SCREENSHOTS"):
        Path(os.environ["SASHIL_PANEL_SCREENSHOTS"], name).write_bytes(png)
