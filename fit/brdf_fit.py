"""Fit a projected BRDF (theta_h, theta_d) with one rational function per RGB channel.

Domain and grazing policy (stored in the coefficient file):

* The BRDF is projected with the cluster **median** after dropping every sample whose light or
  view direction is more than ``GRAZING_CUTOFF_DEG`` = 79 deg from the normal (the RGL files'
  last measured incidence is 78.5 deg; beyond it the tables are extrapolations and values grow
  like 1/cos theta_o). Clusters left without a sample (NaN) are not fitted.
* The fitted box is ``theta_h in [0, 90] deg`` x ``theta_d in [0, THETA_D_MAX_DEG = 78.5] deg``.
  Outside it the inputs are clamped onto the box (``"outside": "clamp"``): at grazing theta_d
  the function returns its value at 78.5 deg instead of growing without bound.
* Intervals: ``"tol"``: ``y +- max(tol y, abs_floor)``; ``"tol+spread"`` (default):
  ``y +- max(tol y, abs_floor, spread_k * sigma)`` where sigma is the cluster's standard
  deviation over phi_d (the projection cannot be more precise than the spread it averages).
  ``abs_floor = floor_frac * tol * median(y)`` keeps zero and tiny values feasible.
* The guarantee (every fitted cluster inside its interval, Q > 0 on the whole box by a
  Bernstein certificate) holds on that box.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .coefficients import RationalModel, Variable, apply_input_transform, apply_value_transform
from .fitter import FitResult, IntervalRationalFitter, intervals_from_spread, intervals_from_tolerance
from .measured import MeasuredBRDF, ProjectedBRDF

GRAZING_CUTOFF_DEG = 79.0
THETA_D_MAX_DEG = 78.5
THETA_H_MAX = 0.5 * np.pi
INTERVALS = ("tol", "tol+spread")
CHANNELS = ("R", "G", "B")


@dataclass
class ChannelData:
    X: np.ndarray          # physical inputs (theta_h, theta_d) in radians, (N, 2)
    y: np.ndarray          # values in 1/sr
    lower: np.ndarray
    upper: np.ndarray
    abs_floor: float


@dataclass
class BRDFFit:
    """Result of :func:`fit_brdf`: the model (with its file metadata) and per-channel results."""

    model: RationalModel
    results: list
    errors: list = field(default_factory=list)   # per channel dict
    time_s: float = 0.0

    @property
    def valid(self) -> bool:
        return all(r.valid for r in self.results)

    @property
    def n_coefficients(self) -> int:
        return self.model.n_coefficients


def project_for_fit(brdf, grazing_cutoff_deg: float = GRAZING_CUTOFF_DEG) -> ProjectedBRDF:
    """Median projection with the grazing cut-off on max(theta_i, theta_o)."""
    if isinstance(brdf, ProjectedBRDF):
        return brdf
    from .projection import project

    return project(brdf, statistic="median", grazing_cutoff_deg=grazing_cutoff_deg, grazing_angle="theta_io")


def channel_data(p: ProjectedBRDF, c: int, tol: float, intervals: str = "tol+spread",
                 floor_frac: float = 0.01, spread_k: float = 1.0,
                 theta_d_max_deg: float = THETA_D_MAX_DEG) -> ChannelData:
    th, td = np.meshgrid(p.theta_h, p.theta_d, indexing="ij")
    v = p.value[..., c]
    ok = np.isfinite(v) & (td <= np.deg2rad(theta_d_max_deg) + 1e-12)
    y = np.maximum(v[ok], 0.0)
    if y.size == 0:
        raise ValueError("no finite cluster in the fitted domain")
    pos = y[y > 0]
    floor = floor_frac * tol * float(np.median(pos) if pos.size else 1.0)
    if intervals == "tol":
        lo, hi = intervals_from_tolerance(y, tol, floor)
    elif intervals == "tol+spread":
        sd = np.sqrt(np.nan_to_num(p.variance[..., c][ok], nan=0.0))
        lo, hi = intervals_from_spread(y, sd, k=spread_k, abs_floor=floor, tol_min=tol)
    else:
        raise ValueError(f"intervals must be one of {INTERVALS}")
    # BRDF values are >= 0: a lower bound below -floor carries no information (and would make
    # the log transform undefined); clip it there.
    lo = np.maximum(lo, -floor)
    return ChannelData(np.stack([th[ok], td[ok]], axis=-1), y, lo, hi, floor)


def fit_brdf(brdf, tol: float = 0.05, intervals: str = "tol+spread", theta_h_transform: str = "sqrt",
             value_transform: str = "log", max_degree: int = 12, max_den_degree: int = 6,
             floor_frac: float = 0.01, spread_k: float = 1.0, name: str | None = None,
             progress=None, source_file: str = "") -> BRDFFit:
    """Fit R, G, B of a measured (or already projected) BRDF. ``progress(channel, event)``
    is called after every degree pair tried."""
    t0 = time.perf_counter()
    p = project_for_fit(brdf)
    name = name or p.name
    variables = [Variable("theta_h", "rad", theta_h_transform, (0.0, THETA_H_MAX)),
                 Variable("theta_d", "rad", "identity", (0.0, float(np.deg2rad(THETA_D_MAX_DEG))))]
    rf_domain = np.array([v.rf_domain for v in variables])
    functions, results, infos, errors, floors, offsets = [], [], [], [], [], []
    data = [channel_data(p, c, tol, intervals, floor_frac, spread_k) for c in range(3)]
    # One value offset for all channels (log transform): twice the largest floor.
    offset = 2.0 * max(d.abs_floor for d in data) if value_transform == "log" else 0.0
    for c, d in enumerate(data):
        U = np.stack([apply_input_transform(d.X[:, 0], theta_h_transform), d.X[:, 1]], axis=-1)
        lo = apply_value_transform(d.lower, value_transform, offset)
        hi = apply_value_transform(d.upper, value_transform, offset)
        yt = apply_value_transform(d.y, value_transform, offset)
        cb = None if progress is None else (lambda e, c=c: progress(CHANNELS[c], e))
        # R, G and B usually need the same degrees: start G and B from the previous channel's
        # pair (a feasible start only prunes the search; the fewest-coefficient pair is kept).
        start = (results[-1].num_degree, results[-1].den_degree) if results and results[-1].valid else None
        fitter = IntervalRationalFitter(max_degree=max_degree, max_den_degree=max_den_degree,
                                        domain=rf_domain, progress=cb, start_degrees=start)
        r = fitter.fit(U, y=yt, lower=lo, upper=hi)
        results.append(r)
        functions.append(r.function)
        err = brdf_errors(r, U, d, value_transform, offset, tol)
        errors.append(err)
        infos.append({"feasible": bool(r.feasible), "valid": bool(r.valid),
                      "num_degree": r.num_degree, "den_degree": r.den_degree, **err,
                      "q_certificate": {"certified": bool(r.certificate and r.certificate.certified),
                                        "lower_bound": r.certificate.lower_bound if r.certificate else None,
                                        "method": r.certificate.method if r.certificate else ""},
                      "fit_time_s": r.time_s})
        floors.append(d.abs_floor)
    total = time.perf_counter() - t0
    model = RationalModel(
        name=name, variables=variables, functions=functions, outputs=CHANNELS, kind="brdf",
        value_transform=value_transform, value_offset=offset, value_min=0.0,
        domain_policy={
            "outside": "clamp", "below_horizon": "zero", "theta_d_max_deg": THETA_D_MAX_DEG,
            "grazing": (f"samples with max(theta_i, theta_o) > {GRAZING_CUTOFF_DEG} deg dropped before the "
                        f"median projection; theta_d > {THETA_D_MAX_DEG} deg is clamped to "
                        f"{THETA_D_MAX_DEG} deg (value at the cut-off, no 1/cos growth)"),
            "guarantee": "every fitted (theta_h, theta_d) cluster inside its interval; Q > 0 on the whole box",
        },
        fit_info={"tolerance": tol, "tolerance_kind": "relative", "intervals": intervals,
                  "spread_k": spread_k if intervals == "tol+spread" else None,
                  "abs_floor": floors, "statistic": "median",
                  "grazing_cutoff_deg": GRAZING_CUTOFF_DEG, "time_s": total,
                  "fitter": "fit.fitter.IntervalRationalFitter (LP, HiGHS, constraint generation)",
                  "max_degree": max_degree, "max_den_degree": max_den_degree,
                  "feasible": [bool(r.feasible) for r in results],
                  "valid": [bool(r.valid) for r in results]},
        function_info=infos,
        source={"file": source_file or (p.source.split("/")[-1] if p.source else ""),
                "sha256": p.source_sha256},
    )
    return BRDFFit(model, results, errors, total)


def brdf_errors(r: FitResult, U, d: ChannelData, value_transform: str, offset: float, tol: float) -> dict:
    """Errors in 1/sr space of one channel on its fitted clusters.

    ``max_rel_error``/``rms_rel_error``: |fit - y| / y over clusters with tol*y >= abs_floor
    (where the relative tolerance applies); ``max_interval_ratio``: max |fit - y| / half-width
    (<= 1: every cluster inside its interval); ``inside``: fraction of clusters inside.
    """
    from .coefficients import invert_value_transform

    f = np.maximum(invert_value_transform(r.function(U), value_transform, offset), 0.0)
    e = np.abs(f - d.y)
    rel_ok = tol * d.y >= d.abs_floor
    rel = e[rel_ok] / d.y[rel_ok]
    inside = (f >= d.lower * (1 - 1e-12) - 1e-300) & (f <= d.upper * (1 + 1e-12))
    return {"max_rel_error": float(rel.max()) if rel.size else 0.0,
            "rms_rel_error": float(np.sqrt(np.mean(rel ** 2))) if rel.size else 0.0,
            "max_interval_ratio": float(np.max(e / (0.5 * (d.upper - d.lower)))),
            "inside_fraction": float(inside.mean()), "n_points": int(d.y.size)}
