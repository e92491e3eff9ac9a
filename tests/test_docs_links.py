"""Every relative link in README.md and docs/*.md points to a file that exists, and
every #anchor to a heading of that file (GitHub's heading slugs)."""
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces -> '-'."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set:
    out, inside = set(), False
    for line in path.read_text().splitlines():
        if line.lstrip().startswith("```"):
            inside = not inside
        elif not inside and line.startswith("#"):
            out.add(slug(line.lstrip("#")))
    return out


def links(path: Path) -> list:
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)   # not inside code blocks
    return [m.group(1) for m in LINK.finditer(text)]


def test_slug_matches_github():
    assert slug(" `summary.json`") == "summaryjson"
    assert slug("Rigid objects and real tosses: `evaluate`") == "rigid-objects-and-real-tosses-evaluate"
    assert slug("The gradient map (Fig. 3)") == "the-gradient-map-fig-3"


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_relative_links_resolve(page):
    bad = []
    for target in links(page):
        if re.match(r"^[a-z]+:", target):          # http:, https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        dest = (page.parent / file).resolve() if file else page
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading with that anchor")
    assert not bad, f"{page.name}: " + "; ".join(bad)
