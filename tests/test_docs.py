"""The documentation describes the product as it is: architecture.md's registry listing is the
generator's output (``docs/gen_registry.py``), its layout table names every module of ``fit/``
and ``warp_rbrdf/`` and no module that is gone, and no page (README.md, docs/*.md) cites an
issue number or narrates how a number changed between runs."""
from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from conftest import ROOT

DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]

#: an issue cited by number: "issue 21", "issues 20-22", "Issue #7", "#41"
ISSUE_NUMBER = re.compile(r"\bissues?\s*#?\s*\d+|(?<![\w&/#])#\d+\b", re.IGNORECASE)
#: run-to-run history: "was 36, now 38", "previous run", "before this pass", "baseline commit",
#: "first / second / third pass"
HISTORY = re.compile(r"\bwas\b[^.\n|]{0,60}\bnow\b|\bprevious (?:run|revision)\b"
                     r"|\bbefore this (?:pass|change|revision)\b|\bbaseline commit\b"
                     r"|\b(?:first|second|third) pass\b", re.IGNORECASE)


def _generator():
    spec = importlib.util.spec_from_file_location("gen_registry", DOCS / "gen_registry.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _hits(pattern: re.Pattern, pages=PAGES) -> list[str]:
    hits = []
    for page in pages:
        for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
            hits += [f"{page.relative_to(ROOT)}:{n}: {m.group(0)!r}" for m in pattern.finditer(line)]
    return hits


def test_registry_listing_is_generated():
    """architecture.md holds exactly what ``python docs/gen_registry.py`` prints, and that names
    every material kind, technique and sampler of the registry."""
    from warp_rbrdf import registry

    gen = _generator()
    text = gen.registry_markdown()
    for name in (*registry.MATERIAL_NAMES, *registry.TECHNIQUE_NAMES, *registry.STRATEGY_NAMES):
        assert f"| `{name}` |" in text, name
    page = (DOCS / "architecture.md").read_text(encoding="utf-8")
    assert gen.embedded(page) == text, "stale registry listing: run python docs/gen_registry.py --write"
    assert gen.with_listing(page) == page


def test_stale_registry_listing_is_detected():
    """A page whose block lacks an entry (the ``rgl`` material) is not the generator's output."""
    gen = _generator()
    page = (DOCS / "architecture.md").read_text(encoding="utf-8")
    stale = "\n".join(ln for ln in page.splitlines() if not ln.startswith("| `rgl` | 4 |")) + "\n"
    assert gen.embedded(stale) != gen.registry_markdown()
    assert gen.with_listing(stale) == page
    with pytest.raises(ValueError):
        gen.embedded(page.replace(gen.BEGIN, ""))


def test_layout_lists_every_module():
    """The layout table of architecture.md names every ``.py`` file of ``fit/`` and
    ``warp_rbrdf/`` (as `` `path` ``), and every such path it names exists."""
    page = (DOCS / "architecture.md").read_text(encoding="utf-8")
    files = {p.relative_to(ROOT).as_posix() for pkg in ("fit", "warp_rbrdf")
             for p in (ROOT / pkg).rglob("*.py") if "__pycache__" not in p.parts}
    assert files
    named = set(re.findall(r"`((?:fit|warp_rbrdf)/[\w/]+\.py)`", page))
    assert not sorted(files - named), f"modules missing from architecture.md: {sorted(files - named)}"
    assert not sorted(named - files), f"architecture.md names modules that do not exist: {sorted(named - files)}"


def test_no_page_cites_an_issue_number():
    """No page cites an issue by number (the docs describe the product, not its tickets)."""
    hits = _hits(ISSUE_NUMBER)
    assert not hits, "issue numbers in the docs:\n" + "\n".join(hits)


def test_no_page_narrates_history():
    """No page narrates how a number changed between runs or revisions."""
    hits = _hits(HISTORY)
    assert not hits, "history in the docs (state today's result instead):\n" + "\n".join(hits)


def test_patterns_catch_what_they_name():
    """The two patterns above match the phrasings they exist for and leave ordinary text alone."""
    for text in ("(issue 22)", "issues 20", "Issue #7", "see #41", "since issue 21 the"):
        assert ISSUE_NUMBER.search(text), text
    for text in ("rendering.md#materials", "x86-64-v3", "a 5 % issue", "&#8594;", "color #fff"):
        assert not ISSUE_NUMBER.search(text), text
    for text in ("met on 38 of 40 (was 36, now 38)", "the previous run", "the previous revision",
                 "80f99c3: the revision before this pass", "Cold start, second pass"):
        assert HISTORY.search(text), text
    for text in ("the flag was removed.", "now rendered", "re-run the command to regenerate"):
        assert not HISTORY.search(text), text
