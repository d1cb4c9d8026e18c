"""The coefficient-file model of a BRDF fit (:mod:`fit.rational.brdf_fit`).

:func:`brdf_model` assembles the :class:`fit.rational.model.RationalModel` /
:class:`fit.rational.model.PiecewiseRationalModel` of the fitted pieces with their per-function
and per-piece records, the domain policy (the constants of the fitted box and the grazing
cut-off: :mod:`fit.rational.domain`), the fit's ``fit_info`` (written by
:func:`fit.rational.coefficient_file.save`) and, for a fit with flagged pieces
(:mod:`fit.rational.flagged`), its fallback record (:mod:`fit.rational.fallback`).
:func:`split_core` separates the core pieces from the grazing band.
"""
from __future__ import annotations

import numpy as np

from .domain import CHANNELS, GRAZING_CUTOFF_DEG, THETA_D_MAX_DEG, THETA_H_MAX
from .fallback import fallback_record
from .model import PiecewiseRationalModel, RationalModel, Variable


def split_core(pieces) -> tuple:
    """``(core pieces, band pieces)``: the core is every piece with the first piece's theta_d
    range (``fit_brdf`` puts the core first)."""
    core = [pc for pc in pieces if pc.theta_d_range_deg == pieces[0].theta_d_range_deg]
    return core, [pc for pc in pieces if pc.theta_d_range_deg != pieces[0].theta_d_range_deg]


def _piece_model(pc, name, kw, vt, offset) -> RationalModel:
    variables = [Variable("theta_h", "rad", kw["theta_h_transform"], tuple(np.deg2rad(pc.theta_h_range_deg))),
                 Variable("theta_d", "rad", "identity", tuple(np.deg2rad(pc.theta_d_range_deg)))]
    finfo = []
    for r, err in zip(pc.results, pc.errors):
        finfo.append({"feasible": bool(r.feasible), "valid": bool(r.valid),
                      "num_degree": r.num_degree, "den_degree": r.den_degree, **err,
                      "q_certificate": {"certified": bool(r.certificate and r.certificate.certified),
                                        "lower_bound": r.certificate.lower_bound if r.certificate else None,
                                        "method": r.certificate.method if r.certificate else ""},
                      "fit_time_s": r.time_s})
    return RationalModel(name=name, variables=variables, functions=[r.function for r in pc.results],
                         outputs=CHANNELS, kind="brdf", value_transform=vt, value_offset=offset,
                         value_min=0.0, value_max=kw["value_max"], function_info=finfo)


def _piece_info(pc) -> dict:
    return {"theta_d_range_deg": list(pc.theta_d_range_deg), "theta_h_range_deg": list(pc.theta_h_range_deg),
            "intervals": pc.intervals,
            "partial_clusters": (None if pc.partial is None else
                                 {"min_sample_fraction": pc.partial[0], "factor": pc.partial[1]}),
            "guaranteed": pc.valid,
            "max_interval_ratio": max(e["max_interval_ratio"] for e in pc.errors),
            "max_rel_error": max(e["max_rel_error"] for e in pc.errors)}


def brdf_model(p, name, pieces, kw, intervals, band_intervals, total, source_file):
    """The coefficient-file model of a BRDF fit: one :class:`RationalModel` per theta_d piece
    (a :class:`PiecewiseRationalModel` split in theta_h where the core was split), the whole a
    piecewise model in theta_d (or the single model when one piece covers the box), with the
    domain policy, the fit's record (``fit_info``) and the source file. ``p``: the projected
    BRDF; ``pieces``: the fit's :class:`fit.rational.brdf_fit.PieceFit` list, core first;
    ``kw``: :func:`fit.rational.brdf_fit.fit_brdf`'s fitting parameters; ``total``: seconds."""
    tol, vt, offset = kw["tol"], kw["value_transform"], kw["offset"]
    floors = [kw["floor_frac"] * tol * float(r) for r in kw["rho_ref"]]
    core = pieces[0].theta_d_range_deg[1]
    groups: dict = {}
    for pc in pieces:                       # theta_d ranges in order, theta_h sub-pieces inside
        groups.setdefault(pc.theta_d_range_deg, []).append(pc)
    models, infos = [], []
    for (a, b), grp in groups.items():
        grp_infos = [_piece_info(pc) for pc in grp]
        if len(grp) == 1:
            models.append(_piece_model(grp[0], name, kw, vt, offset))
            infos.append(grp_infos[0])
            continue
        edges = [grp[0].theta_h_range_deg[0]] + [pc.theta_h_range_deg[1] for pc in grp]
        models.append(PiecewiseRationalModel(
            name=name, variables=[Variable("theta_h", "rad", kw["theta_h_transform"], (0.0, THETA_H_MAX)),
                                  Variable("theta_d", "rad", "identity", tuple(np.deg2rad([a, b])))],
            split_variable="theta_h", edges=[float(np.deg2rad(e)) for e in edges],
            pieces=[_piece_model(pc, name, kw, vt, offset) for pc in grp], kind="brdf",
            piece_info=grp_infos))
        infos.append({"theta_d_range_deg": [a, b], "theta_h_split_deg": edges[1:-1], "intervals": grp[0].intervals,
                      "guaranteed": all(pc.valid for pc in grp),
                      "max_interval_ratio": max(i["max_interval_ratio"] for i in grp_infos),
                      "max_rel_error": max(i["max_rel_error"] for i in grp_infos)})
    core_pcs, band = split_core(pieces)
    core_ok = all(pc.valid for pc in core_pcs)
    splits = [pc.theta_h_range_deg[1] for pc in core_pcs[:-1]]
    split_txt = ("" if not splits else f", split at theta_h = {splits[0]:g} deg into a peak piece and the rest"
                 if len(splits) == 1 else
                 f", split at theta_h = {', '.join(f'{x:.4g}' for x in splits)} deg into a peak piece and {len(splits)} more")
    policy = {
        "outside": "clamp", "below_horizon": "zero", "theta_d_max_deg": THETA_D_MAX_DEG,
        "guaranteed_theta_d_max_deg": core if core_ok else None,
        "grazing": (f"samples with max(theta_i, theta_o) > {GRAZING_CUTOFF_DEG} deg dropped before the "
                    f"median projection; theta_d > {THETA_D_MAX_DEG} deg is clamped to "
                    f"{THETA_D_MAX_DEG} deg (value at the cut-off, no 1/cos growth)"),
        "guarantee": (f"theta_d <= {core:g} deg{split_txt}: every cluster within {intervals!r} intervals "
                      f"(relative {tol:g}, absolute floor tol * A_Y / pi, A_Y = white-sky luminance albedo)"
                      + (f"; {core:g} < theta_d <= {THETA_D_MAX_DEG} deg: {band_intervals!r} intervals"
                         + (f" (clusters with < {band[0].partial[0]:g} of their samples left by the "
                            f"grazing cut-off: within a factor {band[0].partial[1]:g})"
                            if band[0].partial else "") + ", "
                         f"{'met' if band[0].valid else 'best effort (NOT met, see pieces)'}"
                         if band else "") + "; Q > 0 on every piece's box (Bernstein certificate)"),
    }
    fit_info = {"tolerance": tol, "tolerance_kind": "relative", "intervals": intervals,
                "band_intervals": band_intervals if len(pieces) > 1 else None,
                "spread_k": kw["spread_k"], "abs_floor": floors, "floor_frac": kw["floor_frac"],
                "white_sky_albedo": [float(np.pi * r) for r in kw["rho_ref"]],
                "statistic": "median", "grazing_cutoff_deg": GRAZING_CUTOFF_DEG, "time_s": total,
                # (the fitter's name as every file records it; the module is fit.rational.fitter)
                "fitter": "fit.fitter.IntervalRationalFitter (LP, HiGHS, constraint generation)",
                "max_degree": kw["max_degree"], "max_den_degree": kw["max_den_degree"],
                "core_theta_d_deg": core,
                "theta_h_split_deg": splits[0] if splits else None,
                "theta_h_splits_deg": splits,
                "feasible": [all(bool(pc.results[c].feasible) for pc in core_pcs) for c in range(3)],
                "valid": [all(bool(pc.results[c].valid) for pc in core_pcs) for c in range(3)]}
    source = {"file": source_file or (p.source.split("/")[-1] if p.source else ""), "sha256": p.source_sha256}
    if len(models) == 1:
        model = models[0]
        model.domain_policy, model.fit_info, model.source = policy, fit_info, source
    else:
        model = PiecewiseRationalModel(
            name=name, variables=[Variable("theta_h", "rad", kw["theta_h_transform"], (0.0, THETA_H_MAX)),
                                  Variable("theta_d", "rad", "identity",
                                           (0.0, float(np.deg2rad(THETA_D_MAX_DEG))))],
            split_variable="theta_d", edges=[float(np.deg2rad(x)) for x in (0.0, core, THETA_D_MAX_DEG)],
            pieces=models, kind="brdf", domain_policy=policy, fit_info=fit_info, piece_info=infos, source=source)
    # a flagged fit carries the part of its projected table the renderer shows there (from the
    # projection ``p`` it was fitted to), so that it renders without its source measurement
    model.fallback = fallback_record(p, model)
    return model
