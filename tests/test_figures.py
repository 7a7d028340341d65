"""The manual's figures agree with their captions and with the code (tools/figures.py).

Every figure in docs/figures/ keeps beside it the numbers its caption may state (NAME.json, written
by the run that drew it). Here: every image of figures/ in README.md and docs/ is made by an entry of
tools/figures.py, and each number its alt text and caption state is among its kept data; each figure
and its data are the pair one run made (made.json holds their sha256); the kept data is what the code gives now (hysteresis and rig recomputed whole, the law's transmissibility at
its peak, the panel page unchanged since its shots; end to end, every curve's peak, and the drop
test, the comparison, the calibration and the identification run again whole on the virtual clock).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import figures  # noqa: E402

AGAIN = "run .venv/bin/python tools/figures.py --figure {name}"


@pytest.mark.parametrize("name", sorted(figures.FIGURES))
def test_each_figure_is_kept_with_its_data(name):
    assert (figures.OUT / figures.FIGURES[name].file).is_file(), AGAIN.format(name=name)
    assert figures.kept_data(name), AGAIN.format(name=name)


def test_every_figure_in_the_folder_is_made_by_an_entry_and_shown_on_a_page():
    kept = {path.name for path in figures.OUT.iterdir() if path.suffix in (".png", ".svg")}
    made = {figure.file for figure in figures.FIGURES.values()}
    assert kept == made, (
        f"in docs/figures/ but made by no entry: {sorted(kept - made)}; made but absent: {sorted(made - kept)}"
    )
    shown = {file for _page, file, _text in figures.captions()}
    assert made <= shown, f"made but on no page: {sorted(made - shown)}"


def test_each_figure_and_its_data_were_made_together():
    wrong = figures.check_made(tuple(figures.FIGURES))
    assert not wrong, "\n".join(wrong) + "\nrun .venv/bin/python tools/figures.py --figure NAME"


def test_data_made_again_without_its_figure_is_found(tmp_path):
    for name in ("hysteresis.png", "hysteresis.json", "rig.svg", "rig.json", figures.MADE):
        (tmp_path / name).write_bytes((figures.OUT / name).read_bytes())
    (tmp_path / "hysteresis.json").write_text('{"loops": {}}\n', encoding="utf-8")
    assert figures.check_made(("hysteresis", "rig"), tmp_path) == [
        "hysteresis: hysteresis.png and its data are not the pair tools/figures.py made together"
    ]


def test_every_caption_states_only_numbers_of_its_figures_data():
    wrong = figures.check_captions()
    assert not wrong, "\n".join(wrong)


def test_a_caption_stating_a_number_the_data_lacks_fails(tmp_path):
    """The caption check can fail: a page whose caption of hysteresis.png states a peak torque the
    kept data does not hold, and one citing a figure no entry makes."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("# x\n", encoding="utf-8")
    (tmp_path / "docs" / "page.md").write_text(
        "![loops at 0 and 1 A](figures/hysteresis.png)\n\n*peak torque 0.98 N m at 1 A, 0.37 N m at 0 A.*\n\n"
        "![a figure](figures/nowhere.png)\n",
        encoding="utf-8",
    )
    wrong = figures.check_captions(tmp_path)
    assert wrong == [
        "docs/page.md: the caption of figures/hysteresis.png states 0.37, which hysteresis's data does not hold",
        "docs/page.md: figures/nowhere.png is made by no entry of tools/figures.py",
    ]


def test_caption_numbers_skip_names_and_keep_signs():
    # θ2, θ̈2 and T1 are names; ±0.06 and −5 are numbers
    assert figures.CAPTION_NUMBER.findall("θ2 and θ̈2 of T1 stay within ±0.06° after −5 deg, ISO 8608") == [
        "±0.06",
        "−5",
        "8608",
    ]


FAST = sorted(name for name, figure in figures.FIGURES.items() if figure.recompute is not None and not figure.slow)
SLOW = sorted(name for name, figure in figures.FIGURES.items() if figure.slow or figure.whole)


@pytest.mark.parametrize("name", FAST)
def test_the_kept_data_is_what_the_code_gives(name):
    wrong = figures.check_data((name,), slow=False)
    assert not wrong, "\n".join(wrong) + "\n" + AGAIN.format(name=name)


@pytest.mark.e2e
@pytest.mark.parametrize("name", SLOW)
def test_the_kept_data_is_what_a_whole_run_gives(name):
    wrong = figures.check_data((name,), slow=True)
    assert not wrong, "\n".join(wrong) + "\n" + AGAIN.format(name=name)


def test_a_changed_number_in_the_kept_data_is_found():
    kept = figures.kept_data("hysteresis")
    kept["loops"]["1 A"]["peak_torque_nm"] = "0.99"
    assert figures.recompute_hysteresis(kept) == [
        "hysteresis.loops.1 A.peak_torque_nm: kept '0.99', the code gives '0.98'"
    ]


@pytest.mark.parametrize(
    ("page", "command"),
    [
        ("docs/tutorials/your-own-law.md", "sashil " + " ".join(figures.tutorial_figures.RUN_COMMAND)),
        ("docs/tutorials/emulated-board.md", "sashil " + " ".join(figures.tutorial_figures.DOCTOR_COMMAND)),
        ("docs/tutorials/emulated-board.md", "sashil " + " ".join(figures.tutorial_figures.EMULATE_COMMAND)),
        ("docs/how-to/compare-laws.md", "sashil " + " ".join(figures.readme_figures.COMPARE_COMMAND)),
    ],
)
def test_a_figure_of_a_pages_command_is_of_that_command(page, command):
    assert command in (ROOT / page).read_text(encoding="utf-8"), (
        f"{page} no longer runs `{command}`: its figure is of it"
    )
