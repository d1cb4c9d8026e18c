"""The proved bound of one rational function's error against a multilinear interpolant on
cells (:func:`prove_cells`, :class:`ProvedBound`): the method of :mod:`fit.rational.proved_bound`
(its docstring), which applies it to the measured domains of the 2-D and 3-D fits.
"""
from __future__ import annotations

import itertools
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from .cell_enclosure import Enclosure, corner_bits
from .model import invert_value_transform, output_clamp

EPS = np.finfo(float).eps
DEFAULT_ROUNDS = 16
DEFAULT_MAX_CELLS = 40000
#: The enclosures of a cell's error (:mod:`fit.rational.proved_bound`, step 2): ``"ranges"`` bounds the fit's
#: output and the interpolant separately; ``"joint"`` also encloses their difference in one
#: Bernstein form and keeps the smaller bound (the default).
ENCLOSURES = ("ranges", "joint")
WORST_KEPT = 8


@dataclass
class ProvedBound:
    """The bound of one piece and channel (:mod:`fit.rational.proved_bound`). ``proved``: proved on the whole
    measured domain of the piece (None: Q's Bernstein coefficients were inconclusive somewhere);
    ``proved_fraction``: the part of the domain where the proved cell bound is <= ``tolerance``;
    ``verified``: largest error observed, at ``verified_points`` cell centres; ``unit``: the
    error unit; ``cells``: cells bounded at the end; ``time_s``: seconds."""

    piece: int
    channel: str
    proved: float | None
    proved_fraction: float
    verified: float
    verified_points: int
    tolerance: float
    unit: str
    cells: int
    time_s: float

    #: the cells with the largest bounds at the end (``lo``, ``hi``, ``corners``, ``bound``;
    #: :data:`WORST_KEPT` of them), for the analysis of what sets ``proved``; not in the record
    worst_cells: dict | None = field(default=None, repr=False, compare=False)

    @property
    def status(self) -> str:
        """``"proved"`` where ``proved`` is within the tolerance; otherwise ``"verified only: "``
        and why: Q's coefficients inconclusive, the error observed already above the tolerance
        (the fit's own error between the nodes: only another fit lowers it), or the proof ended
        above the tolerance (its cells within ``gap`` of the largest error seen, or its budget
        spent) while every error observed is within it."""
        if self.proved is not None and self.proved <= self.tolerance:
            return "proved"
        if self.proved is None:
            return "verified only: Q's Bernstein coefficients inconclusive on a cell"
        if self.verified > self.tolerance:
            return (f"verified only: the fit's error between the nodes, {100 * self.verified:.3g} % at a cell "
                    f"centre, is above the tolerance")
        return (f"verified only: the proof ended at {100 * self.proved:.3g} % (within its gap of the largest "
                f"error seen, {100 * self.verified:.3g} %, or at its budget of {self.cells} cells), every error "
                f"seen within the tolerance")

    def record(self) -> dict:
        """The coefficient file's ``bound`` record of this piece and channel (JSON values)."""
        d = asdict(self)
        d.pop("worst_cells")
        return d


def _leaf_output(leaf, c: int, r) -> np.ndarray:
    """The output of ``leaf`` (a :class:`fit.rational.model.RationalModel`) for channel ``c`` at
    the values ``r`` of its P/Q: a non-decreasing map (steps 5-7 of its evaluation)."""
    r = np.asarray(r, dtype=np.float64)
    if leaf.value_max is not None and leaf.value_transform == "log":
        r = np.minimum(r, np.log(leaf.value_max + leaf.value_offset))
    with np.errstate(over="ignore"):
        f = invert_value_transform(r, leaf.value_transform, leaf.value_offset)
    if leaf.value_min is not None:
        f = np.maximum(f, leaf.value_min)
    if leaf.value_max is not None:
        f = np.minimum(f, leaf.value_max)
    rng = output_clamp(leaf.function_info[c]) if c < len(leaf.function_info) else None
    if rng is not None:
        f = np.clip(f, rng[0], rng[1])
    return f


def _multilinear(corners, x) -> np.ndarray:
    """Values at local points ``x`` (N, n) in [0, 1]^n of the multilinear functions with the
    ``corners`` (N, 2^n, C) (corner k: bit v of k, most significant first, is the high side of
    axis v): (N, C)."""
    n = x.shape[1]
    out = 0.0
    for k, bits in enumerate(itertools.product((0, 1), repeat=n)):
        w = np.prod([x[:, v] if bits[v] else 1.0 - x[:, v] for v in range(n)], axis=0)
        out = out + w[:, None] * corners[:, k]
    return out


def _children_corners(corners, axis: int) -> tuple:
    """Corner values of the two halves of each cell split at the middle of ``axis``."""
    n = int(round(np.log2(corners.shape[1])))
    lo_c, hi_c = corners.copy(), corners.copy()
    for k, bits in enumerate(itertools.product((0, 1), repeat=n)):
        other = list(bits)
        other[axis] = 1 - bits[axis]
        j = int("".join(map(str, other)), 2)
        mid = 0.5 * (corners[:, k] + corners[:, j])
        if bits[axis]:
            lo_c[:, k] = mid          # the low half's high side is the middle
        else:
            hi_c[:, k] = mid
    return lo_c, hi_c


def _clamps(leaf, c: int) -> tuple:
    """``(L, U)``: the output clamps of channel ``c`` of ``leaf`` (steps 5-7 after the value
    transform) as one clamp ``clip(g, L, U)`` of the transformed value ``g`` (a composition of
    clamps is the clamp between its values at -inf and +inf)."""
    def chain(g):
        f = float(g)
        if leaf.value_max is not None:
            f = min(f, leaf.value_max)          # the log transform's clamp of P/Q, then the value's
        if leaf.value_min is not None:
            f = max(f, leaf.value_min)
        if leaf.value_max is not None:
            f = min(f, leaf.value_max)
        rng = output_clamp(leaf.function_info[c]) if c < len(leaf.function_info) else None
        if rng is not None:
            f = min(max(f, rng[0]), rng[1])
        return f
    return chain(-np.inf), chain(np.inf)


def _joint_bound(leaf, c: int, enc, t_lo, t_hi, m, s0, s_lo):
    """(N,): a proved bound of ``|output - m| / u`` on each cell ``[t_lo, t_hi]`` (the leaf's
    [-1, 1]^n) of channel ``c``, ``m`` multilinear with the corner values ``m`` (N, 2^n), the
    unit ``u >= max(m, s0)`` at every point of the cell (``s0`` (N,)), or, with ``s0`` None,
    only ``u >= s_lo`` (N,), from one Bernstein enclosure of the difference
    (:meth:`fit.rational.cell_enclosure.Enclosure.ratio_minus`).

    Linear value transform: ``P/Q - m`` is enclosed directly, over ``max(m_lo, s0)``. Log
    (``g = exp(P/Q) - o``): ``d = P/Q - log(m + o)`` is enclosed against the multilinear ``l``
    through ``log(m_k + o)`` at the corners; ``log(m + o)`` is concave along every axis (m is
    linear there), so ``0 <= log(m + o) - l <= sum_v D_v^2 / (8 (m_lo + o)^2)`` (``D_v`` the
    largest change of m along an edge of axis v; tensor linear interpolation, its error per
    axis); then ``(g - m) / u = (e^d - 1) (m + o) / u``, and ``(m + o) / max(m, s0)`` is largest at
    ``m = s0`` and smallest at an end of ``[m_lo, m_hi]``, so the relative error is bounded
    without the variation of m over the cell. The clamps ``clip(g, L, U)`` (:func:`_clamps`)
    only move the output towards ``[L, U]``."""
    m_lo, m_hi = m.min(axis=1), m.max(axis=1)
    u_lo = s_lo if s0 is None else np.maximum(m_lo, s0)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        if leaf.value_transform == "log":
            off = float(leaf.value_offset)
            ell = np.log(np.maximum(m, 0.0) + off)
            bits = corner_bits(t_lo.shape[1])
            delta = sum(np.abs(m[:, bits[:, v]] - m[:, ~bits[:, v]]).max(axis=1) ** 2 for v in range(bits.shape[1]))
            delta = delta / (8.0 * (np.maximum(m_lo, 0.0) + off) ** 2) * (1.0 + 1e-9) + 8 * EPS * np.abs(ell).max(axis=1)
            dl, dh = enc.ratio_minus(t_lo, t_hi, ell)
            eh, el = np.expm1(dh), np.expm1(dl - delta)

            def phi(x):
                return (np.maximum(x, 0.0) + off) / (s_lo if s0 is None else np.maximum(x, s0))
            p_max = phi(m_hi if s0 is None else np.clip(s0, m_lo, m_hi))
            p_min = np.minimum(phi(m_lo), phi(m_hi))
            e_hi = np.where(eh >= 0, eh * p_max, eh * p_min)
            e_lo = np.where(el >= 0, el * p_min, el * p_max)
            slack = 16 * EPS * p_max * (1.0 + np.abs(eh) + np.abs(el))       # exp's and the products' rounding
        elif leaf.value_transform == "linear":
            dl, dh = enc.ratio_minus(t_lo, t_hi, m)
            e_hi, e_lo = dh / u_lo, dl / u_lo
            slack = 8 * EPS * (np.abs(m).max(axis=1) + np.abs(dl) + np.abs(dh)) / u_lo
        else:
            return np.full(len(m), np.inf)
        e_hi, e_lo = e_hi + slack, e_lo - slack
        # clip(g, L, U) - m = max(L - m, min(g - m, U - m)); over the unit (>= u_lo on the cell),
        # (K - m) / u is at most max(K - m_lo, 0) / u_lo and at least min(K - m_hi, 0) / u_lo
        L, U = _clamps(leaf, c)
        up = np.maximum(np.minimum(e_hi, np.maximum(U - m_lo, 0.0) / u_lo), np.maximum(L - m_lo, 0.0) / u_lo)
        down = np.maximum(np.minimum(e_lo, np.minimum(U - m_hi, 0.0) / u_lo), np.minimum(L - m_hi, 0.0) / u_lo)
        bound = np.maximum(np.maximum(up, -down), 0.0)
    return np.where(np.isnan(bound), np.inf, bound)


def prove_cells(leaf, c: int, lo, hi, corners, scale, tolerance: float, piece: int = 0, unit: str = "",
                max_rounds: int = DEFAULT_ROUNDS, max_cells: int = DEFAULT_MAX_CELLS, gap: float = 0.05,
                enclose=None, enclosure: str = "joint", floor=None, weight=None, keep_above: float | None = None,
                max_kept: int = 4000) -> ProvedBound:
    """The proved bound of channel ``c`` of ``leaf`` against a multilinear interpolant on cells.

    ``lo``, ``hi`` (N, n): the cells, boxes in the leaf's transformed coordinates (inside its box);
    ``corners`` (N, 2^n, C): the interpolant's values at each cell's corners, every channel
    (:func:`_multilinear`'s order); ``scale(corners) -> (N,)``: a lower bound of the error unit on
    each cell, ``scale(values (N, 1, C))`` its value at points; ``floor(corners) -> (N,)``
    (optional): ``s0`` per cell with the unit ``>= max(m_c, s0)`` at every point of the cell
    (without it only ``scale`` is known of the unit); ``weight(lo, hi) -> (N,)`` (optional): a
    lower bound >= 1 on each box of a factor of the unit that depends on the position only (the
    unit is ``weight`` times the one ``scale`` and ``floor`` describe); ``tolerance``: the target.
    ``enclosure``: one of :data:`ENCLOSURES`. ``enclose`` (tests): replaces the Bernstein
    enclosure of P/Q, ``enclose(fn, t_lo, t_hi)`` (the ``"ranges"`` enclosure only).
    ``keep_above`` (None: the :data:`WORST_KEPT` worst cells): ``worst_cells`` holds every finished
    cell whose bound is above ``keep_above`` times the tolerance (at most ``max_kept``, the largest
    bounds first; at least the :data:`WORST_KEPT` worst), where the proof-guided refit
    (:func:`fit.rational.verify3d.refit_between_nodes`) looks for the fit's spikes."""
    if enclosure not in ENCLOSURES:
        raise ValueError(f"enclosure must be one of {ENCLOSURES}")
    t0 = time.perf_counter()
    fn = leaf.functions[c]
    dom = fn.domain
    encl = Enclosure(fn)
    enc = encl.ratio
    if enclose is not None:
        enc, enclosure = (lambda tl, th: enclose(fn, tl, th)), "ranges"  # noqa: E731
    lo, hi, corners = (np.asarray(a, np.float64) for a in (lo, hi, corners))
    width = dom[:, 1] - dom[:, 0]
    worst, frac_ok, total, seen, n_obs, n_cells = 0.0, 0.0, 0.0, 0.0, 0, 0
    kept = {"lo": lo[:0], "hi": hi[:0], "corners": corners[:0], "bound": np.zeros(0)}
    for rnd in range(max_rounds + 1):
        if len(lo) == 0:
            break
        t_lo, t_hi = (2.0 * lo - (dom[:, 0] + dom[:, 1])) / width, (2.0 * hi - (dom[:, 0] + dom[:, 1])) / width
        t_lo, t_hi = np.clip(t_lo, -1, 1), np.clip(t_hi, -1, 1)
        rl, rh = enc(t_lo, t_hi)
        fl, fh = _leaf_output(leaf, c, rl), _leaf_output(leaf, c, rh)
        fl, fh = fl - 4 * EPS * np.abs(fl), fh + 4 * EPS * np.abs(fh)     # exp's rounding
        m = corners[..., c]
        err = np.maximum(np.maximum(fh - m.min(axis=1), m.max(axis=1) - fl), 0.0)
        err = np.where(np.isfinite(rl) & np.isfinite(rh), err, np.inf)
        bound = err / scale(corners)
        w_cell = weight(lo, hi) if weight is not None else 1.0
        if enclosure == "joint":          # the difference enclosed at once; the smaller bound
            s0 = floor(corners) if floor is not None else None
            bound = np.minimum(bound, _joint_bound(leaf, c, encl, t_lo, t_hi, m, s0, scale(corners)))
        bound = bound / w_cell
        centre = 0.5 * (lo + hi)
        mc = _multilinear(corners, np.full_like(lo, 0.5))
        f_c = _leaf_output(leaf, c, fn(centre))
        obs = np.abs(f_c - mc[:, c]) / scale(mc[:, None, :])
        if weight is not None:
            obs = obs / weight(centre, centre)
        seen = max(seen, float(obs.max()))
        n_obs += len(lo)
        vol = np.prod(hi - lo, axis=1)
        last = rnd == max_rounds or n_cells + 2 * len(lo) > max_cells
        # a cell below the largest error seen anywhere cannot raise the proved maximum
        done = last | (bound <= tolerance) | (bound <= np.maximum(obs, seen) * (1.0 + gap))
        worst = max(worst, float(bound[done].max(initial=0.0)))
        frac_ok += float(vol[done & (bound <= tolerance)].sum())
        total += float(vol[done].sum())
        n_cells += int(done.sum())
        kept = {k: np.concatenate([kept[k], v[done]]) for k, v in
                (("lo", lo), ("hi", hi), ("corners", corners), ("bound", bound))}
        n_keep = WORST_KEPT
        if keep_above is not None:
            n_keep = min(max(WORST_KEPT, int(np.sum(kept["bound"] > keep_above * tolerance))), max_kept)
        top = np.argsort(-kept["bound"])[:n_keep]
        kept = {k: v[top] for k, v in kept.items()}
        keep = ~done
        lo, hi, corners = lo[keep], hi[keep], corners[keep]
        if not len(lo):
            break
        axis = np.argmax((hi - lo) / width, axis=1)
        c_lo, c_hi = np.empty_like(corners), np.empty_like(corners)
        for v in range(lo.shape[1]):
            s = axis == v
            if np.any(s):
                c_lo[s], c_hi[s] = _children_corners(corners[s], v)
        mid = 0.5 * (lo + hi)
        onehot = np.eye(lo.shape[1], dtype=bool)[axis]
        lo = np.concatenate([lo, np.where(onehot, mid, lo)])
        hi = np.concatenate([np.where(onehot, mid, hi), hi])
        corners = np.concatenate([c_lo, c_hi])
    return ProvedBound(piece, "RGB"[c] if c < 3 else str(c), worst if np.isfinite(worst) else None,
                       frac_ok / total if total > 0 else 0.0, seen, n_obs, float(tolerance), unit, n_cells,
                       time.perf_counter() - t0, worst_cells=kept)
