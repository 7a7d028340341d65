"""The tuning socket: owner-only, in the run folder, parameter values only, one-line refusals, and
`sashil tune` against a live `sashil run` (the last test, end to end on the real clock)."""

from __future__ import annotations

import json
import os
import shlex
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from doc_blocks import example

from sashil.cli import main
from sashil.cli.tune import parse_changes
from sashil.errors import ConfigError
from sashil.runtime.tune_socket import SOCKET_NAME, TuneServer, TuningError, request
from sashil.runtime.tuning import LiveTuning
from tests.test_tuning import Gain, Loop


@pytest.fixture
def live(tmp_path):
    """A run folder with a tuning socket served for a Gain law, and a loop applying changes."""
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "config.yaml").write_text("loop: {rate_hz: 1000}\n")
    law = Gain()
    tuning = LiveTuning(law, 1000.0)
    server = TuneServer(folder, tuning).start()
    try:
        with Loop(tuning):
            yield folder, law, server
    finally:
        server.stop()


def test_the_socket_is_owner_only_in_the_run_folder_and_gone_after_the_run(live):
    folder, _law, server = live
    path = folder / SOCKET_NAME
    assert path.is_socket()
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    server.stop()
    assert not path.exists()
    assert not [t for t in threading.enumerate() if t.name == "sashil-tune"]


def test_get_lists_the_running_laws_parameters(live):
    folder, _law, _ = live
    answer = request(folder, {"get": True})
    assert answer["law"] == "gain-law"
    assert answer["parameters"] == {"gain": 1.0, "order": 1, "mode": "soft"}


def test_set_applies_and_answers_with_the_cycle(live):
    folder, law, _ = live
    answer = request(folder, {"set": {"gain": 2.0}, "ramp_s": None})
    assert law.gain == 2.0
    (event,) = answer["events"]
    assert (event["key"], event["old"], event["new"], event["status"]) == ("gain", 1.0, 2.0, "applied")
    assert event["cycle"] - event["arrived_cycle"] <= 2


@pytest.mark.parametrize(
    ("message", "error"),
    [
        ({"set": {"gain": -2}}, "controller.gain: expected a number >= 0, got -2"),
        ({"set": {"bogus": 1}}, "controller.bogus: law 'gain-law' has no parameter bogus"),
        ({"set": {"gain": 13.0}}, "controller.gain: 13 is refused by the law itself"),
        ({"set": [1, 2]}, "expected {'set': {param: value, ...}}"),
        ({"exec": "import os"}, "expected {'set': {param: value, ...}}"),
    ],
)
def test_a_refused_request_is_one_line_and_changes_nothing(live, message, error):
    folder, law, _ = live
    with pytest.raises(TuningError) as err:
        request(folder, message)
    assert str(err.value).startswith(error)
    assert (law.gain, law.order, law.mode) == (1.0, 1, "soft")


def test_garbage_on_the_socket_is_answered_not_acted_on(live):
    _folder, law, server = live
    assert server.handle(b"\xff\xfe not json\n") == {
        "ok": False,
        "error": "not a JSON request: 'utf-8' codec can't decode byte 0xff in position 0: invalid start byte",
    }
    assert server.handle(b"[1, 2]\n")["ok"] is False
    assert server.handle(b"x" * 70000)["error"] == "request larger than 65536 bytes"
    assert law.gain == 1.0


def test_a_deep_run_folder_gets_its_socket_through_a_link(tmp_path):
    folder = tmp_path / ("d" * 60) / ("e" * 60)
    folder.mkdir(parents=True)
    (folder / "config.yaml").write_text("{}\n")
    law = Gain()
    tuning = LiveTuning(law, 1000.0)
    server = TuneServer(folder, tuning).start()
    try:
        link = folder / SOCKET_NAME
        assert link.is_symlink() and link.is_socket()
        target = Path(os.readlink(link))
        assert stat.S_IMODE(target.stat().st_mode) == 0o600
        assert stat.S_IMODE(target.parent.stat().st_mode) == 0o700
        with Loop(tuning):
            request(folder, {"set": {"gain": 3.0}})
        assert law.gain == 3.0
    finally:
        server.stop()
    assert not link.exists() and not link.is_symlink() and not target.parent.exists()


def test_a_folder_without_a_live_run_is_named_in_one_line(tmp_path):
    with pytest.raises(TuningError, match="no such run folder"):
        request(tmp_path / "missing", {"get": True})
    (tmp_path / "plain").mkdir()
    with pytest.raises(TuningError, match=r"not a run folder \(no config.yaml\)"):
        request(tmp_path / "plain", {"get": True})
    ended = tmp_path / "ended"
    ended.mkdir()
    (ended / "config.yaml").write_text("{}\n")
    (ended / "summary.json").write_text(json.dumps({"exit_status": "ok"}))
    with pytest.raises(TuningError, match=r"holds no live run: the run has ended \(summary.json exit_status ok\)"):
        request(ended, {"get": True})


def test_a_stale_socket_of_a_killed_run_is_no_live_run(tmp_path):
    import socket

    folder = tmp_path / "killed"
    folder.mkdir()
    (folder / "config.yaml").write_text("{}\n")
    stale = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    stale.bind(str(folder / SOCKET_NAME))
    stale.close()  # the file stays, nobody listens
    with pytest.raises(TuningError, match="holds no live run"):
        request(folder, {"get": True})


@pytest.mark.parametrize(
    ("texts", "error"),
    [
        (["loop.rate_hz=10"], "only a running law's parameters can change"),
        (["controller.tune_ramp_s=1"], "controller.tune_ramp_s alone changes nothing"),
        (["controller.tune_ramp_s=fast", "controller.c=1"], "controller.tune_ramp_s: expected a number >= 0"),
        (["controller.tune_ramp_s=-1", "controller.c=1"], "controller.tune_ramp_s: expected a number >= 0"),
        (["controller.tune_ramp_s=4000", "controller.c=1"], "controller.tune_ramp_s: expected a number >= 0"),
        (["controller"], "expected section.key=value"),
    ],
)
def test_tune_arguments_are_checked_before_anything_is_sent(texts, error):
    with pytest.raises(ConfigError, match=error):
        parse_changes(texts)


def test_tune_arguments_parse_as_yaml_like_set():
    assert parse_changes(["controller.c_sky=2", "controller.mode=hard", "controller.tune_ramp_s=0.5"]) == (
        {"c_sky": 2, "mode": "hard"},
        0.5,
    )


def readme_commands() -> list[list[str]]:
    """The manual's `sashil tune` example, one argv per `sashil` line (comments and the `&` dropped)."""
    block = example("how-to/tune-live.md", "sh", "sashil tune")
    lines = [line.split("#", 1)[0].replace(" &", "") for line in block.splitlines() if line.startswith("sashil ")]
    return [shlex.split(line) for line in lines]


@pytest.mark.e2e
@pytest.mark.alone  # every tune within the run's 4 s on the wall clock
def test_the_readme_tune_example_changes_a_running_sashil_run_and_replay_reproduces_it(tmp_path, capsys):
    out = str(tmp_path / "R")
    run, *tunes = [[out if arg == "runs/tuned" else arg for arg in argv] for argv in readme_commands()]
    assert run[:2] == ["sashil", "run"] and all(argv[:3] == ["sashil", "tune", out] for argv in tunes)
    run[run.index("--duration") + 1] = "4"  # long enough for the changes, short for the suite
    proc = subprocess.Popen(
        [sys.executable, "-m", "sashil", *run[1:], "-q"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        deadline = time.monotonic() + 60
        while not (Path(out) / SOCKET_NAME).is_socket():
            assert proc.poll() is None and time.monotonic() < deadline, "sashil run did not open its tuning socket"
            time.sleep(0.02)
        for argv in tunes:
            assert main(argv[1:]) == 0, argv
        assert main(["tune", out, "controller.c_sky=-1"]) == 2
        assert main(["tune", out, "controller.c_ground=1"]) == 2
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    captured = capsys.readouterr()
    assert "controller.c_sky = 1.5" in captured.out  # the listing
    assert "sashil tune: error: controller.c_sky: expected a number > 0, got -1" in captured.err
    assert "controller.c_ground: law 'skyhook' has no parameter c_ground (its parameters: c_sky)" in captured.err
    assert proc.returncode == 0
    folder = Path(out)
    assert not (folder / SOCKET_NAME).exists()
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["tuning"]["applied"] == 2 and summary["tuning"]["refused"] == 2
    rows = (folder / "events.csv").read_text().splitlines()
    assert rows[0] == "time_s,cycle,key,old,new,ramp_s,status,arrived_cycle"
    applied = [row.split(",") for row in rows[1:] if ",applied," in row]
    assert [(row[2], row[3], row[4], row[5]) for row in applied] == [
        ("c_sky", "1.5", "2.5", "0.0"),
        ("c_sky", "2.5", "1.0", "2.0"),
    ]
    assert all(int(row[1]) - int(row[7]) <= 2 for row in applied)  # within 2 cycles of arriving
    # the tuned run replays exactly with its own law: the same changes (and ramp) at the same cycles
    assert main(["replay", out, "--out", str(tmp_path / "replay"), "-q"]) == 0
    replay = json.loads((tmp_path / "replay" / "summary.json").read_text())["replay"]
    assert replay["live_changes"] == 2
    assert replay["differences"]["current_cmd_a"]["max_abs"] == 0.0
    assert main(["tune", out, "controller.c_sky=2"]) == 2
    assert "holds no live run: the run has ended (summary.json exit_status ok)" in capsys.readouterr().err


@pytest.mark.e2e
def test_a_run_over_the_emulated_serial_link_is_tuned_and_its_replay_reproduces_it(tmp_path, capsys):
    """The same over the serial stack and the emulated board: real link jitter in the recorded
    periods, a tuned law, and a replay of the recording that still matches every command."""
    from test_link_e2e import Emulator, relaxed_config

    emu = Emulator(tmp_path, "serial", "python")
    out = tmp_path / "link"
    try:
        proc = subprocess.Popen(
            [
                sys.executable, "-m", "sashil", "run", "-q",
                "--driver", "serial", "--port", emu.link, "--config", relaxed_config(tmp_path),
                "--controller", "skyhook", "--set", "controller.c_sky=1.5", "--road", "sine:1.2:1.0",
                "--duration", "3", "--out", str(out),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        try:
            deadline = time.monotonic() + 60
            while not (out / SOCKET_NAME).is_socket():
                assert proc.poll() is None and time.monotonic() < deadline, "no tuning socket"
                time.sleep(0.02)
            assert main(["tune", str(out), "controller.c_sky=3", "controller.tune_ramp_s=0.5"]) == 0
            _, stderr = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    finally:
        emu.stop()
    assert proc.returncode == 0, stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["tuning"]["applied"] == 1 and summary["controller_stats"]["law"]["parameters"] == {"c_sky": 3.0}
    assert main(["replay", str(out), "--out", str(tmp_path / "replay"), "-q"]) == 0
    replay = json.loads((tmp_path / "replay" / "summary.json").read_text())["replay"]
    assert replay["live_changes"] == 1 and replay["differences"]["rows_compared"] >= 2500
    assert replay["differences"]["current_cmd_a"]["max_abs"] == 0.0
    assert replay["differences"]["torque_cmd_nm"]["max_abs"] == 0.0
