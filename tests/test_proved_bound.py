"""The proved bound between data points (fit.rational.proved_bound) against a brute-force check.

A rational function with a lobe and a multilinear measurement on a grid: the proved bound must
never be below the largest error found at dense random points; an enclosure that only looks at
the corners of each cell (a plausible bug) is caught by the same check."""
import numpy as np
import pytest

from fit.rational.function import RationalFunction
from fit.rational.model import RationalModel, Variable
from fit.rational.proved_bound import UNIT_3D_GRAZING, _grid_cells, _multilinear, prove_cells
from lab.analytic import RGLLike, phi_d_lobe


def _model(value_transform="linear"):
    # P/Q with a bump near (0.3, 0.6): Q = 1.2 - 0.8 T1(x) T0 + 0.3 T2(y) ... > 0 on the box
    num_e = [[0, 0], [1, 0], [0, 1], [2, 1], [3, 0], [1, 2]]
    num_c = [1.0, 0.4, -0.3, 0.25, 0.2, -0.15]
    den_e = [[0, 0], [1, 0], [0, 2], [1, 1]]
    den_c = [1.3, 0.5, 0.3, 0.2]
    fn = RationalFunction([[0.0, 1.0], [0.0, 2.0]], num_e, num_c, den_e, den_c)
    assert fn.certify_denominator().certified
    variables = [Variable("a", "", "identity", (0.0, 1.0)), Variable("b", "", "identity", (0.0, 2.0))]
    return RationalModel("t", variables, [fn], outputs=("R",), kind="function",
                         value_transform=value_transform, value_min=None)


def _measurement(seed=3, n=(9, 7)):
    rng = np.random.default_rng(seed)
    axes = (np.linspace(0.0, 1.0, n[0]), np.linspace(0.0, 2.0, n[1]))
    m = _model()
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    values = m(X) * (1.0 + 0.05 * rng.standard_normal(X.shape[:-1] + (1,)))   # the fit +- 5 %
    return axes, values


def _brute_force(model, axes, values, n=200000, seed=5):
    """The largest |fit - m| / max(m, 0.1) at ``n`` random points (m bilinear on the grid)."""
    rng = np.random.default_rng(seed)
    x = rng.random((n, 2)) * np.array([1.0, 2.0])
    i = np.clip(np.searchsorted(axes[0], x[:, 0]) - 1, 0, len(axes[0]) - 2)
    j = np.clip(np.searchsorted(axes[1], x[:, 1]) - 1, 0, len(axes[1]) - 2)
    corners = np.stack([values[i + a, j + b] for a in (0, 1) for b in (0, 1)], axis=1)
    loc = np.stack([(x[:, 0] - axes[0][i]) / (axes[0][i + 1] - axes[0][i]),
                    (x[:, 1] - axes[1][j]) / (axes[1][j + 1] - axes[1][j])], axis=1)
    m = _multilinear(corners, loc)[:, 0]
    return float(np.max(np.abs(model(x)[:, 0] - m) / np.maximum(m, 0.1)))


def _prove(model, axes, values, relative=True, **kw):
    """:func:`prove_cells` in the unit ``max(m, 0.1)``; ``relative``: told so (``floor``), else
    only that the unit is at least its value at the smallest corner."""
    c_lo, c_hi, corners = _grid_cells(axes, values, np.ones(values.shape[:-1], bool))
    floor = (lambda cr: np.full(len(cr), 0.1)) if relative else None
    return prove_cells(model, 0, c_lo, c_hi, corners, lambda cr: np.maximum(cr[..., 0].min(axis=1), 0.1),
                       tolerance=0.01, floor=floor, **kw)


@pytest.mark.parametrize("value_transform", ["linear", "log"])
def test_proved_bound_is_never_below_the_observed_error(value_transform):
    model = _model(value_transform)
    if value_transform == "log":       # the same values through exp: fit exp(P/Q)
        axes = (np.linspace(0.0, 1.0, 9), np.linspace(0.0, 2.0, 7))
        X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
        values = model(X) * (1.0 + 0.05 * np.random.default_rng(3).standard_normal(X.shape[:-1] + (1,)))
    else:
        axes, values = _measurement()
    b = _prove(model, axes, values)
    observed = _brute_force(model, axes, values)
    assert b.proved is not None and b.verified <= b.proved
    assert observed <= b.proved
    assert b.proved <= 1.25 * observed          # and the proof is not vacuous: subdivision tightens it
    assert 0.0 <= b.proved_fraction <= 1.0 and b.cells > 0


def test_a_corner_only_enclosure_is_caught():
    """The enclosure of P/Q by its values at the cell's corners misses interior extremes: on a
    coarse grid (one cell, two halvings) its "bound" falls below the error the brute-force check
    finds, while the Bernstein enclosure stays above it."""
    model = _model()
    axes = (np.array([0.0, 1.0]), np.array([0.0, 2.0]))
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    values = np.full(X.shape[:-1] + (1,), float(np.mean(model(X))))

    def corners_only(fn, t_lo, t_hi):
        pts = [np.stack([np.where(a, t_hi[:, 0], t_lo[:, 0]), np.where(b, t_hi[:, 1], t_lo[:, 1])], axis=1)
               for a in (0, 1) for b in (0, 1)]
        phys = [0.5 * (p + 1.0) * (fn.domain[:, 1] - fn.domain[:, 0]) + fn.domain[:, 0] for p in pts]
        v = np.stack([fn(p) for p in phys], axis=1)
        return v.min(axis=1), v.max(axis=1)

    observed = _brute_force(model, axes, values)
    wrong = _prove(model, axes, values, max_rounds=2, enclose=corners_only)
    right = _prove(model, axes, values, max_rounds=2)
    assert wrong.proved < observed              # the check catches the wrong enclosure
    assert right.proved >= observed


def test_reader_checks_the_bound_records():
    """A file's ``bound`` records are read back; a proved bound below the verified error or a
    fraction outside [0, 1] is a one-line error."""
    import copy

    from fit.errors import BRDFFileError
    from fit.rational.coefficient_file import load, to_dict
    from fit.rational.coefficient_reader import from_dict
    from warp_rbrdf.paths import PACKAGE_DATA

    m = load(sorted(PACKAGE_DATA.glob("paper_white*.json"))[0])
    rec = {"piece": 0, "channel": "R", "proved": 0.06, "proved_fraction": 0.9, "verified": 0.057,
           "verified_points": 100, "tolerance": 0.05, "unit": "relative", "cells": 50, "time_s": 0.1}
    m.fit_info["bound"] = [rec]
    d = to_dict(m)
    assert from_dict(d).fit_info["bound"] == [rec]
    for field, value in (("proved", 0.01), ("proved_fraction", 1.5), ("channel", "X")):
        bad = copy.deepcopy(d)
        bad["fit"]["bound"][0][field] = value
        with pytest.raises(BRDFFileError, match=f"bound.0..{field}"):
            from_dict(bad)


#: a diffuse base and a broad lobe in theta_h that depends on phi_d, not reciprocal (1/sr, RGB)
_broad_lobe = phi_d_lobe(1.5, 0.45, 2)


def _brute_force_3d(res, brdf, n=100000, seed=11, grazing=False):
    """The largest error per (piece, channel) at ``n`` random points of the measured cells, in
    :data:`fit.rational.proved_bound.UNIT_3D` (the measurement trilinear on the fit's grid);
    ``grazing``: in :data:`fit.rational.proved_bound.UNIT_3D_GRAZING`."""
    from fit.rational.samples3d import grazing_weight
    from fit.rational.proved_bound import measurement_grid
    from fit.rational.settings import DEFAULT_CHANNEL_FLOOR

    axes, rho, measured = measurement_grid(brdf, float(res.data.theta_max), res.settings.grid)
    rng = np.random.default_rng(seed)
    u = rng.random((n, 3)) * np.array([a[-1] for a in axes])
    idx = [np.clip(np.searchsorted(axes[v], u[:, v]) - 1, 0, len(axes[v]) - 2) for v in range(3)]
    bits = [(a, b, c) for a in (0, 1) for b in (0, 1) for c in (0, 1)]      # _multilinear's order
    ok = np.all([measured[idx[0] + a, idx[1] + b, idx[2] + c] for a, b, c in bits], axis=0)
    u, idx = u[ok], [i[ok] for i in idx]
    corners = np.stack([rho[idx[0] + a, idx[1] + b, idx[2] + c] for a, b, c in bits], axis=1)
    loc = np.stack([(u[:, v] - axes[v][idx[v]]) / (axes[v][idx[v] + 1] - axes[v][idx[v]]) for v in range(3)], 1)
    m = _multilinear(corners, loc)
    X = np.stack([u[:, 0] ** 2, u[:, 1], u[:, 2]], axis=1)
    f = np.asarray(res.model(X), np.float64)
    s = np.maximum(np.maximum(m, np.asarray(res.noise)[None, :]), DEFAULT_CHANNEL_FLOOR * m.max(axis=1, keepdims=True))
    err = np.abs(f - m) / s
    if grazing:
        err = err / grazing_weight(X, res.settings.grazing_cos)[:, None]
    piece = np.clip(np.searchsorted(res.edges, X[:, 0], side="right") - 1, 0, len(res.edges) - 2)
    return {(k, "RGB"[c]): float(err[piece == k, c].max(initial=0.0))
            for k in range(len(res.edges) - 1) for c in range(3)}


def test_3d_fit_proves_its_bound_between_the_grid_nodes(tmp_path):
    """A small-budget 3-D fit with ``prove_bound``: a bound per piece and channel in the unit of the
    stated tolerance (with the grazing weight), never below the largest error at dense random
    points of the measured cells, recorded in the fit's record (read back from its file) and in
    ``fit_info["domain"]``; without it nothing is claimed. In the unit without the grazing weight
    the bound is again above the error at the random points, and at least the recorded one."""
    from fit.rational.coefficient_file import load, save
    from fit.rational.fit3d import fit_rgl
    from fit.rational.proved_bound import prove_fit3d

    brdf = RGLLike(_broad_lobe, "broad_lobe")
    # a 7 x 6 x 5 grid: 100-400 cells per piece and channel after subdivision, each proof a
    # tenth of a second (9 x 8 x 6: 7000 cells, 10 s for the two proofs)
    fit = dict(grid=(7, 6, 5), n_random=200, n_objective=0, verify=0, degrees=(4, 2), theta_h_edges=[0.3],
               tol=0.05, time_limit=60.0, albedo=False)
    res = fit_rgl(brdf, prove_bound=True, **fit)
    assert len(res.bounds) == 2 * 3 and res.model.fit_info["bound"] == [b.record() for b in res.bounds]
    observed_w = _brute_force_3d(res, brdf, grazing=True)
    for b in res.bounds:          # recorded in the unit of the stated tolerance (the grazing weight)
        assert b.proved is not None and b.unit.startswith(UNIT_3D_GRAZING), b
        assert b.verified <= b.proved and observed_w[(b.piece, b.channel)] <= b.proved, (b, observed_w)
        assert b.proved <= 50 * observed_w[(b.piece, b.channel)] + b.tolerance   # not vacuous
    d = res.model.fit_info["domain"]
    assert d["proved_at"] == "grid cells" and d["proved_bound"] == max(b.proved for b in res.bounds)
    assert d["proved"] == all(b.proved <= b.tolerance for b in res.bounds)
    assert d["proved_over_stated"] == max(b.proved / b.tolerance for b in res.bounds)
    save(res.model, tmp_path / "f.json")
    assert load(tmp_path / "f.json").fit_info["bound"] == res.model.fit_info["bound"]
    plain_unit = prove_fit3d(res, brdf)          # without the grazing weight: a smaller unit
    observed = _brute_force_3d(res, brdf)
    for b, w in zip(plain_unit, res.bounds):
        assert observed[(b.piece, b.channel)] <= b.proved and w.proved <= b.proved * (1 + 1e-9), (b, observed)
    plain = fit_rgl(brdf, prove_bound=False, **fit)
    assert plain.bounds is None and "bound" not in plain.model.fit_info
    assert plain.model.fit_info["domain"]["proved"] is False


def test_joint_enclosure_contains_the_difference():
    """``Enclosure.ratio_minus`` encloses ``P/Q - l`` (l multilinear through given corner values)
    on random sub-boxes: every value at dense points of each box lies inside; the joint enclosure
    is narrower than the range of P/Q plus the range of l on small boxes."""
    from fit.rational.cell_enclosure import Enclosure, corner_bits

    fn = _model().functions[0]
    enc = Enclosure(fn)
    rng = np.random.default_rng(7)
    n = 60
    a = rng.uniform(-1, 1, (n, 2))
    w = rng.uniform(0.01, 0.5, (n, 2))
    t_lo, t_hi = a, np.minimum(a + w, 1.0)
    ell = rng.uniform(0.5, 2.0, (n, 4))
    dl, dh = enc.ratio_minus(t_lo, t_hi, ell)
    rl, rh = enc.ratio(t_lo, t_hi)
    bits = corner_bits(2)
    g = np.linspace(0.0, 1.0, 41)
    loc = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    for i in range(n):
        t = t_lo[i] + loc * (t_hi[i] - t_lo[i])
        x = 0.5 * (t + 1.0) * (fn.domain[:, 1] - fn.domain[:, 0]) + fn.domain[:, 0]
        w_c = np.prod(np.where(bits[None, :, :], loc[:, None, :], 1.0 - loc[:, None, :]), axis=2)
        d = fn(x) - w_c @ ell[i]
        assert dl[i] <= d.min() and d.max() <= dh[i], i
    small = np.max(t_hi - t_lo, axis=1) < 0.1
    joint = dh - dl
    ranges = (rh - rl) + (ell.max(axis=1) - ell.min(axis=1))
    assert np.all(joint[small] < ranges[small])


@pytest.mark.parametrize("relative", [True, False])
@pytest.mark.parametrize("value_transform", ["linear", "log"])
def test_joint_enclosure_is_tighter_and_still_above_the_true_error(value_transform, relative):
    """On cells where the fit follows a varying measurement closely, the separate ranges of fit
    and interpolant (``enclosure="ranges"``) add both variations; the joint enclosure of their
    difference does not: without subdivision it proves a smaller bound, and it is still at least
    the largest error at dense random points."""
    model = _model(value_transform)
    axes = (np.linspace(0.0, 1.0, 9), np.linspace(0.0, 2.0, 7))
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    values = model(X) * (1.0 + 0.02 * np.random.default_rng(3).standard_normal(X.shape[:-1] + (1,)))
    observed = _brute_force(model, axes, values)
    loose = _prove(model, axes, values, relative, max_rounds=0, enclosure="ranges")
    tight = _prove(model, axes, values, relative, max_rounds=0, enclosure="joint")
    assert observed <= tight.proved < 0.8 * loose.proved, (observed, tight.proved, loose.proved)
    refined = _prove(model, axes, values, relative, enclosure="joint")
    assert observed <= refined.proved <= tight.proved


def test_relative_form_of_a_log_fit_is_tighter_and_still_above_the_true_error():
    """A log fit's joint bound in the relative unit (``floor`` given: the unit is ``max(m, s0)``)
    does not carry the variation of m over the cell, which the same bound over the unit's
    smallest value on the cell does; both stay above the brute-force error."""
    model = _model("log")
    axes = (np.linspace(0.0, 1.0, 9), np.linspace(0.0, 2.0, 7))
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    values = model(X) * (1.0 + 0.02 * np.random.default_rng(3).standard_normal(X.shape[:-1] + (1,)))
    observed = _brute_force(model, axes, values)
    rel = _prove(model, axes, values, True, max_rounds=0)
    absolute = _prove(model, axes, values, False, max_rounds=0)
    assert observed <= rel.proved < 0.6 * absolute.proved, (observed, rel.proved, absolute.proved)


def test_status_says_proved_or_verified_only_and_why():
    """``ProvedBound.status``: "proved" only within the tolerance; otherwise "verified only" with
    the reason, and ``summary`` lists exactly those pieces and channels."""
    from fit.rational.proved_bound import ProvedBound, summary

    def b(proved, verified, piece=0):
        return ProvedBound(piece, "R", proved, 0.5, verified, 10, 0.05, "", 5, 0.1)
    ok, real, gap, none = b(0.049, 0.04), b(0.3, 0.2, 1), b(0.052, 0.049, 2), b(None, 0.01, 3)
    assert ok.status == "proved"
    assert real.status.startswith("verified only: the fit's error between the nodes, 20 %")
    assert gap.status.startswith("verified only: the proof ended at 5.2 %")
    assert none.status.startswith("verified only: Q's")
    s = summary([ok, real, gap, none])
    assert s["proved"] is None and len(s["verified_only"]) == 3
    assert [v.split(":")[0] for v in s["verified_only"]] == ["piece 1 R", "piece 2 R", "piece 3 R"]


def test_proof_guided_refit_finds_and_removes_errors_between_the_grid_nodes():
    """``proof_rounds`` (:func:`fit.rational.verify3d.refit_between_nodes`): a fit constrained only
    at a coarse grid and 20 random points leaves its stated bound by hundreds of times between
    the grid nodes (proved); the proof-guided refit starts from that proof (its first round's
    ratio is the fit's), adds the worst points of the cells it finds to the data, refits only the
    functions outside their bound there, proves the last refit too, and returns the fit of the
    lowest proved bound, several times lower, every data point (the added ones included) within
    the stated bound."""
    from fit.rational.fit3d import fit_rgl, verification_ratio
    from fit.rational.verify3d import KEEP_WITHIN

    brdf = RGLLike(_broad_lobe, "broad_lobe")
    fit = dict(grid=(5, 5, 3), n_random=20, n_objective=0, verify=0, degrees=(5, 2), theta_h_edges=[0.3],
               tol=0.05, time_limit=60.0, albedo=False)
    before = fit_rgl(brdf, proof_rounds=0, **fit)
    after = fit_rgl(brdf, proof_rounds=2, **fit)
    d0, d1 = before.model.fit_info["domain"], after.model.fit_info["domain"]
    assert d0["proved_over_stated"] > 100, d0
    rec = after.model.fit_info["proof_refit"]
    log = rec["log"]                  # two refits, then the pass that proves the last one
    assert [e["round"] for e in log] == [0, 1, 2] and log[2]["points_added"] == 0
    assert log[0]["proved_over_stated"] == pytest.approx(d0["proved_over_stated"], rel=1e-9)
    assert d1["proved_over_stated"] < 0.25 * d0["proved_over_stated"], (d0, d1)
    kept = log[rec["kept"]]["proved_over_stated"]       # the lowest proved of the three (a later one within 5 %)
    assert kept <= KEEP_WITHIN * min(e["proved_over_stated"] for e in log)
    assert kept == pytest.approx(d1["proved_over_stated"], rel=1e-9)
    assert all(e["proved_over_stated"] > KEEP_WITHIN * kept for e in log[rec["kept"] + 1:])
    added = sum(e["points_added"] for e in log[:rec["kept"]])
    assert all(e["points_added"] > 0 and e["refitted"] for e in log[:2])
    assert len(after.data.X) == len(before.data.X) + added
    assert np.max(verification_ratio(after, after.data.X, after.data.rho)) <= 1.0 + 1e-9
    kept = {f"{k}{'RGB'[c]}" for k in range(2) for c in range(3)} - set(log[0]["refitted"])
    if kept:            # a function no round refitted is the first fit's, coefficient for coefficient
        for name in kept - set(log[1]["refitted"]):
            k, c = int(name[0]), "RGB".index(name[1])
            f0, f1 = before.model.pieces[k].functions[c], after.model.pieces[k].functions[c]
            assert np.array_equal(f0.num_coef, f1.num_coef)


def test_a_proof_memo_reuses_unchanged_functions_only(monkeypatch):
    """``Fit3DProof(..., memo=)``: the proof of a function already proved under the same value
    range and target is reused (no cell is bounded again); a different function in its place, or
    a request for more kept cells than the stored proof kept, is proved again."""
    import copy

    import fit.rational.proved_bound as pb
    from fit.rational.fit3d import fit_rgl

    brdf = RGLLike(_broad_lobe, "broad_lobe")
    res = fit_rgl(brdf, grid=(5, 5, 3), n_random=20, n_objective=0, verify=0, degrees=(3, 1),
                  theta_h_edges=[0.3], tol=0.05, time_limit=60.0, albedo=False, proof_rounds=0, prove_bound=False)
    calls = []
    real = pb.prove_cells

    def counting(*a, **kw):
        calls.append(kw.get("piece"))
        return real(*a, **kw)
    monkeypatch.setattr(pb, "prove_cells", counting)
    memo = {}
    first = pb.prove_fit3d(res, brdf, grazing=True, memo=memo)
    assert len(calls) == 6
    again = pb.prove_fit3d(res, brdf, grazing=True, memo=memo)
    assert len(calls) == 6 and all(a is b for a, b in zip(first, again))
    other = copy.deepcopy(res.model.pieces[1].functions[0])
    res.model.pieces[1].functions[0] = other
    third = pb.prove_fit3d(res, brdf, grazing=True, memo=memo)
    assert len(calls) == 7 and third[3] is not first[3] and third[0] is first[0]
    pb.Fit3DProof(res, brdf, grazing=True, memo=memo).prove(0, 0, keep_above=1.0)
    assert len(calls) == 8


def test_invert_input_transform_is_the_inverse_of_apply():
    """``invert_input_transform`` undoes ``apply_input_transform`` for every input transform and
    refuses an unknown one."""
    from fit.rational.model import INPUT_TRANSFORMS, apply_input_transform, invert_input_transform

    x = np.linspace(0.0, 1.5, 7)
    for t in INPUT_TRANSFORMS:
        assert np.allclose(invert_input_transform(apply_input_transform(x, t), t), x, rtol=1e-15, atol=0)
    assert np.array_equal(invert_input_transform(np.array([0.5]), "sqrt"), [0.25])
    with pytest.raises(ValueError, match="unknown input transform"):
        invert_input_transform(x, "log")


def test_cell_points_cover_the_interior_faces_and_corners_of_each_cell():
    """The proof-guided refit looks for a spike inside each cell and on its faces, edges and
    corners (``_cell_points``): a spike at a corner of the measured domain (theta_d = 0,
    phi_d = 0) is not seen at the interior points. Each cell gets ``2 L^n - 1`` points, all inside
    it (none on its boundary, which a neighbouring theta_h piece evaluates), one within
    ``FACE_INSET`` of its side of every corner and at its centre, in the fit's variables (theta_h
    through the leaf's square-root transform)."""
    from types import SimpleNamespace

    from fit.rational.verify3d import FACE_INSET, LATTICE, _cell_points

    leaf = SimpleNamespace(variables=[Variable("theta_h", "", "sqrt", (0.0, 1.0)),
                                      Variable("theta_d", "", "identity", (0.0, 1.5)),
                                      Variable("phi_d", "", "identity", (0.0, np.pi))])
    lo = np.array([[0.4, 0.0, 0.0], [0.5, 0.3, 1.0]])
    hi = np.array([[0.5, 0.01, 0.02], [0.6, 0.5, 2.0]])
    X = _cell_points(leaf, {"lo": lo, "hi": hi})
    per = 2 * LATTICE ** 3 - 1
    assert X.shape == (2 * per, 3)
    U = np.column_stack([np.sqrt(X[:, 0]), X[:, 1], X[:, 2]]).reshape(2, per, 3)
    assert np.all(U > lo[:, None, :]) and np.all(U < hi[:, None, :])
    for k in range(2):
        frac = (U[k] - lo[k]) / (hi[k] - lo[k])
        for corner in np.array(np.meshgrid(*([[0.0, 1.0]] * 3), indexing="ij")).reshape(3, -1).T:
            assert np.min(np.max(np.abs(frac - corner), axis=1)) <= FACE_INSET * (1 + 1e-9)
        assert np.min(np.max(np.abs(frac - 0.5), axis=1)) < 1e-12
        assert len(np.unique(np.round(frac, 12), axis=0)) == per


def test_restriction_to_sub_boxes_is_the_same_polynomial_in_three_variables():
    """``cell_enclosure.restrict`` (a batched product per axis): the Bernstein coefficients it
    gives on each sub-box describe the same polynomial there, in every variable of a 3-D tensor
    of unequal degrees, within its error bound; ``_elevate`` (Q one degree higher) is
    ``_times_linear`` with Q at every corner, to the last bit."""
    from math import comb

    from fit.rational.cell_enclosure import _elevate, _times_linear, restrict

    rng = np.random.default_rng(11)
    b = rng.standard_normal((4, 3, 6))
    lo = rng.uniform(0, 0.6, (25, 3))
    hi = lo + rng.uniform(0.05, 0.4, (25, 3))
    out, err = restrict(b, 1e-16, lo, hi)

    def bern(coef, u):          # tensor Bernstein polynomial at points u (M, 3) of [0, 1]^3
        basis = [np.stack([comb(d - 1, k) * u[:, v] ** k * (1 - u[:, v]) ** (d - 1 - k) for k in range(d)], 1)
                 for v, d in enumerate(coef.shape)]
        return np.einsum("abc,ma,mb,mc->m", coef, *basis)

    u = rng.random((40, 3))
    for i in range(len(lo)):
        assert out[i].shape == b.shape
        np.testing.assert_allclose(bern(out[i], u), bern(b, lo[i] + u * (hi[i] - lo[i])), rtol=0, atol=1e-12)
        assert 0 < err[i] < 1e-12
    Q = rng.standard_normal((7, 4, 3, 6))
    corners = np.broadcast_to(Q.reshape(7, 1, 1, 1, 4, 3, 6), (7, 2, 2, 2, 4, 3, 6))
    assert np.array_equal(_elevate(Q, 3), _times_linear(corners, 3))
