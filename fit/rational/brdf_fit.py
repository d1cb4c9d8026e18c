"""Fit a projected BRDF (theta_h, theta_d) with rational functions per RGB channel.

Domain and grazing policy (stored in the coefficient file's ``domain_policy`` and ``fit``):

* The BRDF is projected with the cluster **median** after dropping every sample whose light or
  view direction is more than ``GRAZING_CUTOFF_DEG`` = 79 deg from the normal (the RGL files'
  last measured incidence is 78.5 deg; beyond it the tables are extrapolations and values grow
  like 1/cos theta_o). Clusters left without a sample (NaN) are not fitted.
* The fitted box is ``theta_h in [0, 90] deg`` x ``theta_d in [0, THETA_D_MAX_DEG = 78.5] deg``,
  split in theta_d into a **guaranteed core** ``[0, core]`` and a **grazing band**
  ``[core, 78.5]``, each with its own rational functions (file version 2, see
  :class:`fit.rational.model.PiecewiseRationalModel`). ``core`` is the largest of
  ``CORE_CANDIDATES_DEG`` (60, 50, 40 deg) on which every channel meets the tolerance, or a
  value given by the caller (78.5: one function per channel over the whole box, version 1).
  Why: near grazing the median clusters keep only the phi_d samples that survive the cut-off,
  so neighbouring clusters jump by more than 5 % (satin: 1.2 -> 5.9 between bins at theta_d
  77.5 deg) and no smooth function meets 5 % there (measured: satin's band alone is infeasible
  up to degrees (12, 6)); the band therefore gets its own functions, fitted to the same
  tolerance as a best effort and flagged where they miss it (the renderer then shows the
  projected table there, :mod:`warp_rbrdf.materials.rational`).
* Output clamp: ``rho = min(max(y, 0), value_max)`` with ``value_max`` = twice the largest
  fitted cluster value (Q > 0 rules out poles, but a best-effort band can grow large where no
  cluster constrains it, e.g. theta_h + theta_d > 90 deg; measured: exp overflow on
  cc_iris_purple_gem's band before this clamp).
* If no core is met with one function per channel, the cores are tried again split at
  ``theta_h = 5 deg`` into a specular-peak piece and the rest (cc_iris_purple_gem's red
  highlight drops from 0.95 to exactly 0 within 3.5 deg; no single (12, 6) function follows it),
  and, if none is met that way either, the theta_h pieces that miss their intervals on the last
  core are split at their midpoints in the fit's variable (sqrt: the rest at 34.4 deg, the peak
  at 1.25 deg) and the cores tried again, round after round, up to ``max_theta_h_pieces``
  pieces (:func:`bisect_failing`). The attempts stop at the first core met, so a fit met with
  fewer pieces is the same fit.
* Outside the box the inputs are clamped onto it (``"outside": "clamp"``): at grazing theta_d
  the function returns its value at 78.5 deg instead of growing without bound.
* Intervals: ``"tol"`` (default of the core and of the band): ``y +- max(tol y, abs_floor)``;
  ``"tol+spread"``: ``y +- max(tol y, abs_floor, spread_k * sigma)`` where sigma is the
  cluster's standard deviation over phi_d (the projection cannot be more precise than the
  spread it averages). It was the band's default until the fidelity study showed what it
  vouches for on glossy films: cc_ibiza_sunset's band was ``valid`` under it while 235 % off
  the median at its own data points (blue), and put 130 rim pixels above the reference's range
  under the studio map; with ``"tol"`` that band misses 5 %, is flagged, the renderer shows the
  projected table there and 12 remain (cc_iris_purple_gem 36 -> 4). ``abs_floor = floor_frac * tol * A_Y / pi`` (A_Y: white-sky luminance albedo,
  :func:`white_sky_albedo`): below the value of the equally bright Lambertian the bound is
  absolute, so zero, clipped and tiny values stay feasible and an error there shifts the
  light reflected from a uniform white sky by at most ``tol * A_Y``.
* What is proved at the clusters (every fitted cluster inside its interval, Q > 0 on each
  piece's box by a Bernstein certificate) holds on the core; the band's status (met or best
  effort, with its measured maximum interval ratio) is recorded per piece and never reported as
  met when it is not. Between the clusters, the error proved per piece and channel
  (:func:`fit.rational.proved_bound.prove_brdf`) is ``fit_info["bound"]``.
* What a fit vouches for is recorded per piece and channel: each function's ``valid`` (its
  data inside their intervals and Q > 0 certified) and ``measured_range`` (min and max of the
  clusters of its piece). A function that is not valid is *flagged*: its output is clamped to
  that range (step 7 of :mod:`fit.rational.coefficient_file`), and the renderer shows the
  projected table there instead (:mod:`warp_rbrdf.materials.rational`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..blas_threads import one_blas_thread
from ..formats.colour import LUMINANCE
from ..progress import report
from .brdf_data import ChannelData, channel_data, project_for_fit, white_sky_albedo
from .brdf_model import brdf_model, split_core
from .coefficient_file import save as save_model
from .domain import CHANNELS, THETA_D_MAX_DEG
from .fitter import FitResult, IntervalRationalFitter
from .proved_bound import prove_brdf
from .proved_bound import records as bound_records
from .proved_bound import summary as bound_summary
from .model import (
    Variable,
    vouched_envelope,
    apply_input_transform,
    apply_value_transform,
    invert_value_transform,
)
from .settings import INTERVALS, BRDFFitSettings

__all__ = ["CORE_CANDIDATES_DEG", "INTERVALS", "PRECHECK_ROUNDS", "THETA_D_MAX_DEG", "BRDFFit", "ChannelData",
           "PieceFit", "brdf_errors", "channel_data", "fit_brdf", "project_for_fit", "white_sky_albedo"]


@dataclass
class PieceFit:
    """One theta_d piece of a BRDF fit: its range, interval policy and per-channel results."""

    theta_d_range_deg: tuple
    intervals: str
    results: list                                  # FitResult per channel
    errors: list = field(default_factory=list)     # per channel dict (:func:`brdf_errors`)
    partial: tuple | None = None                   # (min fraction, factor) or None
    rejected: bool = False                         # pre-check or a channel search failed: not fitted
    theta_h_range_deg: tuple = (0.0, 90.0)

    @property
    def valid(self) -> bool:
        return not self.rejected and len(self.results) == 3 and all(r.valid for r in self.results)


@dataclass
class BRDFFit:
    """Result of :func:`fit_brdf`: the model (with its file metadata) and per-piece results.

    ``pieces[0]`` is the guaranteed core; ``results``/``errors`` are the core's per channel.
    """

    model: object                                  # RationalModel or PiecewiseRationalModel
    pieces: list
    time_s: float = 0.0
    settings: BRDFFitSettings | None = None        # the settings that made it
    #: per leaf piece and channel, the error between the clusters proved by
    #: :func:`fit.rational.proved_bound.prove_brdf` (None: not proved)
    bounds: list | None = None

    @property
    def core_pieces(self) -> list:
        """The pieces of the guaranteed core (one, or two when split in theta_h)."""
        return split_core(self.pieces)[0]

    @property
    def band_pieces(self) -> list:
        """The grazing band's pieces (empty when one function covers the whole box)."""
        return split_core(self.pieces)[1]

    @property
    def core_theta_d_deg(self) -> float:
        return self.pieces[0].theta_d_range_deg[1]

    @property
    def results(self) -> list:
        return self.pieces[0].results

    @property
    def errors(self) -> list:
        return self.pieces[0].errors

    @property
    def valid(self) -> bool:
        """Every core piece meets its intervals with Q > 0 certified (the stated guarantee)."""
        return all(pc.valid for pc in self.core_pieces)

    @property
    def all_valid(self) -> bool:
        return all(p.valid for p in self.pieces)

    def save(self, path) -> None:
        """Write :attr:`model` as an ``rbrdf-rational`` coefficient file
        (:func:`fit.rational.coefficient_file.save`)."""
        save_model(self.model, path)

    @property
    def n_coefficients(self) -> int:
        return self.model.n_coefficients

    def summary(self) -> str:
        """One line: the coefficient count, the fit's seconds, what is proved at the clusters and
        what between them, e.g. "total 189 coefficients, 3.6 s, proved within its intervals at
        every cluster of theta_d <= 60 deg; grazing band met; between the clusters proved <= 7.2 %
        (within the tolerance on 91 % of the box), verified max 5.3 % at 3100 points" or "total 735
        coefficients, 21.4 s, NOT within its intervals at every cluster (best fit found, flagged
        infeasible); between the clusters not proved" (the last line ``rbrdf-fit brdf`` prints,
        before "; wrote FILE"). The percentages between the clusters are in the unit of
        :data:`fit.rational.proved_bound.UNIT_2D`, the largest over the pieces and channels."""
        core = self.pieces[0]
        if self.valid:
            status = f"proved within its intervals at every cluster of theta_d <= {core.theta_d_range_deg[1]:g} deg"
            splits = [pc.theta_h_range_deg[1] for pc in self.core_pieces[:-1]]
            if splits:
                status += f" (split at theta_h = {', '.join(f'{x:.3g}' for x in splits)} deg)"
        else:
            status = "NOT within its intervals at every cluster (best fit found, flagged infeasible)"
        band = self.band_pieces
        if band:
            status += ("; grazing band met" if band[0].valid
                       else "; grazing band best effort (NOT within its intervals, flagged)")
        if self.bounds:     # between the clusters: what is proved (fit.rational.proved_bound)
            b = bound_summary(self.bounds)
            proved = "none (Q inconclusive)" if b["proved"] is None else f"<= {100 * b['proved']:.3g} %"
            n = sum(x.verified_points for x in self.bounds)
            status += (f"; between the clusters proved {proved} (within the tolerance on "
                       f"{100 * b['proved_fraction']:.3g} % of the box), verified max "
                       f"{100 * b['verified']:.3g} % at {n} points")
        else:
            status += "; between the clusters not proved"
        return f"total {self.n_coefficients} coefficients, {self.time_s:.1f} s, {status}"


CORE_CANDIDATES_DEG = (60.0, 50.0, 40.0)


def theta_h_splits(peak_split_deg) -> list:
    """The theta_h edges (degrees) of the core's fixed layouts :func:`fit_brdf` tries in turn:
    one piece, and with ``peak_split_deg`` the peak and the rest."""
    return [(0.0, 90.0)] + ([(0.0, float(peak_split_deg), 90.0)] if peak_split_deg else [])


def theta_h_midpoint(a: float, b: float, transform: str) -> float:
    """The midpoint of ``[a, b]`` (degrees) in the fit's own theta_h variable (``"sqrt"``: the
    square roots' midpoint; ``"identity"``: the angles')."""
    return float((0.5 * (np.sqrt(a) + np.sqrt(b))) ** 2 if transform == "sqrt" else 0.5 * (a + b))


def bisect_failing(edges, core_fits, transform: str, max_pieces: int):
    """The next theta_h layout of the refinement: ``edges`` with every piece of ``core_fits``
    (the layout's pieces, all fitted) that misses its intervals split at its midpoint
    (:func:`theta_h_midpoint`), in order while the layout has fewer than ``max_pieces``; None
    when no piece can be split."""
    failing = [i for i, pc in enumerate(core_fits) if not pc.valid]
    room = max_pieces - (len(edges) - 1)
    if not failing or room <= 0:
        return None
    mids = {i: theta_h_midpoint(edges[i], edges[i + 1], transform) for i in failing[:room]}
    out = []
    for i in range(len(edges) - 1):
        out.append(edges[i])
        if i in mids:
            out.append(mids[i])
    return tuple(out + [edges[-1]])
PRECHECK_ROUNDS = 6


@one_blas_thread
def fit_brdf(brdf, settings: BRDFFitSettings | None = None, *, name: str | None = None, progress=None,
             source_file: str = "", prove_bound: bool = True, **params) -> BRDFFit:
    """Fit R, G, B of a measured (or already projected) BRDF over theta_h x theta_d with
    ``settings`` (:class:`fit.rational.settings.BRDFFitSettings`, default its defaults; each of
    its names is also a keyword argument that overrides it, e.g. ``fit_brdf(b, tol=0.1)``).

    ``core_theta_d_deg``: the guaranteed core ``theta_d <= core`` is fitted with ``intervals``
    (default pure tolerance); the grazing band ``core < theta_d <= 78.5 deg`` gets its own
    functions with ``band_intervals`` (best effort, flagged in the file if not met). ``"auto"``
    tries the cores of :data:`CORE_CANDIDATES_DEG` in turn and keeps the first (largest) one
    every channel meets; a number fixes it; ``THETA_D_MAX_DEG`` (78.5) fits one function per
    channel over the whole box (file version 1). ``band_partial = (fraction, factor)``: if the
    band cannot meet its intervals everywhere, it is fitted again with the clusters that kept
    fewer than ``fraction`` of their above-horizon samples after the grazing cut-off only held
    within ``factor`` (see :func:`channel_data`; None: never). ``peak_split_deg``: if no core
    is met with one function per channel, the cores are tried again split at
    ``theta_h = peak_split_deg`` into a specular-peak piece and the rest (None: never), then
    with the pieces that miss split at their midpoints, up to ``max_theta_h_pieces`` theta_h
    pieces (:func:`bisect_failing`).

    ``progress(stage, done, total)`` (:mod:`fit.progress`): stage ``"projecting"`` (0 then 1
    of 1), then per piece tried ``"fitting theta_d A-B ..."`` with the channels fitted so far
    (0 to 3; a piece that is rejected early stops before 3).
    """
    s = BRDFFitSettings.resolve(settings, **params)
    tol, intervals, core_theta_d_deg, band_intervals = s.tol, s.intervals, s.core_theta_d_deg, s.band_intervals
    band_partial = None if s.band_partial is None else tuple(s.band_partial)
    peak_split_deg, theta_h_transform, value_transform = s.peak_split_deg, s.theta_h_transform, s.value_transform
    max_degree, max_den_degree, floor_frac, spread_k = s.max_degree, s.max_den_degree, s.floor_frac, s.spread_k
    t0 = time.perf_counter()
    report(progress, "projecting", 0, 1)
    p = project_for_fit(brdf)
    report(progress, "projecting", 1, 1)
    name = name or p.name
    # Floor reference: the Lambertian with the material's white-sky *luminance* albedo, the
    # same in R, G and B (errors are seen against luminance; a channel that is near zero where
    # the others peak, e.g. blue of a yellow highlight clipped by the RGB conversion, gets no
    # tighter absolute bound than the others).
    rho_ref = np.full(3, float(LUMINANCE @ white_sky_albedo(p)) / np.pi)
    floors = [floor_frac * tol * float(r) for r in rho_ref]
    # One value offset for all channels and pieces (log transform): twice the largest floor.
    offset = 2.0 * max(floors) if value_transform == "log" else 0.0
    # Upper clamp: twice the largest fitted cluster value (Q > 0 rules out poles, but where no
    # cluster constrains the function, e.g. the below-horizon corner theta_h + theta_d > 90 deg
    # of the grazing band, it could still grow without bound).
    _, tdg = np.meshgrid(p.theta_h, p.theta_d, indexing="ij")
    vals = p.value[tdg <= np.deg2rad(THETA_D_MAX_DEG) + 1e-12]
    value_max = 2.0 * float(np.nanmax(vals))
    kw = dict(tol=tol, theta_h_transform=theta_h_transform, value_transform=value_transform,
              offset=offset, max_degree=max_degree, max_den_degree=max_den_degree,
              floor_frac=floor_frac, spread_k=spread_k, rho_ref=rho_ref, progress=progress)
    if core_theta_d_deg == "auto":
        cores = CORE_CANDIDATES_DEG
    else:
        cores = (float(core_theta_d_deg),)
    def attempt(core, edges, full):
        """The core's pieces of one theta_h layout; ``full``: every piece fitted to the end (a
        best effort where it fails), else the first failing piece stops the attempt."""
        fits = []
        for th in zip(edges[:-1], edges[1:]):
            fits.append(_fit_piece(p, (0.0, core), intervals, stop_on_infeasible=not full,
                                   theta_h_range_deg=th, **kw))
            if not fits[-1].valid and not full:
                break
        return fits

    def first_core(edges, full_last):
        """``(core, its pieces, met)`` of the first core met with the theta_h layout ``edges``,
        else of the last core tried (fitted to the end where ``full_last``)."""
        for ci, core in enumerate(cores):
            fits = attempt(core, edges, full_last and ci == len(cores) - 1)
            if all(pc.valid for pc in fits):
                return core, fits, True
        return core, fits, False

    layouts = theta_h_splits(peak_split_deg)
    for li, edges in enumerate(layouts):          # the fixed layouts, each core in turn
        core, core_fits, met = first_core(edges, li == len(layouts) - 1)
        if met:
            break
    while not met and peak_split_deg:             # then the failing theta_h pieces bisected
        edges = bisect_failing(edges, core_fits, theta_h_transform, s.max_theta_h_pieces)
        if edges is None:
            break
        core, core_fits, met = first_core(edges, True)
    pieces = list(core_fits)
    if core < THETA_D_MAX_DEG:
        band = (core, THETA_D_MAX_DEG)
        band_fit = _fit_piece(p, band, band_intervals, stop_on_infeasible=band_partial is not None, **kw)
        if not band_fit.valid and band_partial is not None:
            band_fit = _fit_piece(p, band, band_intervals, partial=band_partial, **kw)
        pieces.append(band_fit)
    total = time.perf_counter() - t0
    model = brdf_model(p, name, pieces, dict(kw, value_max=value_max), intervals, band_intervals, total,
                       source_file)
    bounds = None
    if prove_bound:     # the error between the clusters, proved (fit.rational.proved_bound)
        report(progress, "proving the bound", 0, 1)
        bounds = prove_brdf(model, p)
        model.fit_info["bound"] = bound_records(bounds)
        report(progress, "proving the bound", 1, 1)
    return BRDFFit(model, pieces, time.perf_counter() - t0, settings=s, bounds=bounds)


def _fit_piece(p, theta_d_range_deg, intervals, *, tol, theta_h_transform, value_transform, offset,
               max_degree, max_den_degree, floor_frac, spread_k, rho_ref, progress,
               stop_on_infeasible=False, partial=None, theta_h_range_deg=(0.0, 90.0)) -> PieceFit:
    a, b = theta_d_range_deg
    ha, hb = (float(x) for x in theta_h_range_deg)
    rf_domain = np.array([Variable("theta_h", "rad", theta_h_transform, tuple(np.deg2rad([ha, hb]))).rf_domain,
                          (np.deg2rad(a), np.deg2rad(b))])
    piece = PieceFit((a, b), intervals, [], [], partial=partial, theta_h_range_deg=(ha, hb))
    label = f"theta_d {a:g}-{b:g}" + (f" theta_h {ha:g}-{hb:g}" if (ha, hb) != (0.0, 90.0) else "")
    stage = f"fitting {label}" + (" (partial band)" if partial is not None else "")
    report(progress, stage, 0, 3)
    data = []
    for c in range(3):
        d = channel_data(p, c, tol, intervals, floor_frac, spread_k, (a, b), rho_ref=float(rho_ref[c]),
                         partial_min_fraction=None if partial is None else partial[0],
                         partial_factor=2.0 if partial is None else partial[1])
        if (ha, hb) != (0.0, 90.0):
            sel = (d.X[:, 0] >= np.deg2rad(ha) - 1e-12) & (d.X[:, 0] <= np.deg2rad(hb) + 1e-12)
            d = ChannelData(d.X[sel], d.y[sel], d.lower[sel], d.upper[sel], d.abs_floor)
        U = np.stack([apply_input_transform(d.X[:, 0], theta_h_transform), d.X[:, 1]], axis=-1)
        data.append((d, U, apply_value_transform(d.lower, value_transform, offset),
                     apply_value_transform(d.upper, value_transform, offset),
                     apply_value_transform(d.y, value_transform, offset)))
    order = [0, 1, 2]
    if stop_on_infeasible:
        # Cheap rejection before any degree search. One constraint-generation round at the
        # largest degrees ranks the channels by margin (hardest first); only the hardest gets
        # the full pre-check (PRECHECK_ROUNDS rounds, which refute in 2-5 rounds when they do).
        # The channels are then searched hardest first, and the first one whose search fails
        # rejects the piece (the others are not fitted).
        top = (max_degree, max_den_degree)
        pre = IntervalRationalFitter(max_degree=max_degree, max_den_degree=max_den_degree, domain=rf_domain)
        margins = [pre.subset_margin(U, top, y=yt, lower=lo, upper=hi, rounds=1) for d, U, lo, hi, yt in data]
        order = sorted(range(3), key=lambda c: margins[c])
        c0 = order[0]
        d, U, lo, hi, yt = data[c0]
        ok = not pre.proves_infeasible(U, top, y=yt, lower=lo, upper=hi, max_rounds=PRECHECK_ROUNDS)
        if not ok:
            piece.rejected = True
            return piece
    results, errors = [None] * 3, [None] * 3
    prev = None
    for k, c in enumerate(order):
        d, U, lo, hi, yt = data[c]
        # R, G and B usually need the same degrees: start each channel from the previous one's
        # pair (a feasible start only prunes the search; the fewest-coefficient pair is kept).
        start = (prev.num_degree, prev.den_degree) if prev is not None and prev.valid else None
        # A piece that may be rejected needs no converged best-effort fit of a failing channel.
        fitter = IntervalRationalFitter(max_degree=max_degree, max_den_degree=max_den_degree,
                                        domain=rf_domain, start_degrees=start,
                                        best_effort=not stop_on_infeasible)
        r = fitter.fit(U, y=yt, lower=lo, upper=hi)
        if r.function is None:
            # the LP gave no solution at all (not even a least-violating one): nothing to write
            raise ValueError(f"no rational function for channel {CHANNELS[c]} on {label} ({r.message}); "
                             "a larger tolerance or degree may help")
        results[c], errors[c] = r, brdf_errors(r, U, d, value_transform, offset, tol)
        report(progress, stage, k + 1, 3)
        prev = r
        if stop_on_infeasible and not r.valid:
            piece.rejected = True
            return piece
    piece.results, piece.errors = results, errors
    return piece


def brdf_errors(r: FitResult, U, d: ChannelData, value_transform: str, offset: float, tol: float) -> dict:
    """Errors in 1/sr space of one channel on its fitted clusters.

    ``max_rel_error``/``rms_rel_error``: |fit - y| / y over clusters with tol*y >= abs_floor
    (where the relative tolerance applies); ``max_interval_ratio``: max over clusters of
    |fit - y| / (distance from y to the interval's bound on the side of fit) (<= 1: every
    cluster inside its interval); ``inside``: fraction of clusters inside;
    ``measured_range``: [min, max] of the clusters' values (the measured data of the piece,
    in 1/sr): where the fit is flagged its output is clamped to it
    (:func:`fit.rational.model.flagged`); ``vouched_range``: [max(min lower bound, 0), max upper
    bound] of the clusters' intervals, the upper end at most the reader's limit
    (:func:`fit.rational.model.vouched_envelope`): where the fit is valid its output is clamped to
    it, which changes no value at a data point and bounds the fit in data-free clusters.
    """
    f = np.maximum(invert_value_transform(r.function(U), value_transform, offset), 0.0)
    e = np.abs(f - d.y)
    # Distance to y over the distance from y to the bound on that side (intervals may be
    # asymmetric where the lower bound is clipped at -floor): <= 1 exactly when inside.
    room = np.where(f >= d.y, d.upper - d.y, d.y - d.lower)
    ratio = np.where(e > 0, e / np.maximum(room, 1e-300), 0.0)
    rel_ok = tol * d.y >= d.abs_floor
    rel = e[rel_ok] / d.y[rel_ok]
    inside = (f >= d.lower * (1 - 1e-12) - 1e-300) & (f <= d.upper * (1 + 1e-12))
    return {"max_rel_error": float(rel.max()) if rel.size else 0.0,
            "rms_rel_error": float(np.sqrt(np.mean(rel ** 2))) if rel.size else 0.0,
            "max_interval_ratio": float(np.max(ratio)),
            "inside_fraction": float(inside.mean()), "n_points": int(d.y.size),
            "measured_range": [float(d.y.min()), float(d.y.max())],
            "vouched_range": vouched_envelope(d.lower, d.upper)}
