"""Projection onto (theta_h, theta_d): counts from geometry, statistics against a slow reference."""
import numpy as np
import pytest

from lab.analytic import glossy_lobe, lambert
from fit.formats.angles import half_diff_to_directions
from fit.formats.grid import MERL_SHAPE, phi_d_centres, theta_d_centres, theta_h_centres
from fit.formats.measured import MeasuredBRDF
from fit.formats.merl import read_merl, write_merl
from fit.projection.project import below_horizon_counts, grazing_mask, project
from fit.projection.projected import STATISTICS, ProjectedBRDF


def test_lambert_clusters_equal_albedo_over_pi(tmp_path):
    path = tmp_path / "lambert.binary"
    write_merl(MeasuredBRDF.from_function(lambert((0.8, 0.5, 0.2))), path)
    p = project(read_merl(path))
    full = p.count[..., 0] > 0
    assert full.sum() > 5000
    np.testing.assert_allclose(p.value[full], np.broadcast_to(np.array([0.8, 0.5, 0.2]) / np.pi, (full.sum(), 3)),
                               rtol=1e-12)
    assert np.isnan(p.value[~full]).all()
    np.testing.assert_allclose(p.variance[full], 0.0, atol=1e-20)


def test_below_horizon_count_matches_geometry(tmp_path):
    """The writer marks below-horizon triplets from direction vectors; the count per cluster must
    equal an independent count from the closed-form cosines, and from an explicit loop."""
    path = tmp_path / "g.binary"
    write_merl(MeasuredBRDF.from_function(glossy_lobe()), path)
    p = project(read_merl(path))
    np.testing.assert_array_equal(p.count[..., 0] + p.n_below_horizon, 180)
    # independent: explicit direction vectors, per cluster, for a sample of clusters
    rng = np.random.default_rng(0)
    for i, j in zip(rng.integers(0, 90, 60), rng.integers(0, 90, 60)):
        wi, wo = half_diff_to_directions(theta_h_centres()[i], 0.3, theta_d_centres()[j], phi_d_centres())
        expected = int(np.sum((wi[:, 2] <= 0) | (wo[:, 2] <= 0)))
        assert p.n_below_horizon[i, j] == expected
    # sanity: near the normal nothing is below, beyond theta_h + theta_d > 90 deg something is
    assert below_horizon_counts()[0, 0] == 0 and below_horizon_counts()[89, 89] > 0


def _slow_stat(values, stat):
    v = np.asarray(values, float)
    if v.size == 0:
        return np.nan
    if stat == "median":
        return float(np.median(v))
    if stat == "mean":
        return float(np.mean(v))
    if stat == "geometric":
        return float(np.exp(np.mean(np.log(v)))) if np.all(v > 0) else 0.0
    if stat == "harmonic":
        return float(len(v) / np.sum(1.0 / v)) if np.all(v > 0) else 0.0
    if stat == "rms":
        return float(np.sqrt(np.mean(v * v)))
    raise ValueError(stat)


@pytest.fixture(scope="module")
def random_brdf():
    rng = np.random.default_rng(42)
    values = rng.lognormal(0.0, 1.0, MERL_SHAPE + (3,))
    valid = rng.random(MERL_SHAPE + (3,)) < 0.7
    # some whole clusters empty, some with a single or two samples, some zero values
    valid[5, 7] = False
    valid[6, 8] = False
    valid[6, 8, 3] = True
    valid[7, 9] = False
    valid[7, 9, 10:12] = True
    values[8, 10, :5] = 0.0
    return MeasuredBRDF(values=values, valid=valid)


@pytest.mark.parametrize("stat", STATISTICS)
def test_statistics_against_slow_reference(random_brdf, stat):
    p = project(random_brdf, statistic=stat)
    rng = np.random.default_rng(7)
    clusters = [(5, 7), (6, 8), (7, 9), (8, 10)] + list(zip(rng.integers(0, 90, 150), rng.integers(0, 90, 150)))
    for i, j in clusters:
        for c in range(3):
            vals = [random_brdf.values[i, j, k, c] for k in range(180) if random_brdf.valid[i, j, k, c]]
            assert p.count[i, j, c] == len(vals)
            ref = _slow_stat(vals, stat)
            if np.isnan(ref):
                assert np.isnan(p.value[i, j, c])
            else:
                assert p.value[i, j, c] == pytest.approx(ref, rel=1e-10, abs=1e-300)
            if vals:
                assert p.median[i, j, c] == pytest.approx(np.median(vals), rel=1e-12)
                assert p.mean[i, j, c] == pytest.approx(np.mean(vals), rel=1e-12)
                assert p.variance[i, j, c] == pytest.approx(np.var(vals), rel=1e-8, abs=1e-12)


def test_median_removes_outliers(random_brdf):
    b = MeasuredBRDF(values=random_brdf.values.copy(), valid=np.ones_like(random_brdf.valid))
    b.values[20, 30] = 1.0
    b.values[20, 30, :10] = 1e6  # acquisition artefacts in 10 of 180 samples
    p = project(b)
    assert p.value[20, 30, 0] == 1.0
    assert p.mean[20, 30, 0] > 1e4


def test_grazing_cutoff_drops_only_grazing_samples(tmp_path):
    path = tmp_path / "g.binary"
    write_merl(MeasuredBRDF.from_function(glossy_lobe()), path)
    b = read_merl(path)
    p = project(b, grazing_cutoff_deg=80.0)
    th = theta_h_centres()[:, None, None]
    td = theta_d_centres()[None, :, None]
    pd = phi_d_centres()[None, None, :]
    wi, wo = half_diff_to_directions(th, 0.0, td, pd)
    c80 = np.cos(np.radians(80.0))
    keep = (wi[..., 2] >= c80) & (wo[..., 2] >= c80)
    np.testing.assert_array_equal(p.count[..., 0], keep.sum(axis=-1))
    p_d = project(b, grazing_cutoff_deg=80.0, grazing_angle="theta_d")
    assert (p_d.count[:, theta_d_centres() > np.radians(80)] == 0).all()
    assert grazing_mask(90.0).sum() == (180 * 8100 - below_horizon_counts().sum())


def test_save_load_round_trip(tmp_path, random_brdf):
    p = project(random_brdf)
    p.save(tmp_path / "p.npz")
    q = ProjectedBRDF.load(tmp_path / "p.npz")
    np.testing.assert_array_equal(p.value, q.value)
    np.testing.assert_array_equal(p.count, q.count)
    assert q.statistic == "median" and q.grazing_cutoff_deg is None
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    from fit.errors import BRDFFileError
    with pytest.raises(BRDFFileError):
        ProjectedBRDF.load(tmp_path / "bad.npz")


def test_projected_evaluate_matches_clusters(random_brdf):
    p = project(random_brdf)
    i, j = 30, 40
    wi, wo = half_diff_to_directions(theta_h_centres()[i], 1.0, theta_d_centres()[j], 0.7)
    np.testing.assert_allclose(p.evaluate(wi, wo), np.nan_to_num(p.value[i, j]))
