"""The phi_d fold (issue 20, "roles"): MERL tables fold phi_d into [0, pi) by reciprocity (the
format defines it); tables from a non-reciprocal source (RGL-EPFL files) keep the full circle,
360 bins over [0, 2 pi), so that (light, view) and (view, light) read their own values."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import data_file, rgl_measured

from lab.analytic import glossy_lobe, lambert
from fit.errors import BRDFFileError
from fit.formats.angles import half_diff_to_directions
from fit.formats.grid import (
    FULL_SHAPE,
    MERL_SHAPE,
    phi_d_centres,
    phi_d_index,
    theta_d_centres,
    theta_h_centres,
)
from fit.formats.measured import MeasuredBRDF
from fit.formats.merl import write_merl
from fit.formats.rgl import read_rgl
from fit.projection.project import below_horizon_counts, grazing_mask, project
from fit.projection.projected import ProjectedBRDF
from fit.rational.brdf_fit import channel_data, project_for_fit

LUMA = np.array([0.2126, 0.7152, 0.0722])
GLOSSY = "cc_ibiza_sunset_rgb"   # reciprocal only to 10-27 %


def non_reciprocal(wi, wo):
    """A smooth BRDF whose value changes when light and view are swapped."""
    base = 0.2 + 0.15 * wi[..., 2] ** 2 - 0.05 * wo[..., 0] + 0.03 * wi[..., 1] * wo[..., 2]
    return np.stack([base, 1.5 * base, 0.5 + 0 * base], -1)


def centre_pairs(n_phi_d, n=4000, seed=0, margin=0.02):
    """(light, view) pairs at random bin centres of the grid (phi_h = 0), both above
    ``margin`` (outside to_measured's 1 deg horizon band); also returns the bin indices."""
    rng = np.random.default_rng(seed)
    i, j, k = rng.integers(0, 90, n), rng.integers(0, 90, n), rng.integers(0, n_phi_d, n)
    wl, wv = half_diff_to_directions(theta_h_centres()[i], 0.0, theta_d_centres()[j], phi_d_centres(n_phi_d)[k])
    ok = (wl[:, 2] > margin) & (wv[:, 2] > margin)
    return wl[ok], wv[ok], (i[ok], j[ok], k[ok])


# ------------------------------------------------------------------------------------------
# The grid
# ------------------------------------------------------------------------------------------
def test_grid_folds_only_with_180_bins():
    assert MERL_SHAPE == (90, 90, 180) and FULL_SHAPE == (90, 90, 360)
    full, half = phi_d_centres(360), phi_d_centres(180)
    assert full.shape == (360,) and 0 < full[0] and full[-1] < 2 * np.pi
    np.testing.assert_array_equal(full[:180], half)   # the first half is the MERL grid
    np.testing.assert_array_equal(phi_d_index(full, 360), np.arange(360))
    np.testing.assert_array_equal(phi_d_index(full, 180), np.arange(360) % 180)   # folded
    # phi_d in (-pi, pi] as directions_to_half_diff returns it: wrapped, not folded
    assert phi_d_index(-np.radians(0.5), 360) == 359 and phi_d_index(-np.radians(0.5), 180) == 179
    assert phi_d_index(np.pi, 360) == 180 and phi_d_index(np.pi, 180) == 0
    with pytest.raises(ValueError):
        phi_d_centres(90)


def test_swapping_light_and_view_moves_phi_d_by_pi():
    """The convention the full-circle tables rely on: half_diff_to_directions returns
    (light, view), and (view, light) has the same theta_h, theta_d and phi_d + pi."""
    from fit.formats.angles import directions_to_half_diff
    wl, wv, (_, _, k) = centre_pairs(360)
    th, _, td, pd = directions_to_half_diff(wl, wv)
    np.testing.assert_array_equal(phi_d_index(pd, 360), k)
    th2, _, td2, pd2 = directions_to_half_diff(wv, wl)
    np.testing.assert_allclose(th2, th, atol=1e-12)
    np.testing.assert_allclose(td2, td, atol=1e-12)
    np.testing.assert_array_equal(phi_d_index(pd2, 360), (k + 180) % 360)


# ------------------------------------------------------------------------------------------
# MeasuredBRDF
# ------------------------------------------------------------------------------------------
def test_from_function_full_circle_keeps_both_orders():
    full = MeasuredBRDF.from_function(non_reciprocal, reciprocal=False)
    folded = MeasuredBRDF.from_function(non_reciprocal)
    assert full.values.shape == FULL_SHAPE + (3,) and not full.reciprocal and full.n_phi_d == 360
    assert folded.values.shape == MERL_SHAPE + (3,) and folded.reciprocal and folded.n_phi_d == 180
    assert full.phi_d.shape == (360,)
    wl, wv, _ = centre_pairs(360)
    lv, vl = non_reciprocal(wl, wv), non_reciprocal(wv, wl)
    assert np.abs(lv - vl).max() > 0.05
    np.testing.assert_allclose(full.evaluate(wl, wv), lv, rtol=1e-12)
    np.testing.assert_allclose(full.evaluate(wv, wl), vl, rtol=1e-12)
    # the folded table cannot: both orders read the same bin
    np.testing.assert_array_equal(folded.evaluate(wl, wv, "nearest"), folded.evaluate(wv, wl, "nearest"))
    np.testing.assert_allclose(folded.evaluate(wl, wv), folded.evaluate(wv, wl), rtol=1e-12)
    # valid mask: geometry at the bin centres, on the full circle too
    assert full.valid.shape == full.values.shape
    assert full.valid[..., 0].sum() == 360 * 8100 - below_horizon_counts(360).sum()


def test_measured_brdf_rejects_other_shapes_and_merl_writer_refuses_full_circle(tmp_path):
    from fit.errors import BRDFFileError
    with pytest.raises(BRDFFileError):
        MeasuredBRDF(values=np.zeros((90, 90, 90, 3)), valid=np.zeros((90, 90, 90, 3), bool))
    full = MeasuredBRDF.from_function(lambert(), reciprocal=False)
    with pytest.raises(ValueError, match="reciprocity"):
        write_merl(full, tmp_path / "x.binary")


# ------------------------------------------------------------------------------------------
# RGL files: the resampled table reproduces the file with both roles
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rgl_roles():
    path = data_file(f"rgl/{GLOSSY}.bsdf")
    out = {}
    for incident in ("view", "light"):
        b = read_rgl(path, incident=incident)
        out[incident] = (b, rgl_measured(GLOSSY, incident))   # b.to_measured(), once per session
    return out


@pytest.mark.parametrize("incident", ["view", "light"])
def test_rgl_table_reproduces_the_file_for_both_orders(incident, rgl_roles):
    """At bin centres MeasuredBRDF.evaluate(light, view) == RGLBRDF.evaluate(light, view) and
    the same for the swapped pair, which the source gives a different value (a folded table
    returns one of the two for both: the seam of issue 20)."""
    b, m = rgl_roles[incident]
    wl, wv, _ = centre_pairs(360, seed=5)
    lv, vl = b.evaluate(wl, wv), b.evaluate(wv, wl)
    # the source is not reciprocal at many of these pairs...
    yl, yv = lv @ LUMA, vl @ LUMA
    big = np.abs(yl - yv) > 0.1 * np.maximum(yl, yv)
    assert big.mean() > 0.05, big.mean()
    # ...and the table keeps the difference
    tl, tv = m.evaluate(wl, wv) @ LUMA, m.evaluate(wv, wl) @ LUMA
    np.testing.assert_allclose((tl - tv)[big], (yl - yv)[big], rtol=1e-9)
    np.testing.assert_allclose(m.evaluate(wl, wv), lv, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(m.evaluate(wv, wl), vl, rtol=1e-9, atol=1e-12)
    assert not m.reciprocal and m.values.shape == FULL_SHAPE + (3,)
    assert m.metadata["incident"] == incident and "360" in m.metadata["phi_d"]


def test_rgl_roles_swap_the_halves_and_the_projection_ignores_them(rgl_roles):
    mv, ml = rgl_roles["view"][1], rgl_roles["light"][1]
    wl, wv, _ = centre_pairs(360, seed=6)
    # incident="light" is incident="view" with the arguments swapped
    np.testing.assert_allclose(ml.evaluate(wl, wv), mv.evaluate(wv, wl), rtol=1e-9, atol=1e-12)
    # the projection gathers both orders of every pair: the same for both roles
    pv, pl = project(mv), project(ml)
    assert pv.n_phi_d == pl.n_phi_d == 360
    np.testing.assert_array_equal(pv.count, pl.count)
    np.testing.assert_allclose(pv.median, pl.median, rtol=1e-9, equal_nan=True)
    np.testing.assert_allclose(pv.mean, pl.mean, rtol=1e-9, equal_nan=True)
    # counts: never more than the above-horizon bins of the 360
    assert np.all(pv.count[..., 0] + pv.n_below_horizon <= 360)
    assert pv.count.max() == 360


# ------------------------------------------------------------------------------------------
# Projection and fit inputs on the full circle
# ------------------------------------------------------------------------------------------
def test_projection_counts_and_masks_on_the_full_circle():
    np.testing.assert_array_equal(below_horizon_counts(360), 2 * below_horizon_counts(180))
    for angle in ("theta_io", "theta_d"):
        g = grazing_mask(75.0, angle, n_phi_d=360)
        assert g.shape == FULL_SHAPE
        np.testing.assert_array_equal(g.sum(axis=-1), 2 * grazing_mask(75.0, angle).sum(axis=-1))
    assert grazing_mask(90.0, n_phi_d=360).sum() == 360 * 8100 - below_horizon_counts(360).sum()
    p = project(MeasuredBRDF.from_function(lambert(), reciprocal=False))
    np.testing.assert_array_equal(p.count[..., 0] + p.n_below_horizon, 360)


def test_full_circle_projection_of_a_reciprocal_brdf_equals_the_folded_one():
    """Every statistic, the counts relative to n_phi_d and the fit's intervals (partial
    clusters: count < fraction * (n_phi_d - n_below_horizon)) agree between the two grids."""
    f = glossy_lobe(exponent=30.0, phi_mod=0.3)
    folded, full = MeasuredBRDF.from_function(f), MeasuredBRDF.from_function(f, reciprocal=False)
    pa, pb = project_for_fit(folded), project_for_fit(full)   # 79 deg grazing cut-off
    assert (pa.n_phi_d, pb.n_phi_d) == (180, 360)
    np.testing.assert_array_equal(pb.count, 2 * pa.count)
    np.testing.assert_array_equal(pb.n_below_horizon, 2 * pa.n_below_horizon)
    for s in ("value", "median", "mean", "variance"):
        np.testing.assert_allclose(getattr(pb, s), getattr(pa, s), rtol=1e-9, atol=1e-15, equal_nan=True)
    for c in range(3):
        a = channel_data(pa, c, 0.05, "tol+spread", rho_ref=0.1, partial_min_fraction=0.5)
        b = channel_data(pb, c, 0.05, "tol+spread", rho_ref=0.1, partial_min_fraction=0.5)
        np.testing.assert_allclose(b.lower, a.lower, rtol=1e-9)
        np.testing.assert_allclose(b.upper, a.upper, rtol=1e-9)


def test_projected_npz_keeps_n_phi_d(tmp_path):
    p = project(MeasuredBRDF.from_function(lambert(), reciprocal=False))
    p.save(tmp_path / "p.npz")
    q = ProjectedBRDF.load(tmp_path / "p.npz")
    assert q.n_phi_d == 360
    np.testing.assert_array_equal(q.n_below_horizon, p.n_below_horizon)
    # files written before the key existed are folded MERL projections
    project(MeasuredBRDF.from_function(lambert())).save(tmp_path / "folded.npz")
    with np.load(tmp_path / "folded.npz") as z:
        old = {k: z[k] for k in z.files if k != "n_phi_d"}
    np.savez(tmp_path / "old.npz", **old)
    assert ProjectedBRDF.load(tmp_path / "old.npz").n_phi_d == 180
    # a full-circle projection stripped of its key has counts up to 360: refused, not misread
    with np.load(tmp_path / "p.npz") as z:
        stripped = {k: z[k] for k in z.files if k != "n_phi_d"}
    np.savez(tmp_path / "stripped.npz", **stripped)
    with pytest.raises(BRDFFileError, match="'count' holds values outside"):
        ProjectedBRDF.load(tmp_path / "stripped.npz")
