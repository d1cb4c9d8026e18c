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

And what differs per strategy, each list taken from the registry (a new strategy joins them):
every strategy has a material case; a strategy that combines the environment and BSDF samples
(``mis``) renders a furnace equal to quadrature (its MIS weights sum to one); a strategy with the
derivative estimator weights by its map's Jacobian and is unbiased; a strategy with a
``fallback`` renders with it when its fit is flagged.

Materials: an analytic glossy lobe on the MERL grid (in memory, no shared data needed) with
its tabulated and pieces-layout inverse CDFs, a Lambert material with the paper's global
layout (a glossy lobe's global fit takes minutes), a 3-D rational fit sampled with the inverse
CDFs its coefficient record carries (the rational strategies), and, for the samplers that only draw from
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
    quadrature_albedo,
)
from conftest import RGL_MATERIALS, data_file
from lab import testing as T

from lab.analytic import glossy_lobe, lambert
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

    def __init__(self, name, evaluate, cdf, spec_kw, sampler="mis-rational", own_sampler=False):
        from warp_rbrdf.renderer import Renderer
        from warp_rbrdf.scene import MaterialSpec

        # cdf: what the techniques' NumPy references take (inverse-CDF data, or the RGLBRDF)
        self.name, self.evaluate, self.cdf = name, evaluate, cdf
        spec = MaterialSpec(name="m", sampler=sampler, **spec_kw)
        # own_sampler: no cdf key, the material's fit carries ``cdf`` (fit.sampling.embedded)
        spec.cdf = None if sampler == "mis-rgl" or own_sampler else cdf
        self.spec_kw = spec_kw
        self.renderer = Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=4, spp=1))
        self._draws, self._probs, self._quad = {}, {}, {}

    def quadrature(self, theta_v: float):
        """:func:`chi2.quadrature_albedo` of the material at view ``theta_v`` (cached: every
        strategy's estimator is checked against the same integral)."""
        if theta_v not in self._quad:
            self._quad[theta_v] = quadrature_albedo(self.evaluate, theta_v)
        return self._quad[theta_v]

    def assert_unbiased(self, theta_v, wi, wo, weight, label):
        """:func:`chi2.assert_unbiased` against the case's cached quadrature."""
        assert_unbiased(self.evaluate, theta_v, wi, wo, weight, label, quadrature=self.quadrature(theta_v))

    def spec(self, sampler: str, cdf=None, name: str = "m"):
        """A fresh scene material ``name`` of this case with ``sampler`` and inverse-CDF data
        ``cdf`` (None: none given)."""
        from warp_rbrdf.scene import MaterialSpec

        spec = MaterialSpec(name=name, sampler=sampler, **self.spec_kw)
        spec.cdf = cdf
        return spec

    def draws(self, strategy: str, theta_v: float, n: int, seed: int = 11, xi=None):
        """Warp samples of ``strategy``'s BSDF sample at view ``theta_v`` (phi_v = 0):
        (xi, wo, wi, weight), cached per (strategy, view, n) unless ``xi`` (N, 2) is given."""
        if xi is not None:   # the caller's uniforms: not cached
            return self._sample(strategy, theta_v, np.asarray(xi, float))
        key = (strategy, theta_v, n)
        if key not in self._draws:
            xi = np.random.default_rng(seed).random((n, 2))
            if self.xi_margin:   # keep the uniforms off the square's edges (see Case)
                xi = xi * (1.0 - 2.0 * self.xi_margin) + self.xi_margin
            self._draws[key] = self._sample(strategy, theta_v, xi)
        return self._draws[key]

    def _sample(self, strategy, theta_v, xi):
        wo = np.broadcast_to(spherical_to_direction(theta_v, 0.0), (len(xi), 3))
        wi, w = self.renderer.sample_material("m", wo, xi, strategy)
        return xi, wo, wi.astype(float), w.astype(float)

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
    """The lobe's pieces layout with rational rows and rows the rational technique samples with
    the table: 16 phi pieces and a variance gate on 4096 pairs, not re-measured (the default
    gate, 32768 pairs re-measured on 8x as many and more phi pieces tried, keeps 6 rational
    rows of 16 where this one keeps 7, in 35 s instead of 2 s; the gate itself is
    tests/test_cdf_pieces.py's)."""
    f = glossy_lobe(exponent=60.0, kd=(0.08, 0.06, 0.05), ks=(0.5, 0.6, 0.7))
    brdf = MeasuredBRDF.from_function(f, name="glossy")
    cdf = fit_cdf(brdf.evaluate, name="glossy", table_params=dict(n_v=16),
                  pieces_kw=dict(n_u=(16,), gate_samples=4096, gate_recheck=None))
    assert cdf.layout == "pieces" and not cdf.fallback, cdf.reason
    assert 0 < cdf.maps.row_ok.sum() < cdf.table.n_v, cdf.reason   # both kinds of rows
    return Case("glossy", brdf.evaluate, cdf, dict(type="measured", data=brdf))


@pytest.fixture(scope="module")
def lambert_global():
    """A Lambert material's global-layout inverse CDFs (8 view rows), made once per test session
    (tests/test_cdf_samplers.py)."""
    from test_cdf_samplers import lambert_global_fit

    f = lambert((0.8, 0.6, 0.4))
    cdf = lambert_global_fit(8)
    assert cdf.layout == "global" and not cdf.fallback, cdf.reason
    return Case("lambert-global", f, cdf, dict(type="lambert", albedo=(0.8, 0.6, 0.4)))


@pytest.fixture(scope="module")
def fit3d_own():
    """A 3-D rational fit (θh, θd, |φd|; not reciprocal) sampled with the inverse CDFs it carries
    in its record (no ``cdf`` key; ``tests/test_fit_sampler.py`` makes it: every row rational)."""
    import copy

    from test_fit_sampler import _fit3d_with_sampler

    from fit.sampling.model_sampler import vouched_evaluate

    model, cdf = _fit3d_with_sampler()
    model = copy.deepcopy(model)
    case = Case("fit3d-own", vouched_evaluate(model), cdf, dict(type="rational", data=model), own_sampler=True)
    # the whole square: the fit gives rho cos theta_i (the fitter's default), whose f cos is
    # finite at the light's horizon, so the margin's strips would hold their share (0.16 % low)
    case.xi_margin = 0.0
    return case


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
        [(s.name, "fit3d_own") for s in registry.STRATEGIES if s.name in registry.RATIONAL_STRATEGIES] + \
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
        _, _, wi, w = case.draws(strategy, tv, N_CHI2)
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
    for tv_deg in THETA_V_DEG:
        tv = np.radians(tv_deg)
        _, wo, wi, w = case.draws(strategy, tv, N_CHI2)
        case.assert_unbiased(tv, wi, wo, w, (strategy, which, tv_deg))


# --------------------------------------------------------------------------------------------
# Warp == NumPy, and the pdf
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("strategy,which", CASES)
def test_warp_equals_numpy_and_pdf(request, strategy, which):
    case = _case(request, which)
    tech = registry.technique(registry.strategy(strategy).technique)
    impl = tech.impl()
    for tv_deg in THETA_V_DEG:
        xi, wo, wi, w = case.draws(strategy, np.radians(tv_deg), 4000, seed=5)
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
# What differs per strategy: coverage, MIS weights, the derivative estimator, the fallback
# --------------------------------------------------------------------------------------------
def _first_case(strategy):
    return next(w for s, w in CASES if s == strategy)


def test_every_registered_strategy_runs_the_contract():
    """A strategy added to the registry gets the contract (and the tests below) or fails here:
    every one has a material case, and the per-strategy lists are the registry's."""
    assert sorted({s for s, _ in CASES}) == sorted(registry.STRATEGY_NAMES)
    assert MIS_STRATEGIES == [s.name for s in registry.STRATEGIES if s.light_sample and s.bsdf_sample]
    assert DERIVATIVE_STRATEGIES and FALLBACK_STRATEGIES and MIS_STRATEGIES


MIS_STRATEGIES = [s.name for s in registry.STRATEGIES if s.mis]
DERIVATIVE_STRATEGIES = [s.name for s in registry.STRATEGIES if s.estimator == "derivative"]
FALLBACK_STRATEGIES = [s.name for s in registry.STRATEGIES if s.fallback]
MIS_THETA_V_DEG = 50.0
MIS_SPP = 4096


@pytest.fixture(scope="module")
def furnace_cases(request):
    """``{strategy: case}`` for every MIS strategy (:func:`_first_case`): every furnace scene
    holds all of them, so that their renders share one render kernel (a kernel per material
    kind and technique set, compiled on first use)."""
    return {s: _case(request, _first_case(s)) for s in MIS_STRATEGIES}


def _furnace_render(cases, strategy, theta_v_deg=MIS_THETA_V_DEG, spp=MIS_SPP):
    """Render the material of ``cases[strategy]`` on a plane under a unit constant environment
    with its scene ``sampler = strategy``, seen from ``theta_v_deg`` through a 1 deg field of
    view (every pixel sees the same view within 0.5 deg): ``(luminance of the image mean, its
    standard error)``, the estimate of the integral of f cos over the light. The other cases'
    materials (each with its own strategy) lie on small planes below the lit plane, where no
    path reaches them: every scene of :func:`furnace_cases` uses the same kinds and techniques."""
    from fit.formats.colour import LUMINANCE
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import CameraSpec, IntegratorSpec, Scene, ShapeSpec

    def material(s):
        own = registry.technique(registry.strategy(s).technique).material
        return cases[s].spec(s, None if own else cases[s].cdf, name=s)

    tv = np.radians(theta_v_deg)
    cam = CameraSpec(origin=(0.0, np.cos(tv), np.sin(tv)), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0),
                     fov=1.0, resolution=(4, 4))
    others = [s for s in cases if s != strategy]
    sc = Scene(camera=cam, integrator=IntegratorSpec(spp=spp, seed=1, tile_size=8),
               materials={s: material(s) for s in cases},
               shapes=[ShapeSpec(type="plane", material=strategy, size=(100.0, 100.0))]
               + [ShapeSpec(type="plane", material=s, center=(3.0 * k, -10.0, 0.0), size=(1.0, 1.0))
                  for k, s in enumerate(others)],
               lights=[T.constant_env(1.0)],
               path="<test scene>")
    # and hidden materials of every kind and technique (lab.testing.common_kernel): the render
    # kernel is the common test kernel of other files
    r = Renderer(T.common_kernel(sc))
    # no fallback: each material renders with its own strategy
    assert r.material_data.strategies[r.material_index(strategy)] == strategy
    assert [r.material_data.strategies[r.material_index(s)] for s in cases] == list(cases)
    img, var = r.render(return_variance=True)
    n = img.shape[0] * img.shape[1]
    se = np.sqrt(var.mean(axis=(0, 1)) / spp / n)
    return float(img.mean(axis=(0, 1)) @ LUMINANCE), float(np.abs(LUMINANCE) @ se)


@pytest.mark.parametrize("strategy", MIS_STRATEGIES)
def test_mis_weights_sum_to_one(furnace_cases, strategy):
    """A strategy that combines the environment sample and its BSDF sample weights the two by
    the power heuristic; the combination is unbiased for every integrand exactly when the two
    weights of every direction sum to one (the same BSDF density on both sides: ``1 / weight``
    where the technique's pdf is exact, its pdf function otherwise). The render of a plane
    under a unit constant environment (both pdfs comparable over the whole hemisphere: the
    environment's is uniform) equals the quadrature of f cos within 4 standard errors."""
    case = furnace_cases[strategy]
    m, se = _furnace_render(furnace_cases, strategy)
    q, dq = case.quadrature(np.radians(MIS_THETA_V_DEG))
    assert abs(m - q) < 4 * se + 2 * dq + 1e-6, (strategy, case.name, m, q, se, dq)


@pytest.mark.slow
def test_mis_check_catches_weights_that_do_not_sum_to_one(request, monkeypatch):
    """Negative control of :func:`test_mis_weights_sum_to_one` (slow: it compiles a kernel): a
    power heuristic whose two weights sum to 1.25 where the pdfs are equal makes the check fail."""
    import warp as wp

    from warp_rbrdf import integrator

    @wp.func
    def broken_heuristic(pa: float, pb: float) -> float:
        if pa <= 0.0:
            return 0.0
        if pb <= 0.0:
            return 1.0
        return wp.min(1.0, 1.25 * pa * pa / (pa * pa + pb * pb))

    monkeypatch.setattr(integrator, "power_heuristic", broken_heuristic)
    cases = request.getfixturevalue("furnace_cases")
    case = cases["mis"]
    m, se = _furnace_render(cases, "mis")
    q, dq = case.quadrature(np.radians(MIS_THETA_V_DEG))
    assert abs(m - q) > 4 * se + 2 * dq + 1e-6, (m, q, se, dq)


def _jacobian_weight(case, strategy, theta_v, xi, h=1e-3):
    """|d(theta_l, phi_l) / d(xi_1, xi_2)| sin(theta_l) of the strategy's Warp sample at the
    uniforms ``xi`` (N, 2), by central differences of step ``h``: the inverse density of the
    map, which the derivative estimator's weight alpha must be (eq. 3-4 of the supplementary
    text)."""
    ang = []
    for d in ((h, 0), (-h, 0), (0, h), (0, -h)):
        _, _, wi, _ = case.draws(strategy, theta_v, 0, xi=xi + np.array(d))
        ang.append(direction_to_spherical(wi))
    (t1, p1), (t2, p2), (t3, p3), (t4, p4) = ang
    wrap = lambda a: (a + np.pi) % (2 * np.pi) - np.pi  # noqa: E731
    dt1, dp1 = (t1 - t2) / (2 * h), wrap(p1 - p2) / (2 * h)
    dt2, dp2 = (t3 - t4) / (2 * h), wrap(p3 - p4) / (2 * h)
    _, _, wi, _ = case.draws(strategy, theta_v, 0, xi=xi)
    return np.abs(dt1 * dp2 - dt2 * dp1) * np.sin(direction_to_spherical(wi)[0])


def _matches(weight, ref, tol=0.02, share=0.9):
    """``weight`` equals ``ref`` within ``tol`` (relative) at ``share`` of the points or more
    (central differences straddle the pieces' and the table cells' edges at the others)."""
    return float(np.mean(np.abs(weight / ref - 1.0) < tol)) >= share


@pytest.mark.parametrize("strategy,which", [(s, w) for s, w in CASES if s in DERIVATIVE_STRATEGIES])
def test_derivative_estimator_weight_is_the_maps_jacobian(request, strategy, which):
    """A strategy with ``estimator = "derivative"`` weights its sample by alpha, the derivative
    of its inverse-CDF map (not 1 / a tabulated pdf): alpha equals the map's Jacobian by central
    differences, and ``f cos alpha`` is unbiased (mean equal to the quadrature within 3
    standard errors, :func:`chi2.assert_unbiased`). Negative control: the same checks reject a
    weight off by 3 %."""
    case = _case(request, which)
    rng = np.random.default_rng(3)
    for tv_deg in THETA_V_DEG:
        tv = np.radians(tv_deg)
        xi = 0.05 + 0.9 * rng.random((2000, 2))
        _, _, _, w = case.draws(strategy, tv, 0, xi=xi)
        ok = w > 0
        assert ok.mean() > 0.99, (strategy, tv_deg)
        ref = _jacobian_weight(case, strategy, tv, xi)[ok]
        assert _matches(w[ok], ref), (strategy, which, tv_deg)
        assert not _matches(1.03 * w[ok], ref), (strategy, which, tv_deg)
        _, wo, wi, w = case.draws(strategy, tv, N_CHI2)
        case.assert_unbiased(tv, wi, wo, w, (strategy, which, tv_deg))
        with pytest.raises(AssertionError):
            case.assert_unbiased(tv, wi, wo, 1.03 * w, (strategy, which, tv_deg))


@pytest.mark.parametrize("strategy", FALLBACK_STRATEGIES)
def test_fallback_switches_to_the_fallback_strategy(request, strategy):
    """A strategy with a ``fallback`` renders with it when its inverse CDFs failed verification
    (``CDFFit.fallback``): the material's strategy, technique and combine code are the
    fallback's, its data the fit's table; with the verified fit it keeps its own."""
    import dataclasses

    from warp_rbrdf.renderer import Renderer

    case = _case(request, _first_case(strategy))
    own, fb = registry.strategy(strategy), registry.strategy(registry.strategy(strategy).fallback)
    flagged = dataclasses.replace(case.cdf, fallback=True, reason="flagged by the test")
    for cdf, expect in ((case.cdf, own), (flagged, fb)):
        sc = T.plane_scene(case.spec(strategy, cdf), [T.constant_env(1.0)], resolution=4, spp=1)
        md = Renderer(sc).material_data
        assert md.strategies == [expect.name], (strategy, cdf.fallback)
        assert md.techniques_used() == [registry.technique(expect.technique).code], (strategy, cdf.fallback)
        assert list(md.combine) == [registry.combine_code(expect)], (strategy, cdf.fallback)
        assert (md.cdf[0] is case.cdf) if expect is own else (md.cdf[0] is case.cdf.table)


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
            strategy = next(s.name for s in registry.STRATEGIES if s.technique == tech.name)
            xi, wo, wi, w = case.draws(strategy, tv, N_CHI2)
            counts = histogram(*direction_to_spherical(wi[w > 0]), T_EDGES, P_EDGES)
            assert chi2_pvalue(counts, case.cell_probs(tech, tv), N_CHI2) > P_VALUE, (material, tech.name, tv_deg)
            # + 0.5 % of the value: the midpoint quadrature of the clear coats' near-normal mirror
            # peak on the nearest-bin table (heavy-tailed weights, resolution-limited quadrature)
            assert_unbiased(brdf.evaluate, tv, wi, wo, w, (material, tech.name, tv_deg), rel=0.005)
