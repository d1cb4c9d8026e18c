"""The documentation describes the product as it is: architecture.md's registry listing is the
generator's output (``docs/gen_registry.py``), its layout table names every module of ``fit/``
and ``warp_rbrdf/`` and no module that is gone, no page (README.md, docs/*.md) and no comment or
docstring of the code (``fit/``, ``warp_rbrdf/``, ``studies/``, ``benchmarks/``, ``lab/``,
``tools/``) cites an issue number, no page narrates how a number changed between runs, and each
study's report opens with what the study measures and the command that runs it."""
from __future__ import annotations

import ast
import importlib.util
import io
import re
import tokenize
from pathlib import Path

import pytest

from conftest import ROOT

DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]

#: the folders whose comments and docstrings are documentation too
CODE_FOLDERS = ("fit", "warp_rbrdf", "studies", "benchmarks", "lab", "tools")
#: an issue cited by number: "issue 21", "issues 20-22", "Issue #7", "#41". Not a Markdown
#: heading (``## x``), an anchor (``page.md#3-d-fits``, ``(#3-d-fits)``), an HTML entity
#: (``&#8594;``) or a colour: ``#`` and exactly 3, 6 or 8 hex digits (``#000``, ``#1f77b4``) is
#: read as a colour, so an issue number of that form is not caught.
ISSUE_NUMBER = re.compile(r"\bissues?\s*#?\s*\d+"
                          r"|(?<![\w&/#])#(?!(?:[0-9a-f]{3}|[0-9a-f]{6}|[0-9a-f]{8})\b)\d+\b(?!-)",
                          re.IGNORECASE)
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


def code_prose(path: Path) -> list[tuple[int, str]]:
    """The documentation of a Python file as ``(line, text)``: every comment (without its leading
    ``#`` characters) and every string that stands as a statement (module, class and function
    docstrings, attribute docstrings), one entry per line. Code, string values included, is
    left out."""
    src = path.read_text(encoding="utf-8")
    out = [(t.start[0], t.string.lstrip("#"))
           for t in tokenize.generate_tokens(io.StringIO(src).readline) if t.type == tokenize.COMMENT]
    for node in ast.walk(ast.parse(src, filename=str(path))):
        if (isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
                and isinstance(node.value.value, str)):
            out += [(node.lineno + i, line) for i, line in enumerate(node.value.value.splitlines())]
    return sorted(out)


def code_hits(pattern: re.Pattern, files) -> list[str]:
    """``path:line: match`` for every match of ``pattern`` in the comments and docstrings of
    ``files``."""
    hits = []
    for path in files:
        rel = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
        hits += [f"{rel}:{n}: {m.group(0)!r}" for n, text in code_prose(path) for m in pattern.finditer(text)]
    return hits


def _code_files() -> list[Path]:
    return sorted(p for folder in CODE_FOLDERS for p in (ROOT / folder).rglob("*.py")
                  if "__pycache__" not in p.parts)


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


def test_no_comment_or_docstring_cites_an_issue_number():
    """No comment or docstring of the code cites an issue by number."""
    files = _code_files()
    assert len(files) > 100
    hits = code_hits(ISSUE_NUMBER, files)
    assert not hits, "issue numbers in comments or docstrings:\n" + "\n".join(hits)


def test_code_scan_reads_comments_and_docstrings_only(tmp_path):
    """The scan of the code finds an issue number in a comment, a module, function, class or
    attribute docstring, and not in code: a string value, a colour, a Markdown anchor."""
    f = tmp_path / "m.py"
    f.write_text('"""Module (issue 3)."""\n'
                 "X = 1  # see #12\n"
                 '#: attribute comment, issue #4\n'
                 'Y = 2\n'
                 '"""Attribute docstring: issues 5-6."""\n'
                 "def f():\n"
                 '    """Function, Issue 7."""\n'
                 '    return "issue 8", "#9"\n'
                 "class C:\n"
                 '    """Class: colour #1f77b4, #000, page.md#3-d-fits, (#3-d-fits), ## 10 and #11."""\n',
                 encoding="utf-8")
    found = [h.split(": ", 1)[1] for h in code_hits(ISSUE_NUMBER, [f])]
    assert found == ["'issue 3'", "'#12'", "'issue #4'", "'issues 5'", "'Issue 7'", "'#11'"], found


def test_study_pages_open_with_what_they_measure():
    """Each study's report (``docs/study_<name>.md``) opens as :func:`studies.publish.page_head`
    writes it: the title, the study's ``about`` (what it measures) and the command that ran it,
    then the result. The study modules' ``DOCS`` are read from their source (no import)."""
    from studies.publish import page_head

    studies = {}
    for path in sorted((ROOT / "studies").glob("*.py")):
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] == ["DOCS"]:
                studies[path.stem] = {k.arg: ast.literal_eval(k.value) for k in node.value.keywords}
    assert len(studies) == 6, sorted(studies)
    for module, docs in studies.items():
        about = docs.get("about", "")
        assert about.startswith("What it measures: ") and len(about) > 200, module
        page = (DOCS / f"study_{docs['name']}.md").read_text(encoding="utf-8")
        command = re.search(r"^Command: `([^`]+)`", page, re.MULTILINE)
        assert command and command.group(1).startswith(f"python -m studies.{module} "), module
        assert page.startswith(page_head(docs["title"], command.group(1), about) + "\n"), module
        stale = page.replace(about, about.replace("What it measures: ", "What it measured: "))
        assert not stale.startswith(page_head(docs["title"], command.group(1), about) + "\n")


def test_no_page_narrates_history():
    """No page narrates how a number changed between runs or revisions."""
    hits = _hits(HISTORY)
    assert not hits, "history in the docs (state today's result instead):\n" + "\n".join(hits)


def test_patterns_catch_what_they_name():
    """The two patterns above match the phrasings they exist for and leave ordinary text alone."""
    for text in ("(issue 22)", "issues 20", "Issue #7", "see #41", "since issue 21 the", "#1234"):
        assert ISSUE_NUMBER.search(text), text
    for text in ("rendering.md#materials", "x86-64-v3", "a 5 % issue", "&#8594;", "color #fff",
                 "colour #000000", "`#1f77b4`", "#000", "[3-D fits](#3-d-fits)", "## 2. Heading",
                 "#version 410 core"):
        assert not ISSUE_NUMBER.search(text), text
    for text in ("met on 38 of 40 (was 36, now 38)", "the previous run", "the previous revision",
                 "80f99c3: the revision before this pass", "Cold start, second pass"):
        assert HISTORY.search(text), text
    for text in ("the flag was removed.", "now rendered", "re-run the command to regenerate"):
        assert not HISTORY.search(text), text
