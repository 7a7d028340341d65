"""``sashil identify`` / ``sashil simulate`` end to end, and bad input as one line with exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sashil.cli import main
from sashil.config import load_params
from sashil.identify.synthetic import drop_test_columns
from sashil.models.hysteresis import BoucWenParams
from sashil.recording.data_file import write_data_csv

TRUTH = BoucWenParams(k=95.0, c1=0.5, c2=1.2, alpha1=1.3, alpha2=0.8, beta=600.0, gamma=50.0, delta=500.0, n=0.2)


@pytest.fixture(scope="module")
def drop(tmp_path_factory):
    folder = tmp_path_factory.mktemp("drops")
    write_data_csv(folder / "a0.csv", drop_test_columns(TRUTH, -5.0, 0.0, duration_s=3.0))
    return folder / "a0.csv"


def _columns(n=1000):
    return {
        "time_s": np.arange(n) * 1e-3,
        "theta_rad": np.linspace(-0.08, 0.0, n),
        "current_a": np.zeros(n),
        "current_cmd_a": np.zeros(n),
    }


@pytest.mark.parametrize(
    "mutate,needle",
    [
        (lambda c: c.pop("current_a"), "missing column(s) current_a"),
        (lambda c: c["theta_rad"].__setitem__(5, np.nan), "NaN or inf"),
        (lambda c: c["time_s"].__setitem__(7, 0.0), "time_s not increasing"),
        (lambda c: [c.__setitem__(k, v[:100]) for k, v in list(c.items())], "too short"),
    ],
)
def test_bad_data_is_one_line_exit_2(tmp_path, capsys, mutate, needle):
    cols = _columns()
    mutate(cols)
    path = tmp_path / "bad.csv"
    write_data_csv(path, cols)
    code = main(["identify", str(path), "--passive", "--out", str(tmp_path / "p.yaml")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and str(path) in err and needle in err
    assert not (tmp_path / "p.yaml").exists()


def test_constant_current_with_current_terms_is_refused(drop, tmp_path, capsys):
    code = main(["identify", str(drop), "--out", str(tmp_path / "p.yaml")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "current_a never changes" in err and "--passive" in err and len(err.splitlines()) == 1


def test_identify_then_simulate(drop, tmp_path, capsys):
    out = tmp_path / "params.yaml"
    assert main(["identify", str(drop), "--model", "dahl", "--passive", "--quiet", "--out", str(out)]) == 0
    section = load_params(out)  # the config loader accepts what identify writes
    assert section["name"] == "dahl" and section["params"]["k"] == pytest.approx(95.0, rel=0.03)
    assert (tmp_path / "params_fit.png").stat().st_size > 0
    run = tmp_path / "sim"
    assert main(["simulate", "--params", str(out), "--input", str(drop), "--out", str(run)]) == 0
    summary = json.loads((run / "summary.json").read_text())
    assert summary["exit_status"] == "ok" and summary["model"] == "dahl" and summary["nrmse"] < 0.05
    assert (run / "data.csv").exists() and (run / "config.yaml").exists()


def _write_dahl(path):
    path.write_text("model: dahl\nparams: {J: 1.0, k: 109.0, c1: 0.7, c2: 1.5, kwa: 1.0, kwb: 1.0, rho: 100.0}\n")
    return path


@pytest.mark.parametrize("verb", ["run", "drop-test", "sweep", "calibrate", "emulate"])
def test_a_model_the_rig_verbs_cannot_run_is_one_line_naming_the_file(tmp_path, capsys, verb):
    params = _write_dahl(tmp_path / "dahl.yaml")
    out = tmp_path / "out"
    extra = [] if verb == "emulate" else ["--out", str(out)]
    assert main([verb, "--params", str(params), *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"--params {params}: a dahl model; sashil {verb} runs bouc-wen models only" in err
    assert "sashil simulate runs bouc-wen, dahl, lugre, bingham" in err
    assert not out.exists()


def test_a_config_including_a_model_the_verb_cannot_run_names_the_config(tmp_path, capsys):
    _write_dahl(tmp_path / "dahl.yaml")
    config = tmp_path / "lab.yaml"
    config.write_text("include_params: dahl.yaml\n")
    assert main(["drop-test", "--config", str(config), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"--config {config}: a dahl model; sashil drop-test runs bouc-wen models only" in err


def test_simulate_runs_a_dahl_parameter_file(tmp_path):
    params = _write_dahl(tmp_path / "dahl.yaml")
    out = tmp_path / "sim"
    assert main(["simulate", "--params", str(params), "--duration", "1", "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["model"] == "dahl"


def test_identify_never_overwrites_without_force_and_creates_the_out_folder(drop, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    existing = tmp_path / "params.yaml"
    existing.write_text("keep me\n")
    argv = ["identify", str(drop), "--model", "dahl", "--passive", "--quiet"]
    assert main(argv) == 2  # the default --out, ./params.yaml, exists
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "params.yaml: exists; add --force to overwrite it, or choose another --out" in err
    assert existing.read_text() == "keep me\n" and not (tmp_path / "params_fit.png").exists()
    nested = tmp_path / "fits" / "dahl" / "params.yaml"
    assert main([*argv, "--out", str(nested)]) == 0  # the folder is created
    assert load_params(nested)["name"] == "dahl" and (nested.parent / "params_fit.png").exists()
    assert f"wrote {nested.resolve()} (model dahl)" in capsys.readouterr().out
    assert main([*argv, "--out", str(nested)]) == 2  # the second time: refused ...
    assert f"{nested}: exists; add --force" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 0  # ... unless forced
    assert load_params(existing)["name"] == "dahl"
    assert f"wrote {existing.resolve()} (model dahl)" in capsys.readouterr().out
