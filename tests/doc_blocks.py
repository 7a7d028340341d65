"""The fenced code blocks of a Markdown page, for the tests that run the README's and the manual's examples.

A block is a fence (three backticks and an info string such as ``sh``, ``python``, ``text``,
``yaml``), possibly indented inside a list item. A block that cannot run here (it needs a board, a
CAN interface, a PREEMPT_RT kernel) is preceded by a line in italics that says what it needs, for
the reader and for the tests::

    *Needs a board on /dev/ttyACM0.*
"""

from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass
from pathlib import Path

_FENCE = re.compile(r"^(?P<indent>[ ]*)```(?P<info>[^\n`]*)\n(?P<body>.*?)^(?P=indent)```[ ]*$", re.M | re.S)
_NEEDS = re.compile(r"^\s*\*Needs (?P<what>[^*]+?)\.?\*\s*$")


@dataclass(frozen=True)
class Block:
    info: str  # the fence's info string: "sh", "python", "text", "yaml", ...
    body: str  # the code, dedented
    needs: str  # what it needs to run ("" when it runs anywhere)
    line: int  # the fence's line in the page, from 1


def fenced_blocks(text: str) -> list[Block]:
    """Every fenced block of ``text``, in order."""
    blocks = []
    for match in _FENCE.finditer(text):
        before = text[: match.start()].rstrip("\n").rsplit("\n", 1)[-1]
        needs = _NEEDS.search(before)
        blocks.append(
            Block(
                info=match.group("info").strip(),
                body=textwrap.dedent(match.group("body")),
                needs=needs.group("what") if needs else "",
                line=text.count("\n", 0, match.start()) + 1,
            )
        )
    return blocks


def example(page: str, info: str, containing: str) -> str:
    """The one block of ``info`` in ``docs/<page>`` (or ``README.md``) whose code contains ``containing``."""
    root = Path(__file__).resolve().parents[1]
    path = root / page if page == "README.md" else root / "docs" / page
    found = [b.body for b in fenced_blocks(path.read_text(encoding="utf-8")) if b.info == info and containing in b.body]
    assert len(found) == 1, f"{page}: expected one {info} block with {containing!r}, found {len(found)}"
    return found[0]


def section(text: str, heading: str) -> str:
    """The text under the level-2 ``heading`` (``## Quick start``), up to the next level-2 heading."""
    return text.split(f"\n{heading}\n", 1)[1].split("\n## ", 1)[0]
