"""The panel's server: its guards (token, Host, Origin, one controller), its binary batches, and
runs on the simulated rig started, streamed, tuned and stopped through it."""

from __future__ import annotations

import csv
import json
import shutil
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from starlette.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from sashil.errors import ConfigError
from sashil.panel import guard
from sashil.panel.app import Panel, make_app
from sashil.panel.bench import Bench
from sashil.panel.catalog import laws_catalog
from sashil.panel.frames import PLOT_COLUMNS, decimation_step, decode_batch, encode_batch, next_window

PORT = 8765
TOKEN = "ab" * 24
ORIGIN = f"http://127.0.0.1:{PORT}"
BASE = f"http://127.0.0.1:{PORT}"
WS = f"ws://127.0.0.1:{PORT}/ws"
CHANGES = {"origin": ORIGIN, guard.TOKEN_HEADER: TOKEN}
PROTOCOLS = [guard.SUBPROTOCOL, f"{guard.TOKEN_PROTOCOL_PREFIX}{TOKEN}"]


# -- pure parts -------------------------------------------------------------------------------------
def test_host_allowlist_takes_loopback_names_on_our_port_only():
    assert guard.host_allowed("127.0.0.1:8765", 8765)
    assert guard.host_allowed("localhost:8765", 8765)
    assert guard.host_allowed("[::1]:8765", 8765)
    assert guard.host_allowed("LOCALHOST", 8765)
    assert not guard.host_allowed("localhost:8766", 8765)
    assert not guard.host_allowed("evil.example:8765", 8765)  # a rebound DNS name
    assert not guard.host_allowed("127.0.0.1.evil.example", 8765)
    assert not guard.host_allowed(None, 8765)


def test_origin_must_be_the_panels_own():
    assert guard.origin_allowed("http://localhost:8765", 8765)
    assert not guard.origin_allowed("http://localhost:8766", 8765)
    assert not guard.origin_allowed("https://evil.example", 8765)
    assert not guard.origin_allowed("null", 8765)
    assert not guard.origin_allowed(None, 8765)


def test_token_travels_as_a_subprotocol():
    assert guard.subprotocol_token({"sec-websocket-protocol": f"{guard.SUBPROTOCOL}, token.xyz"}) == "xyz"
    assert guard.subprotocol_token({"sec-websocket-protocol": guard.SUBPROTOCOL}) is None
    assert guard.same_token("xyz", "xyz") and not guard.same_token("xy", "xyz") and not guard.same_token(None, "x")
    assert guard.cookie_name(8765) != guard.cookie_name(8766)
    assert len(guard.new_token()) == 48 and guard.new_token() != guard.new_token()


def test_batches_are_decimated_on_a_fixed_grid_of_rows():
    assert decimation_step(1000.0) == 4 and decimation_step(200.0) == 1 and decimation_step(1001.0) == 5
    assert next_window(100, 0, 4, 1000) == (0, 100)
    assert next_window(100, 97, 4, 1000) == (100, 100)  # nothing new on the grid yet
    assert next_window(5000, 0, 4, 1000) == (4000, 5000)  # a late reader takes the present
    assert next_window(5001, 0, 3, 1000) == (4002, 5001)  # start rounded up onto the grid


def test_a_batch_carries_every_trace_column_after_column():
    traces = {name: np.arange(3.0) + 10 * i for i, name in enumerate(PLOT_COLUMNS)}
    traces["torque_hat_nm"] = np.array([np.nan, 1.0, np.nan])
    data = encode_batch(traces)
    assert data[:8] == (3).to_bytes(4, "little") + len(PLOT_COLUMNS).to_bytes(4, "little")
    assert len(data) == 8 + 8 * 3 * len(PLOT_COLUMNS)
    back = decode_batch(data)
    for name in PLOT_COLUMNS:
        np.testing.assert_array_equal(back[name], traces[name])


# -- the law catalogue --------------------------------------------------------------------------------
LAW_FILE = '''
from sashil.control import Law, Param


class PanelProbe(Law):
    """A law only the laws folder offers."""

    name = "panel-probe"
    gain = Param(1.0, unit="N m s/rad", low=0.0, high=5.0, doc="damping gain")

    def torque(self, state):
        return -self.gain * state.theta_dot_rad_s
'''


def test_laws_come_from_the_registry_and_the_launch_folder(tmp_path):
    (tmp_path / "probe.py").write_text(LAW_FILE)
    (tmp_path / "helpers.py").write_text("X = 1\n")  # no law in it: nothing offered
    laws = {choice.name: choice for choice in laws_catalog(tmp_path)}
    assert {"passive", "skyhook", "panel-probe"} <= set(laws)
    assert laws["panel-probe"].spec == f"{(tmp_path / 'probe.py').resolve()}:PanelProbe"
    gain = laws["panel-probe"].about["parameters"][0]
    assert (gain["name"], gain["unit"], gain["low"], gain["high"], gain["kind"]) == (
        "gain",
        "N m s/rad",
        0.0,
        5.0,
        "float",
    )
    c_sky = next(p for p in laws["skyhook"].about["parameters"] if p["name"] == "c_sky")
    assert c_sky["required"]
    with pytest.raises(ConfigError, match=r"--laws .*: not a folder"):
        laws_catalog(tmp_path / "missing")
    # an installed law's own folder: offered once, as the installed law
    examples = Path(__file__).resolve().parents[1] / "examples" / "soft_skyhook"
    names = [choice.name for choice in laws_catalog(examples)]
    assert names.count("soft-skyhook") == 1
    # another class claiming a registered name: the registry's one line
    (tmp_path / "impostor.py").write_text(LAW_FILE.replace('"panel-probe"', '"skyhook"'))
    with pytest.raises(ConfigError, match=r"claims the name 'skyhook'"):
        laws_catalog(tmp_path)


def test_a_page_names_a_law_never_code(tmp_path):
    bench = Bench(runs_dir=tmp_path / "runs")
    with pytest.raises(ConfigError, match=r"controller\.law: unknown law 'x\.py:Evil'"):
        bench.resolve({"law": "x.py:Evil"})
    with pytest.raises(ConfigError, match="--road: a page chooses"):
        bench.resolve({"law": "passive", "road": "/etc/passwd.csv"})
    with pytest.raises(ConfigError, match=r"^--set: controller.c_sky: expected a number > 0, got -1$"):
        bench.resolve({"law": "skyhook", "params": {"c_sky": "-1"}})
    assert not (tmp_path / "runs").exists()


# -- the server's guards ------------------------------------------------------------------------------
@pytest.fixture
def panel(tmp_path):
    bench = Bench(runs_dir=tmp_path / "runs")
    panel = Panel(bench, TOKEN, PORT)
    before = set(threading.enumerate())
    with TestClient(make_app(panel), base_url=BASE) as client:
        yield panel, client
    assert not [t for t in threading.enumerate() if t not in before and t.name.startswith("sashil")]


def test_the_page_needs_the_token_then_keeps_it_in_a_cookie(panel):
    _, client = panel
    assert client.get("/").status_code == 403
    assert client.get("/?token=wrong").status_code == 403
    assert client.get("/api/laws").status_code == 403
    first = client.get(f"/?token={TOKEN}", follow_redirects=False)
    assert first.status_code == 303 and first.headers["location"] == "/"
    assert f"{guard.cookie_name(PORT)}={TOKEN}" in first.headers["set-cookie"]
    assert "httponly" in first.headers["set-cookie"].lower()
    page = client.get("/")
    assert page.status_code == 200 and f'content="{TOKEN}"' in page.text
    assert client.get("/api/laws").status_code == 200
    assert client.get("/static/panel.js").status_code == 200
    assert client.get("/static/..%2Fapp.py").status_code == 404
    for response in (first, page):
        assert not any(key.lower().startswith("access-control") for key in response.headers)


def test_a_foreign_host_is_refused(panel):
    _, client = panel
    client.get(f"/?token={TOKEN}")
    assert client.get("/api/laws", headers={"host": "evil.example:8765"}).status_code == 403
    assert client.get(f"/?token={TOKEN}", headers={"host": "evil.example"}).status_code == 403


def test_a_change_needs_our_origin_and_the_token_header(panel):
    _, client = panel
    client.get(f"/?token={TOKEN}")  # the cookie alone is what a cross-site form would carry
    assert client.post("/api/stop").status_code == 403
    assert client.post("/api/stop", headers={"origin": ORIGIN}).status_code == 403
    assert client.post("/api/stop", headers={**CHANGES, "origin": "http://evil.example"}).status_code == 403
    assert client.post("/api/stop", headers={**CHANGES, guard.TOKEN_HEADER: "wrong"}).status_code == 403
    answer = client.post("/api/stop", headers=CHANGES)
    assert answer.status_code == 200 and answer.json() == {"stopping": False}


def test_the_websocket_is_closed_unless_origin_and_token_are_right(panel):
    _, client = panel
    for headers, protocols in (
        ({"origin": ORIGIN}, [guard.SUBPROTOCOL]),
        ({"origin": ORIGIN}, [guard.SUBPROTOCOL, "token.wrong"]),
        ({"origin": "http://evil.example"}, PROTOCOLS),
        ({}, PROTOCOLS),
        ({"origin": ORIGIN, "host": "evil.example:8765"}, PROTOCOLS),
    ):
        with pytest.raises(WebSocketDisconnect) as refused:
            with client.websocket_connect(WS, subprotocols=protocols, headers=headers) as ws:
                ws.receive()
        assert refused.value.code == 1008
    with client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as ws:
        hello = ws.receive_json()
        assert hello["type"] == "hello" and hello["state"] == "idle"
        assert ws.accepted_subprotocol == guard.SUBPROTOCOL


def test_one_page_controls_the_others_watch(panel):
    state, client = panel
    with (
        client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as first,
        client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as second,
    ):
        one, two = first.receive_json()["client"], second.receive_json()["client"]
        assert state.controller == one
        refused = client.post("/api/start", json={"law": "passive"}, headers={**CHANGES, "x-sashil-client": two})
        assert refused.status_code == 409 and "watches" in refused.json()["error"]
        bad = client.post(
            "/api/start", json={"law": "skyhook", "params": {"c_sky": -1}}, headers={**CHANGES, "x-sashil-client": one}
        )
        assert bad.status_code == 400
        assert bad.json() == {"error": "--set: controller.c_sky: expected a number > 0, got -1"}
        assert client.post("/api/hand-over", headers={**CHANGES, "x-sashil-client": two}).json() == {
            "handed_over": False
        }
        assert client.post("/api/hand-over", headers={**CHANGES, "x-sashil-client": one}).json() == {
            "handed_over": True
        }
        assert state.controller == two
    assert state.controller is None and not state.bench.busy


# -- runs on the simulated rig ---------------------------------------------------------------------------
def receive(ws: Any) -> tuple[str, Any]:
    """The next message: ("batch", traces) or (its type, the JSON)."""
    message = ws.receive()
    if message.get("bytes") is not None:
        return "batch", decode_batch(message["bytes"])
    data = json.loads(message["text"])
    return data["type"], data


def until(ws: Any, want: str, test: Any = lambda data: True, collect: list[Any] | None = None) -> Any:
    """Read messages until one of type ``want`` passes ``test`` (batches seen on the way are kept).
    A run that ends while something else is awaited fails the test at once (a socket read has no
    timeout: waiting on would hang)."""
    while True:
        kind, data = receive(ws)
        if kind == "batch" and collect is not None:
            collect.append(data)
        if kind == want and test(data):
            return data
        if kind == "status" and want != "status" and data["run_id"] and data["state"] == "idle":
            raise AssertionError(f"the run ended while waiting for a {want}: {data}")


def read_csv(path: Path) -> dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    return {key: np.array([float(row[key]) for row in rows]) for key in rows[0]}


@pytest.mark.e2e
def test_a_run_streams_tunes_and_stops_at_0_a(panel):
    state, client = panel
    with (
        client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as control,
        client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as watch,
    ):
        me = control.receive_json()["client"]
        watch.receive_json()
        headers = {**CHANGES, "x-sashil-client": me}
        started = client.post(
            "/api/start", json={"law": "skyhook", "params": {"c_sky": "1.5"}, "road": "sine:1.0"}, headers=headers
        )
        assert started.status_code == 200, started.text
        folder = Path(started.json()["folder"])
        batches: list[dict[str, np.ndarray]] = []
        until(watch, "batch", lambda b: len(b["time_s"]) > 0, batches)
        until(watch, "status", lambda s: s["state"] == "running", batches)

        refused = client.post("/api/tune", json={"set": {"c_sky": -3}}, headers=headers)
        assert refused.status_code == 400
        assert refused.json() == {"error": "controller.c_sky: expected a number > 0, got -3"}
        applied = client.post("/api/tune", json={"set": {"c_sky": 2.5}, "ramp_s": None}, headers=headers)
        assert applied.status_code == 200, applied.text
        (event,) = applied.json()["events"]
        assert (event["key"], event["old"], event["new"]) == ("c_sky", 1.5, 2.5)
        saved = yaml.safe_load(client.post("/api/save", headers=headers).text)
        assert saved["controller"]["c_sky"] == 2.5 and saved["controller"]["law"].endswith("Skyhook")
        restored = client.post("/api/restore", headers=headers)
        assert restored.status_code == 200 and restored.json()["events"][0]["new"] == 1.5
        until(watch, "batch", lambda b: len(b["time_s"]) and b["time_s"][-1] > event["time_s"], batches)

        watch.send_text(json.dumps({"stop": True}))  # a watching page may STOP
        end = until(watch, "status", lambda s: s["state"] == "idle", batches)
    assert (end["exit_status"], end["stop_reason"]) == ("stopped", "STOP (panel)")
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["exit_status"] == "stopped"
    data = read_csv(folder / "data.csv")
    assert data["current_cmd_a"][-1] == 0.0  # the run ends on the safe state
    # every row a page was sent is a row of data.csv, at the same time, with the same values, in order
    traced = ("theta_rad", "theta_dot_rad_s", "torque_cmd_nm", "torque_hat_nm", "current_a", "theta_road_rad")
    assert_rows_of(batches, data, traced, decimation_step(float(state.bench._config["loop"]["rate_hz"])))
    band = np.concatenate([b["band_lo_nm"] for b in batches])
    assert np.all(band == band)  # the Bouc-Wen band is drawn (no NaN)
    with (folder / "events.csv").open() as f:
        tuned = [row for row in csv.DictReader(f) if row["key"] == "c_sky" and row["status"] == "applied"]
    assert [(float(r["old"]), float(r["new"])) for r in tuned] == [(1.5, 2.5), (2.5, 1.5)]
    # the saved YAML is a config --config reads, with the tuned value
    path = folder.parent / "tuned.yaml"
    path.write_text(yaml.safe_dump(saved))
    from sashil.engine.resolve import ConfigSource, resolve

    assert resolve(ConfigSource(config=path), "run")["controller"]["c_sky"] == 2.5


@pytest.mark.e2e
@pytest.mark.parametrize("on_disconnect", ["stop", "keep"])
def test_the_controlling_page_going_away(tmp_path, on_disconnect):
    """``stop`` (the default): the run stops at 0 A when the controlling page's connection drops;
    ``keep``: it goes on, control passes to the next page, which may stop it."""
    bench = Bench(runs_dir=tmp_path / "runs")
    panel = Panel(bench, TOKEN, PORT, on_disconnect)
    with (
        TestClient(make_app(panel), base_url=BASE) as client,
        client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as watch,
    ):
        me = watch.receive_json()["client"]
        with client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as control:
            client.post("/api/hand-over", headers={**CHANGES, "x-sashil-client": me})
            them = control.receive_json()["client"]
            until(watch, "control", lambda c: c["controller"] == them)
            started = client.post("/api/start", json={"law": "passive"}, headers={**CHANGES, "x-sashil-client": them})
            assert started.status_code == 200, started.text
            until(watch, "batch", lambda b: len(b["time_s"]) > 0)
        until(watch, "control", lambda c: c["controller"] == me)
        if on_disconnect == "stop":
            end = until(watch, "status", lambda s: s["state"] == "idle")
            assert end["stop_reason"] == "STOP (the controlling page disconnected)"
        else:
            until(watch, "batch", lambda b: len(b["time_s"]) > 0)
            assert bench.busy
            assert client.post("/api/stop", headers=CHANGES).json() == {"stopping": True}
            end = until(watch, "status", lambda s: s["state"] == "idle")
            assert end["stop_reason"] == "STOP (panel)"
        assert end["exit_status"] == "stopped"
        assert read_csv(Path(end["folder"]) / "data.csv")["current_cmd_a"][-1] == 0.0


# -- the runs browser -------------------------------------------------------------------------------------
def fake_run(runs: Path, name: str, exit_status: str = "ok") -> Path:
    """A run folder as sashil run leaves it (the files the browser reads)."""
    folder = runs / name
    folder.mkdir(parents=True)
    summary = {"verb": "run", "exit_status": exit_status, "controller": "sashil.control.laws:Passive", "road": "none"}
    summary |= {"started_utc": "2026-11-26T10:00:00+00:00", "timing": {"cycles": 3, "missed_deadlines": 0}}
    (folder / "summary.json").write_text(json.dumps(summary))
    (folder / "config.yaml").write_text("loop:\n  rate_hz: 1000\n")
    (folder / "data.csv").write_text(
        "time_s,theta_rad,current_a,current_cmd_a,theta_road_rad\n0.0,0.1,0.0,0.0,0.0\n0.001,0.2,0.5,1.0,0.0\n0.002,0.3,0.7,1.0,0.01\n"
    )
    return folder


def test_runs_lists_folders_and_serves_only_their_files(panel, tmp_path):
    state, client = panel
    runs = state.bench.runs_dir
    fake_run(runs, "20261126T100000Z-run")
    fake_run(runs, "20261126T100100Z-run", "stopped")
    secret = tmp_path / "secret"
    secret.mkdir()
    (secret / "summary.json").write_text('{"verb": "secret"}')
    (runs / "link-out").symlink_to(secret)  # a folder link out of runs/
    (runs / "20261126T100000Z-run" / "report.md").symlink_to(secret / "summary.json")  # a file link out
    client.get(f"/?token={TOKEN}")
    listed = client.get("/api/runs").json()
    assert [r["name"] for r in listed] == ["20261126T100100Z-run", "20261126T100000Z-run"]
    assert listed[0]["exit_status"] == "stopped" and listed[1]["law"].endswith("Passive")
    assert "report.md" not in listed[1]["files"] and "summary.json" in listed[1]["files"]
    ok = client.get("/api/runs/20261126T100000Z-run/config.yaml")
    assert ok.status_code == 200 and ok.text == "loop:\n  rate_hz: 1000\n"
    for path in (
        "/api/runs/link-out/summary.json",
        "/api/runs/20261126T100000Z-run/report.md",
        "/api/runs/20261126T100000Z-run/data.csv",  # not a file a page opens
        "/api/runs/..%2Fsecret/summary.json",
        "/api/runs/../secret/summary.json",
        "/api/runs/%2E%2E/summary.json",
        "/api/runs/20261126T100000Z-run/..%2F..%2Fsecret%2Fsummary.json",
    ):
        assert client.get(path).status_code == 404, path
    traces = decode_batch(client.get("/api/runs/20261126T100000Z-run/traces").content)
    np.testing.assert_array_equal(traces["theta_rad"], [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(traces["current_a"], [0.0, 0.5, 0.7])
    assert np.isnan(traces["torque_hat_nm"]).all()
    assert client.get("/api/runs/link-out/traces").status_code == 404
    client.cookies.clear()
    assert client.get("/api/runs").status_code == 403


# -- the board checks ---------------------------------------------------------------------------------------
@pytest.mark.e2e
def test_doctor_runs_in_a_child_process_only_while_idle(panel, monkeypatch):
    state, client = panel
    with client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as ws:
        headers = {**CHANGES, "x-sashil-client": ws.receive_json()["client"]}
        children: list[list[str]] = []
        import subprocess

        real_run = subprocess.run

        def spy(argv, **kwargs):
            children.append(list(argv))
            return real_run(argv, **kwargs)

        monkeypatch.setattr(subprocess, "run", spy)
        answer = client.post("/api/doctor", json={"driver": "sim"}, headers=headers)
        assert answer.status_code == 200, answer.text
        checks = {(c["group"], c["name"]): c["status"] for c in answer.json()["checks"]}
        assert ("machine", "sched_fifo") in checks and ("port", "port") in checks
        assert children and children[0][1:4] == ["-m", "sashil", "doctor"] and "--driver=sim" in children[0]
        state.bench.run.state = "running"  # the rig is busy: the checks are refused, nothing is spawned
        try:
            busy = client.post("/api/doctor", json={"driver": "sim"}, headers=headers)
        finally:
            state.bench.run.state = "idle"
        assert busy.status_code == 400 and busy.json() == {"error": "doctor: the rig is not idle (running)"}
        assert len(children) == 1


# -- the verb -----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (["--port", "70000"], "sashil panel: error: --port: expected 0..65535, got 70000"),
        (["--laws", "no-such-folder"], "sashil panel: error: --laws no-such-folder: not a folder"),
        (["--config", "no-such.yaml"], "sashil panel: error: no-such.yaml"),
    ],
)
def test_bad_launch_options_are_one_line_exit_2(argv, line, capsys, tmp_path, monkeypatch):
    from sashil.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["panel", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(line) and "\n" not in err


# -- over the emulated serial link --------------------------------------------------------------------------
@pytest.mark.e2e
def test_a_run_over_the_emulated_serial_link_streams_and_stops_at_0_a(tmp_path):
    from test_link_e2e import Emulator, relaxed_config

    emu = Emulator(tmp_path, "serial", "python")
    try:
        bench = Bench(relaxed_config(tmp_path), runs_dir=tmp_path / "runs")
        panel = Panel(bench, TOKEN, PORT)
        with (
            TestClient(make_app(panel), base_url=BASE) as client,
            client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as ws,
        ):
            headers = {**CHANGES, "x-sashil-client": ws.receive_json()["client"]}
            choice = {"law": "skyhook", "params": {"c_sky": "1.5"}, "driver": "serial", "port": emu.link}
            started = client.post("/api/start", json=choice, headers=headers)
            assert started.status_code == 200, started.text
            batches: list[dict[str, np.ndarray]] = []
            until(ws, "batch", lambda b: len(b["time_s"]) > 0, batches)
            until(ws, "batch", lambda b: len(b["time_s"]) > 0, batches)
            ws.send_text(json.dumps({"stop": True}))
            end = until(ws, "status", lambda s: s["state"] == "idle", batches)
            lines = [e["text"] for e in bench.events_since(0)]
        assert (end["exit_status"], end["stop_reason"]) == ("stopped", "STOP (panel)"), end
        assert any(line.startswith("safe state (0 A) confirmed by the board in ") for line in lines), lines
        assert any(line.startswith("link: ") and " bad frames, " in line for line in lines), lines
        folder = Path(end["folder"])
        assert json.loads((folder / "summary.json").read_text())["driver"] == "serial"
        data = read_csv(folder / "data.csv")
        assert data["current_cmd_a"][-1] == 0.0
        assert_rows_of(batches, data, ("theta_rad", "current_cmd_a"), decimation_step(bench._config["loop"]["rate_hz"]))
    finally:
        emu.stop()


@pytest.mark.e2e
def test_report_of_selected_runs_is_sashil_reports_table(panel):
    state, client = panel
    fake_run(state.bench.runs_dir, "20261126T100000Z-run")
    fake_run(state.bench.runs_dir, "20261126T100100Z-run", "stopped")
    client.get(f"/?token={TOKEN}")
    answer = client.post(
        "/api/report", json={"runs": ["20261126T100000Z-run", "20261126T100100Z-run"]}, headers=CHANGES
    )
    assert answer.status_code == 200, answer.text
    assert answer.text.startswith("# sashil report\n") and "## Controllers compared" in answer.text
    assert "| `20261126T100100Z-run` | run | stopped |" in answer.text
    refused = client.post("/api/report", json={"runs": ["../secret"]}, headers=CHANGES)
    assert refused.json() == {"error": "report: '../secret' is not a run folder in the runs folder"}
    assert client.post("/api/report", json={"runs": ["20261126T100000Z-run"]}).status_code == 403  # no token header


# -- off this machine: HTTPS only, and only when asked --------------------------------------------------------
def test_a_remote_host_is_a_name_the_server_answers_to():
    names = guard.host_names("10.1.2.3")
    assert guard.host_allowed("10.1.2.3:8765", 8765, names) and guard.host_allowed("localhost:8765", 8765, names)
    assert not guard.host_allowed("evil.example:8765", 8765, names)
    assert guard.origin_allowed("https://10.1.2.3:8765", 8765, names, "https")
    assert not guard.origin_allowed("http://10.1.2.3:8765", 8765, names, "https")
    assert guard.host_names("fe80::1")[-1] == "[fe80::1]"
    assert guard.host_names("::1") == guard.LOOPBACK_NAMES and guard.is_loopback("localhost")
    assert guard.is_wildcard("0.0.0.0") and guard.is_wildcard("::") and not guard.is_wildcard("10.1.2.3")


@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (
            ["--host", "10.1.2.3"],
            "--host 10.1.2.3: not a loopback address: the panel can energise the coil; add --allow-remote (HTTPS only)",
        ),
        (
            ["--host", "10.1.2.3", "--allow-remote"],
            "--host 10.1.2.3 --allow-remote: plain HTTP off this machine is refused: add --tls-cert FILE and --tls-key FILE",
        ),
        (
            ["--host", "0.0.0.0", "--allow-remote", "--tls-cert", "c.pem", "--tls-key", "k.pem"],
            "--host 0.0.0.0: a wildcard address cannot be checked",
        ),
        (["--tls-cert", "c.pem"], "--tls-cert and --tls-key: give both or neither"),
        (["--tls-cert", "missing.pem", "--tls-key", "k.pem"], "--tls-cert missing.pem: no such file"),
    ],
)
def test_serving_off_this_machine_needs_allow_remote_and_tls(argv, line, capsys, tmp_path, monkeypatch):
    from sashil.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "c.pem").write_text("x")
    (tmp_path / "k.pem").write_text("x")
    assert main(["panel", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"sashil panel: error: {line}") and "\n" not in err, err


@pytest.mark.e2e
@pytest.mark.skipif(shutil.which("openssl") is None, reason="no openssl to make a test certificate")
def test_https_with_a_certificate_sets_a_secure_cookie(tmp_path):
    import http.client
    import re
    import signal
    import ssl
    import subprocess
    import sys

    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run(
        [
            "openssl",
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "1",
            "-subj",
            "/CN=127.0.0.1",
            f"-keyout={key}",
            f"-out={cert}",
        ],
        check=True,
        capture_output=True,
    )
    argv = [sys.executable, "-m", "sashil", "panel", "--port", "0", "--runs", str(tmp_path / "runs")]
    child = subprocess.Popen(
        [*argv, "--tls-cert", str(cert), "--tls-key", str(key)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = child.stdout.readline() if child.stdout else ""
        match = re.search(r"https://127\.0\.0\.1:(\d+)/\?token=([0-9a-f]+)", line)
        assert match, line
        port, token = int(match.group(1)), match.group(2)
        context = ssl.create_default_context(cafile=str(cert))
        context.check_hostname = False
        conn = http.client.HTTPSConnection("127.0.0.1", port, context=context, timeout=30)
        conn.request("GET", f"/?token={token}")
        first = conn.getresponse()
        first.read()
        assert first.status == 303
        assert "secure" in first.getheader("set-cookie", "").lower()
        conn.request("POST", "/api/stop", headers={"Origin": f"http://127.0.0.1:{port}", guard.TOKEN_HEADER: token})
        plain_origin = conn.getresponse()
        plain_origin.read()
        assert plain_origin.status == 403  # the page's origin is https now
        conn.close()
    finally:
        child.send_signal(signal.SIGINT)
        child.communicate(timeout=30)


# -- choosing an experiment: a drop test and a sweep, resolved as their verbs resolve them ----------------
def cli_line(argv: list[str], capsys: Any) -> str:
    """The one line ``sashil VERB ...`` prints for bad input (after ``sashil VERB: error:``), exit 2."""
    from sashil.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err, err
    return err.split(": error: ", 1)[1]


@pytest.mark.parametrize(
    ("choice", "argv"),
    [
        ({"experiment": "drop-test", "theta0_deg": 45}, ["drop-test", "--theta0-deg", "45"]),
        ({"experiment": "drop-test", "theta0_deg": -0.1}, ["drop-test", "--theta0-deg", "-0.1"]),
        ({"experiment": "drop-test", "currents_a": "0 9"}, ["drop-test", "--current", "0", "--current", "9"]),
        ({"experiment": "drop-test", "currents_a": [0.5, 0.5]}, ["drop-test", "--current", "0.5", "--current", "0.5"]),
        ({"experiment": "drop-test", "duration_s": -2}, ["drop-test", "--duration", "-2"]),
        ({"experiment": "sweep", "f_start_hz": 2, "f_stop_hz": 1}, ["sweep", "--f-start", "2", "--f-stop", "1"]),
        ({"experiment": "sweep", "f_stop_hz": 500}, ["sweep", "--f-stop", "500"]),
        ({"experiment": "sweep", "stepped": True, "steps": 1}, ["sweep", "--stepped", "--steps", "1"]),
        ({"experiment": "sweep", "amplitude_deg": 40}, ["sweep", "--amplitude-deg", "40"]),
        (
            {"experiment": "sweep", "stepped": True, "f_start_hz": 2, "f_stop_hz": 2},
            ["sweep", "--stepped", "--f-start", "2", "--f-stop", "2"],
        ),
    ],
)
def test_a_bad_experiment_value_is_the_clis_line_and_nothing_starts(panel, choice, argv, capsys, monkeypatch):
    state, client = panel
    monkeypatch.chdir(state.bench.runs_dir.parent)
    expected = cli_line(argv, capsys)  # the command line's own refusal of the same value
    assert not Path("runs").exists()
    with client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as ws:
        headers = {**CHANGES, "x-sashil-client": ws.receive_json()["client"]}
        answer = client.post("/api/start", json={"law": "passive", **choice}, headers=headers)
    assert answer.status_code == 400
    assert answer.json() == {"error": expected}
    assert not state.bench.runs_dir.exists() and not state.bench.busy


def test_a_page_value_that_is_no_number_is_argparses_line(tmp_path):
    bench = Bench(runs_dir=tmp_path / "runs")
    for choice, line in (
        ({"theta0_deg": "x"}, "argument --theta0-deg: invalid float value: 'x'"),
        ({"currents_a": "0 one"}, "argument --current: invalid float value: 'one'"),
        ({"currents_a": {"a": 1}}, "argument --current: invalid float value: {'a': 1}"),
        ({"duration_s": True}, "argument --duration: invalid float value: True"),
    ):
        with pytest.raises(ConfigError) as refused:
            bench.resolve({"experiment": "drop-test", "law": "passive", **choice})
        assert str(refused.value) == line
    with pytest.raises(ConfigError, match=r"^argument --steps: invalid int value: 2\.5$"):
        bench.resolve({"experiment": "sweep", "law": "passive", "steps": 2.5})
    with pytest.raises(ConfigError, match=r"^experiment: expected one of run, drop-test, sweep, got 'calibrate'$"):
        bench.resolve({"experiment": "calibrate", "law": "passive"})
    config = bench.resolve(
        {"experiment": "drop-test", "law": "passive", "theta0_deg": "-4", "currents_a": "0, 0.5 1", "duration_s": 2}
    )
    assert (config["drop_test"]["theta0_deg"], list(config["drop_test"]["currents_a"])) == (-4.0, [0.0, 0.5, 1.0])
    assert config["drop_test"]["duration_s"] == 2.0
    sweep = bench.resolve(
        {"experiment": "sweep", "law": "passive", "f_start_hz": 1, "f_stop_hz": 2, "stepped": True, "steps": 3}
    )
    assert (sweep["sweep"]["f_start_hz"], sweep["sweep"]["f_stop_hz"], sweep["sweep"]["steps"]) == (1.0, 2.0, 3)
    assert not (tmp_path / "runs").exists()


def test_sub_runs_are_labelled_in_the_order_their_loops_run(tmp_path):
    from sashil.config.parts import read_keys
    from sashil.lab._sweep import frequencies
    from sashil.panel.bench import PANEL_READS, sub_runs

    bench = Bench(runs_dir=tmp_path / "runs")
    drop = bench.resolve({"experiment": "drop-test", "law": "passive", "currents_a": [1, 0, 0.25]})
    assert sub_runs(read_keys(drop, PANEL_READS), "drop-test") == ["1 A", "0 A", "0.25 A"]
    stepped = bench.resolve(
        {"experiment": "sweep", "law": "passive", "f_start_hz": 1, "f_stop_hz": 4, "stepped": True, "steps": 3}
    )
    assert sub_runs(read_keys(stepped, PANEL_READS), "sweep") == [
        f"{f:.3g} Hz" for f in frequencies(1, 4, 3, stepped["sweep"]["spacing"])
    ]
    chirp = bench.resolve({"experiment": "sweep", "law": "passive", "f_start_hz": 1, "f_stop_hz": 4, "duration_s": 5})
    assert sub_runs(read_keys(chirp, PANEL_READS), "sweep") == ["chirp 1-4 Hz over 5 s"]


class HealthyStream:
    """An in-memory stream (the recorder's reader interface) that reports health as the loop
    process's stream does, and gives no rows once closed (as a closed stream)."""

    def __init__(self, columns: tuple[str, ...]):
        from sashil.recording.recorder import Recorder

        self.recorder = Recorder(None, columns, keep=True)
        self.columns = self.recorder.columns
        self.counts = {"samples_lost": 0, "bad_frames": 0, "watchdog": 0, "clipped_cycles": 0}
        self.open = True

    @property
    def rows_committed(self) -> int:
        return self.recorder.rows_committed

    def add(self, rows: list[list[float]]) -> None:
        for values in rows:
            row = self.recorder.begin_row()
            row[:] = values
            self.recorder.commit_row()

    def copy_rows(self, start: int, stop: int, step: int = 1) -> list[tuple[Any, ...]]:
        return self.recorder.copy_rows(start, stop, step) if self.open else []

    def health(self) -> dict[str, int]:
        return dict(self.counts)


class Counts:
    def __init__(self) -> None:
        self.cycles = 0
        self.missed_deadlines = 0


def test_each_sub_run_is_sent_to_its_end_then_the_next_labelled(tmp_path):
    """A view gets start() and close() once per sub-run, each time with a fresh stream: the page is
    sent every sub-run's rows in order (the rows after the last batch included, read after its
    stream closed), and the status names the sub-run of the rows it was last sent."""
    from sashil.panel.bench import StreamView

    bench = Bench(runs_dir=tmp_path / "runs")
    bench.run.plan, bench.run.experiment, bench.run.state = ["0 A", "1 A"], "drop-test", "running"
    bench._step, bench._keep = 2, 1000
    bench.view = view = StreamView(bench.run.plan, bench._keep, bench._sub_run_started)
    columns = ("time_s", "theta_rad", "current_a", "current_cmd_a")
    rows = lambda a, b, cmd: [[i / 1000, -0.01 * i, 0.1, cmd] for i in range(a, b)]  # noqa: E731

    first, timing = HealthyStream(columns), Counts()
    view.start(first, timing)
    from sashil.engine.events import Event

    bench._on_event(Event("prompt", "press the arm to -5 deg and hold it still"))  # the operator's instruction
    assert bench.status()["prompt"] == "press the arm to -5 deg and hold it still"
    assert bench.events_since(0)[-1] == {
        "seq": 1,
        "kind": "prompt",
        "text": "press the arm to -5 deg and hold it still",
    }
    first.add(rows(0, 10, 0.0))
    timing.cycles, timing.missed_deadlines = 10, 1
    first.counts.update(samples_lost=2, bad_frames=1, clipped_cycles=4)
    sent = decode_batch(bench.next_batch())
    np.testing.assert_array_equal(sent["time_s"], np.arange(0, 10, 2) / 1000)  # every 2nd row, on the grid
    status = bench.status()
    assert status["sub_run"] == {"index": 1, "of": 2, "label": "0 A"}
    assert status["health"] == {"samples_lost": 2, "bad_frames": 1, "watchdog": 0, "clipped_cycles": 4}
    assert status["health_live"] and status["clipped_share"] == 0.4 and status["missed_share"] == 0.1
    assert bench.next_batch() is None  # nothing new

    first.add(rows(10, 21, 0.0))  # the sub-run's last rows, not yet sent when it ends
    timing.cycles = 21
    view.close([], [])
    first.open = False  # its stream is closed next: only the rows copied at close remain
    second = HealthyStream(columns)
    view.start(second, Counts())
    assert bench.status()["prompt"] == ""  # a new sub-run's instructions start afresh
    second.add(rows(0, 6, 1.0))

    tail = decode_batch(bench.next_batch())
    np.testing.assert_array_equal(tail["time_s"], np.arange(10, 21, 2) / 1000)
    assert bench.status()["sub_run"]["label"] == "0 A" and bench.status()["cycles"] == 21  # the counts it ended with
    head = decode_batch(bench.next_batch())
    np.testing.assert_array_equal(head["time_s"], np.arange(0, 6, 2) / 1000)
    np.testing.assert_array_equal(head["current_cmd_a"], [1.0, 1.0, 1.0])
    assert bench.status()["sub_run"] == {"index": 2, "of": 2, "label": "1 A"}
    assert bench.next_batch() is None


def test_the_safe_state_line_and_the_summarys_health():
    from sashil.panel.bench import safe_state, safe_state_line, summary_health

    confirmed = {"current_a": 0.0123, "after_s": 0.038, "confirmed": True}
    assert safe_state_line(confirmed, True) == "0 A confirmed: coil at 0.012 A 38 ms after STOP"
    late = {"current_a": 0.31, "after_s": 0.5, "confirmed": False}
    assert safe_state_line(late, False) == "0 A NOT confirmed: coil at 0.310 A 500 ms after the end: check the rig"
    assert safe_state({"safe_state": confirmed}) == confirmed
    drops = {"runs": [{"safe_state": late}, {"safe_state": confirmed}]}  # a drop test's sub-runs: the last
    assert safe_state(drops) == confirmed and safe_state({"exit_status": "ok"}) is None
    summary = {
        "runs": [
            {"link": {"samples_missed": 2, "bad_frames": 1}, "controller_stats": {"clipped_cycles": 5}},
            {"link": {"samples_missed": 1, "bad_frames": 0}, "controller_stats": {"clipped_cycles": 7}},
        ]
    }
    assert summary_health(summary) == {"samples_lost": 3, "bad_frames": 1, "clipped_cycles": 12}
    assert summary_health({"controller_stats": {"clipped_cycles": 3}}) == {"clipped_cycles": 3}
    assert summary_health({"exit_status": "ok"}) is None


def by_sub_run(ws: Any) -> tuple[dict[str, Any], dict[int, list[dict[str, np.ndarray]]], list[dict[str, Any]]]:
    """Read until the experiment ends: its last status, the batches sent of each sub-run (numbered
    by the status sent before them) and every status seen."""
    shown: dict[int, list[dict[str, np.ndarray]]] = {}
    statuses: list[dict[str, Any]] = []
    index = 0
    while True:
        kind, data = receive(ws)
        if kind == "batch":
            shown.setdefault(index, []).append(data)
        elif kind == "status":
            statuses.append(data)
            index = data["sub_run"]["index"] if data["sub_run"] else 0
            if data["run_id"] and data["state"] == "idle":
                return data, shown, statuses


def assert_rows_of(
    batches: list[dict[str, np.ndarray]], data: dict[str, np.ndarray], names: tuple[str, ...], step: int
) -> np.ndarray:
    """What the stream promises a page, whatever the number of rows a machine managed to send: every
    row of ``batches`` is a row of ``data`` (a run's data.csv, a sub-run's cycles.csv) at the same
    time with the same values, picked on the fixed grid of row numbers (every ``step``-th), each
    once and in the order of the run. The rows' numbers in ``data``."""
    assert batches, "no batch reached the page"
    shown = {name: np.concatenate([b[name] for b in batches]) for name in ("time_s", *names)}
    index = np.searchsorted(data["time_s"], shown["time_s"])
    assert np.all(index < len(data["time_s"])), "a row sent after data.csv's last"
    np.testing.assert_array_equal(data["time_s"][index], shown["time_s"])
    for name in names:
        np.testing.assert_allclose(shown[name], data[name][index], rtol=1e-9, atol=1e-12, err_msg=name)
    assert np.all(np.diff(index) > 0), "rows sent out of order, or twice"
    assert np.all(index % step == 0), f"rows sent off the grid of every {step}th row: {index[index % step != 0]}"
    return index


@pytest.mark.e2e
def test_a_drop_test_from_the_page_runs_each_current_asked(panel):
    state, client = panel
    with client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as ws:
        headers = {**CHANGES, "x-sashil-client": ws.receive_json()["client"]}
        choice = {"experiment": "drop-test", "law": "passive", "currents_a": "0 1", "duration_s": 1.5, "theta0_deg": -5}
        started = client.post("/api/start", json=choice, headers=headers)
        assert started.status_code == 200, started.text
        end, shown, statuses = by_sub_run(ws)
    folder = Path(started.json()["folder"])
    assert folder.name.endswith("-drop-test") and end["folder"] == str(folder)
    assert end["exit_status"] == "ok" and end["experiment"] == "drop-test"
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["verb"] == "drop-test"
    assert [run["current_a"] for run in summary["runs"]] == [0.0, 1.0]
    labels = {s["sub_run"]["index"]: s["sub_run"]["label"] for s in statuses if s["sub_run"]}
    assert labels == {1: "0 A", 2: "1 A"} and end["sub_run"] == {"index": 2, "of": 2, "label": "1 A"}
    # each sub-run's traces are rows of its own loop's stream (cycles.csv: time from its loop's start)
    step = decimation_step(float(state.bench._config["loop"]["rate_hz"]))
    for index, name in ((1, "i0.000A"), (2, "i1.000A")):
        cycles = read_csv(folder / name / "cycles.csv")
        assert_rows_of(shown[index], cycles, ("theta_rad", "current_a", "current_cmd_a"), step)
        assert np.all(np.concatenate([b["current_cmd_a"] for b in shown[index]])[:5] == float(name[1:6]))
    assert sum(line.startswith("period ") for line in end["results"]) == 2  # each drop's figures


@pytest.mark.e2e
def test_a_stepped_sweep_from_the_page_runs_its_frequencies(tmp_path):
    config = tmp_path / "short.yaml"
    config.write_text("sweep:\n  settle_s: 0.5\n  measure_s: 1.0\n  ramp_s: 0.2\n")
    bench = Bench(config, runs_dir=tmp_path / "runs")
    panel = Panel(bench, TOKEN, PORT)
    with (
        TestClient(make_app(panel), base_url=BASE) as client,
        client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as ws,
    ):
        headers = {**CHANGES, "x-sashil-client": ws.receive_json()["client"]}
        choice = {"experiment": "sweep", "law": "passive", "params": {"current_a": "0.5"}}
        choice |= {"f_start_hz": 1, "f_stop_hz": 2, "stepped": True, "steps": 2, "amplitude_deg": 2}
        started = client.post("/api/start", json=choice, headers=headers)
        assert started.status_code == 200, started.text
        end, shown, statuses = by_sub_run(ws)
    folder = Path(started.json()["folder"])
    assert folder.name.endswith("-sweep") and end["exit_status"] == "ok"
    summary = json.loads((folder / "summary.json").read_text())
    assert [round(p["frequency_hz"], 6) for p in summary["points"]] == [1.0, 2.0]
    assert {s["sub_run"]["label"] for s in statuses if s["sub_run"]} == {"1 Hz", "2 Hz"}
    step = decimation_step(float(bench._config["loop"]["rate_hz"]))
    for index, name in ((1, "f1.000Hz"), (2, "f2.000Hz")):
        cycles = read_csv(folder / name / "cycles.csv")
        assert_rows_of(shown[index], cycles, ("theta_rad", "theta_road_rad", "current_cmd_a"), step)
    assert any("transmissibility" in line for line in end["results"])


@pytest.mark.e2e
def test_stop_shows_the_decay_and_the_boards_confirmation(panel):
    """After STOP the loop reads on at 0 A until the coil is at the safe level: the page is sent
    those rows too, and shows the one line of summary.json's safe_state once the run ended."""
    state, client = panel
    with client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as ws:
        headers = {**CHANGES, "x-sashil-client": ws.receive_json()["client"]}
        choice = {"law": "passive", "params": {"current_a": "1.0"}, "road": "none"}
        started = client.post("/api/start", json=choice, headers=headers)
        assert started.status_code == 200, started.text
        batches: list[dict[str, np.ndarray]] = []
        until(ws, "batch", lambda b: len(b["time_s"]) and b["current_a"][-1] > 0.9, batches)  # the coil is on
        live = until(ws, "status", lambda s: s["health_live"])  # the loop process's stream reports its health
        assert live["health"] == {"samples_lost": 0, "bad_frames": 0, "watchdog": 0, "clipped_cycles": 0}
        assert live["clipped_share"] == 0.0 and live["cycles"] > 0  # a constant current is never clipped
        assert client.post("/api/stop", headers=CHANGES).json() == {"stopping": True}
        end, shown, _ = by_sub_run(ws)
    batches += shown.get(0, [])
    folder = Path(end["folder"])
    safe = json.loads((folder / "summary.json").read_text())["safe_state"]
    assert end["safe_state"] == safe and safe["confirmed"]
    line = f"0 A confirmed: coil at {safe['current_a']:.3f} A {1e3 * safe['after_s']:.0f} ms after STOP"
    assert end["safe_state_line"] == line and abs(safe["current_a"]) <= 0.05
    data = read_csv(folder / "data.csv")
    zero = int(np.flatnonzero(data["current_cmd_a"] != 0.0)[-1]) + 1  # from here on, 0 A commanded
    assert data["current_a"][zero] > 0.5 and abs(data["current_a"][-1]) <= 0.05  # the decay is recorded
    rate = float(state.bench._config["loop"]["rate_hz"])
    assert_rows_of(batches, data, ("current_a", "current_cmd_a"), decimation_step(rate))
    times = np.concatenate([b["time_s"] for b in batches])
    decay = times[times >= data["time_s"][zero]]
    assert len(decay) >= 2  # the page drew the decay, to within one decimation step of its end
    assert data["time_s"][-1] - decay[-1] < decimation_step(rate) / rate + 1e-9


@pytest.mark.e2e
def test_stop_during_a_drop_test_ends_its_current_drop_and_the_test(tmp_path):
    """Over the emulated serial link (its operator holds the arm at -5 deg and lets go after 1 s):
    STOP during the first of two drops ends that drop at 0 A, and the second never starts."""
    from test_link_e2e import Emulator, relaxed_config

    emu = Emulator(tmp_path, "serial", "python", "--hold-deg", "-5", "--release-after", "1")
    try:
        bench = Bench(relaxed_config(tmp_path), runs_dir=tmp_path / "runs")
        panel = Panel(bench, TOKEN, PORT)
        with (
            TestClient(make_app(panel), base_url=BASE) as client,
            client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as ws,
        ):
            headers = {**CHANGES, "x-sashil-client": ws.receive_json()["client"]}
            choice = {"experiment": "drop-test", "law": "passive", "currents_a": [0.5, 1.0], "duration_s": 20}
            choice |= {"driver": "serial", "port": emu.link}
            started = client.post("/api/start", json=choice, headers=headers)
            assert started.status_code == 200, started.text
            until(ws, "status", lambda s: s["prompt"].startswith("release detected: "))  # the arm swings
            refused = client.post("/api/tune", json={"set": {"current_a": 0.2}}, headers=headers)
            assert refused.json() == {"error": "live tuning: a run on a road is tuned live, not a drop-test"}
            ws.send_text(json.dumps({"stop": True}))
            end, _, _ = by_sub_run(ws)
            prompts = [e["text"] for e in bench.events_since(0) if e["kind"] == "prompt"]
    finally:
        emu.stop()
    assert end["exit_status"] == "stopped" and end["stop_reason"] == "STOP (panel)", end
    assert end["sub_run"] == {"index": 1, "of": 2, "label": "0.5 A"} and end["prompt"] == ""
    assert [text.split(" ")[:2] for text in prompts] == [["hold", "detected"], ["release", "detected:"]]
    folder = Path(end["folder"])
    summary = json.loads((folder / "summary.json").read_text())
    assert [run["current_a"] for run in summary["runs"]] == [0.5]
    assert not (folder / "i1.000A").exists()
    cycles = read_csv(folder / "i0.500A" / "cycles.csv")
    assert cycles["current_cmd_a"][-1] == 0.0 and cycles["time_s"][-1] < 15.0  # ended early, at 0 A


@pytest.mark.e2e
def test_stop_during_a_sweep_ends_its_frequency_and_the_sweep(tmp_path):
    """A stepped sine over the emulated serial link (each frequency's loop in a loop process of its
    own, its health live on the page): STOP during the first frequency ends it at 0 A, and the
    second never starts."""
    from test_link_e2e import Emulator, relaxed_config

    emu = Emulator(tmp_path, "serial", "python")
    try:
        config = Path(relaxed_config(tmp_path))
        config.write_text(config.read_text() + "sweep:\n  settle_s: 5.0\n  measure_s: 5.0\n")
        bench = Bench(config, runs_dir=tmp_path / "runs")
        panel = Panel(bench, TOKEN, PORT)
        with (
            TestClient(make_app(panel), base_url=BASE) as client,
            client.websocket_connect(WS, subprotocols=PROTOCOLS, headers={"origin": ORIGIN}) as ws,
        ):
            headers = {**CHANGES, "x-sashil-client": ws.receive_json()["client"]}
            choice = {"experiment": "sweep", "law": "passive", "params": {"current_a": "0.5"}}
            choice |= {
                "f_start_hz": 1,
                "f_stop_hz": 2,
                "stepped": True,
                "steps": 2,
                "driver": "serial",
                "port": emu.link,
            }
            started = client.post("/api/start", json=choice, headers=headers)
            assert started.status_code == 200, started.text
            live = until(ws, "status", lambda s: s["health_live"] and s["cycles"] > 500)
            assert live["sub_run"] == {"index": 1, "of": 2, "label": "1 Hz"}
            assert set(live["health"]) == {"samples_lost", "bad_frames", "watchdog", "clipped_cycles"}
            ws.send_text(json.dumps({"stop": True}))
            end, _, _ = by_sub_run(ws)
    finally:
        emu.stop()
    assert end["exit_status"] == "stopped" and end["stop_reason"] == "STOP (panel)", end
    assert end["sub_run"]["index"] == 1
    folder = Path(end["folder"])
    assert (folder / "f1.000Hz").is_dir() and not (folder / "f2.000Hz").exists()
    cycles = read_csv(folder / "f1.000Hz" / "cycles.csv")
    assert cycles["current_cmd_a"][-1] == 0.0 and cycles["time_s"][-1] < 9.0  # ended early, at 0 A
