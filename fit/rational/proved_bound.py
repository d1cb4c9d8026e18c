"""A proved bound of a fit's error between its data points, per piece and channel.

What is bounded: the largest error ``|fit - m| / s`` over a piece's measured domain, where ``m``
is the measurement's interpolant and ``s`` the error unit:

* 2-D fits (:mod:`fit.rational.brdf_fit`): ``m`` is the cluster table of the projection the fit
  was made from, piecewise constant on the MERL bins (the ``projected`` material reads it
  nearest-cluster, :meth:`fit.projection.projected.ProjectedBRDF.lookup`); the measured domain is
  every bin with a finite cluster value, intersected with the piece's box; ``s = max(m,
  abs_floor / tol)``: the fit's interval, ``m +- max(tol m, abs_floor)``, over ``tol``
  (:data:`UNIT_2D`);
* 3-D fits (:mod:`fit.rational.fit3d`): ``m`` is the measurement (the RGL reference evaluation)
  sampled at the nodes of a grid uniform in the fit's coordinates ``(sqrt(theta_h), theta_d,
  |phi_d|)`` (the fit's own data grid by default) and trilinear between them; the measured domain is
  every grid cell whose 8 nodes are measured (light and view within ``theta_max``), intersected
  with the piece's box; ``s = max(m_c, noise_c, channel_floor max(m_R, m_G, m_B))``: the fit's
  error unit without its grazing weight (>= 1, so a bound in this unit is one in the fit's)
  (:data:`UNIT_3D`).

How it is proved, per cell of the measured domain (a box in the fit's coordinates):

1. P and Q are raised to common per-variable degrees and converted to tensor Bernstein
   coefficients on the piece's box (:func:`fit.rational.bernstein.bernstein_coefficients_float`,
   with its rounding-error bound), then restricted to the cell (the de Casteljau map to a
   sub-interval, a matrix of convex weights per axis, with a rounding-error bound added per axis);
2. where every Bernstein coefficient of Q exceeds its error bound, P/Q on the cell is a convex
   combination of the ratios ``b_P,i / b_Q,i`` (rational Bezier form), so it lies between their
   smallest and largest (each taken with the error bounds against it); the fit's output is a
   non-decreasing map of P/Q (the value transform and the clamps of
   :class:`fit.rational.model.RationalModel`), so its output lies between the map's values there;
3. the interpolant lies between its smallest and largest node value on the cell (multilinear
   extremes are at the corners), and ``s`` is at least its value at those smallest nodes;
4. the cell's bound is ``max(f_hi - m_lo, m_hi - f_lo) / s_lo``. A cell whose bound is above the
   target (the fit's stated tolerance) and more than ``gap`` above both the error observed at its
   centre and the largest error observed so far anywhere is halved (along its widest side relative to the piece) and both halves bounded again, up to
   ``max_rounds`` halvings and ``max_cells`` cells.

The result (:class:`ProvedBound`, one per piece and channel): ``proved``, the largest cell bound
(a proof on the whole measured domain; inf where Q's coefficients stayed inconclusive); the
fraction of the domain (area or volume in the fit's coordinates) whose cell bound is within the
tolerance; ``verified``, the largest error observed at the cell centres (a lower bound of the true
largest error, so ``verified <= proved``).
"""
from __future__ import annotations

import itertools
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from .cell_enclosure import Enclosure, corner_bits
from .model import apply_input_transform, invert_value_transform, output_clamp

UNIT_2D = "|fit - cluster| / max(cluster, abs_floor / tolerance) (relative, floored), nearest-cluster table"
UNIT_3D = ("|fit - m_c| / max(m_c, noise_c, channel_floor * max(m)) (no grazing weight), m trilinear on the "
           "grid of the measurement in (sqrt(theta_h), theta_d, |phi_d|)")
EPS = np.finfo(float).eps
DEFAULT_ROUNDS = 16
DEFAULT_MAX_CELLS = 40000
#: The enclosures of a cell's error (module docstring, step 2): ``"ranges"`` bounds the fit's
#: output and the interpolant separately; ``"joint"`` also encloses their difference in one
#: Bernstein form and keeps the smaller bound (the default).
ENCLOSURES = ("ranges", "joint")
WORST_KEPT = 8


@dataclass
class ProvedBound:
    """The bound of one piece and channel (module docstring). ``proved``: proved on the whole
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

    def record(self) -> dict:
        """The coefficient file's ``bound`` record of this piece and channel (JSON values)."""
        d = asdict(self)
        d.pop("worst_cells")
        return d


def records(bounds) -> list:
    """``fit_info["bound"]``: the records of a list of :class:`ProvedBound`."""
    return [b.record() for b in bounds]


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


def leaves(model) -> list:
    """The single-box :class:`fit.rational.model.RationalModel` pieces of ``model``, in order."""
    if hasattr(model, "split_variable"):
        return [leaf for p in model.pieces for leaf in leaves(p)]
    return [model]


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


def _joint_error(leaf, c: int, enc, t_lo, t_hi, m):
    """``(e_lo, e_hi)`` (N,): proved bounds of ``output - m`` on each cell ``[t_lo, t_hi]``
    (the leaf's [-1, 1]^n) of channel ``c``, ``m`` multilinear with the corner values ``m``
    (N, 2^n), from one Bernstein enclosure of the difference
    (:meth:`fit.rational.cell_enclosure.Enclosure.ratio_minus`).

    Linear value transform: ``P/Q - m`` directly. Log (``g = exp(P/Q) - o``): ``d = P/Q -
    log(m + o)`` is enclosed against the multilinear ``l`` through ``log(m_k + o)`` at the
    corners; ``log(m + o)`` is concave along every axis (m is linear there), so ``0 <= log(m + o)
    - l <= sum_v D_v^2 / (8 (m_lo + o)^2)`` (``D_v`` the largest change of m along an edge of
    axis v; tensor linear interpolation, its error per axis), and ``g - m = (m + o)(e^d - 1)``.
    The clamps (:func:`_clamps`) move the output towards ``[L, U]`` only."""
    m_lo, m_hi = m.min(axis=1), m.max(axis=1)
    if leaf.value_transform == "log":
        off = float(leaf.value_offset)
        base = np.maximum(m, 0.0) + off
        ell = np.log(base)
        n = t_lo.shape[1]
        bits = corner_bits(n)
        delta = 0.0
        for v in range(n):
            diff = np.abs(m[:, bits[:, v]] - m[:, ~bits[:, v]]).max(axis=1)
            delta = delta + diff ** 2
        delta = delta / (8.0 * (np.maximum(m_lo, 0.0) + off) ** 2)
        delta = delta * (1.0 + 1e-9) + 8 * EPS * np.abs(ell).max(axis=1)
        dl, dh = enc.ratio_minus(t_lo, t_hi, ell)
        dl = dl - delta
        b_lo, b_hi = np.maximum(m_lo, 0.0) + off, np.maximum(m_hi, 0.0) + off
        with np.errstate(over="ignore", invalid="ignore"):
            eh, el = np.expm1(dh), np.expm1(dl)
            e_hi = np.where(eh >= 0, b_hi * eh, b_lo * eh)
            e_lo = np.where(el >= 0, b_lo * el, b_hi * el)
            # exp's and the products' rounding, relative to the values involved
            slack = 16 * EPS * (b_hi + np.abs(e_hi) + np.abs(e_lo))
        e_hi, e_lo = e_hi + slack, e_lo - slack
    elif leaf.value_transform == "linear":
        e_lo, e_hi = enc.ratio_minus(t_lo, t_hi, m)
        slack = 8 * EPS * (np.abs(m).max(axis=1) + np.abs(e_lo) + np.abs(e_hi))
        e_hi, e_lo = e_hi + slack, e_lo - slack
    else:
        return np.full(len(m), -np.inf), np.full(len(m), np.inf)
    L, U = _clamps(leaf, c)
    with np.errstate(invalid="ignore"):
        up = np.maximum(np.minimum(e_hi, U - m_lo), L - m_lo)
        down = np.maximum(np.minimum(e_lo, U - m_hi), L - m_hi)
    bad = ~(np.isfinite(e_lo) & np.isfinite(e_hi))
    return np.where(bad, -np.inf, down), np.where(bad, np.inf, up)


def prove_cells(leaf, c: int, lo, hi, corners, scale, tolerance: float, piece: int = 0, unit: str = "",
                max_rounds: int = DEFAULT_ROUNDS, max_cells: int = DEFAULT_MAX_CELLS, gap: float = 0.05,
                enclose=None, enclosure: str = "joint") -> ProvedBound:
    """The proved bound of channel ``c`` of ``leaf`` against a multilinear interpolant on cells.

    ``lo``, ``hi`` (N, n): the cells, boxes in the leaf's transformed coordinates (inside its box);
    ``corners`` (N, 2^n, C): the interpolant's values at each cell's corners, every channel
    (:func:`_multilinear`'s order); ``scale(corners) -> (N,)``: a lower bound of the error unit on
    each cell, ``scale(values (N, 1, C))`` its value at points; ``tolerance``: the target.
    ``enclosure``: one of :data:`ENCLOSURES`. ``enclose`` (tests): replaces the Bernstein
    enclosure of P/Q, ``enclose(fn, t_lo, t_hi)`` (the ``"ranges"`` enclosure only)."""
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
        if enclosure == "joint":          # the difference enclosed at once; the smaller bound
            el, eh = _joint_error(leaf, c, encl, t_lo, t_hi, m)
            err = np.minimum(err, np.maximum(np.maximum(eh, -el), 0.0))
        bound = err / scale(corners)
        centre = 0.5 * (lo + hi)
        mc = _multilinear(corners, np.full_like(lo, 0.5))
        f_c = _leaf_output(leaf, c, fn(centre))
        obs = np.abs(f_c - mc[:, c]) / scale(mc[:, None, :])
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
        top = np.argsort(-kept["bound"])[:WORST_KEPT]
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


# --------------------------------------------------------------------------------------------
# The fits' measured domains
# --------------------------------------------------------------------------------------------
def _clip(c_lo, c_hi, corners, box) -> tuple:
    """Cells ``[c_lo, c_hi]`` (N, n) with multilinear ``corners`` (N, 2^n, C) intersected with
    ``box`` (n, 2): ``(lo, hi, corners)`` of the non-empty ones, the corners interpolated."""
    lo, hi = np.maximum(c_lo, box[:, 0]), np.minimum(c_hi, box[:, 1])
    sel = np.all(hi > lo, axis=1)
    lo, hi, c_lo, c_hi, corners = lo[sel], hi[sel], c_lo[sel], c_hi[sel], corners[sel]
    n = lo.shape[1]
    cc = [_multilinear(corners, (np.where(b, hi, lo) - c_lo) / (c_hi - c_lo))
          for b in np.array(list(itertools.product((0, 1), repeat=n)), bool)]
    return lo, hi, np.stack(cc, axis=1) if cc else corners


def _grid_cells(axes, values, measured) -> tuple:
    """The cells of a tensor grid (node coordinates per axis ``axes``, node ``values`` (..., C))
    whose 2^n nodes are all ``measured``: ``(c_lo, c_hi, corners)``."""
    n = len(axes)
    idx = np.stack(np.meshgrid(*(np.arange(len(a) - 1) for a in axes), indexing="ij"), axis=-1).reshape(-1, n)
    bits = np.array(list(itertools.product((0, 1), repeat=n)))
    nodes = tuple(np.moveaxis(idx[:, None, :] + bits[None, :, :], -1, 0))   # n arrays (N, 2^n)
    ok = measured[nodes].all(axis=1)
    idx = idx[ok]
    corners = values[tuple(a[ok] for a in nodes)]
    c_lo = np.stack([axes[v][idx[:, v]] for v in range(n)], axis=1)
    c_hi = np.stack([axes[v][idx[:, v] + 1] for v in range(n)], axis=1)
    return c_lo, c_hi, corners


def _box(leaf) -> np.ndarray:
    return np.array([apply_input_transform(np.asarray(v.domain), v.transform) for v in leaf.variables])


INTERPOLANTS_2D = ("bilinear", "nearest")


def prove_brdf(model, projected, interpolant: str = "bilinear", **kw) -> list:
    """:class:`ProvedBound` per leaf piece (in :func:`leaves` order) and channel of a 2-D fit
    ``model`` against the cluster table ``projected`` (the
    :class:`fit.projection.projected.ProjectedBRDF` it was fitted to), :data:`UNIT_2D`.

    ``interpolant``: ``"bilinear"`` (default): between the cluster centres, bilinear in the fit's
    coordinates (``sqrt(theta_h)``, theta_d), the reading of the table that the fit's intervals
    (one per cluster centre) describe; the measured domain is every cell of four finite clusters,
    clipped to the piece. ``"nearest"``: the table as the ``projected`` material reads it, constant
    on each MERL bin (its jumps between bins count as error). ``kw``: :func:`prove_cells`'s
    budget."""
    from ..formats.grid import N_THETA_D, N_THETA_H, theta_d_centres, theta_h_centres
    if interpolant not in INTERPOLANTS_2D:
        raise ValueError(f"interpolant must be one of {INTERPOLANTS_2D}")
    fi = model.fit_info
    tol = float(fi["tolerance"])
    floors = [float(f) for f in fi["abs_floor"]]
    value = np.maximum(np.nan_to_num(projected.value, nan=0.0), 0.0)
    unit = UNIT_2D.replace("nearest-cluster table", f"{interpolant} cluster table")
    out = []
    for k, leaf in enumerate(leaves(model)):
        tf = leaf.variables[0].transform
        if interpolant == "nearest":
            eh = (np.arange(N_THETA_H + 1) / N_THETA_H) ** 2 * (0.5 * np.pi)
            ed = np.arange(N_THETA_D + 1) / N_THETA_D * (0.5 * np.pi)
            I, J = (a.reshape(-1) for a in np.meshgrid(np.arange(N_THETA_H), np.arange(N_THETA_D), indexing="ij"))
            c_lo = np.stack([apply_input_transform(eh[I], tf), ed[J]], axis=1)
            c_hi = np.stack([apply_input_transform(eh[I + 1], tf), ed[J + 1]], axis=1)
            corners = np.repeat(value[I, J][:, None, :], 4, axis=1)
            finite = np.isfinite(projected.value[I, J])
        else:
            axes = (apply_input_transform(theta_h_centres(), tf), theta_d_centres())
            c_lo, c_hi, corners = _grid_cells(axes, value, np.all(np.isfinite(projected.value), axis=-1))
            finite = np.ones((len(c_lo), 3), bool)
        for c in range(3):
            lo, hi, cc = _clip(c_lo[finite[:, c]], c_hi[finite[:, c]], corners[finite[:, c]], _box(leaf))
            floor = floors[c] / tol

            def scale(cr, c=c, floor=floor):
                return np.maximum(cr[..., c].min(axis=1), floor)
            out.append(prove_cells(leaf, c, lo, hi, cc, scale, tol, piece=k, unit=unit, **kw))
    return out


def measurement_grid(brdf, theta_max: float, grid) -> tuple:
    """The 3-D measurement on a grid uniform in ``(sqrt(theta_h), theta_d, |phi_d|)`` with
    ``grid`` = (n_h, n_d, n_p) nodes over ``[0, theta_max]^2 x [0, pi]``: ``(axes, rho, measured)``,
    ``axes`` the node coordinates per axis in the fit's coordinates, ``rho`` (n_h, n_d, n_p, 3)
    (1/sr, 0 where not measured), ``measured`` (n_h, n_d, n_p): light and view both above the
    horizon and within ``theta_max`` (as :func:`fit.rational.samples3d.sample_grid`)."""
    from ..formats.angles import half_diff_to_directions
    nh, nd, npd = (int(g) for g in grid)
    axes = (np.sqrt(theta_max) * np.linspace(0.0, 1.0, nh), np.linspace(0.0, theta_max, nd),
            np.linspace(0.0, np.pi, npd))
    U = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    wi, wo = half_diff_to_directions(U[..., 0] ** 2, 0.0, U[..., 1], U[..., 2])
    cmin = np.cos(theta_max) - 1e-9
    measured = (wi[..., 2] >= cmin) & (wo[..., 2] >= cmin) & (wi[..., 2] > 0) & (wo[..., 2] > 0)
    rho = np.zeros(U.shape[:-1] + (3,))
    rho[measured] = np.maximum(np.asarray(brdf.evaluate(wi[measured], wo[measured]), np.float64), 0.0)
    return axes, rho, measured


def prove_fit3d(res, brdf, grid=None, **kw) -> list:
    """:class:`ProvedBound` per piece and channel of a 3-D fit ``res``
    (:class:`fit.rational.result3d.Fit3D`) against the measurement ``brdf`` on
    :func:`measurement_grid` (``grid``: default the fit's data grid), :data:`UNIT_3D`; the
    target of each is the piece's and channel's stated tolerance. ``kw``: :func:`prove_cells`'s
    budget."""
    from .settings import DEFAULT_CHANNEL_FLOOR
    fi = res.model.fit_info
    tm = float(res.data.theta_max) if res.data is not None else float(np.deg2rad(fi["theta_max_deg"]))
    grid = tuple(grid or (res.settings.grid if res.settings is not None else fi["grid"]))
    axes, rho, measured = measurement_grid(brdf, tm, grid)
    noise = np.asarray(res.noise, np.float64)
    cf = float(fi.get("channel_floor", DEFAULT_CHANNEL_FLOOR))
    c_lo, c_hi, corners = _grid_cells(axes, rho, measured)
    tol = {(r["piece"], "RGB".index(r["channel"])): float(r["tolerance"]) for r in res.records}

    def scale(cr):
        mins = cr.min(axis=1)                                           # (N, 3)
        return mins, np.maximum(cf * mins.max(axis=1), 0.0)
    out = []
    for k, leaf in enumerate(leaves(res.model)):
        lo, hi, cc = _clip(c_lo, c_hi, corners, _box(leaf))
        for c in range(3):
            def scale_c(cr, c=c):
                mins, floor = scale(cr)
                return np.maximum(np.maximum(mins[:, c], noise[c]), floor)
            out.append(prove_cells(leaf, c, lo, hi, cc, scale_c, tol.get((k, c), 0.0), piece=k, unit=UNIT_3D,
                                   **kw))
    return out


def record_fit3d(res, brdf, **kw) -> list:
    """:func:`prove_fit3d` of the 3-D fit ``res`` against ``brdf``, kept in ``res.bounds`` and
    its records in ``res.model.fit_info["bound"]`` (what :func:`fit.rational.result3d.domain_record`
    then reads)."""
    res.bounds = prove_fit3d(res, brdf, **kw)
    res.model.fit_info["bound"] = records(res.bounds)
    return res.bounds


def summary(bounds) -> dict:
    """The largest ``proved`` (None if any is None), the smallest ``proved_fraction`` and the
    largest ``verified`` of a list of :class:`ProvedBound`."""
    proved = [b.proved for b in bounds]
    return {"proved": None if any(p is None for p in proved) else max(proved, default=0.0),
            "proved_fraction": min((b.proved_fraction for b in bounds), default=0.0),
            "verified": max((b.verified for b in bounds), default=0.0)}
