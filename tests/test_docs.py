"""The manual (docs/, built with mkdocs) cannot drift from the code, and its examples run.

- The reference pages tools/gen_reference.py writes equal what it writes now from the code, and the
  home page (docs/index.md) what tools/gen_home.py writes from the README.
- The CLI reference lists every verb and every option, the config reference every key, and
  nothing the code does not have.
- Every code block of the tutorials and how-to guides is ``sh`` or ``python`` (run here, page by page,
  in order, in a fresh folder), ``text`` or ``yaml`` (shown, not run), or says what it needs
  (``*Needs a board on /dev/ttyACM0.*`` on the line before it, see tests/doc_blocks.py).
- The site builds in mkdocs' strict mode when the docs extra is installed (``pip install -e '.[docs]'``).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from doc_blocks import fenced_blocks
from warm_sashil import WarmSashil

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
sys.path.insert(0, str(ROOT / "tools"))

import gen_home  # noqa: E402
import gen_reference  # noqa: E402

RUN = {"sh", "python"}
SHOWN = {"text", "yaml"}
#: the page whose commands run in fresh interpreters, the installed ``sashil`` script among them
COLD_PAGE = "first-drop-test.md"
#: the pages whose examples run as tests
EXAMPLE_PAGES = sorted((DOCS / "tutorials").glob("*.md")) + sorted((DOCS / "how-to").glob("*.md"))


def test_generated_reference_is_current():
    stale = gen_reference.stale_pages(DOCS / "reference")
    assert not stale, f"docs/reference/{', '.join(stale)} differ from the code: run python tools/gen_reference.py"


def test_home_page_is_the_readme():
    """docs/index.md is tools/gen_home.py's copy of README.md (its links into docs/ made relative)."""
    written = gen_home.home_page((ROOT / "README.md").read_text(encoding="utf-8"))
    assert (DOCS / "index.md").read_text(encoding="utf-8") == written, (
        "docs/index.md is stale: python tools/gen_home.py"
    )


def test_every_config_key_has_a_meaning_and_every_choice_its_choices():
    from sashil.config.schema import Field, Section
    from sashil.config.sections import SCHEMA

    rows = list(gen_reference._config_rows(SCHEMA, ""))
    assert len(rows) > 100
    no_meaning = [row[0] for row in rows if not row[4].strip()]
    assert not no_meaning, f"config keys without a meaning (a doc= in sashil/config/sections.py): {no_meaning}"

    def choices(fields, prefix=""):
        for key, spec in fields.items():
            if isinstance(spec, Section):
                yield from choices(spec.fields, f"{prefix}{key}.")
            elif isinstance(spec, Field) and spec.kind.startswith("choice"):
                yield f"`{prefix}{key}`", spec.choices

    shown = {row[0]: row[3] for row in rows}
    for key, options in choices(SCHEMA):
        assert options and all(f"`{option}`" in shown[key] for option in options), f"{key}: its choices"


def test_the_api_reference_links_its_types_and_hides_private_fields():
    page = (DOCS / "reference" / "python-api.md").read_text(encoding="utf-8")
    assert "[`Run`](python-api.md#run)" in page and "[`RunConfig`](python-api.md#sashillabrunconfig)" in page
    assert "_sub_entries" not in page


def test_python_api_reference_has_every_public_name():
    import sashil
    import sashil.lab as lab
    import sashil.testing as testing

    page = (DOCS / "reference" / "python-api.md").read_text(encoding="utf-8")
    headings = set(re.findall(r"^#{2,3} (\S+)$", page, flags=re.M))
    names = {"sashil.run", "sashil.drop_test", "sashil.load_run", "Run"}
    names |= {f"Run.{n}" for n in vars(sashil.Run) if not n.startswith("_")}
    names |= {f"sashil.lab.{n}" for n in lab.__all__}
    names |= {f"sashil.testing.{n}" for n in testing.__all__ if callable(getattr(testing, n))}
    assert not names - headings, f"python-api.md lacks {sorted(names - headings)}"


def test_cli_reference_has_every_verb_and_option_and_no_other():
    from sashil.cli import VERBS, build_parser

    page = (DOCS / "reference" / "cli.md").read_text(encoding="utf-8")
    documented = re.findall(r"^## (\S+)$", page, flags=re.M)
    assert documented == list(VERBS)
    parsers = gen_reference.verb_parsers(build_parser())
    for verb, chunk in zip(documented, re.split(r"^## \S+$", page, flags=re.M)[1:], strict=True):
        actions = [a for a in parsers[verb]._actions if a.help != argparse.SUPPRESS]
        options = {o for a in actions for o in a.option_strings}
        # its own options as table rows; the shared ones it takes by name on the line linking their table
        listed = set(re.findall(r"^\| `(-[-\w]+)", chunk, flags=re.M)) | set(re.findall(r", `(-[-\w]+)", chunk))
        shared_line = re.search(r"^\[Shared options\]\(#[\w-]+\): (.*)\.$", chunk, flags=re.M)
        named = set(re.findall(r"`(-[-\w]+)`", shared_line.group(1))) if shared_line else set()
        listed |= {o for a in actions if named & set(a.option_strings) for o in a.option_strings}
        assert listed == options - {"-h", "--help"}, verb


def test_config_reference_has_every_key_and_no_other():
    from sashil.config.schema import Section
    from sashil.config.sections import SCHEMA

    def keys(fields, prefix=""):
        for name, spec in fields.items():
            if isinstance(spec, Section):
                if spec.open_keys:
                    yield prefix + name
                yield from keys(spec.fields, f"{prefix}{name}.")
            else:
                yield prefix + name

    page = (DOCS / "reference" / "config.md").read_text(encoding="utf-8")
    assert re.findall(r"^\| `([\w.]+)` \|", page, flags=re.M) == list(keys(SCHEMA))


def test_one_page_runs_the_installed_sashil_in_fresh_interpreters():
    assert [p.name for p in EXAMPLE_PAGES].count(COLD_PAGE) == 1


@pytest.mark.parametrize("page", EXAMPLE_PAGES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_block_runs_or_says_what_it_needs(page: Path):
    for block in fenced_blocks(page.read_text(encoding="utf-8")):
        assert block.info in RUN | SHOWN, f"{page.name}:{block.line}: a fence needs one of {sorted(RUN | SHOWN)}"
        if block.info in SHOWN:
            assert not block.needs, f"{page.name}:{block.line}: a shown block runs nothing, it needs nothing"


@pytest.mark.parametrize("page", sorted((DOCS / "tutorials").glob("*.md")), ids=lambda p: p.name)
def test_tutorials_say_how_to_use_the_quick_starts_environment(page: Path):
    text = page.read_text(encoding="utf-8")
    blocks = [block for block in fenced_blocks(text) if block.info == "sh"]
    if not blocks:
        return
    first = text.splitlines()[: blocks[0].line]
    assert any("source .venv/bin/activate" in line for line in first), (
        f"{page.name}: activate .venv before its commands"
    )
    assert not any(".venv/bin/" in block.body for block in blocks), f"{page.name}: commands as in the active .venv"


def _page_id(page: Path) -> str:
    return f"{page.parent.name}/{page.name}"


#: pages whose runs hold the bench's own limits without a link (a loop at normal priority, within the
#: default share of missed deadlines)
AT_THE_LIMITS = {"preempt-rt.md"}


def _alone_if_linked(page: Path) -> object:
    """A page that runs ``sashil emulate`` drives its link at the bench's own limits, as a reader's
    would, and so does a page of :data:`AT_THE_LIMITS`: it runs by itself (pyproject's ``alone``
    marker)."""
    if page.name in AT_THE_LIMITS or "sashil emulate" in page.read_text(encoding="utf-8"):
        return pytest.param(page, marks=pytest.mark.alone)
    return page


def _script(page: Path, folder: Path, python: str = f'"{sys.executable}"') -> str:
    """The page's runnable blocks as one bash script (python blocks written beside it and run by
    ``python``)."""
    # a block that fails leaves nothing behind: what the page started in the background is stopped
    lines = ["set -euo pipefail", "trap 'jobs -p | xargs -r kill -INT 2>/dev/null || true; wait' EXIT"]
    for n, block in enumerate(fenced_blocks(page.read_text(encoding="utf-8"))):
        if block.needs or block.info not in RUN:
            continue
        if block.info == "python":
            (folder / f"block{n}.py").write_text(block.body, encoding="utf-8")
            lines.append(f"{python} block{n}.py")
        else:
            lines.append(block.body)
    lines.append("wait")  # anything a block started in the background
    return "\n".join(lines) + "\n"


@pytest.mark.e2e
@pytest.mark.parametrize("page", [_alone_if_linked(page) for page in EXAMPLE_PAGES], ids=_page_id)
def test_examples_run(page: Path, tmp_path: Path, warm_sashil: WarmSashil):
    # the first tutorial runs as a reader's shell runs it: the installed sashil console script and a
    # fresh interpreter for each block; every other page's sashil and python blocks fork the warm
    # interpreter (tests/warm_sashil.py)
    cold = page.name == COLD_PAGE
    script = _script(page, tmp_path) if cold else _script(page, tmp_path, python=warm_sashil.python[0])
    if script.count("\n") <= 3:
        pytest.skip(f"{page.name}: no block runs here (none, or each needs hardware)")
    for name in ("configs", "examples", "drivers"):
        (tmp_path / name).symlink_to(ROOT / name)
    first = [] if cold else [str(warm_sashil.bin)]
    path = os.pathsep.join((*first, str(Path(sys.executable).parent), os.environ.get("PATH", "")))
    env = {**os.environ, "PATH": path}
    done = subprocess.run(["bash", "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{page.name}: exit {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"


@pytest.mark.e2e
def test_site_builds_strictly(tmp_path: Path):
    if shutil.which("mkdocs", path=str(Path(sys.executable).parent)) is None:
        pytest.skip("mkdocs is not installed: pip install -e '.[docs]' builds the manual")
    done = subprocess.run(
        [str(Path(sys.executable).parent / "mkdocs"), "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    pages = list((tmp_path / "site").rglob("*.html"))
    loads = re.compile(
        r"""<(?:script|img|iframe)[^>]+src=["']https?://|<link[^>]+href=["']https?://|url\(["']?https?://"""
    )
    fetched = [p for p in pages if loads.search(p.read_text(encoding="utf-8"))]
    assert not fetched, f"pages that load from the network: {fetched[:3]}"
    # search from site/index.html opened as a file: Material's offline plugin inlines the index into a
    # script, and the vendored iframe-worker shim runs the search worker where file:// forbids workers
    index = (tmp_path / "site" / "search" / "search_index.js").read_text(encoding="utf-8")
    assert index.startswith("var __index = {") and '"location":"how-to/test-your-law-in-ci.html"' in index
    home = (tmp_path / "site" / "index.html").read_text(encoding="utf-8")
    assert '<script src="assets/javascripts/iframe-worker/shim.js">' in home
