"""The pieces and channels a 2-D BRDF fit does not vouch for.

Each single-box piece of a fit (a theta_d range, possibly split in theta_h) records per channel
whether its function is within its intervals (``valid``, :func:`fit.rational.model.flagged`)
and the range of the measured clusters it was fitted to (``measured_range``).
:func:`flagged_regions` lists the pieces and channels a fit does not vouch for,
:func:`describe_regions` says it in words, and :func:`region_measured_range` computes a
piece's range from the projection for files written before it was recorded. The renderer's
fallback (:mod:`fit.rational.fallback`, :mod:`fit.rational.vouched`) shows the projection there.
Angles in radians.
"""
from __future__ import annotations

import numpy as np

from ..formats.grid import theta_d_centres, theta_h_centres
from .model import flagged

CHANNEL_WORDS = {"R": "red", "G": "green", "B": "blue"}


def leaf_models(model) -> list:
    """The single-box models of a (possibly nested) piecewise model, in evaluation order."""
    pieces = getattr(model, "pieces", None)
    return [q for p in pieces for q in leaf_models(p)] if pieces is not None else [model]


def flagged_regions(model) -> list:
    """The pieces of a BRDF model whose record flags at least one channel, as dicts
    ``{"leaf": k, "model": leaf, "channels": (c, ...), "theta_h": (lo, hi), "theta_d": (lo, hi)}``
    (``k``: index of the piece among :func:`leaf_models` of ``model``; ranges in radians, the
    piece's box). A region is one piece of the fit: the unit the fitter states its guarantee
    for (the core, each of its theta_h parts, the grazing band). Empty when the fit is within
    its intervals everywhere (or records nothing)."""
    out = []
    for k, leaf in enumerate(leaf_models(model)):
        chans = tuple(c for c, info in enumerate(leaf.function_info) if flagged(info))
        if chans:
            box = {v.name: v.domain for v in leaf.variables}
            out.append({"leaf": k, "model": leaf, "channels": chans,
                        "theta_h": box.get("theta_h"), "theta_d": box.get("theta_d")})
    return out


def _range_words(name: str, rng, whole) -> str:
    if rng is None or whole is None:
        return ""
    a, b = (float(np.degrees(v)) for v in rng)
    lo_edge, hi_edge = (np.isclose(rng[0], whole[0]), np.isclose(rng[1], whole[1]))
    if lo_edge and hi_edge:
        return ""
    if lo_edge:
        return f"{name} <= {b:.4g} deg"
    if hi_edge:
        return f"{name} > {a:.4g} deg"
    return f"{a:.4g} < {name} <= {b:.4g} deg"


def describe_regions(model, regions=None) -> str:
    """``regions`` (default :func:`flagged_regions`) in words, e.g. ``"theta_d > 60 deg (blue
    channel)"`` or ``"theta_d <= 40 deg, theta_h <= 5 deg (all channels); theta_d > 40 deg (red
    and blue channels)"``."""
    regions = flagged_regions(model) if regions is None else regions
    whole = {v.name: v.domain for v in model.variables}
    parts = []
    for r in regions:
        where = ", ".join(w for w in (_range_words("theta_d", r["theta_d"], whole.get("theta_d")),
                                      _range_words("theta_h", r["theta_h"], whole.get("theta_h"))) if w)
        outs = r["model"].outputs
        if len(r["channels"]) == len(outs):
            chans = "all channels"
        else:
            names = [CHANNEL_WORDS.get(outs[c], outs[c]) for c in r["channels"]]
            chans = (names[0] + " channel" if len(names) == 1
                     else ", ".join(names[:-1]) + " and " + names[-1] + " channels")
        parts.append(f"{where or 'the whole domain'} ({chans})")
    return "; ".join(parts)


def region_measured_range(p, leaf, c: int):
    """``(lo, hi)``: min and max over the finite clusters of channel ``c`` of the projection
    ``p`` inside ``leaf``'s box (values below 0 counted as 0), i.e. the data
    :func:`fit.rational.brdf_fit.channel_data` gives the fitter for that piece; None when the
    box holds no finite cluster."""
    box = {v.name: v.domain for v in leaf.variables}
    th, td = np.meshgrid(theta_h_centres(), theta_d_centres(), indexing="ij")
    ok = np.isfinite(p.value[..., c])
    for name, grid in (("theta_h", th), ("theta_d", td)):
        if name in box:
            lo, hi = box[name]
            ok &= (grid >= lo - 1e-12) & (grid <= hi + 1e-12)
    if not ok.any():
        return None
    y = np.maximum(p.value[..., c][ok], 0.0)
    return float(y.min()), float(y.max())

