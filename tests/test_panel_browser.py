"""The panel in a real browser: Debian's Chromium driven by Playwright (no browser download), against
``sashil panel`` started as a user starts it, on the simulated rig.

Set ``SASHIL_PANEL_SCREENSHOTS=DIR`` to keep the screenshots of the Bench and Runs views the test
takes, as ``DIR/panel.png`` and ``DIR/panel-runs.png``. The manual's figures of the panel come from
``tools/panel_figures.py``, not from here (a clean runs folder, no overruns).
"""

from __future__ import annotations

import contextlib
import csv
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from test_panel import fake_run

from sashil.testing.browser import chromium_path, launch_chromium, panel_server

sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install -e '.[test]')")

pytestmark = [
    pytest.mark.e2e,
    pytest.mark.skipif(chromium_path() is None, reason="no system Chromium (apt-get install chromium; .ci/run does)"),
]
#: a first run on a machine compiles the loop's kernels (cached after): the page waits for it
FIRST_TRACE_MS = 90_000


@contextlib.contextmanager
def serve_panel(tmp_path: Path, *options: str) -> Iterator[tuple[str, Path]]:
    """``sashil panel --port 0 [options]`` in a child process, with one earlier run in its runs
    folder; its printed URL and runs folder; SIGINT at the end (the server stops any run at 0 A and
    exits)."""
    fake_run(tmp_path / "runs", "20261126T100000Z-run")
    with panel_server(["--runs", str(tmp_path / "runs"), *options]) as url:
        yield url, tmp_path / "runs"


@pytest.fixture
def panel_url(tmp_path):
    """The panel on the simulated rig (:func:`serve_panel`)."""
    with serve_panel(tmp_path) as served:
        yield served


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
        browser = launch_chromium(playwright)
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

            # the loop's health as it runs: the loop process's stream reports it
            page.wait_for_function("window.panel.status.health_live === true")
            for shown_count in ("missed ", "clipped ", "lost ", "bad frames ", "watchdog "):
                sync_api.expect(page.locator("#health")).to_contain_text(shown_count)
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
            safe = status["safe_state"]  # summary.json's: the coil read down to 0.05 A at 0 A, shown in one line
            sync_api.expect(page.locator("#safe-state")).to_have_text(
                f"0 A confirmed: coil at {safe['current_a']:.3f} A {1e3 * safe['after_s']:.0f} ms after STOP"
            )
            sync_api.expect(page.locator("#safe-state")).to_have_class("confirmed")
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
    from sashil.engine.resolve import ConfigSource, resolve

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


def test_a_drop_test_from_the_page_in_chromium(tmp_path):
    """Choose a drop test, refuse a bad current with the CLI's line, drop at two currents over the
    emulated serial link (whose operator holds the arm at -5 deg and lets go after 1 s): the page
    shows the operator's instructions in its prompt box, labels each sub-run, draws its rows and
    lists each drop's result; the run is in Runs."""
    from test_link_e2e import Emulator, relaxed_config

    emu = Emulator(tmp_path, "serial", "python", "--hold-deg", "-5", "--release-after", "1")
    try:
        with (
            serve_panel(tmp_path, "--config", relaxed_config(tmp_path)) as (url, runs),
            sync_api.sync_playwright() as playwright,
        ):
            browser = launch_chromium(playwright)
            try:
                page = browser.new_page(viewport={"width": 1400, "height": 1000})
                page.goto(url)
                page.wait_for_function("window.panel && window.panel.laws.length > 0 && window.panel.client")
                page.select_option("#experiment", "drop-test")
                assert page.locator("#law").input_value() == "passive"  # a drop test's constant current
                assert page.locator("#road").is_hidden() and page.locator("#currents").is_visible()
                page.select_option("#driver", "serial")
                page.fill("#port", emu.link)
                page.fill("#currents", "0 9")
                page.click("#start")
                sync_api.expect(page.locator("#refusal")).to_have_text(
                    "--current: expected a current in [0, 1] A (rig.current_max_a), got 9"
                )
                assert [p.name for p in runs.iterdir()] == ["20261126T100000Z-run"]  # nothing started
                page.fill("#currents", "0 1")
                page.fill("#drop-duration", "1.5")
                seen: dict[str, list[str]] = {"sub-run": [], "prompt": []}
                page.expose_function("note", lambda box, text: seen[box].append(text))
                page.evaluate(
                    """for (const id of ["sub-run", "prompt"]) new MutationObserver(() => {
                         const box = document.getElementById(id);
                         if (!box.hidden) window.note(id, box.textContent);
                       }).observe(document.getElementById(id), {childList: true, characterData: true, subtree: true, attributes: true})"""
                )
                page.click("#start")
                page.wait_for_function(
                    "window.panel.status.run_id === 1 && window.panel.status.state === 'idle'", timeout=FIRST_TRACE_MS
                )
                status = page.evaluate("window.panel.status")
                sync_api.expect(page.locator("#sub-run")).to_have_text("drop test 2 of 2: 1 A")
                sync_api.expect(page.locator("#results li").filter(has_text="period ")).to_have_count(2)
                sync_api.expect(page.locator("#prompt")).to_be_hidden()  # the instructions end with the run
                shown = page.evaluate("window.panel.data")
                page.wait_for_selector(f'#run-table td:text-is("{Path(status["folder"]).name}")')
            finally:
                browser.close()
    finally:
        emu.stop()
    assert status["exit_status"] == "ok" and status["experiment"] == "drop-test", status
    assert "drop test 1 of 2: 0 A" in seen["sub-run"]
    assert any(text.startswith("hold detected at ") and "release the arm when ready" in text for text in seen["prompt"])
    assert any(text.startswith("release detected: ") for text in seen["prompt"])
    cycles = read_csv(Path(status["folder"]) / "i1.000A" / "cycles.csv")  # the last sub-run's own rows
    times = np.array(shown["time_s"], dtype=float)
    assert len(times) and np.all(np.diff(times) > 0)  # rows of the stream, in its order, each once
    index = np.searchsorted(cycles["time_s"], times)
    np.testing.assert_array_equal(cycles["time_s"][index], times)
    np.testing.assert_allclose(np.array(shown["theta_rad"], dtype=float), cycles["theta_rad"][index], rtol=1e-9)
