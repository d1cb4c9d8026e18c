"""Tabulated inverse-CDF sampler: chi-square against its own density, unbiasedness vs quadrature,
zero-mass rows."""
import numpy as np
import pytest
from chi2 import chi2_pvalue, edges, histogram, table_cell_probs

from lab.analytic import glossy_lobe, lambert
from fit.formats.angles import spherical_to_direction
from fit.formats.colour import LUMINANCE
from fit.projection.albedo import directional_albedo
from fit.sampling.table import tabulate

THETA_V = [0.0, np.radians(45), np.radians(85)]


@pytest.fixture(scope="module")
def glossy():
    f = glossy_lobe(exponent=200.0, kd=(0.02, 0.02, 0.02))
    return f, tabulate(f, n_v=16, n_t=48, n_p=48)


@pytest.mark.parametrize("theta_v", THETA_V)
def test_chi_square_against_own_density(glossy, theta_v):
    _, table = glossy
    rng = np.random.default_rng(11)
    n = 100_000
    tl, pl, _ = table.sample(theta_v, rng.random(n), rng.random(n))
    t_edges, p_edges = edges(7, 9)                 # not aligned with the table's cells
    probs = table_cell_probs(table, theta_v, t_edges, p_edges)
    assert probs.sum() == pytest.approx(1.0, abs=1e-12)
    assert chi2_pvalue(histogram(tl, pl, t_edges, p_edges), probs, n) > 1e-3


def test_sample_pdf_equals_pdf_function(glossy):
    _, table = glossy
    rng = np.random.default_rng(1)
    for tv in THETA_V:
        tl, pl, pdf = table.sample(tv, rng.random(2000), rng.random(2000))
        np.testing.assert_allclose(pdf, table.pdf(tv, tl, pl), rtol=1e-9)
        assert (pdf > 0).all() and (tl >= 0).all() and (tl <= np.pi / 2).all()


@pytest.mark.parametrize("theta_v", THETA_V)
def test_unbiased_against_quadrature(glossy, theta_v):
    f, table = glossy
    rng = np.random.default_rng(5)
    n = 200_000
    tl, pl, pdf = table.sample(theta_v, rng.random(n), rng.random(n))
    wi = spherical_to_direction(tl, pl)
    wo = spherical_to_direction(theta_v, 0.0)
    g = (f(wi, wo) @ LUMINANCE) * np.cos(tl) / pdf
    est, se = g.mean(), g.std(ddof=1) / np.sqrt(n)
    ref = directional_albedo(lambda a, b: (f(a, b) @ LUMINANCE)[..., None], theta_v, n_theta=720, n_phi=1440)[0]
    assert abs(est - ref) < 3 * se + 1e-4 * ref, (est, ref, se)


def test_importance_sampling_reduces_variance(glossy):
    f, table = glossy
    rng = np.random.default_rng(3)
    n = 50_000
    tv = np.radians(30)
    wo = spherical_to_direction(tv, 0.0)
    tl, pl, pdf = table.sample(tv, rng.random(n), rng.random(n))
    g_is = (f(spherical_to_direction(tl, pl), wo) @ LUMINANCE) * np.cos(tl) / pdf
    # cosine sampling
    u1, u2 = rng.random(n), rng.random(n)
    tc = np.arcsin(np.sqrt(u1))
    pc = 2 * np.pi * u2
    g_cos = (f(spherical_to_direction(tc, pc), wo) @ LUMINANCE) * np.pi
    assert g_is.var() < 0.2 * g_cos.var()


def test_zero_mass_rows_fall_back_to_cosine():
    def black_at_grazing(wi, wo):
        out = lambert()(wi, wo).copy()
        grazing = np.broadcast_to(wo[..., 2] < np.cos(np.radians(80)), out.shape[:-1])
        out[grazing] = 0.0
        return out

    table = tabulate(black_at_grazing, n_v=18, n_t=16, n_p=16)
    assert table.row_fallback[-1] and not table.row_fallback[0]
    # fallback rows hold the exact cell masses of the cosine-weighted density
    edges = np.linspace(0, np.pi / 2, 17)
    cos_mass = np.diff(np.sin(edges) ** 2)
    np.testing.assert_allclose(np.diff(table.cdf_theta[-1]), cos_mass, rtol=1e-12)
    np.testing.assert_allclose(np.diff(table.cdf_phi[-1], axis=1), 1 / 16, rtol=1e-12)


def test_every_direction_has_positive_density(glossy):
    _, table = glossy
    tl, pl = np.meshgrid(np.linspace(0.001, 1.57, 60), np.linspace(-np.pi, np.pi, 60))
    for tv in THETA_V:
        assert (table.pdf(tv, tl, pl) > 0).all()
