"""One contract, run over every registered sampler (:data:`warp_rbrdf.registry.STRATEGIES`).

For the BSDF sample a sampler's technique draws in Warp (``Renderer.sample_material``):

1. **its own density** -- a chi-square test of the sampled (theta_l, phi_l) against the cell
   probabilities of the density the sampler claims (the technique's exact pdf integrated over
   the cells; for the rational maps, whose pdf for MIS is only approximate, the exact
   probabilities of the map itself, from its monotone CDFs), cells with few expected counts
   pooled as in Mitsuba 3's chi2 harness;
2. **unbiasedness** -- the estimator ``f cos(theta_l) * weight`` of the integral of
   ``f cos`` over the light direction (view fixed) against quadrature, within 3 sigma (plus the
   quadrature's own uncertainty);
3. **Warp == NumPy** -- the technique's NumPy reference draws the same directions and weights
   from the same uniforms;
4. **its pdf** -- the Warp pdf equals the NumPy one; where the registry says the pdf is exact,
   ``pdf(wi) * weight == 1``; where it is approximate, ``pdf > 0`` wherever a sample has weight.

Materials: an analytic glossy lobe on the MERL grid (in memory, no shared data needed) with
its tabulated and pieces-layout inverse CDFs, and a Lambert material with the paper's global
layout (a glossy lobe's global fit takes minutes). The slow variant runs the contract on the
six shared RGL materials.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from fit.analytic import glossy_lobe, lambert
from conftest import RGL_MATERIALS, data_file
from fit.formats.angles import spherical_to_direction
from fit.formats.colour import LUMINANCE
from fit.formats.measured import MeasuredBRDF
from fit.projection.albedo import directional_albedo
from fit.sampling.cdf_file import fit_cdf
from warp_rbrdf import registry

THETA_V_DEG = (5.0, 45.0, 80.0)
N_CHI2 = 40_000
N_T, N_P = 8, 16               # chi-square cells: theta_l in [0, pi/2], phi_l in [-pi, pi]
MIN_EXPECTED = 5.0
P_VALUE = 1e-4


# --------------------------------------------------------------------------------------------
# Materials and their samplers
# --------------------------------------------------------------------------------------------
class Case:
    """One material in a renderer, with the inverse-CDF data its rational sampler uses."""

    def __init__(self, name, evaluate, cdf, spec_kw):
        from warp_rbrdf import testing as T
        from warp_rbrdf.renderer import Renderer
        from warp_rbrdf.scene import MaterialSpec

        self.name, self.evaluate, self.cdf = name, evaluate, cdf
        spec = MaterialSpec(name="m", sampler="mis-rational", **spec_kw)
        spec.cdf = cdf
        self.renderer = Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=4, spp=1))
        self._draws = {}

    def draws(self, technique: str, theta_v: float, n: int, seed: int = 11):
        """Warp samples of ``technique`` at view ``theta_v`` (phi_v = 0): (xi, wi, weight),
        cached per (technique, view, n)."""
        key = (technique, theta_v, n)
        if key not in self._draws:
            rng = np.random.default_rng(seed)
            xi = rng.random((n, 2)) * 0.998 + 0.001
            wo = np.broadcast_to(spherical_to_direction(theta_v, 0.0), (n, 3))
            strategy = next(s.name for s in registry.STRATEGIES if s.technique == technique)
            wi, w = self.renderer.sample_material("m", wo, xi, strategy)
            self._draws[key] = (xi, wo, wi.astype(float), w.astype(float))
        return self._draws[key]


@pytest.fixture(scope="module")
def glossy():
    f = glossy_lobe(exponent=60.0, kd=(0.08, 0.06, 0.05), ks=(0.5, 0.6, 0.7))
    brdf = MeasuredBRDF.from_function(f, name="glossy")
    cdf = fit_cdf(brdf.evaluate, name="glossy", table_params=dict(n_v=16))
    assert cdf.layout == "pieces" and not cdf.fallback, cdf.reason
    return Case("glossy", brdf.evaluate, cdf, dict(type="measured", data=brdf))


@pytest.fixture(scope="module")
def lambert_global():
    f = lambert((0.8, 0.6, 0.4))
    cdf = fit_cdf(f, name="lambert", table_params=dict(n_v=8, n_t=32, n_p=32),
                  phi_kw=dict(degrees=(2, 1)), refinements=0, layout="global")
    assert cdf.layout == "global" and not cdf.fallback, cdf.reason
    return Case("lambert-global", f, cdf, dict(type="lambert", albedo=(0.8, 0.6, 0.4)))


CASES = [(s.name, "glossy") for s in registry.STRATEGIES] + \
        [(s.name, "lambert_global") for s in registry.STRATEGIES if s.name in registry.RATIONAL_STRATEGIES]


def _case(request, which):
    return request.getfixturevalue(which)


# --------------------------------------------------------------------------------------------
# The sampler's own density
# --------------------------------------------------------------------------------------------
def _edges():
    return np.linspace(0.0, np.pi / 2, N_T + 1), np.linspace(-np.pi, np.pi, N_P + 1)


def _pdf_cell_probs(tech, cdf, theta_v, sub=24):
    """Cell probabilities of an exact pdf: midpoint quadrature in solid angle on ``sub`` x
    ``sub`` points per cell (exact for the table, whose pdf sin(theta) is constant on its cells,
    since the chi-square cells are unions of table cells)."""
    te, pe = _edges()
    t = (np.arange(N_T * sub) + 0.5) / (N_T * sub) * (np.pi / 2)
    p = -np.pi + (np.arange(N_P * sub) + 0.5) / (N_P * sub) * (2 * np.pi)
    tt, pp = np.meshgrid(t, p, indexing="ij")
    wi = spherical_to_direction(tt, pp).reshape(-1, 3)
    wo = np.broadcast_to(spherical_to_direction(theta_v, 0.0), wi.shape)
    pdf = tech.impl().numpy_pdf(cdf, wi, wo).reshape(tt.shape)
    cell = pdf * np.sin(tt) * (t[1] - t[0]) * (p[1] - p[0])
    return cell.reshape(N_T, sub, N_P, sub).sum(axis=(1, 3))


def _map_cell_probs(cdf, theta_v, nq=64):
    """Exact cell probabilities of the rational maps (table rows included) from their monotone
    CDFs: P(theta cell) from ``theta_cdf``, then the conditional phi mass at ``nq`` theta_l
    quantiles inside it from ``phi_cdf_half`` (symmetric in phi, mass 1/2 per side)."""
    te, pe = _edges()
    mu_e = cdf.theta_cdf(theta_v, te)
    probs = np.zeros((N_T, N_P))
    for a in range(N_T):
        mu = mu_e[a] + (np.arange(nq) + 0.5) / nq * (mu_e[a + 1] - mu_e[a])
        tl = cdf.sample(np.full(nq, theta_v), mu, np.full(nq, 0.75))[0]

        def C(p):
            return cdf.phi_cdf_half(np.full(nq, theta_v), tl, np.full(nq, p))

        for b in range(N_P):
            lo, hi = pe[b], pe[b + 1]
            if lo >= 0:
                pr = 0.5 * (C(hi) - C(lo))
            elif hi <= 0:
                pr = 0.5 * (C(-lo) - C(-hi))
            else:
                pr = 0.5 * (C(hi) + C(-lo))
            probs[a, b] = (mu_e[a + 1] - mu_e[a]) * pr.mean()
    return probs


def _chi2_pvalue(counts, probs, n):
    """Pearson chi-square p-value; cells expected below MIN_EXPECTED are pooled into one."""
    exp = probs.ravel() * n
    obs = counts.ravel()
    low = exp < MIN_EXPECTED
    e = np.append(exp[~low], exp[low].sum())
    o = np.append(obs[~low], obs[low].sum())
    keep = e > 0
    assert o[~keep].sum() == 0, "samples in cells of zero probability"
    stat = float(np.sum((o[keep] - e[keep]) ** 2 / e[keep]))
    return float(chi2.sf(stat, max(int(keep.sum()) - 1, 1)))


@pytest.mark.parametrize("strategy,which", CASES)
def test_chi2_against_own_density(request, strategy, which):
    case = _case(request, which)
    tech = registry.technique(registry.strategy(strategy).technique)
    te, pe = _edges()
    for tv_deg in THETA_V_DEG:
        tv = np.radians(tv_deg)
        _, _, wi, w = case.draws(tech.name, tv, N_CHI2)
        ok = w > 0
        tl = np.arctan2(np.hypot(wi[ok, 0], wi[ok, 1]), wi[ok, 2])
        pl = np.arctan2(wi[ok, 1], wi[ok, 0])
        counts, _, _ = np.histogram2d(tl, pl, bins=[te, pe])
        probs = _map_cell_probs(case.cdf, tv) if not tech.pdf_exact else _pdf_cell_probs(tech, case.cdf, tv)
        assert probs.sum() == pytest.approx(1.0, abs=2e-3), (strategy, tv_deg, probs.sum())
        assert _chi2_pvalue(counts, probs / probs.sum(), N_CHI2) > P_VALUE, (strategy, which, tv_deg)


# --------------------------------------------------------------------------------------------
# Unbiasedness against quadrature
# --------------------------------------------------------------------------------------------
def _assert_unbiased(evaluate, tv, wi, wo, weight, label):
    """``f cos * weight`` (luminance) against the quadrature of f cos over the light."""
    est = (np.asarray(evaluate(wi, wo), float) @ LUMINANCE) * np.maximum(wi[:, 2], 0.0) * weight
    m, se = est.mean(), est.std() / np.sqrt(len(est))
    swap = lambda a, b: evaluate(b, a)  # noqa: E731  (directional_albedo integrates its 2nd argument)
    q1 = directional_albedo(swap, tv) @ LUMINANCE
    q2 = directional_albedo(swap, tv, 180, 720) @ LUMINANCE
    assert abs(m - q2) < 3 * se + 2 * abs(q2 - q1) + 1e-6, (label, m, q2, se, q1)


@pytest.mark.parametrize("strategy,which", CASES)
def test_unbiased_against_quadrature(request, strategy, which):
    case = _case(request, which)
    tech = registry.strategy(strategy).technique
    for tv_deg in THETA_V_DEG:
        tv = np.radians(tv_deg)
        _, wo, wi, w = case.draws(tech, tv, N_CHI2)
        _assert_unbiased(case.evaluate, tv, wi, wo, w, (strategy, which, tv_deg))


# --------------------------------------------------------------------------------------------
# Warp == NumPy, and the pdf
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("strategy,which", CASES)
def test_warp_equals_numpy_and_pdf(request, strategy, which):
    case = _case(request, which)
    tech = registry.technique(registry.strategy(strategy).technique)
    impl = tech.impl()
    for tv_deg in THETA_V_DEG:
        xi, wo, wi, w = case.draws(tech.name, np.radians(tv_deg), 4000, seed=5)
        ref_wi, ref_w = impl.numpy_sample(case.cdf, wo, xi)
        np.testing.assert_allclose(wi, ref_wi, atol=2e-4, err_msg=f"{strategy} {tv_deg}")
        np.testing.assert_allclose(w, ref_w, rtol=2e-3, atol=1e-5, err_msg=f"{strategy} {tv_deg}")
        pdf = case.renderer.pdf_material("m", wi, wo, strategy).astype(float)
        np.testing.assert_allclose(pdf, impl.numpy_pdf(case.cdf, wi, wo), rtol=2e-3, atol=1e-6)
        ok = w > 0
        if tech.pdf_exact:
            np.testing.assert_allclose(pdf[ok] * w[ok], 1.0, rtol=2e-3)
        else:
            assert np.all(pdf[ok] > 0)


# --------------------------------------------------------------------------------------------
# The same contract on the shared RGL materials (slow: a pieces fit per material)
# --------------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("material", RGL_MATERIALS)
def test_contract_on_rgl_materials(material):
    from fit.formats import load_measured

    brdf = load_measured(data_file(f"rgl/{material}.bsdf"))
    cdf = fit_cdf(brdf.evaluate, name=material)
    case = Case(material, brdf.evaluate, cdf, dict(type="measured", data=brdf))
    te, pe = _edges()
    for tech in registry.TECHNIQUES:
        for tv_deg in THETA_V_DEG:
            tv = np.radians(tv_deg)
            xi, wo, wi, w = case.draws(tech.name, tv, N_CHI2)
            ok = w > 0
            tl = np.arctan2(np.hypot(wi[ok, 0], wi[ok, 1]), wi[ok, 2])
            pl = np.arctan2(wi[ok, 1], wi[ok, 0])
            counts, _, _ = np.histogram2d(tl, pl, bins=[te, pe])
            probs = _map_cell_probs(cdf, tv) if not tech.pdf_exact else _pdf_cell_probs(tech, cdf, tv)
            assert _chi2_pvalue(counts, probs / probs.sum(), N_CHI2) > P_VALUE, (material, tech.name, tv_deg)
            _assert_unbiased(brdf.evaluate, tv, wi, wo, w, (material, tech.name, tv_deg))
