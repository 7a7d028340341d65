"""The run folder's writer, fed the documents a verb's runs emit: config.yaml at each start,
data.csv and each sub-run's summary.json at its stop, the folder's summary.json at the verb's end
(once), and the first failing run ending the set."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from sashil.errors import ConfigError, SafetyTrip
from sashil.writer.documents import Documents, RunRecord, versions
from sashil.writer.folder_writer import FolderWriter, ending
from sashil.writer.run_folder import RunFolder


def test_the_writer_of_several_runs_writes_each_and_the_folder_once(tmp_path):
    folder = RunFolder.create(tmp_path / "out", "drop-test")
    writer = FolderWriter(folder, "drop-test", {"driver": "sim", "controller": "passive"})
    seen: list[tuple[str, object]] = []
    documents = Documents([writer, lambda kind, doc: seen.append((kind, doc.get("run")))])
    documents.start(None, {"loop": {"rate_hz": 1000.0}})
    documents.start("i0.000A", {"loop": {"rate_hz": 1000.0}, "drop_test": {"currents_a": [0.0]}})
    documents.progress("i0.000A", "dropping")
    data = {"time_s": np.array([0.0, 0.001]), "theta_rad": np.array([-0.1, -0.09])}
    documents.stop(
        "i0.000A",
        RunRecord(summary={"timing": {"cycles": 2}}, entry={"current_a": 0.0, "timing": {"cycles": 2}}, data=data),
    )
    trip = SafetyTrip("angle 12 deg beyond the limit")
    documents.stop("i1.000A", RunRecord(error=trip, entry={"current_a": 1.0, "controller": "passive 1 A"}))
    documents.end(note="two drops")

    kinds = [("start", None), ("start", "i0.000A"), ("progress", "i0.000A")]
    assert seen == [*kinds, ("stop", "i0.000A"), ("stop", "i1.000A"), ("stop", None)]
    root = tmp_path / "out"
    assert yaml.safe_load((root / "config.yaml").read_text()) == {"loop": {"rate_hz": 1000.0}}
    assert yaml.safe_load((root / "i0.000A" / "config.yaml").read_text())["drop_test"] == {"currents_a": [0.0]}
    assert not (root / "i1.000A" / "config.yaml").exists()  # its start recorded no config
    assert (root / "i0.000A" / "data.csv").read_text().splitlines()[0] == "time_s,theta_rad"
    first = json.loads((root / "i0.000A" / "summary.json").read_text())
    assert (first["exit_status"], first["controller"], first["timing"]) == ("ok", "passive", {"cycles": 2})
    assert first["runs"][0]["folder"] == "."
    second = json.loads((root / "i1.000A" / "summary.json").read_text())
    assert second["controller"] == "passive 1 A"  # its entry's own value of a common key
    assert second["exit_status"] == ending(trip)["exit_status"] == "safety_trip"
    summary = json.loads((root / "summary.json").read_text())
    assert summary["exit_status"] == "safety_trip" and summary["error"] == "angle 12 deg beyond the limit"
    assert [run["folder"] for run in summary["runs"]] == ["i0.000A", "i1.000A"] and summary["note"] == "two drops"
    assert summary["timing"] is None  # several runs: no run's loop keys at the top
    assert writer.failed and writer.error is trip
    with pytest.raises(RuntimeError, match="written once"):
        documents.end()


def test_a_single_run_is_the_folder_with_its_loop_keys_at_the_top(tmp_path):
    folder = RunFolder.create(tmp_path / "one", "sweep")
    writer = FolderWriter(folder, "sweep", {"driver": "sim"}, several=False)
    documents = Documents([writer])
    documents.start("f1.000Hz", {"sweep": {"stepped": False}})  # a single run's start is the folder's
    documents.stop("f1.000Hz", RunRecord(entry={"timing": {"cycles": 9}, "link": None}))
    documents.end()
    summary = json.loads((tmp_path / "one" / "summary.json").read_text())
    assert summary["timing"] == {"cycles": 9} and summary["runs"][0]["folder"] == "."
    assert sorted(p.name for p in (tmp_path / "one").iterdir()) == ["config.yaml", "summary.json"]


def test_the_start_document_carries_the_versions_and_the_ending_rule():
    starts: list[dict] = []
    Documents([lambda kind, doc: starts.append(dict(doc))]).start("r", None)
    assert starts[0]["versions"] == versions() and starts[0]["spec"] is None and starts[0]["config"] is None
    assert ending(None) == {"exit_status": "ok", "error": None, "exit_code": 0}
    assert ending(ConfigError("--out x: exists"))["exit_code"] == 2


def test_the_writer_is_the_one_caller_of_the_summary_and_config_writes():
    """summary.json and config.yaml are each written from one call site, whatever the verb: the
    session's, a verb's, and a loop's that its session left (runtime/orphan.py) go through the writer."""
    import ast
    from pathlib import Path

    import sashil

    callers = set()
    for path in Path(sashil.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                name = getattr(node.func, "id", None) or getattr(node.func, "attr", None)
                if name in ("write_summary", "write_config"):
                    callers.add((path.relative_to(Path(sashil.__file__).parent).as_posix(), name))
    assert callers == {("writer/folder_writer.py", "write_summary"), ("writer/folder_writer.py", "write_config")}
