"""A proved bound of a fit's error between its data points, per piece and channel.

What is bounded: the largest error ``|fit - m| / s`` over a piece's measured domain, where ``m``
is the measurement's interpolant and ``s`` the error unit:

* 2-D fits (:mod:`fit.rational.brdf_fit`): ``m`` is the cluster table of the projection the fit
  was made from, bilinear between the cluster centres in the fit's coordinates (default; or, with
  ``interpolant="nearest"``, piecewise constant on the MERL bins as the ``projected`` material
  reads it); the measured domain is every cell of finite clusters, intersected with the piece's
  box; ``s = max(m, abs_floor / tol)``: the fit's interval, ``m +- max(tol m, abs_floor)``, over
  ``tol`` (:data:`UNIT_2D`);
* 3-D fits (:mod:`fit.rational.fit3d`): ``m`` is the measurement (the RGL reference evaluation)
  sampled at the nodes of a grid uniform in the fit's coordinates ``(sqrt(theta_h), theta_d,
  |phi_d|)`` (the fit's own data grid by default) and trilinear between them; the measured domain is
  every grid cell whose 8 nodes are measured (light and view within ``theta_max``), intersected
  with the piece's box; ``s = max(m_c, noise_c, channel_floor max(m_R, m_G, m_B))``: the fit's
  error unit without its grazing weight (>= 1, so a bound in this unit is one in the fit's)
  (:data:`UNIT_3D`), or, with ``grazing=True``, times a lower bound of the grazing weight on the
  cell (:data:`UNIT_3D_GRAZING`: the unit of the fit's stated tolerance). A fit whose functions
  give ``rho cos theta_i`` (value factor ``"1/cos_theta_i"``, :mod:`fit.rational.model`) is
  bounded in that unit: ``m`` interpolates ``rho cos theta_i`` at the nodes, and the bound is
  one on the relative error of the functions' values against it (the same relative error of
  rho at the nodes; between them the interpolant is that of ``rho cos theta_i``).

How it is proved, per cell of the measured domain (a box in the fit's coordinates;
:func:`fit.rational.cell_proof.prove_cells`, enclosures in :mod:`fit.rational.cell_enclosure`):

1. P and Q are raised to common per-variable degrees and converted to tensor Bernstein
   coefficients on the piece's box (:func:`fit.rational.bernstein.bernstein_coefficients_float`,
   with its rounding-error bound), then restricted to the cell (the de Casteljau map to a
   sub-interval, a matrix of convex weights per axis, with a rounding-error bound added per axis);
2. ``"ranges"``: where every Bernstein coefficient of Q exceeds its error bound, P/Q on the cell
   lies between the smallest and largest ratio ``b_P,i / b_Q,i`` (rational Bezier form), the
   fit's output (a non-decreasing map of P/Q: the value transform and the clamps of
   :class:`fit.rational.model.RationalModel`) between the map's values there, the interpolant
   between its smallest and largest corner value (multilinear extremes are at the corners), and
   the cell's bound is ``max(f_hi - m_lo, m_hi - f_lo) / s_lo``: the variations of the fit and
   of the interpolant over the cell add up. ``"joint"`` (default) also encloses the difference
   in one Bernstein form: ``P - l Q`` against Q of one degree more, ``l`` multilinear through
   the interpolant's corner values (linear value transform) or through ``log(m + offset)`` at the
   corners with a bound of ``log``'s interpolation error (log transform), and divides by the unit
   point by point where the unit is ``max(m, s0)`` (the relative error of a log fit does not carry
   the variation of m); the cell's bound is the smaller of the two;
3. a cell whose bound is above the target (the fit's stated tolerance) and more than ``gap``
   above both the error observed at its centre and the largest error observed so far anywhere
   is halved (along its widest side relative to the piece) and both halves bounded again, up to
   ``max_rounds`` halvings and ``max_cells`` cells.

The result (:class:`ProvedBound`, one per piece and channel): ``proved``, the largest cell bound
(a proof on the whole measured domain; None where Q's coefficients stayed inconclusive); the
fraction of the domain (area or volume in the fit's coordinates) whose cell bound is within the
tolerance; ``verified``, the largest error observed at the cell centres (a lower bound of the true
largest error, so ``verified <= proved``); ``status``: "proved" where ``proved`` is within the
tolerance, else "verified only" and why.
"""
from __future__ import annotations

import copy
import itertools

import numpy as np

from .cell_proof import (DEFAULT_MAX_CELLS, DEFAULT_ROUNDS, ENCLOSURES, EPS, WORST_KEPT,  # noqa: F401
                         ProvedBound, _leaf_output, _multilinear, prove_cells)
from .model import apply_input_transform, invert_input_transform, value_factor_weights
from .result3d import file_value_range


UNIT_2D = "|fit - cluster| / max(cluster, abs_floor / tolerance) (relative, floored), nearest-cluster table"
UNIT_3D = ("|fit - m_c| / max(m_c, noise_c, channel_floor * max(m)) (no grazing weight), m trilinear on the "
           "grid of the measurement in (sqrt(theta_h), theta_d, |phi_d|)")
UNIT_3D_GRAZING = ("|fit - m_c| / (max(m_c, noise_c, channel_floor * max(m)) * max(1, grazing_cos / (cos theta_i "
                   "cos theta_o))) (the fit's stated unit), m trilinear on the grid of the measurement in "
                   "(sqrt(theta_h), theta_d, |phi_d|)")


def records(bounds) -> list:
    """``fit_info["bound"]``: the records of a list of :class:`ProvedBound`."""
    return [b.record() for b in bounds]


def leaves(model) -> list:
    """The single-box :class:`fit.rational.model.RationalModel` pieces of ``model``, in order."""
    if hasattr(model, "split_variable"):
        return [leaf for p in model.pieces for leaf in leaves(p)]
    return [model]


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

            def s0(cr, floor=floor):
                return np.full(len(cr), floor)
            out.append(prove_cells(leaf, c, lo, hi, cc, scale, tol, piece=k, unit=unit, floor=s0, **kw))
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


def grazing_weight_lower(leaf, grazing_cos: float):
    """``weight(lo, hi)`` for :func:`prove_cells`: on each box of a 3-D leaf's transformed
    coordinates (theta_h, theta_d, |phi_d|), a lower bound of the fit's grazing weight ``max(1,
    grazing_cos / max(cos theta_i cos theta_o, 1e-6))``
    (:func:`fit.rational.samples3d.grazing_weight`), from ``cos theta_i cos theta_o = cos^2
    theta_d cos^2 theta_h - sin^2 theta_d sin^2 theta_h cos^2 phi_d``: largest at the box's
    smallest theta_h and theta_d and its smallest ``cos^2 phi_d``."""
    tf = [v.transform for v in leaf.variables]

    def phys(x, v):
        return invert_input_transform(x, tf[v])

    def weight(lo, hi):
        h0, d0 = phys(lo[:, 0], 0), phys(lo[:, 1], 1)
        p0, p1 = lo[:, 2], hi[:, 2]
        c2 = np.where((p0 <= 0.5 * np.pi) & (p1 >= 0.5 * np.pi), 0.0,
                      np.minimum(np.cos(p0) ** 2, np.cos(p1) ** 2))
        cc = np.cos(d0) ** 2 * np.cos(h0) ** 2 - np.sin(d0) ** 2 * np.sin(h0) ** 2 * c2
        cc = cc * (1.0 + 1e-12) + 4 * EPS
        return np.maximum(1.0, grazing_cos / np.maximum(cc, 1e-6)) * (1.0 - 1e-12)
    return weight


class Fit3DProof:
    """The proof of :func:`prove_fit3d` one piece and channel at a time: the measurement on its grid
    (:func:`measurement_grid`) and each piece's cells are made once, :meth:`prove` bounds one
    function of the fit (or another function in its place: the guard of the albedo policy,
    :mod:`fit.rational.albedo3d`, proves a candidate refit before it keeps it). Arguments as
    :func:`prove_fit3d`; ``memo`` (a dict the caller keeps between proofs of the same fit's
    refits): a function proved before, unchanged and under the same value range, is not proved
    again. What is proved is the model its coefficient file holds: a copy of the fit
    with the file's one value range (:func:`fit.rational.result3d.file_value_range`), whose clamp
    does not hide a spike of a later theta_h piece as that piece's own, lower ``value_max`` does
    while the fit is made."""

    def __init__(self, res, brdf, grid=None, grazing: bool = False, memo: dict | None = None):
        from .settings import DEFAULT_CHANNEL_FLOOR, DEFAULT_GRAZING_COS
        fi = res.model.fit_info
        model = copy.deepcopy(res.model)
        file_value_range(model)
        self.model, self.grazing = model, bool(grazing)
        self.grazing_cos = float(fi.get("grazing_cos", DEFAULT_GRAZING_COS))
        tm = float(res.data.theta_max) if res.data is not None else float(np.deg2rad(fi["theta_max_deg"]))
        grid = tuple(grid or (res.settings.grid if res.settings is not None else fi["grid"]))
        axes, rho, measured = measurement_grid(brdf, tm, grid)
        factor = getattr(res.model, "value_factor", "none")
        if factor != "none":        # the functions give rho / w (step 8): the nodes' values in their unit
            U = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
            X = np.stack([U[..., 0] ** 2, U[..., 1], U[..., 2]], axis=-1)
            rho = rho / value_factor_weights(X, factor)[..., None]
        self.unit = (UNIT_3D_GRAZING if grazing else UNIT_3D) + (
            f"; fit and m in the functions' unit, rho / ({factor})" if factor != "none" else "")
        self.noise = np.asarray(res.noise, np.float64)
        self.channel_floor = float(fi.get("channel_floor", DEFAULT_CHANNEL_FLOOR))
        self.tol = {(r["piece"], "RGB".index(r["channel"])): float(r["tolerance"]) for r in res.records}
        c_lo, c_hi, corners = _grid_cells(axes, rho, measured)
        self.leaves, self.originals = leaves(model), leaves(res.model)
        self.cells = [_clip(c_lo, c_hi, corners, _box(leaf)) for leaf in self.leaves]
        self.memo = memo

    def _scale(self, cr):
        mins = cr.min(axis=1)                                           # (N, 3)
        return mins, np.maximum(self.channel_floor * mins.max(axis=1), 0.0)

    def prove(self, k: int, c: int, function=None, tolerance=None, **kw) -> ProvedBound:
        """:class:`ProvedBound` of piece ``k``, channel ``c`` (``function``: this rational function
        in place of the fit's; ``tolerance``: the target, default the piece's and channel's stated
        tolerance). ``kw``: :func:`prove_cells`'s budget."""
        leaf = self.leaves[k]
        fn = self.originals[k].functions[c] if function is None else function     # the fit's own object
        target = self.tol.get((k, c), 0.0) if tolerance is None else float(tolerance)
        keep = kw.get("keep_above")
        key = (k, c, self.grazing, leaf.value_min, leaf.value_max, target,
               tuple(sorted((a, v) for a, v in kw.items() if a != "keep_above")))
        hit = self.memo.get(key) if self.memo is not None else None
        if hit is not None and hit[0] is fn and (keep is None or hit[2] == keep):
            return hit[1]
        lo, hi, cc = self.cells[k]
        noise = self.noise

        def scale_c(cr):
            mins, floor = self._scale(cr)
            return np.maximum(np.maximum(mins[:, c], noise[c]), floor)

        def s0(cr):
            return np.maximum(self._scale(cr)[1], noise[c])
        saved = leaf.functions[c]
        if function is not None:
            leaf.functions[c] = function
        try:
            b = prove_cells(leaf, c, lo, hi, cc, scale_c, target, piece=k, unit=self.unit, floor=s0,
                            weight=grazing_weight_lower(leaf, self.grazing_cos) if self.grazing else None, **kw)
        finally:
            leaf.functions[c] = saved
        if self.memo is not None:
            self.memo[key] = (fn, b, keep)   # holds the function: an identity test, never a reused id
        return b


def prove_fit3d(res, brdf, grid=None, grazing: bool = False, memo: dict | None = None, **kw) -> list:
    """:class:`ProvedBound` per piece and channel of a 3-D fit ``res``
    (:class:`fit.rational.result3d.Fit3D`) against the measurement ``brdf`` on
    :func:`measurement_grid` (``grid``: default the fit's data grid), :data:`UNIT_3D`; the
    target of each is the piece's and channel's stated tolerance. ``grazing``: the unit with the
    fit's grazing weight (:data:`UNIT_3D_GRAZING`, the unit of its stated tolerance;
    :func:`grazing_weight_lower`). ``memo``: as for :class:`Fit3DProof`. ``kw``: :func:`prove_cells`'s
    budget."""
    proof = Fit3DProof(res, brdf, grid, grazing, memo)
    return [proof.prove(k, c, **kw) for k in range(len(proof.leaves)) for c in range(3)]


def record_fit3d(res, brdf, grazing: bool = True, **kw) -> list:
    """:func:`prove_fit3d` of the 3-D fit ``res`` against ``brdf``, in the unit of its stated
    tolerance by default (``grazing``, :data:`UNIT_3D_GRAZING`: each record's ``proved`` and
    ``tolerance`` are in one unit), kept in ``res.bounds`` and its records in
    ``res.model.fit_info["bound"]`` (what :func:`fit.rational.result3d.domain_record` then
    reads)."""
    res.bounds = prove_fit3d(res, brdf, grazing=grazing, **kw)
    res.model.fit_info["bound"] = records(res.bounds)
    return res.bounds


def summary(bounds) -> dict:
    """The largest ``proved`` (None if any is None), the smallest ``proved_fraction``, the
    largest ``verified`` of a list of :class:`ProvedBound`, and ``verified_only``: the pieces and
    channels whose bound is not proved within the tolerance, with the reason
    (:attr:`ProvedBound.status`)."""
    proved = [b.proved for b in bounds]
    return {"proved": None if any(p is None for p in proved) else max(proved, default=0.0),
            "proved_fraction": min((b.proved_fraction for b in bounds), default=0.0),
            "verified": max((b.verified for b in bounds), default=0.0),
            "verified_only": [f"piece {b.piece} {b.channel}: {b.status[len('verified only: '):]}"
                              for b in bounds if b.status != "proved"]}
