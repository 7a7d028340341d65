"""MATLAB export: data.mat loads with scipy.io.loadmat with the same columns and the same values."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.io import loadmat

import sashil
from sashil.cli import main
from sashil.errors import DataFileError
from sashil.recording.data_file import read_data_csv, write_data_csv
from sashil.recording.matlab import export_mat, write_mat


def test_write_mat_round_trip_exact(tmp_path):
    rng = np.random.default_rng(7)
    cols = {"time_s": np.arange(5) * 1e-3, "theta_rad": rng.normal(size=5), "trip_code": np.array([0, 0, 0, 0, 3])}
    path = write_mat(tmp_path / "d.mat", cols, {"verb": "run"})
    doc = loadmat(path)
    assert [str(c[0]) for c in doc["columns"][0]] == ["time_s", "theta_rad", "trip_code"]
    for name, values in cols.items():
        assert doc[name].shape == (5, 1)
        assert np.array_equal(doc[name][:, 0], np.asarray(values, dtype=float))  # bit-exact doubles
    assert str(doc["sashil"]["verb"][0, 0][0]) == "run"


def test_drop_test_format_mat_matches_data_csv(tmp_path):
    out = tmp_path / "D"
    assert main(["drop-test", "--duration", "1", "--out", str(out), "--format", "mat"]) == 0
    data = read_data_csv(out / "data.csv", required=())
    doc = loadmat(out / "data.mat")
    assert [str(c[0]) for c in doc["columns"][0]] == list(data)
    for name, values in data.items():
        assert np.array_equal(doc[name][:, 0], values), name


def _struct(doc: dict) -> dict[str, str]:
    """The ``sashil`` struct of a loaded .mat file as field -> text."""
    meta = doc["sashil"]
    return {name: str(np.ravel(meta[name][0, 0])[0]) for name in meta.dtype.names}


@pytest.mark.parametrize(
    "verb, argv, expected",
    [
        ("drop-test", ["--duration", "1", "--current", "0.5"], {"controller": "passive 0.5 A", "current_a": "0.5"}),
        (
            "sweep",
            ["--duration", "1", "--f-start", "1", "--f-stop", "2", "--current", "0"],
            {"controller": "passive 0 A"},
        ),
    ],
)
def test_data_mat_holds_verb_exit_status_and_version(tmp_path, verb, argv, expected):
    out = tmp_path / "D"
    assert main([verb, *argv, "--out", str(out), "--format", "mat", "-q"]) == 0
    meta = _struct(loadmat(out / "data.mat"))
    assert meta == {"verb": verb, "exit_status": "ok", "sashil_version": sashil.__version__, **expected}


def test_export_from_a_run_folder_carries_its_metadata(tmp_path):
    write_data_csv(tmp_path / "data.csv", {"time_s": [0.0, 0.001], "theta_rad": [0.1, -0.2], "current_a": [0.0, 0.5]})
    (tmp_path / "summary.json").write_text(
        '{"verb": "run", "exit_status": "safety_trip", "provenance": {"sashil_version": "9.9"}}'
    )
    doc = loadmat(export_mat(tmp_path / "data.csv"))
    assert doc["theta_rad"][:, 0].tolist() == [0.1, -0.2]
    meta = doc["sashil"]
    assert str(meta["exit_status"][0, 0][0]) == "safety_trip" and str(meta["sashil_version"][0, 0][0]) == "9.9"


def test_a_column_matlab_cannot_name_is_refused(tmp_path):
    with pytest.raises(DataFileError, match="'2nd' is not usable as a MATLAB variable name"):
        write_mat(tmp_path / "x.mat", {"time_s": [0.0], "2nd": [1.0]})
    assert not (tmp_path / "x.mat").exists()


def test_report_format_mat_exports_every_data_csv(tmp_path):
    out = tmp_path / "D"
    assert main(["drop-test", "--current", "0", "--current", "1", "--duration", "1", "--out", str(out)]) == 0
    assert main(["report", str(out), "--out", str(tmp_path / "R"), "--format", "mat", "-q"]) == 0
    for sub in ("i0.000A", "i1.000A"):
        data = read_data_csv(out / sub / "data.csv")
        assert np.array_equal(loadmat(out / sub / "data.mat")["theta_rad"][:, 0], data["theta_rad"])
