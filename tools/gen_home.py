"""Write the manual's home page, docs/index.md, from README.md.

The README is the project's front page on GitHub and the manual's home page in the site: one text,
so the two cannot drift. The links into docs/ become links relative to docs/; the README's Markdown
is otherwise copied as it is. tests/test_docs.py fails while docs/index.md differs from what this
writes.

    python tools/gen_home.py
    python tools/gen_home.py --quick   # print the page, write nothing
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
HOME = ROOT / "docs" / "index.md"

HEADER = "<!-- written by tools/gen_home.py from README.md: edit the README, then run the tool -->\n\n"


def home_page(readme: str) -> str:
    """The home page's Markdown for the README's text: its ``](docs/...)`` links relative to docs/."""
    return HEADER + re.sub(r"\]\(docs/", "](", readme)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="print the page, write nothing")
    page = home_page(README.read_text(encoding="utf-8"))
    if parser.parse_args().quick:
        print(page)
        return
    HOME.write_text(page, encoding="utf-8")
    print(f"wrote {HOME.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
