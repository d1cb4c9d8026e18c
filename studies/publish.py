"""Output of the studies: CSV / JSON / Markdown / PNG writers, and ``--docs`` publishing (each
study's charts to ``docs/images/``, its full report to ``docs/study_<name>.md`` and its block in
``docs/results.md`` between its ``<!-- BEGIN study:NAME -->`` / ``<!-- END study:NAME -->``
markers)."""
from __future__ import annotations

import csv
import json
import os
import shlex
import shutil
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def write_csv(path, rows: list[dict]):
    path = Path(path)
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def write_json(path, obj):
    Path(path).write_text(json.dumps(obj, indent=1, default=_json_default))


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(type(o))


def md_table(rows: list[list], header: list[str]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(" --- " for _ in header) + "|"]
    for r in rows:
        out.append("| " + " | ".join(_fmt(x) for x in r) + " |")
    return "\n".join(out) + "\n"


def _fmt(x):
    if isinstance(x, float):
        if not np.isfinite(x):
            return "–"
        a = abs(x)
        if a != 0 and (a < 1e-3 or a >= 1e5):
            return f"{x:.2e}"
        return f"{x:.3g}" if a < 100 else f"{x:.0f}"
    return str(x)


def save_png(path, img, exposure=1.0):
    """sRGB PNG of a linear image (exposure stated by the caller)."""
    import matplotlib.image as mpimg

    x = np.clip(np.asarray(img, np.float64) * exposure, 0, None)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    mpimg.imsave(str(path), np.clip(srgb, 0, 1))


def save_figure(fig, path, dpi: int = 72):
    """Save a matplotlib figure as an RGB PNG (the opaque alpha left out: about 10 % smaller)
    and close it; 72 dpi gives the contact sheets about 100 px per 256 px render."""
    import matplotlib.pyplot as plt
    from PIL import Image     # matplotlib's own dependency

    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    Image.open(path).convert("RGB").save(path, optimize=True)


def machine_info() -> dict:
    import platform

    return {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
            "time": time.strftime("%Y-%m-%d %H:%M:%S")}


# --------------------------------------------------------------------------------------------
# Publishing (``--docs``): docs/images/study_*.png, docs/study_<name>.md and the study's block in
# docs/results.md
RESULTS_PAGE = Path("docs") / "results.md"
DOCS_HELP = ("also write docs/images/study_*.png, docs/study_<name>.md and the study's block in "
             "docs/results.md (between its BEGIN/END study markers)")


def add_docs_arguments(parser):
    """``--docs`` (and ``--docs-root``, the folder holding docs/) for a study's CLI."""
    parser.add_argument("--docs", action="store_true", help=DOCS_HELP)
    parser.add_argument("--docs-root", default=str(ROOT),
                        help="folder holding docs/ (docs/results.md with the studies' markers, docs/images/, "
                             "docs/study_<name>.md); default: the repository root")


def publish_run(args, res: dict, block_table, script, argv, docs: dict):
    """A study's ``--docs`` step after its run: :func:`publish_docs` of the run ``res`` (its
    ``markdown`` and ``meta``) with ``block_table(res)``, the command rebuilt from ``script`` and
    ``argv``, and the study's ``docs`` dict (name, title, charts); nothing without ``--docs``."""
    if not args.docs:
        return None
    pub = publish_docs(out=args.out, summary_md=res["markdown"], meta=res["meta"], block_table=block_table(res),
                       command=command_line(script, argv), docs_root=args.docs_root, **docs)
    n = len(pub["images"])
    print(f"published {pub['doc']}, {n} chart{'s' if n != 1 else ''} and the block in {pub['results']}")
    return pub


def command_line(script, argv=None) -> str:
    """The command that ran a study, as ``python -m studies.<name> ARGS`` (``script``: the study's
    file, e.g. its ``__file__`` or ``sys.argv[0]``; ``argv``: the arguments, default
    ``sys.argv[1:]``). A script outside the repository is given as ``python PATH ARGS``."""
    script = Path(script).resolve()
    args = sys.argv[1:] if argv is None else list(argv)
    try:
        rel = script.relative_to(ROOT)
    except ValueError:
        return shlex.join(["python", str(script), *map(str, args)])
    return shlex.join(["python", "-m", ".".join(rel.with_suffix("").parts), *map(str, args)])


def block_markers(name: str) -> tuple[str, str]:
    """The study's BEGIN / END markers in docs/results.md."""
    return f"<!-- BEGIN study:{name} -->", f"<!-- END study:{name} -->"


def replace_block(text: str, name: str, block: str, where: str = str(RESULTS_PAGE)) -> str:
    """``text`` with what lies between the study's two markers replaced by ``block`` (the markers
    and everything outside them unchanged). A marker that is missing, repeated or out of order is a
    ``ValueError`` naming it (and ``where``, the file the text comes from)."""
    begin, end = block_markers(name)
    for m in (begin, end):
        n = text.count(m)
        if n != 1:
            raise ValueError(f"{where}: marker {m!r} " + ("not found" if n == 0 else f"found {n} times")
                             + f": add the pair {begin!r} ... {end!r} where the study's block goes")
    i = text.index(begin) + len(begin)
    j = text.index(end)
    if j < i:
        raise ValueError(f"{where}: marker {end!r} comes before {begin!r}")
    return text[:i] + "\n" + block.strip("\n") + "\n" + text[j:]


def _run_line(meta: dict) -> tuple[str, str]:
    """(long, short) description of the run: wall seconds and machine."""
    wall = meta.get("wall_seconds")
    m = meta.get("machine") or machine_info()
    w = f"{wall:.0f} s" if isinstance(wall, (int, float)) else "–"
    return (f"Wall time: {w} (the study's run, charts excluded). Machine: {m.get('cpus')} CPUs, "
            f"{m.get('platform')}, Python {m.get('python')}; finished {m.get('time')}.",
            f"{w} on {m.get('cpus')} CPUs, {str(m.get('time', ''))[:10]}")


def page_head(title: str, command: str, about: str = "") -> str:
    """The opening of a study's report ``docs/study_<name>.md``: its title, ``about`` (what the
    study measures, one paragraph; none when empty) and how to run it (``command``)."""
    run = (f"Command: `{command}` (with `--docs` it regenerates this page, its charts and its block "
           "in [results.md](results.md); edits here are overwritten).")
    return "\n".join([f"# {title}", "", *([about.strip(), ""] if about.strip() else []), run, ""])


def publish_docs(name: str, title: str, out, summary_md: str, meta: dict, charts: dict,
                 block_table: str, command: str | None = None, docs_root=None,
                 block_charts=None, about: str = "") -> dict:
    """Publish one study's run (its ``--docs``).

    ``name``: the study's key (markers ``<!-- BEGIN study:<name> -->`` /
    ``<!-- END study:<name> -->`` in ``docs/results.md``, report ``docs/study_<name>.md``);
    ``out``: the folder the run wrote its charts to; ``charts``: {file in ``out``: name under
    ``docs/images/``}, in display order; ``block_charts``: the subset (of those names) shown in
    the results page's block (default: all); ``summary_md``: the study's full markdown summary;
    ``meta``: its meta (``wall_seconds``, ``machine``); ``block_table``: the compact markdown of
    key numbers for the block; ``command``: the command line (default: rebuilt from
    ``sys.argv``); ``docs_root``: folder holding ``docs/`` (default: the repository root);
    ``about``: what the study measures, the report's first paragraph (:func:`page_head`).

    The block's links are relative to ``docs/`` (``images/<chart>``, ``study_<name>.md``).
    Everything is checked (charts present, ``docs/results.md`` present with the study's markers
    once each) before anything is written, so a failure leaves the docs as they were. Returns
    the paths written (``images``, ``doc``, ``results``) and the ``block``."""
    root = Path(docs_root) if docs_root is not None else ROOT
    if meta.get("preset") == "smoke" and root.resolve() == ROOT.resolve():
        raise ValueError(f"study {name}: a --smoke run would overwrite the repository's docs (docs/results.md "
                         "block, docs/study_*.md); give --docs-root another folder")
    out = Path(out)
    command = command or command_line(sys.argv[0])
    results = root / RESULTS_PAGE
    missing = [str(out / s) for s in charts if not (out / s).is_file()]
    if missing:
        raise FileNotFoundError(f"study {name}: chart(s) not written by this run: {', '.join(missing)}")
    if not results.is_file():
        raise FileNotFoundError(f"no {RESULTS_PAGE.as_posix()} in {root}")
    with open(results, encoding="utf-8", newline="") as f:
        text = f.read()
    long_run, short_run = _run_line(meta)
    shown = [d for d in charts.values() if block_charts is None or d in block_charts]
    block = "\n".join([f"**{title}** · `{command}` ({short_run})", "",
                       *[f"![{Path(d).stem}](images/{d})" for d in shown], "",
                       block_table.strip("\n"), "",
                       f"Generated by `--docs`; the full report with every table: "
                       f"[study_{name}.md](study_{name}.md)."])
    new_text = replace_block(text, name, block, where=str(results))
    images = root / "docs" / "images"
    images.mkdir(parents=True, exist_ok=True)
    written = []
    for src, dst in charts.items():
        shutil.copyfile(out / src, images / dst)
        written.append(images / dst)
    doc = root / "docs" / f"study_{name}.md"
    doc.write_text("\n".join([page_head(title, command, about), long_run, "",
                              *[f"![{Path(d).stem}](images/{d})\n" for d in charts.values()],
                              summary_md.strip("\n"), ""]), encoding="utf-8")
    if new_text != text:
        with open(results, "w", encoding="utf-8", newline="") as f:
            f.write(new_text)
    return dict(images=written, doc=doc, results=results, block=block)
