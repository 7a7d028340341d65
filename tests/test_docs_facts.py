"""The manual states only what exists, in the present tense.

- Every ``--option`` of a ``sashil VERB`` command on a page is an option of that verb's parser, and
  every option named alone is one of some verb's.
- Every ``controller.KEY`` is a key of the controller section or a parameter of a law ``sashil laws``
  lists.
- A page that lists the exit statuses lists every one of ``sashil.errors``; the README's exit codes
  are ``sashil.errors``' codes.
- Every file a page cites (``configs/...``, ``tools/...``, ``DESIGN.md``) exists.
- The protocol version, the udev rule and the CI how-to's sample test are the code's own.
- No page speaks in a changelog's voice ("now", "no longer", "as before").
- Every page is within two clicks of the home page, and every hardware page says at its top that it
  has not yet run on a real board.

The contributor pages (architecture, contributing, contributor/) are the code's notebook and are
left out of the voice check.
"""

from __future__ import annotations

import re
import sys
from functools import cache
from pathlib import Path

import pytest
from doc_blocks import fenced_blocks

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
sys.path.insert(0, str(ROOT / "tools"))

import gen_reference  # noqa: E402

CONTRIBUTOR = {"architecture.md", "contributing.md"}


def _is_contributor(page: Path) -> bool:
    rel = page.relative_to(DOCS)
    return rel.parts[0] == "contributor" or str(rel) in CONTRIBUTOR


#: the manual's pages a lab reads (the contributor pages aside), and the README
MANUAL = sorted(p for p in DOCS.rglob("*.md") if not _is_contributor(p))
PAGES = [*MANUAL, ROOT / "README.md"]

#: options of other programs that pages show beside sashil's (pip, pytest, git, mkdocs)
FOREIGN_OPTIONS = {
    "--no-deps",
    "--no-build-isolation",
    "--wheel",
    "--sashil-seed",
    "--dist",
    "--strict",
    "--reload",
    "--site-dir",
}

_FENCE = re.compile(r"^[ ]*```.*?^[ ]*```[ ]*$", re.M | re.S)
_CODE_SPAN = re.compile(r"`([^`\n]+)`")


def _page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


def _prose(text: str) -> str:
    """The page without its fenced blocks, inline code spans and HTML comments."""
    text = re.sub(r"<!--.*?-->", "", _FENCE.sub("", text), flags=re.S)
    return _CODE_SPAN.sub("", text)


def _code(text: str, *, output: bool = True) -> list[str]:
    """Every line of a fenced block and every inline code span of the page; ``output=False`` leaves
    out the ``text`` blocks, a program's printed output rather than commands to type."""
    blocks = [block for block in fenced_blocks(text) if output or block.info != "text"]
    lines = [line for block in blocks for line in block.body.splitlines()]
    return lines + _CODE_SPAN.findall(_FENCE.sub("", text))


@cache
def _verb_options() -> dict[str, set[str]]:
    from sashil.cli import build_parser

    parsers = gen_reference.verb_parsers(build_parser())
    return {verb: {o for a in p._actions for o in a.option_strings} for verb, p in parsers.items()}


def _commands(line: str) -> list[tuple[str, list[str]]]:
    """The ``sashil VERB`` commands of a shell line, each with its tokens up to the next command."""
    line = line.split(" #", 1)[0]
    found = []
    for part in re.split(r" && | \|\| | \| |; |\$\(|\)", line):
        words = part.split()
        for n, word in enumerate(words[:-1]):
            if word in ("sashil", ".venv/bin/sashil"):
                found.append((words[n + 1], words[n + 2 :]))
                break
    return found


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_every_option_of_a_command_exists(page: Path):
    options = _verb_options()
    wrong = []
    for line in _code(page.read_text(encoding="utf-8"), output=False):
        for verb, words in _commands(line):
            if verb not in options:
                if not verb.startswith("-") and re.fullmatch(r"[a-z][a-z-]+", verb):
                    wrong.append(f"sashil {verb}: no such verb")
                continue
            for word in words:
                option = re.match(r"\[?(--?[a-z][\w-]*)", word)
                if option and option.group(1) not in options[verb] and option.group(1) not in FOREIGN_OPTIONS:
                    wrong.append(f"sashil {verb} {option.group(1)}")
    assert not wrong, f"{_page_id(page)}: options the parser does not have: {sorted(set(wrong))}"


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_every_option_named_alone_is_some_verbs(page: Path):
    every = set().union(*_verb_options().values()) | FOREIGN_OPTIONS
    alone = [span for span in _CODE_SPAN.findall(_FENCE.sub("", page.read_text(encoding="utf-8")))]
    named = {m.group(1) for span in alone if (m := re.fullmatch(r"(--[a-z][\w-]*)(?:[ =].*)?", span))}
    assert named <= every, f"{_page_id(page)}: options no verb has: {sorted(named - every)}"


@cache
def _controller_keys() -> set[str]:
    from sashil.config.sections import SCHEMA
    from sashil.control.law_registry import describe, find_law, known_laws

    keys = set(SCHEMA["controller"].fields)
    entries = [*known_laws(), find_law("examples/soft_skyhook/soft_skyhook.py:SoftSkyhook")]
    for entry in entries:
        keys |= {p["name"] for p in describe(entry)["parameters"]}
    return keys


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_every_controller_key_is_a_law_parameter_or_a_controller_key(page: Path):
    text = page.read_text(encoding="utf-8")
    named = set(re.findall(r"\bcontroller\.([a-z_][a-z0-9_]*)", text)) - {"md", "py", "x"}
    unknown = named - _controller_keys()
    assert not unknown, f"{_page_id(page)}: controller keys no law and no controller setting has: {sorted(unknown)}"


def test_pages_that_list_exit_statuses_list_every_one():
    from sashil.errors import EXIT_STATUS_CODES

    listing = [p for p in PAGES if "deadline_missed" in p.read_text(encoding="utf-8")]
    assert listing, "some page lists the exit statuses"
    for page in listing:
        text = page.read_text(encoding="utf-8")
        missing = [status for status in EXIT_STATUS_CODES if not re.search(rf"\b{status}\b", text)]
        assert not missing, f"{_page_id(page)}: leaves out the exit statuses {missing}"


def test_the_readme_names_every_exit_code():
    from sashil.errors import EXIT_STATUS_CODES, ConfigError

    sentence = re.search(r"Exit codes: (.*?)\.\s*\n\n", (ROOT / "README.md").read_text(encoding="utf-8"), re.S)
    assert sentence, "README.md: an 'Exit codes: ...' sentence"
    named = {int(code) for code in re.findall(r"(\d+) [a-z]", sentence.group(1))}
    assert named == {*EXIT_STATUS_CODES.values(), ConfigError.exit_code}


_CITED = re.compile(r"^(?:\.\./)*((?:configs|tools|tests|drivers|src|examples)/[\w./-]+|[A-Z][A-Z_]+\.md)$")


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_every_cited_file_exists(page: Path):
    text = page.read_text(encoding="utf-8")
    cited = {span.split()[0] for span in _CODE_SPAN.findall(text) if span.split()}
    cited |= set(re.findall(r"\b(?:configs|tools)/[\w-]+\.(?:yaml|py)\b", text))
    cited |= set(re.findall(r"\b[A-Z][A-Z_]+\.md\b", text))
    paths = {m.group(1).rstrip(".") for c in cited if (m := _CITED.match(c))}
    missing = sorted(p for p in paths if "*" not in p and "<" not in p and not (ROOT / p).exists())
    assert not missing, f"{_page_id(page)}: cites files that do not exist: {missing}"


def test_the_protocol_version_is_the_codes():
    from sashil.drivers.messages import PROTOCOL_VERSION

    for page in PAGES:
        text = _prose(page.read_text(encoding="utf-8"))
        for version in re.findall(r"protocol (?:v|version )(\d+)", text):
            assert int(version) == PROTOCOL_VERSION, f"{_page_id(page)}: protocol version {version}"


def test_the_udev_rule_on_the_rtdac_page_is_the_codes():
    from sashil.drivers.rtdac_usb import UDEV_FILE, UDEV_RULE

    page = (DOCS / "reference" / "backends" / "rtdac.md").read_text(encoding="utf-8")
    assert f"echo '{UDEV_RULE}' | sudo tee {UDEV_FILE}" in page


def test_the_ci_how_to_shows_the_examples_own_test():
    page = (DOCS / "how-to" / "test-your-law-in-ci.md").read_text(encoding="utf-8")
    test = (ROOT / "examples" / "soft_skyhook" / "tests" / "test_soft_skyhook.py").read_text(encoding="utf-8")
    assert any(block.body == test for block in fenced_blocks(page))


#: the words of a changelog: a page says what the code does, not what it did before
_CHANGELOG = re.compile(
    r"\b(now|no longer|as before|anymore|previously|newly|used to|has been (?:added|removed|renamed))\b", re.I
)


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_pages_speak_in_the_present_not_a_changelog(page: Path):
    text = _prose(page.read_text(encoding="utf-8")).replace("from now on", "")
    found = [
        f"line {text.count(chr(10), 0, m.start()) + 1}: {m.group(0)!r}"
        for m in _CHANGELOG.finditer(text)
        # "Citing ... cite the software" and the like are fine; only the changelog words count
    ]
    assert not found, f"{_page_id(page)}: a changelog's words: {found}"


def _links(page: Path) -> set[Path]:
    text = _FENCE.sub("", page.read_text(encoding="utf-8"))
    out = set()
    for target in re.findall(r"\]\(([^)#\s]+\.md)(?:#[^)]*)?\)", text):
        linked = (page.parent / target).resolve()
        if linked.is_relative_to(DOCS) and linked.exists():
            out.add(linked)
    return out


def test_every_page_is_within_two_clicks_of_the_home_page():
    home = (DOCS / "index.md").resolve()
    one = _links(home)
    two = set().union(*(_links(page) for page in one))
    reached = {home} | one | two
    pages = {p.resolve() for p in DOCS.rglob("*.md")}
    assert not pages - reached, f"pages more than two clicks from the home page: {sorted(pages - reached)}"


#: pages about hardware no one has run sashil on yet
HARDWARE_PAGES = [
    "reference/backends/serial.md",
    "reference/backends/can.md",
    "reference/backends/rtdac.md",
    "how-to/own-board.md",
    "how-to/heartbeat-relay.md",
    "tutorials/inteco-first-hour.md",
]


@pytest.mark.parametrize("page", HARDWARE_PAGES)
def test_hardware_pages_say_at_the_top_they_have_not_run_on_a_board(page: str):
    top = "\n".join((DOCS / page).read_text(encoding="utf-8").splitlines()[:12])
    assert "Not yet run on a real board" in top, f"docs/{page}: 'Not yet run on a real board' at its top"


def test_the_first_hour_leaves_its_transcripts_to_the_tool():
    text = (DOCS / "tutorials" / "inteco-first-hour.md").read_text(encoding="utf-8")
    for name in ("doctor", "walk"):
        between = re.search(rf"<!-- transcript: {name} -->\n(.*?)<!-- /transcript -->", text, re.S)
        assert between, f"the {name} transcript's markers"
        blocks = fenced_blocks(between.group(1))
        assert len(blocks) == 1 and blocks[0].info == "text", f"one text block between the {name} markers"


#: the glossary's terms as pages write them, and each one's anchor in docs/reference/glossary.md
GLOSSARY_TERMS = {
    r"feasible band": "feasible-band",
    r"device pacing": "device-pacing",
    r"NRMSE": "nrmse",
    r"z_u": "the-rigs-symbols",
    r"seed 00[01]": "seed-001-seed-000",
    r"share of the bound": "share-of-the-bound",
    r"link gap": "link-gap",
    r"\bADD\b": "add",
    r"\bPDD\b": "pdd",
    r"T̂|T\*": "t-star-t-hat",
}


def _written_by_hand(page: Path) -> bool:
    head = page.read_text(encoding="utf-8")[:100]
    return not head.startswith(("<!-- generated by", "<!-- written by"))


@pytest.mark.parametrize(
    "page",
    [p for p in MANUAL if _written_by_hand(p) and p.name != "glossary.md"],
    ids=_page_id,
)
def test_a_page_links_each_glossary_term_it_uses(page: Path):
    text = page.read_text(encoding="utf-8")
    prose = "\n".join(line for line in _prose(text).splitlines() if not line.startswith(("#", "|", "![", "*")))
    glossary = (DOCS / "reference" / "glossary.md").read_text(encoding="utf-8")
    unlinked = []
    for term, anchor in GLOSSARY_TERMS.items():
        assert f"{{#{anchor}}}" in glossary or anchor == "the-rigs-symbols", f"glossary: no anchor {anchor}"
        if re.search(term, prose) and f"glossary.md#{anchor})" not in text:
            unlinked.append(term)
    assert not unlinked, f"{_page_id(page)}: uses glossary terms it does not link: {unlinked}"
