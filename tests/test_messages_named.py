"""Messages a new user meets name what they gave: ``sashil tune`` blames its own argument (not
``--set``), ``sashil.run`` is quiet when asked, a run on a port that cannot be opened leaves no
folder, and ``sashil.run(LawClass)`` labels the run by the law's name."""

from __future__ import annotations

import sashil
from sashil.cli import main
from sashil.control import Law


class Steady(Law):
    """A law given to ``sashil.run`` as a class (labelled by its name, not ``module:Class``)."""

    name = "steady-half-amp"

    def current(self, state):
        return 0.5


def test_tune_names_its_own_argument_not_set(tmp_path, capsys):
    assert main(["tune", str(tmp_path / "x"), "c_sky=1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sashil tune: error: sashil tune 'c_sky=1': expected section.key=value")
    assert "--set" not in err[0]


def test_run_on_a_port_that_cannot_be_opened_is_one_line_and_no_folder(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(
        ["run", "--driver", "serial", "--port", str(tmp_path / "ttyUSB9"), "--duration", "1", "--out", str(out)]
    )
    err = capsys.readouterr().err
    assert code == 2 and not out.exists() and "run folder" not in err
    assert err.strip().splitlines()[-1].startswith("sashil run: error: serial port") and "cannot open" in err


def test_sashil_run_quiet_prints_no_progress_and_labels_a_class_by_its_name(tmp_path, capsys):
    run = sashil.run(Steady, duration_s=0.3, out=tmp_path / "run", quiet=True)
    err = capsys.readouterr().err
    assert "live tuning:" not in err and "run folder:" not in err and "sashil run:" not in err
    assert run.summary["controller"] == "steady-half-amp"
    assert run.summary["controller_origin"] == f"module {__name__}"
    assert run.config["controller"]["law"] == f"{__name__}:Steady"  # what reruns it
    data = run.data
    assert set(data["current_law_a"][:-1]) == {0.5} and set(data["current_cmd_a"][:-1]) == {0.5}
