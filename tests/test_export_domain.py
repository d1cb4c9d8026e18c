"""The exports (:mod:`fit.export`) on a fit's measured domain (:mod:`fit.rational.domain`): a 2-D
fit that records its grazing cut-off c (both shipped fits: 79 deg) has data only where
cos theta_h cos theta_d >= cos c; beyond, the file's recipe extrapolates (satin_rosaline_rgb,
both directions at 80-89 deg: red up to 494 /sr, the fit's maximum, at theta_h 23 deg where
the domain's edge gives 0.54). Every export
moves the angles onto the domain first, as the renderer does, so the compiled C (double and
float) and the Mitsuba plugin's runtime agree with the renderer's NumPy reference
``warp_rbrdf.materials.rational.evaluate_at_angles(model, None, cutoff)`` at grazing pairs
beyond the cut-off and inside it. The GLSL / HLSL / BRDF Explorer bodies are the C statements
(tests/test_export.py: test_glsl_is_the_c_statements, compiled by glslangValidator). Fits
that record no cut-off are exported as before: the same text without the domain statements
and comments (checked here; against the code before the rule, byte for byte, when it was
written).
"""
from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from test_export import FITS, compile_c, need_mitsuba

from fit.export import to_brdf_explorer, to_c, to_glsl, to_hlsl, to_mitsuba_plugin
from fit.export import mitsuba_plugin as MP
from fit.rational.coefficient_file import load
from fit.rational.domain import measured_domain

NAMES = ["paper_white", "satin"]


def model_of(name):
    return load(FITS[NAMES.index(name)])


def without_cutoff(model):
    m = copy.deepcopy(model)
    m.fit_info = {k: v for k, v in m.fit_info.items() if k != "grazing_cutoff_deg"}
    return m


def pairs(n=1500, seed=7):
    """(wi, wo, beyond): half the pairs with both directions at 80-89 deg (any azimuths: beyond
    the 79 deg cut-off's domain), half uniform on the hemisphere (mostly inside)."""
    rng = np.random.default_rng(seed)

    def dirs(theta):
        phi = rng.uniform(0, 2 * np.pi, len(theta))
        return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)

    k = n // 2
    g = np.radians(rng.uniform(80.0, 89.0, (2, k)))
    u = np.arccos(rng.uniform(0.0, 1.0, (2, n - k)))
    wi = np.concatenate([dirs(g[0]), dirs(u[0])])
    wo = np.concatenate([dirs(g[1]), dirs(u[1])])
    cos_cut = np.cos(np.radians(79.0))
    beyond = 0.5 * (wi[:, 2] + wo[:, 2]) < cos_cut       # cos th cos td = (cos ti + cos to) / 2
    return wi, wo, beyond


def reference(model):
    from warp_rbrdf.materials.rational import evaluate_at_angles

    return evaluate_at_angles(model, None, measured_domain(model))


def rel_err(got, ref):
    """max |got - ref| / max(ref, 1e-3 of the channel's maximum)."""
    floor = 1e-3 * ref.max(axis=0)
    return float((np.abs(got - ref) / np.maximum(ref, floor)).max())


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("real, tol", [("double", 1e-9), ("double-expf", 1e-4), ("float", 1e-2)])
def test_c_export_stays_on_the_measured_domain(tmp_path, name, real, tol):
    model = model_of(name)
    assert measured_domain(model) == 79.0
    wi, wo, beyond = pairs()
    got, a, b = compile_c(model, tmp_path, real)(wi, wo)
    ref = reference(model)(a, b)
    recipe = model.evaluate(a, b)             # the file's recipe alone: what the export was
    assert beyond.sum() > 700 and (~beyond).sum() > 500
    err_in, err_out = rel_err(got[~beyond], ref[~beyond]), rel_err(got[beyond], ref[beyond])
    old = rel_err(recipe[beyond], ref[beyond])
    print(f"{name} {real}: rel error inside {err_in:.3g}, beyond {err_out:.3g}; recipe beyond: max "
          f"{recipe[beyond].max():.4g} /sr vs {ref[beyond].max():.4g} on the domain (rel {old:.3g})")
    assert err_in < tol and err_out < tol, (err_in, err_out)
    assert old > 0.1                          # the recipe differs there: the test sees the rule


@pytest.mark.parametrize("name", NAMES)
def test_mitsuba_runtime_stays_on_the_measured_domain(name):
    need_mitsuba()
    model = model_of(name)
    assert MP.plan(model)["cutoff_deg"] == 79.0
    wi, wo, beyond = pairs(300)
    a, b = wi.astype(np.float32).astype(float), wo.astype(np.float32).astype(float)
    got = MP.evaluate(model, a, b)
    ref = reference(model)(a, b)
    err_in, err_out = rel_err(got[~beyond], ref[~beyond]), rel_err(got[beyond], ref[beyond])
    print(f"{name} plugin: rel error inside {err_in:.3g}, beyond {err_out:.3g}")
    assert err_in < 1e-4 and err_out < 1e-4, (err_in, err_out)
    assert rel_err(model.evaluate(a, b)[beyond], ref[beyond]) > 0.1


def domain_free(text: str) -> str:
    """An export's text with the measured domain's statements, comments and prelude taken out
    (what the same fit without a recorded cut-off exports)."""
    from fit.export.c_source import DOMAIN_PRELUDE

    text = text.replace(DOMAIN_PRELUDE + "\n", "")
    out, skip = [], 0
    for line in text.splitlines(keepends=True):
        s = line.strip().lstrip("*# ").strip()
        if skip:
            skip -= 1
            continue
        if s.startswith("Measured domain: the fit was made"):
            skip = 4
            continue
        if "measured domain (grazing cut-off" in s or "theta_h_m =" in s or "theta_d_m =" in s:
            continue
        out.append(line)
    return "".join(out).replace("theta_h_m", "th_" if "th_, " in text else "theta_h") \
        .replace("theta_d_m", "td_" if "th_, " in text else "theta_d")


@pytest.mark.parametrize("name", NAMES)
def test_fits_without_a_cutoff_export_as_before(name):
    """Without a recorded cut-off (or with 90 deg: every sample kept) nothing of the domain is
    emitted: the text is the cut-off fit's export minus its domain statements, comments and C
    prelude (the GLSL double variant: minus its cos / acos helpers too), and the Mitsuba plan
    holds no domain."""
    model = model_of(name)
    free = without_cutoff(model)
    ninety = copy.deepcopy(model)
    ninety.fit_info["grazing_cutoff_deg"] = 90.0
    for m in (free, ninety):
        assert measured_domain(m) is None
        for f in (to_c, lambda x: to_c(x, header=False), to_glsl, to_hlsl, to_brdf_explorer):
            text, with_cut = f(m), f(model)
            assert "acos" not in text and "measured domain" not in text.lower()
            assert "acos" in with_cut and text != with_cut
            assert domain_free(with_cut) == text
        dbl, dbl_cut = to_glsl(m, precision="double"), to_glsl(model, precision="double")
        fn = "rbrdf_" + model.name
        helpers = "".join(f"double {fn}_{g}_(double x)\n{{\n    return double({g}(float(x)));\n}}\n\n"
                          for g in ("cos", "acos"))
        assert helpers in dbl_cut and domain_free(dbl_cut.replace(helpers, "")) == dbl
        assert "cutoff_deg" not in MP.plan(m)
        # the standalone module carries the runtime's domain code, which a plan without
        # "cutoff_deg" never runs; its docstring says nothing of a domain
        assert "grazing cut-off c =" not in to_mitsuba_plugin(m) and "grazing cut-off c =" in to_mitsuba_plugin(model)
    assert json.dumps(MP.plan(free)) == json.dumps({k: v for k, v in MP.plan(model).items() if k != "cutoff_deg"})


def test_standalone_module_without_a_cutoff_evaluates_the_recipe(tmp_path):
    """The standalone module of a fit without a cut-off still imports and evaluates the recipe
    alone, beyond the 79 deg domain too."""
    need_mitsuba()
    import mitsuba as mi
    from test_export import import_file

    free = without_cutoff(model_of("satin"))
    path = tmp_path / "free_plugin.py"
    path.write_text(to_mitsuba_plugin(free, name="free_satin"))
    mod = import_file(path, "free_plugin")
    bsdf = mi.load_dict({"type": mod.register()})
    wi, wo, beyond = pairs(40)
    ctx = mi.BSDFContext()
    for a, b in zip(wi[beyond][:10].astype(np.float32).astype(float), wo[beyond][:10].astype(np.float32).astype(float)):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*b)
        e = np.array(bsdf.eval(ctx, si, mi.Vector3f(*a)), float)
        assert np.allclose(e, free.evaluate(a, b) * a[2], rtol=1e-4, atol=1e-7)


def test_domain_rule_is_the_renderers():
    """One definition: the renderer's names are fit.rational.domain's."""
    from fit.rational import domain
    from warp_rbrdf.materials import rational

    assert rational.measured_domain is domain.measured_domain
    assert rational.onto_measured_domain is domain.onto_measured_domain
