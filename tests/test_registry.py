"""The registry (warp_rbrdf.registry) is the one source of names: every entry is implemented,
documented and reachable from a scene file, and one contract checks every material kind
(Warp evaluation == the kind's NumPy evaluation). The samplers' contract is
tests/test_sampler_contract.py."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import data_file

from fit.formats.angles import spherical_to_direction
from fit.formats.measured import MeasuredBRDF
from fit.projection.project import project
from warp_rbrdf import registry
from warp_rbrdf.scene import FORMAT_DOC, MaterialSpec, parse_scene

MATERIAL_API = ("load", "kernel_eval")
TECHNIQUE_API = ("kernel_functions", "numpy_sample", "numpy_pdf")


@pytest.mark.parametrize("kind", registry.MATERIALS, ids=lambda k: k.name)
def test_material_kind_implements_the_interface(kind):
    impl = kind.impl()
    missing = [a for a in MATERIAL_API if not hasattr(impl, a)]
    assert not missing, f"{kind.module} lacks {missing}"
    assert set(kind.keys) <= {"albedo", "file", "scale", "statistic", "incident", "interpolation", "unvouched"}
    # the roles key exactly on the kinds that read RGL files
    assert ("incident" in kind.keys) == (".bsdf" in kind.suffixes)
    assert ("file" in kind.keys) == bool(kind.suffixes)


@pytest.mark.parametrize("tech", registry.TECHNIQUES, ids=lambda t: t.name)
def test_technique_implements_the_interface(tech):
    impl = tech.impl()
    missing = [a for a in TECHNIQUE_API if not hasattr(impl, a)]
    assert not missing, f"{tech.module} lacks {missing}"
    assert not tech.needs_fit or tech.needs_table
    assert tech.material is None or tech.material in registry.MATERIAL_NAMES


def test_codes_are_unique_and_strategies_are_consistent():
    for entries in (registry.MATERIALS, registry.TECHNIQUES):
        codes = [e.code for e in entries]
        assert len(set(codes)) == len(codes)
    names = [s.name for s in registry.STRATEGIES]
    assert len(set(names)) == len(names)
    for s in registry.STRATEGIES:
        t = registry.technique(s.technique)
        # a strategy needs a fallback exactly when its technique needs a verified fit, and the
        # fallback keeps the way samples are combined but needs no fit
        assert (s.fallback is not None) == t.needs_fit, s.name
        if s.fallback:
            fb = registry.strategy(s.fallback)
            assert not registry.technique(fb.technique).needs_fit
            assert registry.combine_code(fb) == registry.combine_code(s)
        assert s.estimator in ("pdf", "derivative")
    assert registry.strategy("mis-rational").mis and not registry.strategy("mis-rational").pdf_exact
    assert registry.strategy("mis-tabulated").pdf_exact
    assert registry.combine_code(registry.strategy("light")) == registry.COMBINE_LIGHT


def test_scene_format_and_help_list_every_name():
    from warp_rbrdf.cli import _parser

    help_text = _parser()._subparsers._group_actions[0].choices["render"].format_help()
    for name in registry.MATERIAL_NAMES + registry.STRATEGY_NAMES:
        assert name in FORMAT_DOC and name in help_text, name


@pytest.mark.parametrize("sampler", registry.STRATEGY_NAMES)
def test_every_sampler_parses_in_a_scene(sampler):
    own = registry.technique(registry.strategy(sampler).technique).material
    if own is not None:   # a sampler of one kind's own tables: refused on another kind
        with pytest.raises(ValueError, match="a 'lambert' material cannot use it"):
            parse_scene(f'[materials.m]\ntype = "lambert"\nsampler = "{sampler}"\n')
        return
    sc = parse_scene(f'[materials.m]\ntype = "lambert"\nsampler = "{sampler}"\n')
    assert sc.materials["m"].sampler == sampler
    with pytest.raises(ValueError, match="expected one of"):
        parse_scene(f'[materials.m]\ntype = "lambert"\nsampler = "{sampler}x"\n')


# --------------------------------------------------------------------------------------------
# One contract for every material kind: Warp == NumPy
# --------------------------------------------------------------------------------------------
def _specs():
    """One in-memory instance of every registered material kind (a new kind must add one)."""
    from lab.analytic import glossy_lobe
    from fit.rational.coefficient_file import load
    from warp_rbrdf.paths import PACKAGE_DATA

    from fit.formats.rgl import read_rgl

    brdf = MeasuredBRDF.from_function(glossy_lobe(exponent=40.0), name="glossy")
    rgl = read_rgl(data_file("rgl/cc_ibiza_sunset_rgb.bsdf"))
    s = "mis"   # the evaluation contract needs no sampler data (the defaults tabulate at load)
    return {
        "rgl": MaterialSpec(name="rgl", type="rgl", data=rgl, scale=(1.0, 0.8, 1.2), sampler=s),
        "lambert": MaterialSpec(name="lambert", type="lambert", albedo=(0.2, 0.5, 0.9), sampler=s),
        "measured": MaterialSpec(name="measured", type="measured", data=brdf, scale=(1.0, 0.5, 2.0), sampler=s),
        "projected": MaterialSpec(name="projected", type="projected", data=project(brdf), scale=(0.5, 1.0, 1.0),
                                  sampler=s),
        "rational": MaterialSpec(name="rational", type="rational", sampler=s,
                                 data=load(PACKAGE_DATA / "satin_rosaline_rgb.json"), scale=(1.0, 1.0, 0.7)),
    }


@pytest.fixture(scope="module")
def all_kinds():
    """One renderer holding one material of every kind (one compile)."""
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import Scene, ShapeSpec
    from lab.testing import top_down_camera

    specs = _specs()
    assert set(specs) == set(registry.MATERIAL_NAMES), "add an instance of the new kind to _specs()"
    sc = Scene(camera=top_down_camera(4), materials=specs,
               shapes=[ShapeSpec(type="sphere", material=n, center=(3.0 * i, -10.0, 0.0), radius=0.5)
                       for i, n in enumerate(specs)])
    return Renderer(sc)


@pytest.mark.parametrize("kind", registry.MATERIAL_NAMES)
def test_material_warp_equals_numpy(all_kinds, kind):
    r = all_kinds
    m = r.material_index(kind)
    rng = np.random.default_rng(3)
    n = 4000
    wi = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    wo = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    wi[:50, 2] *= -1                                     # below the horizon: 0
    got = r.eval_material(kind, wi, wo).astype(float)
    ref = r.material_data.loaded[m].evaluate(wi, wo)
    assert np.all(got[:50] == 0) and np.all(ref[:50] == 0)
    # float32 angles: a few directions fall into the neighbouring table bin
    close = np.all(np.isclose(got, ref, rtol=1e-4, atol=1e-6), axis=1)
    assert close.mean() > 0.995, (kind, close.mean())


# --------------------------------------------------------------------------------------------
# Default strategy per material kind
@pytest.mark.parametrize("kind", registry.MATERIALS, ids=lambda k: k.name)
@pytest.mark.parametrize("cdf", [False, True])
def test_default_strategy_is_the_kinds_own_sampling_in_mis(kind, cdf):
    """Each kind's default is MIS (environment + BSDF sample) with a BSDF technique the kind can
    use; never the cosine sample for a measured material (only Lambert's own density is the
    cosine); a technique that needs verified rational inverse CDFs only with a cdf file; an
    inverse-CDF technique only for kinds that tabulate (the ones with data to sample)."""
    name = registry.default_strategy(kind.name, cdf)
    s = registry.strategy(name)
    t = registry.technique(s.technique)
    assert s.mis and s.estimator == "pdf"
    assert t.material in (None, kind.name)
    assert (t.name == "cosine") == (kind.name == "lambert"), (kind.name, name)
    assert not t.needs_fit or cdf
    assert t.name != "uniform"


def test_default_strategy_choices():
    """The choices the registry documents (a change here is a change of the renderer's default)."""
    d = registry.default_strategy
    assert (d("lambert"), d("rgl"), d("measured"), d("projected"), d("rational")) == (
        "mis", "mis-rgl", "mis-tabulated", "mis-tabulated", "mis-tabulated")
    assert d("rational", cdf=True) == "mis-rational" and d("measured", cdf=True) == "mis-tabulated"
    with pytest.raises(KeyError, match="unknown material type"):
        d("velvet")


def test_scene_default_sampler_per_kind(tmp_path):
    """A scene that names no sampler gives each material its kind's default; [integrator]
    sampler replaces the defaults, a material's own sampler replaces both; the Python API
    (MaterialSpec without sampler) resolves the same default."""
    cdf = tmp_path / "c.json"
    cdf.write_text("{}")                        # only its presence matters to the parser
    fit = tmp_path / "f.json"
    fit.write_text("{}")
    bsdf = data_file("rgl/cc_ibiza_sunset_rgb.bsdf")
    body = (f'[materials.a]\ntype = "lambert"\n'
            f'[materials.b]\ntype = "rgl"\nfile = "{bsdf}"\n'
            f'[materials.c]\ntype = "measured"\nfile = "{bsdf}"\n'
            f'[materials.d]\ntype = "rational"\nfile = "{fit}"\n'
            f'[materials.e]\ntype = "rational"\nfile = "{fit}"\ncdf = "{cdf}"\n'
            f'[materials.f]\ntype = "measured"\nfile = "{bsdf}"\nsampler = "light"\n')
    sc = parse_scene(body)
    got = {k: m.sampler for k, m in sc.materials.items()}
    assert sc.integrator.sampler is None
    assert got == {"a": "mis", "b": "mis-rgl", "c": "mis-tabulated", "d": "mis-tabulated",
                   "e": "mis-rational", "f": "light"}
    sc = parse_scene('[integrator]\nsampler = "cosine"\n' + body)
    got = {k: m.sampler for k, m in sc.materials.items()}
    assert set(got.values()) == {"cosine", "light"} and got["f"] == "light"
    assert MaterialSpec(name="x", type="rgl").sampler == "mis-rgl"
    assert MaterialSpec(name="x", type="rational", cdf=cdf).sampler == "mis-rational"
    assert MaterialSpec(name="x", type="measured", sampler="mis").sampler == "mis"
