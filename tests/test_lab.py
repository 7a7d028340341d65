"""sashil as a library: experiments as functions on a config resolved once and frozen, events
instead of prints, one summary per folder, and runs that lost too much not ending ``ok``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import sashil
from sashil.config import dump_config
from sashil.config.frozen import FrozenSection, thaw
from sashil.config.parts import LoopParts, StageParts
from sashil.engine.events import Event
from sashil.engine.resolve import ConfigSource, Option, default_config, resolve
from sashil.errors import ConfigError, LossError, exit_code_of, status_of
from sashil.lab._drop_test import drop_test
from sashil.recording.outputs import Outputs
from sashil.runtime.runner import losses
from sashil.runtime.timing import TimingStats
from sashil.writer.run_folder import RunFolder
from sashil.writer.summary_writer import write_summary


def _imports_of(code: str) -> set[str]:
    """The top-level packages a fresh interpreter has imported after running ``code``."""
    probe = f"{code}\nimport sys; print(' '.join(sorted({{m.split('.')[0] for m in sys.modules}})))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return set(done.stdout.split())


def test_the_package_and_the_version_import_no_numerics():
    heavy = {"numpy", "scipy", "numba", "matplotlib", "yaml"}
    assert not heavy & _imports_of("import sashil; sashil.__version__")
    code = "from sashil.cli import main\ntry:\n    main(['--version'])\nexcept SystemExit:\n    pass"
    assert not heavy & _imports_of(code)


@pytest.mark.parametrize("verb", ["drop-test", "run", "report", "laws", "tune", "identify"])
def test_a_verbs_help_imports_no_numerics(verb):
    code = f"from sashil.cli import main\ntry:\n    main([{verb!r}, '--help'])\nexcept SystemExit:\n    pass"
    assert not {"numpy", "scipy", "numba", "matplotlib"} & _imports_of(code)


def test_the_python_api_never_imports_the_command_line(tmp_path):
    code = f"import sashil; sashil.drop_test([0.0], duration_s=0.3, out={str(tmp_path / 'D')!r})"
    probe = f"{code}\nimport sys; print(sorted(name for name in sys.modules if name.startswith('sashil.cli')))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert done.stdout.strip().splitlines()[-1] == "[]"
    assert (tmp_path / "D" / "summary.json").is_file()


def test_the_resolved_config_is_read_only_and_is_what_config_yaml_holds():
    source = ConfigSource(sets=("loop.rate_hz=500",), options=(Option("--duration", "drop_test.duration_s", 2.0),))
    config = resolve(source, "drop-test")
    assert isinstance(config, FrozenSection) and isinstance(config["loop"], FrozenSection)
    assert config["loop"]["rate_hz"] == 500.0 and config["drop_test"]["duration_s"] == 2.0
    assert config["driver"]["clock"] == "virtual"  # the sim backend's own clock for a drop test
    with pytest.raises(TypeError, match="read-only"):
        config["loop"]["rate_hz"] = 1000.0
    with pytest.raises(TypeError, match="read-only"):
        config["drop_test"].update(duration_s=1.0)
    writable = thaw(config)
    writable["loop"]["rate_hz"] = 1000.0  # a copy: the resolved config keeps its value
    assert config["loop"]["rate_hz"] == 500.0
    assert yaml.safe_load(dump_config(config)) == thaw(config)


def test_an_option_is_checked_by_the_schema_and_named_in_the_error():
    with pytest.raises(ConfigError, match=r"^--duration: drop_test.duration_s: expected a number > 0, got -1"):
        resolve(ConfigSource(options=(Option("--duration", "drop_test.duration_s", -1.0),)), "drop-test")


def test_run_resolves_its_clock_road_and_rate_from_the_backend():
    config = resolve(ConfigSource(), "run")
    assert config["driver"]["clock"] == "real" and config["run"]["road"] == "sine:1.0"
    with pytest.raises(ConfigError, match=r"^driver.clock: virtual: sashil run runs on the real clock"):
        resolve(ConfigSource(sets=("driver.clock=virtual",)), "run")
    with pytest.raises(ConfigError, match=r"^--rate: 15000 Hz is above what the sim backend can do \(10000 Hz\)"):
        resolve(ConfigSource(options=(Option("--rate", "loop.rate_hz", 15000.0),)), "run")
    with pytest.raises(ConfigError, match=r"^--port /dev/null: the driver is sim, which has no port"):
        resolve(ConfigSource(port="/dev/null"), "run")
    with pytest.raises(ConfigError, match=r"^--road sine:x"):
        resolve(ConfigSource(options=(Option("--road", "run.road", "sine:x"),)), "run")
    with pytest.raises(ConfigError, match=r"^run.road sine:x: expected sine:F_HZ"):
        resolve(ConfigSource(sets=("run.road=sine:x",)), "run")


def test_the_drop_test_function_returns_its_run_and_tells_its_caller_by_events(tmp_path):
    config = resolve(ConfigSource(options=(Option("currents_a", "drop_test.currents_a", [0.0, 1.0]),)), "drop-test")
    events: list[Event] = []
    run = drop_test(config, Outputs(out=tmp_path / "D"), events.append)
    assert [sub.name for sub in run.runs] == ["i0.000A", "i1.000A"]
    assert run.summary["exit_status"] == "ok" and run.config["drop_test"]["currents_a"] == [0.0, 1.0]
    first, stiff = (sub.metrics["peaks_deg"][0] for sub in run.runs)
    assert first > stiff > 0  # more current, more damping: a lower first peak
    kinds = [event.kind for event in events]
    assert kinds.count("progress") == 2 and kinds.count("result") == 2 and kinds[-1] == "folder"
    assert events[-1].data["folder"] == str(tmp_path / "D")
    assert np.all(np.diff(run.runs[0].data["time_s"]) > 0)


def test_bad_input_to_a_library_function_leaves_no_folder(tmp_path):
    config = resolve(ConfigSource(), "drop-test")
    with pytest.raises(ConfigError, match="--format blf"):
        drop_test(config, Outputs(out=tmp_path / "D", formats=("blf",)))
    assert not (tmp_path / "D").exists()


def test_summary_json_is_written_once_per_folder(tmp_path):
    folder = RunFolder.create(tmp_path / "F", "run")
    write_summary(folder, {"exit_status": "ok"})
    with pytest.raises(RuntimeError, match="written once"):
        write_summary(folder, {"exit_status": "ok"})
    assert json.loads((tmp_path / "F" / "summary.json").read_text())["exit_status"] == "ok"


def test_lateness_counts_the_deadlines_an_overrun_skipped():
    period = 1_000_000  # 1 ms
    timing = TimingStats(1000.0, window=4096)
    for _ in range(7):  # seven cycles on time
        timing.lateness[timing.cycles & timing.mask] = 0
        timing.cycles += 1
    # one cycle 3.5 periods late: it passed three deadlines, then 2.5, 1.5 and 0.5 periods late
    timing.lateness[timing.cycles & timing.mask] = 3_500_000
    timing.cycles += 1
    timing.missed_deadlines += 3
    timing.skip(3_500_000, period, 3)
    stats = timing.stats_us("lateness")
    values = np.array([0] * 7 + [3500, 2500, 1500, 500], dtype=float)  # 11 scheduled deadlines, in us
    assert stats["p50"] == pytest.approx(np.quantile(values, 0.5))
    assert stats["p99"] == pytest.approx(np.quantile(values, 0.99))
    assert stats["max"] == 3500.0


def test_a_run_that_lost_more_than_the_config_allows_is_not_ok():
    config = default_config()
    timing = TimingStats(1000.0, window=4096)
    timing.cycles, timing.missed_deadlines = 4667, 5333  # the wrecked run: half its deadlines missed
    lost = losses(LoopParts.read(config), timing, None)
    assert isinstance(lost, LossError) and "missed 5333 of 10000 deadlines" in str(lost)
    assert "loop.max_missed_fraction allows 25 %" in str(lost)
    assert status_of(lost) == "lossy" and exit_code_of("lossy", lost) == 5
    timing.missed_deadlines = 90  # a loaded VM over serial: 90 per 60 s is within the default
    timing.cycles = 60_000
    assert losses(LoopParts.read(config), timing, None) is None
    link = {"samples": 7_000, "samples_missed": 3_000}
    lost = losses(LoopParts.read(config), timing, link)
    assert lost is not None and "lost 3000 of 10000 samples" in str(lost) and "driver.max_lost_fraction" in str(lost)


def test_the_passive_law_declares_it_reads_no_state():
    from sashil.control.laws import Passive, Skyhook
    from sashil.control.registry import make_stage

    assert Passive.reads_state is False and Skyhook.reads_state is True
    label, stage = make_stage(StageParts.read(resolve(ConfigSource(sets=("controller.current_a=0.4",)), "run")))
    assert label == "passive 0.4 A" and stage.law.current_a == 0.4
    label, stage = make_stage(
        StageParts.read(resolve(ConfigSource(controller="skyhook", sets=("controller.c_sky=2",)), "run"))
    )
    assert label == "skyhook" and stage.law.c_sky == 2.0


def test_sashil_run_from_python_keeps_its_signature(tmp_path):
    relaxed = {"loop.max_missed_fraction": 1.0}  # a shared CI machine may stall a 0.2 s run on the real clock
    run = sashil.run(current_a=0.25, duration_s=0.2, out=Path(tmp_path / "R"), set=relaxed)
    assert run.summary["controller"] == "passive 0.25 A" and run.config["driver"]["clock"] == "real"
    assert run.config["run"]["duration_s"] == 0.2 and len(run.data["time_s"]) > 100


def test_every_experiment_is_a_function_of_sashil_lab_even_after_its_module_is_imported():
    import importlib

    import sashil.lab as lab

    modules = {
        name: f"sashil.lab._{name}" for name in ("drop_test", "sweep", "compare", "calibrate", "replay", "simulate")
    }
    modules["closed_loop"] = "sashil.engine.sashil_run"  # sashil run's session, which the engine runs
    for name, module in modules.items():
        importlib.import_module(module)
        assert callable(getattr(lab, name)) and getattr(lab, name).__name__ == name
        assert name in lab.__all__
