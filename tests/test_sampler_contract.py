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
its tabulated and pieces-layout inverse CDFs, a Lambert material with the paper's global
layout (a glossy lobe's global fit takes minutes), and, for the samplers that only draw from
an ``rgl`` material's own tables (the format's luminance + VNDF warps), a glossy and a matte
shared RGL file as ``rgl`` materials. The slow variant runs the contract on the six shared RGL
materials.
"""
from __future__ import annotations

import numpy as np
import pytest
from chi2 import (
    assert_unbiased,
    chi2_pvalue,
    edges,
    histogram,
    map_cell_probs,
    pdf_cell_probs,
)
from conftest import RGL_MATERIALS, data_file

from fit.analytic import glossy_lobe, lambert
from fit.formats.angles import direction_to_spherical, spherical_to_direction
from fit.formats.measured import MeasuredBRDF
from fit.sampling.cdf_file import fit_cdf
from warp_rbrdf import registry

THETA_V_DEG = (5.0, 45.0, 80.0)
N_CHI2 = 40_000
T_EDGES, P_EDGES = edges(8, 16)   # chi-square cells, unions of the tables' cells
P_VALUE = 1e-4


# --------------------------------------------------------------------------------------------
# Materials and their samplers
# --------------------------------------------------------------------------------------------
class Case:
    """One material in a renderer, with the inverse-CDF data its rational sampler uses."""

    #: The uniforms are drawn from [m, 1 - m]^2 with this margin m. Samplers that are
    #: uniform-preserving enough pass with it, but it removes 0.4 % of the primary sample space,
    #: which biases f cos * weight by up to that much where the removed strips carry less (or
    #: more) than their share of the integral: the rgl samplers (their luminance warp
    #: concentrates the integrand away from the edges) draw from the whole square.
    xi_margin = 0.001
    #: sub-cells per chi-square cell of the quadrature of a technique's exact pdf
    pdf_sub = 24

    def __init__(self, name, evaluate, cdf, spec_kw, sampler="mis-rational"):
        from lab import testing as T
        from warp_rbrdf.renderer import Renderer
        from warp_rbrdf.scene import MaterialSpec

        # cdf: what the techniques' NumPy references take (inverse-CDF data, or the RGLBRDF)
        self.name, self.evaluate, self.cdf = name, evaluate, cdf
        spec = MaterialSpec(name="m", sampler=sampler, **spec_kw)
        spec.cdf = None if sampler == "mis-rgl" else cdf
        self.renderer = Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=4, spp=1))
        self._draws, self._probs = {}, {}

    def draws(self, technique: str, theta_v: float, n: int, seed: int = 11):
        """Warp samples of ``technique`` at view ``theta_v`` (phi_v = 0): (xi, wi, weight),
        cached per (technique, view, n)."""
        key = (technique, theta_v, n)
        if key not in self._draws:
            rng = np.random.default_rng(seed)
            xi = rng.random((n, 2))
            if self.xi_margin:   # keep the uniforms off the square's edges (see Case)
                xi = xi * (1.0 - 2.0 * self.xi_margin) + self.xi_margin
            wo = np.broadcast_to(spherical_to_direction(theta_v, 0.0), (n, 3))
            strategy = next(s.name for s in registry.STRATEGIES if s.technique == technique)
            wi, w = self.renderer.sample_material("m", wo, xi, strategy)
            self._draws[key] = (xi, wo, wi.astype(float), w.astype(float))
        return self._draws[key]

    def cell_probs(self, tech, theta_v: float):
        """Probabilities of the chi-square cells under the technique's own density (cached)."""
        key = (tech.name, theta_v)
        if key not in self._probs:
            wo = spherical_to_direction(theta_v, 0.0)
            if tech.pdf_exact:
                p = pdf_cell_probs(lambda wi: tech.impl().numpy_pdf(self.cdf, wi, np.broadcast_to(wo, wi.shape)),
                                   T_EDGES, P_EDGES, sub=self.pdf_sub)
            else:
                p = map_cell_probs(self.cdf, theta_v, T_EDGES, P_EDGES)
            self._probs[key] = p
        return self._probs[key]


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


def _rgl_case(material):
    from fit.formats.rgl import read_rgl

    b = read_rgl(data_file(f"rgl/{material}.bsdf"))
    case = Case(material, b.evaluate, b, dict(type="rgl", data=b), sampler="mis-rgl")
    case.xi_margin = 0.0
    case.pdf_sub = 64   # the clear coat's peak at an 80 deg view is narrow: 24 loses 0.6 %
    return case


@pytest.fixture(scope="module")
def rgl_glossy():
    return _rgl_case("cc_ibiza_sunset_rgb")


@pytest.fixture(scope="module")
def rgl_matte():
    return _rgl_case("paper_white_rgb")


def _own_material(s):
    return registry.technique(s.technique).material


CASES = [(s.name, "glossy") for s in registry.STRATEGIES if _own_material(s) is None] + \
        [(s.name, "lambert_global") for s in registry.STRATEGIES if s.name in registry.RATIONAL_STRATEGIES] + \
        [(s.name, w) for s in registry.STRATEGIES if _own_material(s) == "rgl"
         for w in ("rgl_glossy", "rgl_matte")]


def _case(request, which):
    return request.getfixturevalue(which)


# --------------------------------------------------------------------------------------------
# The sampler's own density
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("strategy,which", CASES)
def test_chi2_against_own_density(request, strategy, which):
    case = _case(request, which)
    tech = registry.technique(registry.strategy(strategy).technique)
    for tv_deg in THETA_V_DEG:
        tv = np.radians(tv_deg)
        _, _, wi, w = case.draws(tech.name, tv, N_CHI2)
        counts = histogram(*direction_to_spherical(wi[w > 0]), T_EDGES, P_EDGES)
        probs = case.cell_probs(tech, tv)
        # the density's mass over the hemisphere is the fraction of draws that give a sample
        # (1, or less where a reflected micro-normal can leave the hemisphere: rgl at grazing views)
        valid = float(np.mean(w > 0))
        tol = 2e-3 + 3.0 * np.sqrt(max(valid * (1.0 - valid), 1e-12) / N_CHI2)
        assert probs.sum() == pytest.approx(valid, abs=tol), (strategy, tv_deg, probs.sum(), valid)
        assert chi2_pvalue(counts, probs, N_CHI2) > P_VALUE, (strategy, which, tv_deg)


# --------------------------------------------------------------------------------------------
# Unbiasedness against quadrature
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("strategy,which", CASES)
def test_unbiased_against_quadrature(request, strategy, which):
    case = _case(request, which)
    tech = registry.strategy(strategy).technique
    for tv_deg in THETA_V_DEG:
        tv = np.radians(tv_deg)
        _, wo, wi, w = case.draws(tech, tv, N_CHI2)
        assert_unbiased(case.evaluate, tv, wi, wo, w, (strategy, which, tv_deg))


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
    for tech in registry.TECHNIQUES:
        if tech.material is not None:   # a technique of another material kind's own tables
            continue
        for tv_deg in THETA_V_DEG:
            tv = np.radians(tv_deg)
            xi, wo, wi, w = case.draws(tech.name, tv, N_CHI2)
            counts = histogram(*direction_to_spherical(wi[w > 0]), T_EDGES, P_EDGES)
            assert chi2_pvalue(counts, case.cell_probs(tech, tv), N_CHI2) > P_VALUE, (material, tech.name, tv_deg)
            # + 0.5 % of the value: the midpoint quadrature of the clear coats' near-normal mirror
            # peak on the nearest-bin table (heavy-tailed weights, resolution-limited quadrature)
            assert_unbiased(brdf.evaluate, tv, wi, wo, w, (material, tech.name, tv_deg), rel=0.005)
