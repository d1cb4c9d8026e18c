"""Benchmark: time to 1 % error of our renderer against Mitsuba 3, per RGL material
and environment map, on the reference scene of Mitsuba's ``measured`` plugin.

Scene (:mod:`lab.mitsuba_reference`): unit sphere at the origin, camera at (0, 0, 4)
looking at the origin, 30 deg vertical field of view, ``--resolution`` px square (256), the map
at scale 1, hidden; direct lighting with one environment sample and one BSDF sample per camera
sample, power heuristic. Mitsuba renders the ``.bsdf`` file with its ``measured`` plugin and
its ``multijitter`` sampler (``--variant``: ``llvm_ad_rgb`` when a libLLVM is found, else
``scalar_rgb``); we render it through the public renderer API (``Renderer``) with each
``--ours KIND:SAMPLER`` (default ``rgl:mis-rgl``: the file evaluated exactly, its own
importance sampling in MIS, Mitsuba's estimator but for the environment sample's MIS
compensation, ``--mis-compensation``, 0 to turn it off) and our ``stratified`` (correlated
multi-jitter) pattern; the best of them per case is compared.

Error. Both renderers are unbiased estimators of their own converged image, so the RMSE of an
N-spp image against that converged image is estimated from two independent N-spp renders X1, X2
(different seeds): RMSE^2 = mean over the sphere's fully covered pixels and the 3 channels of
(X1 - X2)^2 / 2. The relative RMSE divides by the mean of (X1 + X2) / 2 over the same values.
Each renderer climbs the ladder ``--spp`` (two seeds per rung, the two renderers interleaved
render by render); a rung's time is the median wall-clock time of its renders (one render call
returning a NumPy image, after an untimed warm-up that compiles the kernels; set-up and compile
are reported apart). Time to ``--target`` (1 %): interpolated in log(RMSE)-log(time) between
the two rungs that bracket the target, or, when the last rung is still above it, extrapolated
from the last rung with RMSE proportional to N^-1/2 at that rung's samples/s
(t = t_last * (RMSE_last / target)^2). The table states which, and the measured slope
d log RMSE / d log N between the last two rungs (-0.5 for independent samples; steeper means
stratification still helps and the extrapolation is pessimistic for that renderer).

Extension (heavy-tailed cases; ``--no-extend`` turns it off): near-mirror materials
under a small bright source (the sun of ``rooitou``) have fireflies, and a 64-spp seed-pair
estimate is then dominated by the few that were drawn (relative RMSE 0.7-2.5, extrapolated over a
factor 5000-60000 in time). After the base ladder a renderer's top rung is *untrusted* when its
relative RMSE is above ``--extend-rmse`` (0.25), the standard error of its log MSE above
``--extend-se`` (0.1), or its slope from the rung below outside [-1.1, -0.4]
(:class:`ExtendRule`, :func:`untrusted`); while any renderer still above the target is untrusted,
all of them render one more rung at 4x the spp (two new seeds, interleaved), up to
``--extend-max-spp`` (1024) while the case's render time so far plus 4x its last rung's stays
within ``--extend-budget`` (480 s); past the cap or the budget the top rung pools more seed
pairs, up to ``--extend-pairs`` (8) while one more pair fits the budget
(:func:`seed_pairs_estimate`). Cases that stay untrusted are marked. Uncertainty: per rung
the standard error of the log relative MSE (first order, successive differences over pixels:
:func:`seed_pair_estimate`), propagated to the times and the ratio (:func:`log_time_se`): the
table's ``ratio ± 1 s.e.``.

Check (``--check``): for a few materials, a converged Mitsuba reference (``--check-spp`` spp in
passes of at most 64 spp, two halves with their own seeds; its own noise is the halves'
difference) against the top rung of every renderer: the RMSE against the reference minus the
reference's own variance must equal the seed-pair estimate (Mitsuba: the estimator is right;
ours: also no per-pixel bias against Mitsuba), and the image means must agree within their
standard errors.

    python -m benchmarks.bench_vs_mitsuba [--quick] [--materials a b] [--maps studio rooitou]
        [--resolution 256] [--spp 4 16 64 256] [--ours rgl:mis-rgl measured:mis-tabulated]
        [--variant auto|llvm_ad_rgb|scalar_rgb] [--threads N] [--check 2] [--check-spp 1024]
        [--json results/bench_vs_mitsuba.json] [--docs] [--no-extend] [--extend-max-spp 1024]
        [--extend-budget 480] [--extend-rmse 0.25] [--extend-se 0.1] [--extend-pairs 8]

``--quick``: 2 materials, the studio map, 64 px, spp 4 16, check at 256 spp (the smoke test).
``--docs`` writes docs/bench_vs_mitsuba.md (generated; edits there are overwritten).
The full benchmark is the one command ``python -m benchmarks.bench_vs_mitsuba --docs
--json results/bench_vs_mitsuba.json``: every ``.bsdf`` of ``$RBRDF_DATA/rgl`` (20) under both maps,
256 px, spp 4 16 64 256, the check on 2 materials at 1024 spp: the 36 cases that need no
extension take 15-20 s each, the check about 20 s a material and map; ``--resolution 128``
takes about a quarter of that. The 256-spp rung is in the default ladder because a ratio
extrapolated from 64 spp was off by up to 20 % against a ladder to 1 % itself on six cases
(docs/rendering.md, 2026-11-28), and for the MIS-compensated estimator always low, by 6-20 %:
stratification keeps paying past 64 spp, by an amount that depends on the estimator. The extension adds, per heavy-tailed case, a 1024-spp rung and then up to 7 seed pairs at
1024 spp (16 and 7 s a render, ours / Mitsuba, on the 2-core Zen 5 machine at load 1-2): the
whole run took 42 min there (2026-11-28, 2,508 s); expect 4 such cases (ilm_solo_m_68 and
chm_mint under both maps). They stay untrusted at 1024 spp with 8 pairs: the standard error of
log MSE is 0.12-0.14 under studio (the threshold 0.1) and the relative RMSE 0.38-0.66 under
rooitou, where it barely falls from 64 to 1024 spp (Mitsuba, ilm_solo_m_68: 0.72, 0.94, 0.66),
the sign of rare events (the sun in a near-mirror lobe) not yet sampled often enough for
N^-1/2; their ratios carry +-18-20 % (studio) and +-38 % (rooitou), lower bounds.
Mitsuba comes with the ``reference`` extra; its LLVM variant needs a shared libLLVM (Debian:
``apt-get install libllvm19``; found automatically, or set ``DRJIT_LIBLLVM_PATH``).
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import itertools
import json
import os
import platform
import shlex
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warp_rbrdf.scene.specs import IntegratorSpec

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "bench_vs_mitsuba.md"

#: The two maps (files under $RBRDF_DATA/envmaps): a few compact lights, a tiny strong sun.
MAPS = {"studio": "envmaps/studio_small_03_1k.hdr", "rooitou": "envmaps/rooitou_park_1k.hdr"}
#: --quick: one glossy and one diffuse file, one map.
QUICK_MATERIALS = ("cc_ibiza_sunset_rgb", "paper_white_rgb")
#: Materials of the --check (when selected): the same two.
CHECK_MATERIALS = QUICK_MATERIALS
#: Our renderer's sample pattern (its best: correlated multi-jitter) and Mitsuba's sampler.
OUR_PATTERN = "stratified"
MITSUBA_SAMPLER = "multijitter"
#: Largest Mitsuba pass of the check's reference (spp; keeps the LLVM wavefront in memory).
MAX_PASS_SPP = 64
#: The accuracy-speed targets (reported, never asserted).
TARGETS = {"median_ratio": 3.0, "max_ratio": 10.0, "rate_ratio": 0.4}


# --------------------------------------------------------------------------------------------
# Error and time to the target
def seed_pair_estimate(x1: np.ndarray, x2: np.ndarray, mask: np.ndarray) -> tuple[float, float, float]:
    """(relative RMSE of one render, mean, standard error of the log relative MSE) from two
    independent renders ``x1``, ``x2`` (H, W, 3) of the same unbiased estimator, over the pixels
    of ``mask`` (H, W) and the 3 channels.

    Relative RMSE: sqrt(mean((x1 - x2)^2) / 2) / mean((x1 + x2) / 2). Its uncertainty: per pixel
    v = mean over channels of (x1 - x2)^2 / 2 and m = mean over channels of (x1 + x2) / 2
    (channels correlate, pixels are taken as independent); the relative MSE is mean(v) / mean(m)^2
    = V / M^2 and, to first order, log(V / M^2) - its value = mean(z) with z = v / V - 2 m / M.
    The variance of each z_p is estimated from successive differences along the mask's
    row-major order, var(mean(z)) = sum((z_p+1 - z_p)^2) / 2 / P^2, which removes the image's
    smooth variation of the per-pixel variance (a highlight's pixels have a larger variance
    than the rest: structure, not noise; a plain or block bootstrap over pixels counts it and
    overstates the error 4x on a synthetic highlight). It is the relative standard error of a
    time to the target extrapolated from these renders (time ~ MSE). Large when a few pixels
    (fireflies) carry the sum; for such heavy-tailed noise it is a lower bound (it sees only
    the rare events that were drawn, and the log is nonlinear: 1.6-2.7x below the spread over
    independent pairs on synthetic Pareto fireflies)."""
    return _estimate(*_pixel_terms(x1, x2, mask))


def _pixel_terms(x1, x2, mask) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel of ``mask``: v, the channel mean of (x1 - x2)^2 / 2, and m, of (x1 + x2) / 2."""
    a = np.asarray(x1, np.float64)[mask]
    b = np.asarray(x2, np.float64)[mask]
    return ((a - b) ** 2 / 2).reshape(len(a), -1).mean(axis=1), ((a + b) / 2).reshape(len(a), -1).mean(axis=1)


def _estimate(v: np.ndarray, m: np.ndarray) -> tuple[float, float, float]:
    """(relative RMSE, mean, first-order standard error of the log relative MSE) of the per-pixel
    terms of :func:`_pixel_terms` (:func:`seed_pair_estimate`'s formula)."""
    V, M = float(v.mean()), float(m.mean())
    if not (M > 0) or len(v) < 2:
        return float("inf"), M, float("inf")
    rel = float(np.sqrt(V) / M)
    if not (V > 0):
        return rel, M, float("inf")
    z = v / V - 2 * m / M
    return rel, M, float(np.sqrt(np.sum(np.diff(z) ** 2) / 2) / len(z))


def seed_pairs_estimate(pairs: list, mask: np.ndarray) -> tuple[float, float, float]:
    """:func:`seed_pair_estimate` pooled over ``pairs`` (a list of (x1, x2), independent seed
    pairs of one spp): per pixel v and m averaged over the pairs, then the same relative RMSE and
    first-order standard error; with two pairs or more the standard error is at least the spread
    of the pairs' own log MSE over sqrt(pairs) (model-free: it sees the rare large samples one
    pair drew and another did not). One pair: :func:`seed_pair_estimate` itself."""
    if len(pairs) == 1:
        return seed_pair_estimate(*pairs[0], mask)
    terms = [_pixel_terms(x1, x2, mask) for x1, x2 in pairs]
    rel, M, se = _estimate(np.mean([v for v, _ in terms], axis=0), np.mean([m for _, m in terms], axis=0))
    logs = [np.log(v.mean() / m.mean() ** 2) for v, m in terms if v.mean() > 0 and m.mean() > 0]
    if np.isfinite(se) and len(logs) == len(pairs):
        se = max(se, float(np.std(logs, ddof=1) / np.sqrt(len(logs))))
    return rel, M, se


def relative_rmse(x1: np.ndarray, x2: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """(relative RMSE of one render, mean): the first two numbers of :func:`seed_pair_estimate`."""
    rel, mean, _ = seed_pair_estimate(x1, x2, mask)
    return rel, mean


@dataclass
class Rung:
    spp: int
    seconds: float          # median wall-clock seconds of one render at this spp
    rel_rmse: float         # of one render (seed-pair estimate)
    mean: float             # image mean over the mask (both renders)
    times: list = field(default_factory=list)
    mse_se: float = 0.0     # standard error of log(rel_rmse^2) (seed_pairs_estimate)
    pairs: int = 1          # independent seed pairs pooled at this spp

    @property
    def samples_per_s(self) -> float:
        return self.spp / self.seconds   # per pixel; multiplied by the pixel count where shown


def time_to_target(rungs: list[Rung], target: float) -> tuple[float, str]:
    """Seconds of one render whose relative RMSE is ``target``, and how it was found:
    "interpolated" (log-log between the bracketing rungs), "measured" (the first rung already
    at or below the target: scaled down with RMSE ~ N^-1/2 at its rate) or "extrapolated"
    (from the last rung, RMSE ~ N^-1/2 at its samples/s)."""
    ok = [r for r in rungs if np.isfinite(r.rel_rmse) and r.rel_rmse > 0]
    if not ok:
        return float("nan"), "none"
    for lo, hi in itertools.pairwise(ok):
        if lo.rel_rmse > target >= hi.rel_rmse:
            u = (np.log(target) - np.log(lo.rel_rmse)) / (np.log(hi.rel_rmse) - np.log(lo.rel_rmse))
            return float(np.exp(np.log(lo.seconds) + u * (np.log(hi.seconds) - np.log(lo.seconds)))), \
                "interpolated"
    first, last = ok[0], ok[-1]
    if first.rel_rmse <= target:
        return first.seconds * (first.rel_rmse / target) ** 2, "measured"
    return last.seconds * (last.rel_rmse / target) ** 2, "extrapolated"


def time_to_target_slope(rungs: list[Rung], target: float) -> float:
    """Like :func:`time_to_target`, but an extrapolation from the last rung follows the measured
    slope s of the last two rungs, clamped to [-1, -0.5] (RMSE ~ N^s, time ~ N), instead of
    N^-1/2: t = t_last * (RMSE_last / target)^(1 / |s|). Stratification keeps s below -0.5 at
    low spp and fades at high spp, so the true time lies between the two estimates."""
    t, how = time_to_target(rungs, target)
    if how != "extrapolated":
        return t
    s = last_slope(rungs)
    s = -0.5 if not np.isfinite(s) else min(max(s, -1.0), -0.5)
    last = rungs[-1]
    return last.seconds * (last.rel_rmse / target) ** (1.0 / abs(s))


def last_slope(rungs: list[Rung]) -> float:
    """d log(relative RMSE) / d log(spp) between the last two rungs (NaN with one rung)."""
    if len(rungs) < 2:
        return float("nan")
    a, b = rungs[-2], rungs[-1]
    return float(np.log(b.rel_rmse / a.rel_rmse) / np.log(b.spp / a.spp))


def log_time_se(rungs: list[Rung], target: float, how=None) -> float:
    """First-order standard error of log(time to ``target``) from the rungs' ``mse_se``:
    sqrt(sum_i (d log t / d log MSE_i * mse_se_i)^2), the derivatives by finite differences of
    ``how`` (:func:`time_to_target` by default, or :func:`time_to_target_slope`). For a time
    extrapolated with N^-1/2 it is the top rung's ``mse_se``; timing noise is not included."""
    how = how or time_to_target

    def t_of(rs):
        t = how(rs, target)
        return t[0] if isinstance(t, tuple) else t

    t0 = t_of(rungs)
    if not (np.isfinite(t0) and t0 > 0):
        return float("nan")
    h = 1e-4
    var = 0.0
    for i, r in enumerate(rungs):
        pert = list(rungs)
        pert[i] = dataclasses.replace(r, rel_rmse=r.rel_rmse * np.exp(h / 2))   # MSE * e^h
        d = (np.log(t_of(pert)) - np.log(t0)) / h
        if abs(d) > 1e-9:
            var += (d * r.mse_se) ** 2
    return float(np.sqrt(var))


# --------------------------------------------------------------------------------------------
# Extending the ladder for cases whose estimate is not trustworthy
@dataclass(frozen=True)
class ExtendRule:
    """When a case's ladder gets another rung (``factor`` x the top spp, every renderer still
    above the target, interleaved as the base ladder). A renderer's top rung is *untrusted* when

    - its relative RMSE exceeds ``max_rel_rmse``: the N^-1/2 extrapolation to the target would
      span more than a factor (max_rel_rmse / target)^2 in spp (625 for 0.25 and 1 %), or
    - the standard error of its log MSE (:func:`seed_pair_estimate`; = the relative standard
      error of its extrapolated time) exceeds ``max_mse_se``, or
    - its slope d log RMSE / d log N from the rung below lies outside ``slope_band``: an
      unbiased estimator with finite variance converges between N^-1 (2-D stratification of a
      smooth integrand) and N^-1/2 (independent samples), so a slope outside [-1, -0.5] by more
      than the band's margin means the estimate is noise-dominated (a firefly at one rung and
      not the other) or the case is not yet in its asymptotic regime.

    The case is extended while any renderer still above the target is untrusted. Where the next
    rung would exceed ``max_spp``, or the case's render time so far plus ``factor`` x its last
    rung's time would exceed ``budget_s``, the top rung gets another seed pair instead (pooled:
    :func:`seed_pairs_estimate`) while it holds fewer than ``max_pairs`` and the time so far
    plus one more pair (the last pair's time) stays within ``budget_s``; after that the case
    is reported as unresolved, with the reasons. ``enabled=False`` (``--no-extend``) only
    reports."""

    enabled: bool = True
    max_rel_rmse: float = 0.25
    max_mse_se: float = 0.10
    slope_band: tuple[float, float] = (-1.1, -0.4)
    max_spp: int = 1024
    budget_s: float = 480.0
    factor: int = 4
    max_pairs: int = 8


def untrusted(rungs: dict[str, list[Rung]], target: float, rule: ExtendRule) -> list[str]:
    """Why the top rungs of ``rungs`` (renderer label -> rungs, ascending spp) are not
    trustworthy under ``rule`` (one line per renderer and failed test; empty: trusted).
    Renderers already at or below ``target`` are trusted (interpolated, not extrapolated)."""
    out = []
    lo, hi = rule.slope_band
    for label, rs in rungs.items():
        if not rs:
            continue
        top = rs[-1]
        if top.rel_rmse <= target:
            continue
        if not (top.rel_rmse <= rule.max_rel_rmse):
            out.append(f"{label} rel. RMSE {top.rel_rmse:.3g} > {rule.max_rel_rmse:g} at {top.spp} spp")
        if not (top.mse_se <= rule.max_mse_se):
            out.append(f"{label} s.e. of log MSE {top.mse_se:.3g} > {rule.max_mse_se:g} at {top.spp} spp")
        s = last_slope(rs)
        if len(rs) >= 2 and not (lo <= s <= hi):
            out.append(f"{label} slope {s:.3g} outside [{lo:g}, {hi:g}] at {rs[-2].spp}-{top.spp} spp")
    return out


def next_rung(rungs: dict[str, list[Rung]], target: float, rule: ExtendRule, spent_s: float,
              last_rung_s: float) -> tuple[int | None, list[str], str]:
    """The extension decision after the ladder's rungs so far: (next spp or None, reasons
    (:func:`untrusted`), status). Status: "trusted" (nothing to do), "extend" (render the next
    spp), "seeds" (render one more seed pair at the top spp: the next rung would pass
    ``rule.max_spp`` or the budget, and the top rung holds fewer than ``rule.max_pairs`` pairs
    with ``spent_s + last_rung_s`` within ``rule.budget_s``), "cap" (the next rung would pass
    ``rule.max_spp``), "budget" (``spent_s`` seconds of rendering so far plus ``rule.factor`` x
    ``last_rung_s`` would pass ``rule.budget_s``) or "off" (``rule.enabled`` is false)."""
    reasons = untrusted(rungs, target, rule)
    if not reasons:
        return None, [], "trusted"
    if not rule.enabled:
        return None, reasons, "off"
    top = max(rs[-1].spp for rs in rungs.values() if rs)
    nxt = rule.factor * top
    if nxt <= rule.max_spp and spent_s + rule.factor * last_rung_s <= rule.budget_s:
        return nxt, reasons, "extend"
    # the renderers that would render the pair: at the top spp and still above the target
    pairs = min((rs[-1].pairs for rs in rungs.values() if rs and rs[-1].spp == top and rs[-1].rel_rmse > target),
                default=rule.max_pairs)
    if pairs < rule.max_pairs and spent_s + last_rung_s <= rule.budget_s:
        return top, reasons, "seeds"
    return None, reasons, ("cap" if nxt > rule.max_spp else "budget")


# --------------------------------------------------------------------------------------------
# The two renderers
class Ours:
    """Our renderer on the reference scene with material kind ``kind`` from the ``.bsdf`` file
    and strategy ``sampler`` (through the public API: Scene -> Renderer -> render)."""

    def __init__(self, config: str, path: Path, envmap: Path, resolution: int, threads: int,
                 mis_compensation: float | None = None):
        from lab import mitsuba_reference as MR
        from warp_rbrdf.renderer import Renderer
        from warp_rbrdf.scene import MaterialSpec

        self.label = config
        kind, sampler = config.split(":")
        sc = MR.sphere_scene(path, envmap, 1, resolution, pattern=OUR_PATTERN)
        if (kind, sampler) != ("rgl", "mis-rgl"):
            sc = copy.copy(sc)
            sc.materials = {"obj": MaterialSpec(name="obj", type=kind, file=Path(path), sampler=sampler,
                                                incident="view")}
            sc.integrator = copy.copy(sc.integrator)
            sc.integrator.sampler = sampler
        if mis_compensation is not None:     # sc.integrator is this scene's own (sphere_scene builds it)
            sc.integrator.mis_compensation = float(mis_compensation)
        self.threads = threads
        t0 = time.perf_counter()
        self.r = Renderer(sc, device="cpu")
        self.setup_s = time.perf_counter() - t0
        self.compile_s = self.r.compile()
        t0 = time.perf_counter()
        self.r.render(spp=1, seed=2**31, threads=threads)   # warm-up (first launches)
        self.warmup_s = time.perf_counter() - t0

    def render(self, spp: int, seed: int) -> tuple[np.ndarray, float]:
        t0 = time.perf_counter()
        img = self.r.render(spp=spp, seed=seed, threads=self.threads)
        return np.asarray(img, np.float64), time.perf_counter() - t0


class Mitsuba:
    """Mitsuba 3's ``measured`` plugin on the same scene, ``multijitter`` sampler. A JIT variant
    compiles a kernel per (spp, scene layout): the first render of each spp of a case is an
    untimed warm-up (its seconds are reported as compile)."""

    label = "mitsuba"

    def __init__(self, path: Path, envmap: Path, resolution: int, spp: int):
        from lab import mitsuba_reference as MR

        self.MR = MR
        t0 = time.perf_counter()
        self.scene = MR.timing_scene(path, envmap, spp, resolution, sampler=MITSUBA_SAMPLER)
        self.setup_s = time.perf_counter() - t0
        self.compile_s = 0.0

    def warm(self, spp: int):
        t0 = time.perf_counter()
        self.MR.render_timed(self.scene, spp, seed=2**31 - 1)
        self.compile_s += time.perf_counter() - t0

    def render(self, spp: int, seed: int) -> tuple[np.ndarray, float]:
        return self.MR.render_timed(self.scene, spp, seed)  # spp overrides the sampler's count

    def reference(self, spp: int, seed0: int) -> tuple[np.ndarray, np.ndarray]:
        """Two independent half-``spp`` images (passes of <= MAX_PASS_SPP spp, own seeds)."""
        per = min(MAX_PASS_SPP, spp // 2)
        n = max(1, (spp // 2) // per)
        halves = []
        for h in range(2):
            acc = 0.0
            for k in range(n):
                img, _ = self.render(per, seed0 + h * n + k)
                acc = acc + img
            halves.append(acc / n)
        return halves[0], halves[1]


# --------------------------------------------------------------------------------------------
def climb(renderers: list, ladder: list[int], target: float, rule: ExtendRule, mask: np.ndarray,
          log=print) -> tuple[dict, dict, dict]:
    """Render the ``ladder`` (spp, ascending) with every renderer, then extend it under ``rule``
    (:func:`next_rung`). A renderer is an object with ``label`` and ``render(spp, seed) ->
    (image (H, W, 3), seconds)``, and optionally ``warm(spp)`` (an untimed warm-up before each
    of its rungs). Per rung: two seeds, the renderers interleaved render by render; a renderer
    whose last rung is at or below ``target`` stops; another seed pair at the top spp (status
    "seeds") is pooled into the top rung. Returns (label -> list of :class:`Rung`, label -> the
    top rung's last two images, the extension record: its rungs (and seed pairs) with their
    reasons, the final status and reasons, the top spp, the case's render seconds)."""
    rungs = {r.label: [] for r in renderers}
    last_images = {}
    top_pairs = {r.label: [] for r in renderers}      # the seed pairs of each renderer's top rung
    extension = {"rungs": [], "status": "trusted", "reasons": []}
    t_case = time.perf_counter()
    last_rung_s = 0.0
    k = 0
    while True:
        if k < len(ladder):
            spp = ladder[k]
        else:   # the base ladder is done: extend while the estimate is not trustworthy
            spp, reasons, status = next_rung(rungs, target, rule, time.perf_counter() - t_case, last_rung_s)
            extension["status"], extension["reasons"] = status, reasons
            if spp is None:
                if reasons:
                    log(f"  not extended ({status}): " + "; ".join(reasons))
                break
            if status == "seeds":
                extension["rungs"].append({"spp": spp, "reasons": reasons, "seed_pair": True})
                log(f"  another seed pair at {spp} spp: " + "; ".join(reasons))
            else:
                extension["rungs"].append({"spp": spp, "reasons": reasons})
                log(f"  extending to {spp} spp: " + "; ".join(reasons))
        active = [r for r in renderers if not rungs[r.label] or rungs[r.label][-1].rel_rmse > target]
        if not active:
            break
        t_rung = time.perf_counter()
        for r in active:
            if hasattr(r, "warm"):
                r.warm(spp)
        seeds = (1000 + 2 * k, 1001 + 2 * k)
        imgs = {r.label: [] for r in active}
        times = {r.label: [] for r in active}
        for seed in seeds:                       # interleaved: every renderer, then the next seed
            for r in active:
                img, dt = r.render(spp, seed)
                imgs[r.label].append(img)
                times[r.label].append(dt)
        for r in active:
            rs = rungs[r.label]
            if rs and rs[-1].spp == spp:               # another seed pair at the top spp: pooled
                top_pairs[r.label].append(tuple(imgs[r.label]))
                times[r.label] = rs[-1].times + times[r.label]
                rs.pop()
            else:
                top_pairs[r.label] = [tuple(imgs[r.label])]
            e, mean, se = seed_pairs_estimate(top_pairs[r.label], mask)
            rs.append(Rung(spp, statistics.median(times[r.label]), e, mean, times[r.label], se,
                           len(top_pairs[r.label])))
            last_images[r.label] = imgs[r.label]
        last_rung_s = time.perf_counter() - t_rung
        log("  " + "  ".join(f"{r.label} {spp} spp {rungs[r.label][-1].seconds:.2f} s "
                             f"rmse {rungs[r.label][-1].rel_rmse:.4f} (s.e. {rungs[r.label][-1].mse_se:.2g}"
                             f"{', ' + str(rungs[r.label][-1].pairs) + ' pairs' if rungs[r.label][-1].pairs > 1 else ''})"
                             for r in active))
        k += 1
    extension["top_spp"] = max(rs[-1].spp for rs in rungs.values() if rs)
    extension["render_s"] = time.perf_counter() - t_case
    return rungs, last_images, extension


def run_case(material: str, path: Path, map_name: str, envmap: Path, a, mask, log) -> dict:
    ours = [Ours(c, path, envmap, a.resolution, a.threads, a.mis_compensation) for c in a.ours]
    mit = Mitsuba(path, envmap, a.resolution, a.spp[0])
    renderers = ours + [mit]
    rungs, last_images, extension = climb(renderers, list(a.spp), a.target, a.extend_rule, mask, log)
    npx = int(a.resolution) ** 2
    out = {"material": material, "map": map_name, "renderers": {}}
    for r in renderers:
        rs = rungs[r.label]
        t, how = time_to_target(rs, a.target)
        out["renderers"][r.label] = {
            "setup_s": r.setup_s, "compile_s": r.compile_s, "time_to_target_s": t, "how": how,
            "time_to_target_slope_s": time_to_target_slope(rs, a.target),
            "time_log_se": log_time_se(rs, a.target),
            "time_slope_log_se": log_time_se(rs, a.target, time_to_target_slope),
            "slope": last_slope(rs), "samples_per_s": npx * rs[-1].samples_per_s,
            "rungs": [{"spp": x.spp, "seconds": x.seconds, "times": x.times, "rel_rmse": x.rel_rmse,
                       "mean": x.mean, "mse_se": x.mse_se, "pairs": x.pairs} for x in rs]}
    best = min((c for c in a.ours), key=lambda c: out["renderers"][c]["time_to_target_s"])
    out["best"] = best
    out["ratio"] = out["renderers"][best]["time_to_target_s"] / out["renderers"]["mitsuba"]["time_to_target_s"]
    out["ratio_slope"] = (out["renderers"][best]["time_to_target_slope_s"]
                          / out["renderers"]["mitsuba"]["time_to_target_slope_s"])
    out["rate_ratio"] = out["renderers"][best]["samples_per_s"] / out["renderers"]["mitsuba"]["samples_per_s"]
    o, mi = out["renderers"][best], out["renderers"]["mitsuba"]
    out["ratio_log_se"] = float(np.hypot(o["time_log_se"], mi["time_log_se"]))
    out["ratio_slope_log_se"] = float(np.hypot(o["time_slope_log_se"], mi["time_slope_log_se"]))
    out["extension"] = extension
    if material in a.check_materials:
        out["check"] = check(mit, last_images, rungs, a, mask, log)
    return out


def check(mit: Mitsuba, last_images: dict, rungs: dict, a, mask, log) -> dict:
    """Every renderer's top rung against a converged Mitsuba reference (see the docstring)."""
    t0 = time.perf_counter()
    r1, r2 = mit.reference(a.check_spp, seed0=100000)
    ref_s = time.perf_counter() - t0
    R1, R2 = r1[mask], r2[mask]
    R = (R1 + R2) / 2
    mean_r = float(R.mean())
    var_r = (R1 - R2) ** 2 / 4                       # per-value variance of the reference
    out = {"reference_spp": a.check_spp, "reference_s": ref_s,
           "reference_rel_rmse": float(np.sqrt(var_r.mean()) / mean_r), "renderers": {}}
    for label, (x1, x2) in last_images.items():
        X1, X2 = x1[mask], x2[mask]
        var_x = (X1 - X2) ** 2 / 2                   # per-value variance of one render
        mse_ref = (np.mean((X1 - R) ** 2) + np.mean((X2 - R) ** 2)) / 2
        corrected = max(mse_ref - var_r.mean(), 0.0)
        pair = rungs[label][-1].rel_rmse
        vs_ref = float(np.sqrt(corrected) / mean_r)
        bias_ms = mse_ref - var_r.mean() - var_x.mean()
        mean_x = float((X1 + X2).mean() / 2)
        se = float(np.sqrt(var_x.sum() / 2 + var_r.sum())) / X1.size
        out["renderers"][label] = {
            "spp": rungs[label][-1].spp, "pair_rel_rmse": pair, "ref_rel_rmse": vs_ref,
            "ratio": vs_ref / pair if pair > 0 else float("nan"),
            "pixel_bias_rel_rms": float(np.sign(bias_ms) * np.sqrt(abs(bias_ms)) / mean_r),
            "mean_rel_diff": (mean_x - mean_r) / mean_r, "mean_z": (mean_x - mean_r) / se if se > 0 else 0.0}
        log(f"  check {label}: pair {pair:.4f} vs reference {vs_ref:.4f} (ratio {vs_ref / pair:.3f}); "
            f"mean {100 * (mean_x - mean_r) / mean_r:+.3f} % (z {out['renderers'][label]['mean_z']:+.1f})")
    return out


# --------------------------------------------------------------------------------------------
def summarize(cases: list[dict]) -> dict:
    ratios = [c["ratio"] for c in cases if np.isfinite(c["ratio"])]
    rates = [c["rate_ratio"] for c in cases if np.isfinite(c["rate_ratio"])]
    s = {"cases": len(cases),
         "median_ratio": float(np.median(ratios)) if ratios else float("nan"),
         "max_ratio": float(np.max(ratios)) if ratios else float("nan"),
         "min_ratio": float(np.min(ratios)) if ratios else float("nan"),
         "median_rate_ratio": float(np.median(rates)) if rates else float("nan"),
         "median_variance_ratio": float(np.median([
             (c["renderers"][c["best"]]["rungs"][-1]["rel_rmse"] / c["renderers"]["mitsuba"]["rungs"][-1]["rel_rmse"]) ** 2
             for c in cases])),
         "median_ratio_slope": float(np.median([c["ratio_slope"] for c in cases])),
         "max_ratio_slope": float(np.max([c["ratio_slope"] for c in cases])),
         "median_samples_per_s": {},
         "extended": [_case_name(c) for c in cases if c.get("extension", {}).get("rungs")],
         "unresolved": [_case_name(c) for c in cases
                        if c.get("extension", {}).get("status") in ("cap", "budget", "off")]}
    if ratios:
        worst = max((c for c in cases if np.isfinite(c["ratio"])), key=lambda c: c["ratio"])
        s["max_ratio_case"] = _case_name(worst)
        s["max_ratio_log_se"] = worst.get("ratio_log_se", float("nan"))
    trusted = [c["ratio"] for c in cases if np.isfinite(c["ratio"]) and _case_name(c) not in s["unresolved"]]
    s["max_ratio_trusted"] = float(np.max(trusted)) if trusted else float("nan")
    s["median_ratio_trusted"] = float(np.median(trusted)) if trusted else float("nan")
    labels = sorted({k for c in cases for k in c["renderers"]})
    for k in labels:
        v = [c["renderers"][k]["samples_per_s"] for c in cases if k in c["renderers"]]
        s["median_samples_per_s"][k] = float(np.median(v))
    s["targets"] = {"median_ratio <= 3": s["median_ratio"] <= TARGETS["median_ratio"],
                    "max_ratio <= 10": s["max_ratio"] <= TARGETS["max_ratio"],
                    "samples/s >= 40 % of Mitsuba's (median)": s["median_rate_ratio"] >= TARGETS["rate_ratio"]}
    return s


def _case_name(c: dict) -> str:
    return f"{c['material'].removesuffix('_rgb')} / {c['map']}"


def _pm(x: float, log_se: float) -> str:
    """``x`` ± its first-order standard error (``log_se`` = standard error of log x)."""
    if not np.isfinite(log_se):
        return _f(x)
    return f"{_f(x)} ± {_f(x * log_se, 2)}"


def _top(c: dict) -> str:
    """Top spp of a case: * extended, ! still untrusted where the extension stopped."""
    e = c.get("extension", {})
    mark = ("*" if e.get("rungs") else "") + ("!" if e.get("status") in ("cap", "budget", "off") else "")
    return f"{e.get('top_spp', '–')}{mark}"


def _extension_rungs(rungs: list[dict]) -> str:
    """The extension's rungs for the table: their spp, then ``+ k pairs at N`` for the seed
    pairs added at the top spp."""
    spps = [str(x["spp"]) for x in rungs if not x.get("seed_pair")]
    pairs = [x["spp"] for x in rungs if x.get("seed_pair")]
    if pairs:
        spps.append(f"+ {len(pairs)} seed pair{'s' if len(pairs) > 1 else ''} at {pairs[-1]}")
    return ", ".join(spps)


def _compact(reasons: list[str]) -> str:
    """:func:`untrusted`'s lines as "label: RMSE x, s.e. y, slope z; label: ..."."""
    import re

    per: dict[str, list[str]] = {}
    for w in reasons:
        m = re.match(r"(\S+) (rel\. RMSE|s\.e\. of log MSE|slope) (\S+)", w)
        if m:
            key = {"rel. RMSE": "RMSE", "s.e. of log MSE": "s.e."}.get(m.group(2), m.group(2))
            per.setdefault(m.group(1), []).append(f"{key} {m.group(3)}")
    return "; ".join(f"{k}: {', '.join(v)}" for k, v in per.items()) or "–"


def _f(x, digits=3):
    if not isinstance(x, (int, float)) or not np.isfinite(x):
        return "–"
    a = abs(x)
    if a != 0 and (a < 1e-3 or a >= 1e5):
        return f"{x:.2e}"
    return f"{x:.{digits}g}" if a < 100 else f"{x:.0f}"


def md_table(rows, header) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(" --- " for _ in header) + "|"]
    out += ["| " + " | ".join(x if isinstance(x, str) else _f(x) for x in r) + " |" for r in rows]
    return "\n".join(out) + "\n"


def _method_extension(a: dict) -> str:
    """The Method paragraph on the ladder's extension and the ratios' uncertainty."""
    e = ExtendRule(**{**dataclasses.asdict(ExtendRule()), **a.get("extend", {}),
                      "slope_band": tuple(a.get("extend", {}).get("slope_band", ExtendRule.slope_band))})
    lo, hi = e.slope_band
    rule = (
        f"**Ladder extension** ({'on' if e.enabled else 'off: `--no-extend`, untrusted cases only reported'}). "
        "After the base ladder a renderer's top rung is *untrusted* when (a) its relative RMSE is above "
        f"{e.max_rel_rmse:g} (the extrapolation to {100 * a['target']:g} % would span more than a factor "
        f"{(e.max_rel_rmse / a['target']) ** 2:.0f} in N), (b) the standard error of its log MSE (below) is "
        f"above {e.max_mse_se:g}, or (c) its slope from the rung below lies outside [{lo:g}, {hi:g}] (an "
        "unbiased estimator of finite variance converges between N^−1, 2-D stratification of a smooth "
        "integrand, and N^−1/2, independent samples: a slope outside [−1, −0.5] by more than 0.1 means "
        "one of the two estimates is noise-dominated, e.g. fireflies at one rung and not the other, or "
        "the case is not yet in its asymptotic regime). While a renderer still above the target has an "
        f"untrusted top rung, every renderer still above the target renders one more rung at {e.factor}× "
        "the spp (two new seeds, interleaved as above), up to "
        f"{e.max_spp} spp and while the case's render time so far plus {e.factor}× its last rung's stays "
        f"within {e.budget_s:g} s. More spp first rather than more seeds: at equal cost both draw the "
        "same number of samples (the same chance to draw rare, large contributions), and more spp also "
        "shortens the extrapolation and brings both renderers closer to their asymptotic slope. Where "
        "the next rung would pass the cap or the budget, the top rung gets more seed pairs instead (two "
        f"new seeds each, interleaved), up to {e.max_pairs} pairs while the case's render time plus one "
        "more pair stays within the budget: the pairs are pooled (per pixel the mean of their squared "
        "differences and of their means), and the standard error is at least the spread of the pairs' "
        "own log MSE over √pairs. *top spp*: the last rung (* extended; ! still untrusted where the cap "
        "or the budget stopped it, reasons below the table).")
    unc = (
        "**Uncertainty** (the ± of the ratios, 1 σ, first order): per rung, the standard error of the "
        "log of the seed-pair relative MSE to first order: per pixel the channel means v = (X1 − X2)²/2 "
        "and m = (X1 + X2)/2, z = v/V − 2m/M (V, M their means over the P pixels), var(log MSE) = "
        "var(mean z), each pixel's variance of z estimated from successive differences along mask "
        "rows: Σ(z_{p+1} − z_p)² / 2 / P² (pixels independent; the image's smooth variation of the "
        "per-pixel variance, e.g. a highlight, is structure, not noise, and cancels). It is "
        "propagated through each renderer's time to the target (for an extrapolated time it is the "
        "top rung's standard error) and combined over the two renderers in quadrature. It is large "
        "when a few pixels carry the sum; it counts neither "
        "timing noise nor the extrapolation's model error (the "
        "two ratio columns bracket that), and it cannot see contributions rarer than the renders drew: "
        "for a case still untrusted at its top rung (!) it is a lower bound.")
    return rule + "\n\n" + unc


def _compensation_text(a: dict) -> str:
    """How our environment sample differs from Mitsuba's, for the Method paragraph."""
    f = a.get("mis_compensation", 0.0)
    if not f:
        return ("; the environment sampled by its full luminance, as Mitsuba's `envmap` does: the "
                "same estimator")
    return (f"; our environment sample is MIS-compensated (`integrator.mis_compensation` = {f:g}: "
            f"it samples the map's luminance less {f:g} of its mean, docs/sampling.md), Mitsuba's "
            "`envmap` samples the full luminance: the variance columns compare the two estimators")


def report(res: dict) -> str:
    """The Markdown report (docs/bench_vs_mitsuba.md)."""
    cases, s, m = res["cases"], res["summary"], res["machine"]
    a = res["args"]
    L = ["# Time to 1 % error: our renderer against Mitsuba 3", "",
         ("What it measures: the wall-clock time each renderer needs to reach 1 % relative RMSE against "
         "its own converged image, our renderer (`--ours`, by default the `rgl` material: the RGL "
         "file evaluated exactly, sampler `mis-rgl`) against Mitsuba 3's `measured` plugin, on the "
         "shared RGL-EPFL materials under the `studio` and `rooitou` maps in the reference scene of "
         "that plugin; and how the ratio splits into samples per second and variance per sample."), "",
         f"Command: `{res['command']}` (with `--docs` it regenerates this page; edits here are overwritten).",
         "",
         (f"Wall time: {res['wall_s']:.0f} s. Machine: {m['cpus']} CPUs ({m['processor']}), {m['platform']}, "
         f"Python {m['python']}, Warp {m['warp']}, Mitsuba {m['mitsuba']} variant `{m['variant']}`"
         f"{' (libLLVM ' + m['libllvm'] + ')' if m.get('libllvm') else ''}; both renderers on "
         f"{a['threads']} threads; load average at start {m['loadavg_start']}, at end "
         f"{m['loadavg_end']}; finished {res['date']}."), ""]
    method = ["## Method", "",
         (f"Reference scene of Mitsuba's `measured` plugin (unit sphere, camera at (0, 0, 4), 30° vertical "
         f"fov, hidden map at scale 1, direct lighting: one environment and one BSDF sample per camera "
         f"sample, power heuristic), {a['resolution']}×{a['resolution']} px. Mitsuba: `measured` plugin, "
         f"`{MITSUBA_SAMPLER}` sampler. Ours (`warp_rbrdf.Renderer`, `{OUR_PATTERN}` pattern = correlated "
         f"multi-jitter): {', '.join('`' + c + '`' for c in a['ours'])} (material kind : sampler; the "
         "best per case is compared)" + _compensation_text(a) + "."), "",
         ("Each renderer against **its own converged image**: the RMSE of one N-spp render is estimated "
         "from two independent N-spp renders X1, X2 (seeds differ) as sqrt(mean((X1 − X2)²) / 2) over "
         f"the {res['mask_pixels']} pixels fully inside the sphere's silhouette and the 3 channels, "
         "relative to the image mean there. Ladder: "
         f"{', '.join(str(x) for x in a['spp'])} spp, two seeds per rung, the renderers interleaved render "
         "by render; a rung's time is the median wall-clock time of one render call returning a NumPy "
         "image, after an untimed warm-up (kernel compile; Mitsuba's LLVM variant compiles per spp). "
         f"Time to {100 * a['target']:g} %: interpolated in log RMSE – log time between bracketing rungs, "
         "else extrapolated from the last rung with RMSE ∝ N^−1/2 at its samples/s "
         "(t = t_last · (RMSE_last / target)²). *slope*: d log RMSE / d log N between the last two "
         "rungs (−0.5 for independent samples; steeper: stratification still helps, so the "
         "extrapolation overstates that renderer's time). Ratio = ours / Mitsuba (> 1: Mitsuba faster). "
         "*ratio (slopes)*: the same with each renderer extrapolated along its own measured slope "
         "(clamped to [−1, −0.5]; t = t_last · (RMSE_last / target)^(1/|slope|)); stratification fades "
         "as N grows, so the true ratio lies between the two columns. "
         "Samples/s: camera samples (each: camera ray, environment sample, BSDF sample, two shadow rays) "
         "per second at the top rung. *variance ratio*: (ours / Mitsuba relative RMSE)² at the top rung "
         "(equal spp): with N^−1/2 extrapolation, ratio = variance ratio / samples/s ratio, so the two "
         "columns say how much of the gap is noise per sample and how much is speed."), "",
         _method_extension(a), ""]
    L += ["## Summary", "",
          f"Over {s['cases']} cases: time-to-{100 * a['target']:g} % ratio ours/Mitsuba median "
          f"**{_f(s['median_ratio'])}**, max **{_f(s['max_ratio'])}**, min {_f(s['min_ratio'])}; "
          f"with each renderer's measured slope instead of N^−1/2 for the extrapolation (clamped to "
          f"[−1, −0.5]): median {_f(s['median_ratio_slope'])}, max {_f(s['max_ratio_slope'])}; "
          f"samples/s ours/Mitsuba median **{_f(s['median_rate_ratio'])}**, variance per sample at the top "
          f"rung ours/Mitsuba median {_f(s['median_variance_ratio'])} (median samples/s: "
          + ", ".join(f"{k} {v / 1e6:.3g} M" for k, v in s["median_samples_per_s"].items()) + ").", "",
          (f"Ladder extended in {len(s.get('extended', []))} case(s)"
           + (": " + ", ".join(s["extended"]) if s.get("extended") else "")
           + f"; still untrusted at the top rung: {len(s.get('unresolved', []))}"
           + (" (" + ", ".join(s["unresolved"]) + ")" if s.get("unresolved") else "")
           + (f". Largest ratio: {s['max_ratio_case']}, {_pm(s['max_ratio'], s['max_ratio_log_se'])}"
              if "max_ratio_case" in s else "")
           + (f"; over the trusted cases only: median {_f(s['median_ratio_trusted'])}, max "
              f"{_f(s['max_ratio_trusted'])}" if s.get("unresolved") else "") + "."), "",
          "Targets: "
          + "; ".join(f"{k}: {'met' if v else 'not met'}" for k, v in s["targets"].items()) + ".", ""]
    L += method
    rows = []
    for c in cases:
        o, mi = c["renderers"][c["best"]], c["renderers"]["mitsuba"]
        rows.append([c["material"].removesuffix("_rgb"), c["map"], c["best"], _top(c), o["time_to_target_s"],
                     mi["time_to_target_s"], _pm(c["ratio"], c.get("ratio_log_se", float("nan"))),
                     _pm(c["ratio_slope"], c.get("ratio_slope_log_se", float("nan"))),
                     o["samples_per_s"] / 1e6, mi["samples_per_s"] / 1e6,
                     c["rate_ratio"], (o["rungs"][-1]["rel_rmse"] / mi["rungs"][-1]["rel_rmse"]) ** 2,
                     o["rungs"][-1]["rel_rmse"], mi["rungs"][-1]["rel_rmse"],
                     f"{o['how'][:6]} / {mi['how'][:6]}", f"{_f(o['slope'])} / {_f(mi['slope'])}"])
    L += ["## Per material and map", "",
          md_table(rows, ["material", "map", "ours", "top spp", "ours s to 1 %", "Mitsuba s to 1 %", "ratio",
                          "ratio (slopes)",
                          "ours M samples/s", "Mitsuba M samples/s", "samples/s ratio",
                          "variance ratio @top",
                          "ours rel. RMSE @top", "Mitsuba rel. RMSE @top", "how (ours / Mi.)",
                          "slope (ours / Mi.)"])]
    ext = [c for c in cases if c.get("extension", {}).get("rungs") or c.get("extension", {}).get("reasons")]
    if ext:
        rows = [[c["material"].removesuffix("_rgb"), c["map"], _top(c), c["extension"]["status"],
                 _extension_rungs(c["extension"]["rungs"]) or "–",
                 _compact(c["extension"]["rungs"][0]["reasons"] if c["extension"]["rungs"]
                          else c["extension"]["reasons"]),
                 _compact(c["extension"]["reasons"]) if c["extension"]["status"] != "trusted" else "–"]
                for c in ext]
        L += ["### Extended or untrusted cases", "",
              ("What made the base ladder's top rung untrusted, the extension rungs rendered, and what "
               "was still untrusted where the extension stopped (status: trusted, cap, budget or off; "
               "every reason of every rung is in the JSON)."), "",
              md_table(rows, ["material", "map", "top spp", "status", "extension rungs (spp)",
                              "untrusted at the base ladder's top", "untrusted at the top"])]
    if len(a["ours"]) > 1:
        rows = [[c["material"].removesuffix("_rgb"), c["map"]]
                + [c["renderers"][k]["time_to_target_s"] / c["renderers"]["mitsuba"]["time_to_target_s"]
                   for k in a["ours"]] for c in cases]
        L += ["### Every configuration of ours (time-to-target ratio over Mitsuba)", "",
              md_table(rows, ["material", "map"] + a["ours"])]
    rows = [[c["material"].removesuffix("_rgb"), c["map"]]
            + [f"{_f(c['renderers'][k]['setup_s'])} / {_f(c['renderers'][k]['compile_s'])}"
               for k in a["ours"] + ["mitsuba"]] for c in cases]
    L += ["### Set-up and compile (s, not in the times above)", "",
          ("Ours: scene build (files, tables, BVH) / kernel compile or cache load; Mitsuba: scene load "
          "/ summed untimed warm-up renders (one per rung: LLVM compile + one render)."), "",
          md_table(rows, ["material", "map"] + [f"{k} set-up / compile" for k in a["ours"] + ["mitsuba"]])]
    checks = [c for c in cases if "check" in c]
    if checks:
        rows = []
        for c in checks:
            ch = c["check"]
            for k, v in ch["renderers"].items():
                rows.append([c["material"].removesuffix("_rgb"), c["map"], k, v["spp"], v["pair_rel_rmse"],
                             v["ref_rel_rmse"], v["ratio"], v["pixel_bias_rel_rms"], 100 * v["mean_rel_diff"],
                             v["mean_z"], ch["reference_rel_rmse"]])
        L += ["## Check against a converged reference", "",
              (f"Reference: Mitsuba (`{MITSUBA_SAMPLER}`) at {a['check_spp']} spp, as two half-spp images "
              f"(passes of ≤ {MAX_PASS_SPP} spp, seeds of their own); its own noise (relative RMSE of the "
              "reference, from the halves' difference) is in the last column and is subtracted: vs ref. = "
              "sqrt(mean((X − R)²) − var(R)) / mean(R), averaged over the top rung's two renders X. "
              "ratio = vs ref. / pair estimate (1 when the seed-pair estimate is right and the renderer "
              "agrees with Mitsuba's converged image pixel by pixel); pixel bias: the signed square root "
              "of what remains, mean((X − R)²) − var(R) − var(X), relative to the mean (≈ 0 within noise "
              "when unbiased); mean diff.: the image mean over the mask against the reference's, in %, "
              "and its z-score (both renderers' noise)."), "",
              md_table(rows, ["material", "map", "renderer", "spp", "pair estimate", "vs ref.", "ratio",
                              "pixel bias (rel. rms)", "mean diff. %", "z", "ref. own rel. RMSE"])]
    L += ["Raw numbers: the JSON written by `--json`.", ""]
    return "\n".join(L)


def machine_info(variant: str) -> dict:
    import warp

    from lab import mitsuba_reference as MR

    proc = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                proc = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpus": os.cpu_count(), "processor": proc, "platform": platform.platform(),
            "python": platform.python_version(), "warp": warp.config.version, "mitsuba": MR.version(),
            "variant": variant, "libllvm": os.environ.get("DRJIT_LIBLLVM_PATH") if variant.startswith("llvm") else None,
            "loadavg_start": _loadavg()}


def _loadavg() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "?"


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(type(o))


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_vs_mitsuba", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", help="RGL file stems (default: every .bsdf in $RBRDF_DATA/rgl)")
    ap.add_argument("--maps", nargs="+", choices=sorted(MAPS), help="default: studio rooitou")
    ap.add_argument("--resolution", type=int, help="image side in pixels (default 256)")
    ap.add_argument("--spp", type=int, nargs="+", help="the spp ladder (default 4 16 64 256)")
    ap.add_argument("--target", type=float, default=0.01, help="relative RMSE target (default 0.01)")
    ap.add_argument("--ours", nargs="+", default=["rgl:mis-rgl"],
                    help="our configurations KIND:SAMPLER (kinds rgl, measured, projected)")
    ap.add_argument("--mis-compensation", type=float, default=IntegratorSpec.mis_compensation,
                    help="our integrator.mis_compensation (default %(default)g; 0: the environment "
                         "sampled by its full luminance, as Mitsuba's envmap does)")
    ap.add_argument("--variant", default="auto", help="Mitsuba variant: auto (llvm_ad_rgb if a libLLVM is "
                                                      "found, else scalar_rgb) or a variant name")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1, help="threads of both renderers")
    ap.add_argument("--check", type=int, help="check this many of CHECK_MATERIALS (default 2; --quick 1)")
    ap.add_argument("--check-spp", type=int, help="spp of the check's reference (default 1024; --quick 256)")
    d = ExtendRule()
    ap.add_argument("--no-extend", action="store_true",
                    help="never extend the ladder (untrusted cases are still reported)")
    ap.add_argument("--extend-max-spp", type=int, default=d.max_spp,
                    help=f"no extension rung above this spp (default {d.max_spp})")
    ap.add_argument("--extend-pairs", type=int, default=d.max_pairs,
                    help=f"seed pairs the top rung may pool where another rung would pass the cap or the "
                         f"budget (default {d.max_pairs}; 1: none added)")
    ap.add_argument("--extend-budget", type=float, default=d.budget_s,
                    help=f"render seconds per case the extension may reach (default {d.budget_s:g})")
    ap.add_argument("--extend-rmse", type=float, default=d.max_rel_rmse,
                    help=f"extend while a top rung's relative RMSE is above this (default {d.max_rel_rmse:g})")
    ap.add_argument("--extend-se", type=float, default=d.max_mse_se,
                    help=f"extend while a top rung's s.e. of log MSE is above this (default {d.max_mse_se:g})")
    ap.add_argument("--quick", action="store_true", help="2 materials, the studio map, 64 px, spp 4 16")
    ap.add_argument("--json", help="write the raw results here")
    ap.add_argument("--docs", action="store_true", help="write docs/bench_vs_mitsuba.md")
    a = ap.parse_args(argv)
    if hasattr(sys.stdout, "reconfigure"):
        sys.stdout.reconfigure(line_buffering=True)   # progress lines reach a log file as they come

    from lab import mitsuba_reference as MR
    from warp_rbrdf.paths import require_data_root

    data = require_data_root("the RGL files and environment maps")
    a.materials = a.materials or (list(QUICK_MATERIALS) if a.quick else
                                  sorted(p.stem for p in (data / "rgl").glob("*.bsdf")))
    a.maps = a.maps or (["studio"] if a.quick else ["studio", "rooitou"])
    a.resolution = a.resolution or (64 if a.quick else 256)
    a.spp = sorted(a.spp or ([4, 16] if a.quick else [4, 16, 64, 256]))
    a.check = (1 if a.quick else 2) if a.check is None else a.check
    a.check_spp = a.check_spp or (256 if a.quick else 1024)
    for flag, v in (("--extend-max-spp", a.extend_max_spp), ("--extend-budget", a.extend_budget),
                    ("--extend-rmse", a.extend_rmse), ("--extend-se", a.extend_se)):
        if not (np.isfinite(v) and v > 0):
            ap.error(f"{flag} {v}: expected a positive number")
    if min(a.spp) < 1:
        ap.error(f"--spp {min(a.spp)}: expected positive sample counts")
    if not 0.0 <= a.mis_compensation <= 1.0:
        ap.error(f"--mis-compensation {a.mis_compensation}: expected a number in [0, 1]")
    a.extend_rule = ExtendRule(enabled=not a.no_extend, max_rel_rmse=a.extend_rmse, max_mse_se=a.extend_se,
                               max_spp=a.extend_max_spp, budget_s=a.extend_budget, max_pairs=a.extend_pairs)
    sel = [m for m in CHECK_MATERIALS if m in a.materials] or a.materials[:1]
    a.check_materials = sel[:a.check]
    for c in a.ours:
        kind, _, sampler = c.partition(":")
        if kind not in ("rgl", "measured", "projected") or not sampler:
            ap.error(f"--ours {c!r}: expected KIND:SAMPLER with KIND rgl, measured or projected")
    paths = {}
    for m in a.materials:
        p = data / "rgl" / f"{m}.bsdf"
        if not p.exists():
            ap.error(f"no RGL file {p}")
        paths[m] = p

    if a.variant == "auto":
        try:
            variant = MR.set_variant(MR.LLVM_VARIANT)
        except MR.ReferenceUnavailable as e:
            print(f"{e}; using {MR.VARIANT}")
            variant = MR.set_variant(MR.VARIANT)
    else:
        variant = MR.set_variant(a.variant)
    MR.set_thread_count(a.threads)
    info = machine_info(variant)
    mask = MR.sphere_mask(a.resolution)
    print(f"Mitsuba {info['mitsuba']} {variant}; {a.resolution} px, spp {a.spp}, ours {a.ours}, "
          f"{a.threads} threads; {len(a.materials)} materials x {len(a.maps)} maps")
    t_start = time.perf_counter()
    cases = []
    for map_name in a.maps:
        envmap = data / MAPS[map_name]
        for m in a.materials:
            print(f"{m} / {map_name}")
            c = run_case(m, paths[m], map_name, envmap, a, mask, print)
            cases.append(c)
            o, mi = c["renderers"][c["best"]], c["renderers"]["mitsuba"]
            print(f"  -> to {100 * a.target:g} %: ours ({c['best']}) {o['time_to_target_s']:.3g} s "
                  f"({o['how']}), Mitsuba {mi['time_to_target_s']:.3g} s ({mi['how']}); ratio {c['ratio']:.3g} "
                  f"± {100 * c['ratio_log_se']:.2g} % (top {c['extension']['top_spp']} spp, "
                  f"{c['extension']['status']}); "
                  f"samples/s {o['samples_per_s'] / 1e6:.3g} M vs {mi['samples_per_s'] / 1e6:.3g} M")
    info["loadavg_end"] = _loadavg()
    res = {"command": "python -m benchmarks.bench_vs_mitsuba "
                      + " ".join(shlex.quote(x) for x in (sys.argv[1:] if argv is None else argv)),
           "date": time.strftime("%Y-%m-%d %H:%M:%S"), "wall_s": time.perf_counter() - t_start,
           "machine": info, "mask_pixels": int(mask.sum()),
           "args": {"materials": a.materials, "maps": a.maps, "resolution": a.resolution, "spp": a.spp,
                    "target": a.target, "ours": a.ours, "threads": a.threads, "check_spp": a.check_spp,
                    "mis_compensation": a.mis_compensation,
                    "check_materials": a.check_materials, "extend": dataclasses.asdict(a.extend_rule)},
           "cases": cases, "summary": summarize(cases)}
    s = res["summary"]
    print(f"{s['cases']} cases: ratio ours/Mitsuba median {s['median_ratio']:.3g}, max {s['max_ratio']:.3g}; "
          f"samples/s ratio median {s['median_rate_ratio']:.3g}; " +
          "; ".join(f"{k}: {'met' if v else 'not met'}" for k, v in s["targets"].items()))
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(res, indent=1, default=_json_default))
    if a.docs:
        DOCS.write_text(report(res))
        print(f"wrote {DOCS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
