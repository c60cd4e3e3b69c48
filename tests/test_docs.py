"""The README and docs/ hold together: the README stays a short guide with a working table of
contents, every relative link and picture resolves to a file of the repository (and a link's
#anchor to a heading of its target), and the equations map names functions that exist."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
CHECKED = [README, *DOCS, ROOT / "bench" / "RESULTS.md", ROOT / "sample_data" / "README.md"]

README_MAX_LINES = 450
FENCE = re.compile(r"^(```|~~~).*?^\1[^\n]*$", re.M | re.S)
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(([^()\s]+)\)")
HEADING = re.compile(r"^(#{1,6})\s+(.+?)\s*#*\s*$", re.M)


def prose(text: str) -> str:
    """``text`` without its fenced code blocks (their lines are not markdown)."""
    return FENCE.sub("", text)


def slug(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to hyphens."""
    s = heading.strip().lower()
    s = re.sub(r"[^\w\- ]", "", s)
    return s.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for m in HEADING.finditer(prose(path.read_text(encoding="utf-8"))):
        base = slug(m.group(2))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(path: Path) -> list[str]:
    return [m.group(1) for m in LINK.finditer(prose(path.read_text(encoding="utf-8")))]


def test_slug_matches_the_anchors_github_makes():
    assert slug("### `draw --box`: how the masks were chosen".lstrip("# ")) == "draw---box-how-the-masks-were-chosen"
    assert slug("Hand-set dynamics (AC §9.6)") == "hand-set-dynamics-ac-96"
    assert slug("draw — make a template") == "draw--make-a-template"


def test_readme_is_short():
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= README_MAX_LINES, f"README.md has {n} lines; move detail to docs/ (at most {README_MAX_LINES})"


def test_readme_has_a_table_of_contents_whose_anchors_exist():
    text = prose(README.read_text(encoding="utf-8"))
    m = re.search(r"^## Contents\n(.*?)(?=^## )", text, re.M | re.S)
    assert m, "README.md has no '## Contents' section"
    toc = re.findall(r"\]\(#([^)]+)\)", m.group(1))
    assert len(toc) >= 8
    missing = [a for a in toc if a not in anchors(README)]
    assert not missing, f"table of contents points to no heading: {missing}"
    # and every second-level section is listed
    sections = [slug(h) for h in re.findall(r"^## (.+)$", text, re.M) if h != "Contents"]
    assert [s for s in sections if s not in toc] == []


@pytest.mark.parametrize("doc", CHECKED, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(doc: Path):
    bad = []
    for target in links(doc):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # https:, mailto: ...
            continue
        path, _, anchor = target.partition("#")
        dest = (doc.parent / path).resolve() if path else doc
        if not dest.exists():
            bad.append(f"{target}: no such file")
            continue
        try:
            dest.relative_to(ROOT)
        except ValueError:
            bad.append(f"{target}: outside the repository")
            continue
        if anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading with that anchor in {dest.relative_to(ROOT)}")
    assert not bad, f"{doc.relative_to(ROOT)}: " + "; ".join(bad)


def test_the_docs_are_linked_from_the_readme():
    linked = {(README.parent / t.partition("#")[0]).resolve() for t in links(README)}
    assert [d.name for d in DOCS if d.resolve() not in linked] == []


def test_the_equations_map_names_functions_that_exist():
    text = (ROOT / "docs" / "design.md").read_text(encoding="utf-8")
    table = text[text.index("## Where the equations are"):]
    table = table[: table.index("\n## ")]
    names = sorted(set(re.findall(r"`((?:shapes|dynamics|observe|trackers|io|run)\.[\w.]+)`", table)))
    assert len(names) > 30
    missing = []
    for name in names:
        parts = name.split(".")
        for k in range(len(parts), 0, -1):  # the longest importable module, then attributes
            try:
                obj = importlib.import_module("trackcli." + ".".join(parts[:k]))
            except ImportError:
                continue
            try:
                for attr in parts[k:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                missing.append(name)
            break
        else:
            missing.append(name)
    assert not missing, f"docs/design.md names what the code does not have: {missing}"
