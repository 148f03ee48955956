"""Every relative link in the project's Markdown resolves: the file exists, and where the link
names a heading (``page.md#anchor``), that page has the heading. Every repository file the
text names in inline code (``docs/data/x.json``) exists.

Links and headings are read with markdown-it (CommonMark), so links inside code are not
links; a heading's anchor is made as GitHub makes it (the heading's text, lower case,
punctuation other than ``-`` and ``_`` dropped, spaces turned into ``-``, a repeated
anchor numbered ``-1``, ``-2``, ...).
"""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path
from urllib.parse import unquote

import pytest

markdown_it = pytest.importorskip("markdown_it")

REPO = Path(__file__).resolve().parents[1]
PAGES = sorted(
    p
    for p in [
        REPO / "README.md",
        *REPO.glob("docs/**/*.md"),
        *REPO.glob("checkpoints/*.md"),
        *REPO.glob("experiments/*.md"),
    ]
    if p.is_file()
)


def _slug(text: str) -> str:
    text = text.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def test_slug_is_githubs() -> None:
    assert _slug("`local` from the roadmap expert, then PPO (2026-12-05)") == (
        "local-from-the-roadmap-expert-then-ppo-2026-12-05"
    )
    assert _slug("64 draws per escape step (2026-12-05, late): for Slot, not for 3D-Boxes") == (
        "64-draws-per-escape-step-2026-12-05-late-for-slot-not-for-3d-boxes"
    )
    assert _slug("How the shipped policy was trained") == "how-the-shipped-policy-was-trained"


def _tokens(page: Path) -> list:
    return markdown_it.MarkdownIt("commonmark").parse(page.read_text(encoding="utf-8"))


@cache
def anchors(page: Path) -> frozenset[str]:
    tokens = _tokens(page)
    seen: dict[str, int] = {}
    out = set()
    for i, tok in enumerate(tokens):
        if tok.type != "heading_open":
            continue
        inline = tokens[i + 1]
        text = "".join(c.content for c in inline.children or [] if c.type in ("text", "code_inline"))
        base = _slug(text)
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return frozenset(out)


def links(page: Path) -> list[str]:
    out = []
    for tok in _tokens(page):
        for child in tok.children or []:
            if child.type == "link_open":
                out.append(str(child.attrs["href"]))
            elif child.type == "image":
                out.append(str(child.attrs["src"]))
    return out


def test_anchors_of_a_page_with_repeated_headings(tmp_path: Path) -> None:
    page = tmp_path / "p.md"
    page.write_text("# Title\n\n## Usage\n\n## Usage\n\n```\n## not a heading\n```\n")
    assert anchors(page) == {"title", "usage", "usage-1"}


def broken_links(page: Path) -> list[str]:
    broken = []
    for href in links(page):
        if re.match(r"^[a-z][a-z0-9+.-]*:", href):  # http:, mailto:, ...
            continue
        path, _, anchor = href.partition("#")
        target = (page.parent / unquote(path)).resolve() if path else page
        if not target.exists():
            broken.append(f"{href}: no such file")
        elif anchor and target.suffix == ".md" and unquote(anchor) not in anchors(target):
            broken.append(f"{href}: no such heading in {target.name}")
    return broken


def test_broken_links_are_found(tmp_path: Path) -> None:
    (tmp_path / "a.md").write_text("# A page\n\nSee [b](b.md#there), [c](c.md), [self](#a-page), `[x](nowhere.md)`.\n")
    (tmp_path / "b.md").write_text("# Here\n")
    found = broken_links(tmp_path / "a.md")
    assert [f.split(":")[0] for f in found] == ["b.md#there", "c.md"]


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(REPO)) for p in PAGES])
def test_links_resolve(page: Path) -> None:
    assert broken_links(page) == []


REPO_PATH = re.compile(r"^(src|docs|checkpoints|scripts|benchmarks|experiments|examples|tests)/[\w./-]*$")
#: options whose value is a file a command writes, not one the repository has
WRITES = {"-o", "--out", "--json", "--figure", "--plot", "--run-dir", "--runs"}


def missing_files(page: Path) -> list[str]:
    """Repository paths the page names in inline code (``docs/data/x.json``) that do not
    exist; a path written by a command (``-o docs/img/x``) or with a pattern in it is not
    checked."""
    missing = []
    for tok in _tokens(page):
        for child in tok.children or []:
            if child.type != "code_inline":
                continue
            words = child.content.split()
            for i, word in enumerate(words):
                word = word.strip("(),;:'\"")
                if i and words[i - 1] in WRITES:
                    continue
                if REPO_PATH.match(word) and not any(c in word for c in "{<*") and not (REPO / word).exists():
                    missing.append(word)
    return missing


def test_missing_files_are_found(tmp_path: Path) -> None:
    page = tmp_path / "p.md"
    page.write_text("`docs/results/README.md`, `docs/no_such.json`, `cmd -o docs/img/new`, `docs/{a,b}.csv`\n")
    assert missing_files(page) == ["docs/no_such.json"]


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(REPO)) for p in PAGES])
def test_named_files_exist(page: Path) -> None:
    assert missing_files(page) == []


def test_docs_the_package_names_exist() -> None:
    """The Markdown pages the package's help texts and docstrings point users to exist (a
    path in a git revision, ``REV:docs/x.md``, is history, not a pointer)."""
    named = {
        m.group(0)
        for src in (REPO / "src" / "pointplan").rglob("*.py")
        for m in re.finditer(r"(?<![:\w/])docs/[\w/.-]+\.md", src.read_text(encoding="utf-8"))
    }
    assert len(named) > 3
    assert sorted(n for n in named if not (REPO / n).exists()) == []
