"""The database report of a batch: one row per material and tolerance (:class:`BatchReport`),
written as CSV and Markdown, and the chart of coefficients against tolerance
(:func:`plot_coefficients`).

Columns (:data:`COLUMNS`; units in the names): ``material``, ``tol`` (relative tolerance),
``status`` (``done`` / ``skipped`` (done by an earlier run) / ``failed`` / ``missing`` (not done;
``--report-only``)), ``coefs`` (total)
and ``coefs_r`` / ``coefs_g`` / ``coefs_b`` (per channel, summed over the theta_d / theta_h
pieces), ``core_deg`` (theta_d of the guaranteed core, degrees), ``guaranteed`` (every
cluster of the core inside its interval, Q > 0 certified), ``band`` (grazing band: ``met``,
``best effort`` or ``none``), ``core_max_err_pct`` / ``core_rms_err_pct`` (relative error on
the core's clusters where the relative tolerance applies, percent), ``fit_s`` (the BRDF fit's
own seconds, as its manifest records them), ``sampler`` (the fit's own inverse CDFs stored in
its file, as ``rbrdf-fit brdf`` stores them: ``rational 29/32`` rows, ``table``, ``none``;
empty with ``--no-sampler``), ``cdf_rows_rational`` (view rows of the inverse
CDFs sampled with the rational pieces, e.g. ``32/32``), ``cdf_fallback``,
``cdf_var_ratio_med`` / ``cdf_var_ratio_max`` (variance per sample of the rational sampler /
the tabulated one, over the rational rows: the fitter's measure; the samples/s ratio needs the
renderer, ``benchmarks.bench_samplers``), ``cdf_s`` (seconds), ``error`` (one line).

No pandas needed: :class:`BatchReport` is a list of dicts with :meth:`~BatchReport.to_csv`,
:meth:`~BatchReport.to_markdown`, column access ``report["coefs"]`` and
:meth:`~BatchReport.to_pandas` when pandas is installed.
"""
from __future__ import annotations

import csv
import io
import math

COLUMNS = ("material", "tol", "status", "coefs", "coefs_r", "coefs_g", "coefs_b", "core_deg", "guaranteed", "band",
           "core_max_err_pct", "core_rms_err_pct", "fit_s", "sampler", "cdf_rows_rational", "cdf_fallback",
           "cdf_var_ratio_med", "cdf_var_ratio_max", "cdf_s", "error")

_MD_HEADERS = {"material": "material", "tol": "tol", "status": "status", "coefs": "coefs",
               "coefs_r": "R", "coefs_g": "G", "coefs_b": "B", "core_deg": "core θd°",
               "guaranteed": "guaranteed", "band": "grazing band", "core_max_err_pct": "core max %",
               "core_rms_err_pct": "core RMS %", "fit_s": "fit s", "sampler": "own sampler", "cdf_rows_rational": "CDF rows rational",
               "cdf_fallback": "CDF fallback", "cdf_var_ratio_med": "var. ratio med",
               "cdf_var_ratio_max": "var. ratio max", "cdf_s": "CDF s", "error": "error"}


def _num(x, digits: int):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return None
    return round(float(x), digits)


def _sampler_cell(rec: dict):
    """The ``sampler`` cell of a BRDF record: ``rational 29/32`` (view rows of the fit's own
    inverse CDFs sampled with the rational pieces), ``table``, ``none`` (nothing vouched to
    sample), None when the output stores none (``--no-sampler``)."""
    kind = rec.get("sampler")
    if kind == "rational":
        return f"rational {rec.get('sampler_rows_rational')}/{rec.get('sampler_rows')}"
    return kind


def rows_from_results(results) -> list:
    """Report rows from the task results of :func:`fit.batch.tasks.run_material` (one row per
    material and tolerance; a material without a BRDF record, e.g. ``--no-cdf`` aside, gets
    one row with its error)."""
    rows = []
    for res in results:
        cdf = res.get("cdf") or {}
        cdf_cols = {}
        if cdf and cdf.get("status") not in ("failed", "missing"):
            cdf_cols = {"cdf_rows_rational": f"{cdf.get('rows_rational')}/{cdf.get('rows')}",
                        "cdf_fallback": cdf.get("fallback"),
                        "cdf_var_ratio_med": _num(cdf.get("variance_ratio_median"), 3),
                        "cdf_var_ratio_max": _num(cdf.get("variance_ratio_max"), 3),
                        "cdf_s": _num(cdf.get("cdf_s"), 2)}
        elif cdf.get("status") == "failed":
            cdf_cols = {"cdf_rows_rational": "failed"}
        for rec in res.get("brdf") or [{"status": "failed", "tol": None}]:
            row = dict.fromkeys(COLUMNS)
            row.update(material=res.get("name"), tol=rec.get("tol"), status=rec.get("status"))
            if rec.get("status") not in ("failed", "missing"):
                rgb = rec.get("coefficients_rgb") or [None] * 3
                row.update(coefs=rec.get("coefficients"), coefs_r=rgb[0], coefs_g=rgb[1], coefs_b=rgb[2],
                           core_deg=rec.get("core_theta_d_deg"), guaranteed=rec.get("guaranteed"),
                           band=rec.get("band"),
                           core_max_err_pct=_num(100 * rec["core_max_rel_error"], 2)
                           if rec.get("core_max_rel_error") is not None else None,
                           core_rms_err_pct=_num(100 * rec["core_rms_rel_error"], 2)
                           if rec.get("core_rms_rel_error") is not None else None,
                           fit_s=_num(rec.get("fit_s"), 2), sampler=_sampler_cell(rec))
            row.update(cdf_cols)
            errors = [e for e in (res.get("error"), rec.get("error"), cdf.get("error")) if e]
            if cdf.get("status") == "failed" and rec.get("status") != "failed":
                row["status"] = f"{row['status']} (CDF failed)"
            row["error"] = "; ".join(dict.fromkeys(errors)) or None
            rows.append(row)
    rows.sort(key=lambda r: (str(r["material"]), r["tol"] if r["tol"] is not None else -1.0))
    return rows


class BatchReport:
    """The report table: ``rows`` (dicts with the keys of :data:`COLUMNS`), one per material and
    tolerance, sorted by material then tolerance. ``wall_s``: the batch's wall time (s);
    ``counts``: how many outputs were done, skipped, failed."""

    def __init__(self, rows, wall_s: float | None = None, counts: dict | None = None, workers: int | None = None):
        self.rows = list(rows)
        self.columns = COLUMNS
        self.wall_s = wall_s
        self.counts = dict(counts or {})
        self.workers = workers

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self):
        return iter(self.rows)

    def __getitem__(self, key):
        """``report["coefs"]``: a column as a list; ``report[i]``: row ``i``."""
        if isinstance(key, str):
            if key not in self.columns:
                raise KeyError(key)
            return [r[key] for r in self.rows]
        return self.rows[key]

    def failed(self) -> list:
        """Rows whose BRDF or CDF failed."""
        return [r for r in self.rows if str(r["status"]).startswith("failed") or "failed" in str(r["status"])]

    def to_csv(self, path=None) -> str:
        """The table as CSV (header + one line per row; empty cell = no value); written to
        ``path`` atomically when given. Returns the text."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(self.columns)
        for r in self.rows:
            w.writerow(["" if r[c] is None else r[c] for c in self.columns])
        text = buf.getvalue()
        if path is not None:
            _write_text(path, text)
        return text

    def to_markdown(self, path=None, columns=None) -> str:
        """The table as a Markdown (GitHub) table, ``columns`` (default: all but ``error``,
        which is listed under the table for failed rows); written atomically to ``path`` when
        given. Returns the text."""
        cols = list(columns or [c for c in self.columns if c != "error"])
        lines = ["| " + " | ".join(_MD_HEADERS.get(c, c) for c in cols) + " |",
                 "| " + " | ".join("---" for _ in cols) + " |"]
        for r in self.rows:
            lines.append("| " + " | ".join(_md_cell(r[c]) for c in cols) + " |")
        errs = [r for r in self.rows if r.get("error")]
        if errs:
            lines.append("")
            lines += [f"- {_md_cell(r['material'])} (tol {r['tol']}): {_md_cell(r['error'])}" for r in errs]
        text = "\n".join(lines) + "\n"
        if path is not None:
            _write_text(path, text)
        return text

    def to_pandas(self):
        """A ``pandas.DataFrame`` of the rows (pandas is not a dependency: ImportError without it)."""
        import pandas as pd

        return pd.DataFrame(self.rows, columns=list(self.columns))


def _md_cell(v) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    return str(v).replace("|", "\\|").replace("\n", " ")


def _write_text(path, text: str) -> None:
    from ..outputs import atomic_write

    with atomic_write(path) as f:
        f.write(text)


def plot_coefficients(rows, path, outputs=None, title: str = "coefficients against tolerance") -> bool:
    """PNG chart of every material's total coefficient count against the tolerance (log-log;
    one line per material; failed rows left out; in black the median over the materials fitted
    at every tolerance). Staged
    in ``outputs`` (:class:`fit.outputs.OutputSet`) when given. Returns False (nothing written)
    when no row has a coefficient count."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.ticker import (
        FixedLocator,
        LogLocator,
        NullFormatter,
        ScalarFormatter,
    )

    from ..outputs import save_figure

    by_mat: dict = {}
    for r in rows:
        if r.get("coefs") is None or r.get("tol") is None:
            continue
        by_mat.setdefault(r["material"], []).append((float(r["tol"]), int(r["coefs"]), bool(r.get("guaranteed"))))
    if not by_mat:
        return False
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    tols = sorted({t for pts in by_mat.values() for t, _, _ in pts})
    for name, pts in sorted(by_mat.items()):
        pts.sort()
        t, c, ok = zip(*pts)
        ax.plot(t, c, "-", color="0.7", lw=0.8, zorder=1)
        ax.scatter([x for x, g in zip(t, ok) if g], [y for y, g in zip(c, ok) if g], s=14, color="tab:blue", zorder=2)
        ax.scatter([x for x, g in zip(t, ok) if not g], [y for y, g in zip(c, ok) if not g], s=22, marker="x",
                   color="tab:red", zorder=3)
    # the median over the materials fitted at every tolerance (a median over different sets of
    # materials would mix the materials' differences into the trend)
    full = [pts for pts in by_mat.values() if {t for t, _, _ in pts} == set(tols)]
    if full:
        med = []
        for t in tols:
            cs = sorted(c for pts in full for tt, c, _ in pts if tt == t)
            med.append(cs[len(cs) // 2] if len(cs) % 2 else 0.5 * (cs[len(cs) // 2 - 1] + cs[len(cs) // 2]))
        ax.plot(tols, med, "k-o", lw=2, ms=5, zorder=4,
                label=f"median of the {len(full)} materials fitted at every tolerance")
    ax.scatter([], [], s=14, color="tab:blue", label="core guaranteed")
    ax.scatter([], [], s=22, marker="x", color="tab:red", label="core NOT guaranteed (flagged)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_major_locator(FixedLocator(tols))
    ax.set_xticklabels([f"{t:g}" for t in tols])
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(ScalarFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())
    if len(tols) == 1:
        ax.set_xlim(tols[0] / 1.5, tols[0] * 1.5)
    ax.set_xlabel("relative tolerance")
    ax.set_ylabel("coefficients (R + G + B, all pieces)")
    ax.set_title(f"{title} ({len(by_mat)} materials)")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path, outputs=outputs)
    return True
