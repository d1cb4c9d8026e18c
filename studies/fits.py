"""Rational fits for the studies: find or make a coefficient file for a material and tolerance.

Order of preference (the first that works):

1. ``results/fits/<material>_tol<t>_cli.json`` made earlier by this module with the same
   interval options (:func:`made_with`; one made with others is fitted again and replaced);
2. a shipped ``warp_rbrdf/data/<material>*.json`` whose ``fit.tolerance`` equals ``t`` and
   whose interval options are the requested ones (the shipped fits are made with
   :data:`FIT_OPTIONS`; a flagged one carries its fallback table, :mod:`fit.rational.fallback`),
   or, where no new fit may be made (``allow_fit=False``), one made with other options (source
   ``"shipped (other interval options)"``; none of today's shipped files);
3. the project's fitter, called in this process: :func:`fit.rational.brdf_fit.fit_brdf` on the
   measured file with the options ``rbrdf-fit brdf`` passes by default (:data:`FIT_OPTIONS`),
   saved with :func:`fit.rational.coefficient_file.save`: the same fit and file as
   ``rbrdf-fit brdf FILE --tol t --out X.json``. Its source is labelled ``"cli"`` and its cache
   file ends in ``_cli.json``, so fits cached by earlier runs are reused. A fit has no time
   limit (no child process, no timeout): it runs to its end, and the fit study reports its
   seconds;
4. only with ``allow_direct=True`` (the fit study's ``--direct-fallback``): a stand-in made here
   with :class:`fit.rational.fitter.IntervalRationalFitter` on the median projection (one function per
   channel over (sqrt theta_h, theta_d), theta_d <= 80 deg, intervals ``y +- max(t |y|, floor)``).
   It is labelled ``source = "direct"`` everywhere it is reported; it is not the shipped fitter.

A fit whose guaranteed core misses the tolerance (flagged by the fitter) is written to the cache
like any other but refused, with :meth:`fit.rational.brdf_fit.BRDFFit.summary` as the reason,
unless the caller allows it (``allow_infeasible``).

Returns ``(model, info)``; ``model`` is ``None`` (and ``info["error"]`` says why) when nothing
works.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from fit.rational.settings import BRDFFitSettings
from studies import common as C

FIT_DIR = C.ROOT / "results" / "fits"

#: The settings the studies fit with: :class:`fit.rational.settings.BRDFFitSettings`'s
#: defaults, which are ``rbrdf-fit brdf``'s (``fit/cli/brdf.py`` reads them from there); the
#: tolerance is the study's.
FIT_SETTINGS = BRDFFitSettings()
#: :data:`FIT_SETTINGS` without the tolerance, as a dict (fit_brdf's keyword arguments).
FIT_OPTIONS = {k: v for k, v in FIT_SETTINGS.get_params().items() if k != "tol"}


def brdf_fit_available() -> tuple[bool, str]:
    """Whether the project's fitter (``fit.rational.brdf_fit``) imports, and how it is called."""
    try:
        import fit.rational.brdf_fit  # noqa: F401
    except Exception as e:  # noqa: BLE001
        return False, f"fit.rational.brdf_fit not importable ({type(e).__name__}: {e})"
    return True, "fit.rational.brdf_fit.fit_brdf with rbrdf-fit brdf's defaults"


def _tag(tol: float) -> str:
    return f"{tol:g}".replace(".", "p")


#: The options a coefficient file records in its ``fit`` block (``fit.rational.brdf_model``)
#: that must equal the requested ones for a cached or shipped file to stand for a new fit.
RECORDED_OPTIONS = ("intervals", "band_intervals")


def made_with(model, options: dict | None = None) -> bool:
    """Whether ``model``'s recorded fit options (:data:`RECORDED_OPTIONS`; a file that records
    none of them passes) are those of :data:`FIT_OPTIONS` updated with ``options``. A fit made
    with other intervals (e.g. a ``band_intervals="tol+spread"`` band, the default before the
    fidelity study) is a different fit and is not reused for this one. A one-function fit
    (version 1) records ``band_intervals`` None: it has no band, so that option cannot differ."""
    want = dict(FIT_OPTIONS, **(options or {}))
    fi = getattr(model, "fit_info", None) or {}
    for k in RECORDED_OPTIONS:
        if fi.get(k) is not None and k in want and fi[k] != want[k]:
            return False
    return True


def shipped_model(stem: str, tol: float):
    """``(model, path)`` of a coefficient file shipped in ``warp_rbrdf/data/`` for the material
    file stem ``stem`` (e.g. ``paper_white_rgb``) whose ``fit.tolerance`` equals ``tol``, whatever
    its interval options (:func:`made_with` tells), or None."""
    from fit.rational.coefficient_file import load
    from warp_rbrdf.paths import PACKAGE_DATA

    for p in sorted(PACKAGE_DATA.glob(f"{stem}*.json")) if PACKAGE_DATA.is_dir() else []:
        try:
            m = load(p)
        except Exception:  # noqa: BLE001
            continue
        if abs(float(m.fit_info.get("tolerance", -1)) - tol) < 1e-12:
            return m, p
    return None


def rational_model(material: str, tol: float = 0.05, allow_fit: bool = True, allow_direct: bool = False,
                   fit_dir: Path | None = None, fit_options: dict | None = None,
                   direct_stride: int = 3, direct_max_degree: int = 8, allow_infeasible: bool = False):
    """``(model, info)``: the rational fit of ``material`` (a :data:`studies.common.MATERIALS` key
    or a file path) at relative tolerance ``tol``, from the first of: a cached fitter file in
    ``fit_dir``, a cached direct fit (with ``allow_direct``), a shipped file of that tolerance, a
    new :func:`fit.rational.brdf_fit.fit_brdf` (with ``allow_fit``; :data:`FIT_OPTIONS` updated
    with ``fit_options``; no time limit), a new direct fit (with ``allow_direct``). ``(None,
    info)`` with ``info["error"]`` when none is available.

    ``allow_infeasible``: also accept a fit whose guaranteed core misses the tolerance (the
    fitter's flagged best effort; ``rbrdf-fit brdf --allow-infeasible``). Without it such a fit,
    cached or new, is refused (a new one is still cached, as the command wrote its file) with
    the fitter's summary line as the reason, so a study never renders a fit it believes
    guaranteed when it is not."""
    from fit.rational.coefficient_file import load, save

    fit_dir = Path(fit_dir or FIT_DIR)
    fit_dir.mkdir(parents=True, exist_ok=True)
    stem = Path(C.MATERIALS.get(material, material)).stem
    info = {"material": material, "tol": tol}
    direct_name = f"{stem}_tol{_tag(tol)}_direct_s{direct_stride}_d{direct_max_degree}.json"
    for src, name in (("cli", f"{stem}_tol{_tag(tol)}_cli.json"), ("direct", direct_name)):
        p = fit_dir / name
        if p.exists() and (src == "cli" or allow_direct):
            m = load(p)
            if src == "cli" and not made_with(m, fit_options):
                continue          # made with other options: fitted again below (and replaced)
            if src == "cli" and not allow_infeasible and not model_summary(m)["core_guaranteed"]:
                return None, dict(info, source=None, file=str(p),
                                  error=f"cached fit {p.name} is flagged: its core misses the tolerance")
            return m, dict(info, source=f"{src} (cached)", file=str(p), fit_seconds=m.fit_info.get("time_s"))
    # a shipped file made with other interval options stands in only where no new fit may be made
    # (``allow_fit=False``: the studies' --no-fit and smoke runs), and says so in its source
    shipped = shipped_model(stem, tol)
    other = shipped is not None and not made_with(shipped[0], fit_options)
    if shipped is not None and not (other and allow_fit):
        m, p = shipped
        return m, dict(info, source="shipped (other interval options)" if other else "shipped", file=str(p),
                       fit_seconds=m.fit_info.get("time_s"))
    errors = []
    if allow_fit:
        ok, why = brdf_fit_available()
        if ok:
            out = fit_dir / f"{stem}_tol{_tag(tol)}_cli.json"
            try:
                fit = fit_material(material, tol, **(fit_options or {}))
            except Exception as e:  # noqa: BLE001 - an unreadable file, a fit that cannot start
                errors.append(f"fit_brdf failed: {type(e).__name__}: {e}")
            else:
                save(fit.model, out)
                if fit.valid or allow_infeasible:
                    # fit_seconds: the fitter's own time, as the file records it (the same
                    # number a cached run reports)
                    return fit.model, dict(info, source="cli", file=str(out),
                                           fit_seconds=fit.model.fit_info["time_s"])
                errors.append(f"fit flagged ({out.name}): {fit.summary()}")
        else:
            errors.append(why)
    if allow_direct:
        out = fit_dir / direct_name
        t0 = time.perf_counter()
        try:
            m = direct_fit(material, tol, stride=direct_stride, max_degree=direct_max_degree)
        except Exception as e:  # noqa: BLE001
            errors.append(f"direct fit failed: {type(e).__name__}: {e}")
        else:
            m.fit_info["time_s"] = time.perf_counter() - t0
            save(m, out)
            return m, dict(info, source="direct", file=str(out), fit_seconds=m.fit_info["time_s"])
    return None, dict(info, source=None, error="; ".join(errors) or "no fit available")


def fit_material(material: str, tol: float, **options):
    """:func:`fit.rational.brdf_fit.fit_brdf` of a material (a :data:`studies.common.MATERIALS`
    key or a file path) at ``tol`` with :data:`FIT_SETTINGS` (``options`` changed): the
    :class:`fit.rational.brdf_fit.BRDFFit` that ``rbrdf-fit brdf FILE --tol TOL`` makes."""
    from fit.formats import load_measured
    from fit.rational.brdf_fit import fit_brdf

    path = C.data_path(C.MATERIALS[material]) if material in C.MATERIALS else Path(material)
    return fit_brdf(load_measured(path), FIT_SETTINGS.clone(tol=tol, **options), source_file=path.name)


def direct_fit(material: str, tol: float, abs_floor_rel: float = 1e-3, theta_d_max_deg: float = 80.0,
               max_degree: int = 8, stride: int = 1, proj=None):
    """Stand-in fit (see the module docstring): IntervalRationalFitter per channel on the median
    projection. ``abs_floor`` = ``abs_floor_rel`` x the channel's largest value."""
    from fit.rational.fitter import IntervalRationalFitter
    from fit.rational.model import RationalModel, Variable

    pj = proj if proj is not None else C.projected(material)
    th = pj.theta_h[::stride]
    td = pj.theta_d[::stride]
    val = np.asarray(pj.value, float)[::stride, ::stride]
    keep_d = td <= np.radians(theta_d_max_deg)
    TH, TD = np.meshgrid(th, td[keep_d], indexing="ij")
    X = np.stack([np.sqrt(TH.ravel()), TD.ravel()], -1)
    dom_x = [(float(th.min()), float(th.max())), (float(td[keep_d].min()), float(td[keep_d].max()))]
    dom_u = np.array([[np.sqrt(dom_x[0][0]), np.sqrt(dom_x[0][1])], list(dom_x[1])])
    funcs, infos = [], []
    for c in range(3):
        y = val[:, keep_d, c].ravel()
        ok = np.isfinite(y)
        floor = abs_floor_rel * float(np.nanmax(y))
        res = IntervalRationalFitter(tol=tol, abs_floor=floor, max_degree=max_degree, domain=dom_u).fit(X[ok], y[ok])
        f = res.function
        f.var_names = ("theta_h", "theta_d")
        funcs.append(f)
        infos.append({"feasible": bool(res.feasible), "valid": bool(res.valid), "degrees": [res.num_degree, res.den_degree],
                      "max_error_ratio": float(res.max_error_ratio), "fit_seconds": float(res.time_s)})
    return RationalModel(name=f"{Path(C.MATERIALS.get(material, material)).stem}", variables=[
        Variable("theta_h", "rad", "sqrt", dom_x[0]), Variable("theta_d", "rad", "identity", dom_x[1])],
        functions=funcs, fit_info={"tolerance": tol, "tolerance_kind": "relative", "fitter": "studies.fits.direct_fit",
                                   "abs_floor_rel": abs_floor_rel, "theta_d_max_deg": theta_d_max_deg},
        function_info=infos, domain_policy={"outside": "clamp", "below_horizon": "zero",
                                            "theta_d_max_deg": theta_d_max_deg})


def model_summary(model) -> dict:
    """Coefficient counts and feasibility of a (possibly piecewise) rational model."""
    def leaves(m):   # the single-function models of a (possibly nested) piecewise model
        return [q for p in m.pieces for q in leaves(p)] if getattr(m, "pieces", None) else [m]

    pieces = leaves(model)
    fi = [i for p in pieces for i in (p.function_info or [{} for _ in p.functions])]
    feas = [bool(i.get("feasible", i.get("valid", True))) for i in fi]
    per_channel = [sum(int(p.functions[c].n_coefficients) for p in pieces) for c in range(len(pieces[0].functions))]
    core = (getattr(model, "fit_info", None) or {}).get("valid")   # rbrdf-fit brdf: per channel
    return {"n_coefficients": int(model.n_coefficients), "feasible_all": all(feas),
            "core_guaranteed": all(feas) if core is None else bool(all(core)),
            "per_channel": per_channel, "n_pieces": len(pieces),
            "info": json.loads(json.dumps(fi, default=str))}