"""CLI polish: every verb's --help ends with an example, rig verbs share option names,
--quiet silences progress, and the recording options are refused cleanly when misused."""

from __future__ import annotations

import importlib

import pytest

from sashil.cli import VERBS, build_parser, main


def _verb_help(verb: str, capsys) -> str:
    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args([verb, "--help"])
    assert exit_info.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("verb", list(VERBS))
def test_every_verb_help_has_an_example(verb, capsys):
    module = importlib.import_module(VERBS[verb].module)
    assert module.EXAMPLE.startswith(f"sashil {verb}")
    text = _verb_help(verb, capsys)
    assert f"example:\n  {module.EXAMPLE}" in text


@pytest.mark.parametrize("verb", ["drop-test", "run", "sweep"])
def test_rig_verbs_share_option_names(verb, capsys):
    text = _verb_help(verb, capsys)
    for option in (
        "--config FILE",
        "--params FILE",
        "--driver",
        "--port PORT",
        "--out DIR",
        "--rerun ",
        "--rerun-save [FILE.rrd]",
        "--rerun-connect URL",
        "--format FMT",
    ):
        assert option in text, f"{verb}: {option}"


def test_top_level_help_lists_exit_codes(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--help"])
    text = capsys.readouterr().out
    for code in ("0", "1", "2", "3", "4", "130"):
        assert f"\n  {code:>3}  " in text


def test_quiet_drop_test_prints_only_the_run_folder(tmp_path, capsys):
    assert main(["drop-test", "--duration", "2", "--out", str(tmp_path / "D"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [f"run folder: {tmp_path / 'D'} (plot drop_test.png)"]


def test_quiet_and_verbose_together_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["drop-test", "-q", "-v"])
    assert exit_info.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_unknown_format_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["drop-test", "--format", "xlsx"])
    assert exit_info.value.code == 2
    assert "--format" in capsys.readouterr().err


def test_run_progress_text_and_hooks_fan_out():
    import io

    from sashil.recording.run_progress import RunProgress, SessionHooks

    progress = RunProgress(60.0, 1000.0, stream=io.StringIO(), width=10)
    assert progress.text(18_000, 2) == "run   18.0 s / 60 s [###-------] 18000 cycles, 2 missed deadline(s)"
    assert (
        RunProgress(None, 500.0, stream=io.StringIO()).text(1000, 0) == "run    2.0 s 1000 cycles, 0 missed deadline(s)"
    )
    assert progress.interval_s == 10.0  # not a terminal: a plain line every 10 s

    calls = []

    class Hook:
        def __init__(self, name, stats):
            self.name, self.stats = name, stats

        def start(self, recorder, timing):
            calls.append(("start", self.name, recorder, timing))

        def close(self, trips, notes=()):
            calls.append(("close", self.name, list(trips)))
            return self.stats

    hooks = SessionHooks(None, Hook("a", None), Hook("b", {"sends": 3}))
    hooks.start("rec", "timing")
    assert hooks.close([{"time_s": 1.0}]) == {"sends": 3}
    assert calls == [
        ("start", "a", "rec", "timing"),
        ("start", "b", "rec", "timing"),
        ("close", "a", [{"time_s": 1.0}]),
        ("close", "b", [{"time_s": 1.0}]),
    ]
