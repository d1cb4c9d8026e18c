"""Exports of rational fits (issue 23 part 2, :mod:`fit.export`): the C code compiled with ``cc``
and compared with the NumPy evaluation at random direction pairs, the GLSL (and the BRDF
Explorer shader block) compiled by ``glslangValidator`` and checked to be the same statements as
the C, the Mitsuba 3 plugin compared with the NumPy evaluation and, on the reference sphere,
with this project's render of the same fit, and ``rbrdf-fit export``.

Tools: ``cc`` and ``glslangValidator`` (Debian ``glslang-tools``, installed by .ci/run) and
Mitsuba (the ``reference`` extra). Locally a missing tool skips; under CI it fails.

3-D fits (coefficient file version 3, (theta_h, theta_d, |phi_d|), not reciprocal) go through the
same checks: a small 3-D fit of a synthetic non-reciprocal lobe (``fit_samples``, two theta_h
pieces; version 4: its functions give rho cos theta_i, the value factor ``"1/cos_theta_i"`` that
the fitter makes by default), a copy with a flagged channel and a copy without the factor (version
3), compiled in C and compared with :func:`fit.rational.variables3d.evaluate_directions` (light
and view roles kept; a tenth of the pairs with a grazing light, wi.z down to 1e-4, where the
factor is large and at its floor), GLSL / HLSL / ``.brdf`` compiled, the Mitsuba plugin's
``eval`` (``wo`` the light, ``si.wi`` the viewer).

Tolerances (measured, docs/exports.md, over 20 fits and 20 000 pairs each). C in double: the
NumPy recipe to rounding (max relative 1.5e-10 where a value is above 1e-2 of its channel's
maximum; required 1e-7 above 1e-3 of it, and 1e-9 of the maximum absolute). C in float (what
the GLSL computes): Chebyshev sums of high-degree pieces in float32 (satin_rosaline_rgb: 4.4e-3
relative, 1.1e-3 of the maximum absolute, near the specular peak; up to 4.2e-2 on another
fit); required 1e-2 and 3e-3 on the fits tested here.
"""
from __future__ import annotations

import copy
import ctypes
import functools
import importlib.util
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, data_file, missing, require_mitsuba

from fit.cli import main as cli_main
from fit.export import to_brdf_explorer, to_c, to_glsl, to_hlsl, to_mitsuba_plugin
from fit.export.brdf_explorer import extract_shader
from fit.export.c_source import C, function_name
from fit.export.emitter import Emitter, ExportError, flagged_summary, glsl_literal
from fit.export.escape import literal
from fit.export.glsl import GLSL
from fit.rational import model as M
from fit.rational.coefficient_file import load
from fit.rational.domain import measured_domain
from fit.rational.variables3d import evaluate_directions, half_diff_3d, is_3d

FITS = [ROOT / "warp_rbrdf" / "data" / "paper_white_rgb.json",
        ROOT / "warp_rbrdf" / "data" / "satin_rosaline_rgb.json"]
ENVMAP = "envmaps/studio_small_03_1k.hdr"


def need(tool: str) -> str:
    path = shutil.which(tool)
    if path is None:
        missing(f"{tool} not found (Debian: apt-get install glslang-tools / a C compiler)")
    return path


def need_mitsuba():
    MR = require_mitsuba()
    MR.set_variant(MR.VARIANT)
    return MR


def tricky_model():
    """satin_rosaline_rgb with its core split again in theta_h (a nested split, as fits with a
    specular-peak piece have) and one flagged channel with a measured range that cuts into
    its values: the flagged-piece policy and nested selection are exercised. (The shipped
    satin's own flagged band, blue, is marked valid here, and its embedded fallback table,
    which covers only that band, dropped: this one flagged channel is the only one.)"""
    m = copy.deepcopy(load(FITS[1]))
    m.fallback = None
    band = m.pieces[1]
    band.function_info = [dict(i, valid=True, feasible=True) for i in band.function_info]
    core = m.pieces[0]
    edges = [0.0, np.radians(10.0), np.pi / 2]
    sub = []
    for j in range(2):
        p = copy.deepcopy(core)
        p.variables[0] = M.Variable("theta_h", "rad", "sqrt", (edges[j], edges[j + 1]))
        for f in p.functions:             # mapped onto the sub-box, as a fitted piece would be
            f.domain[0] = p.variables[0].rf_domain
        sub.append(p)
    sub[0].function_info[1] = dict(sub[0].function_info[1], valid=False, measured_range=[0.05, 3.0])
    m.pieces[0] = M.PiecewiseRationalModel(name="core", variables=copy.deepcopy(core.variables),
                                           split_variable="theta_h", edges=edges, pieces=sub)
    return m


def single_linear_model():
    """A version-1 (single box) model with the linear value transform: satin_rosaline_rgb's
    core piece read as linear values, P/Q + 5 (P + 5 Q: repeated exponent rows), clamped to
    [0, max]: the emitter's single-box and linear paths."""
    from fit.rational.function import RationalFunction

    m = copy.deepcopy(load(FITS[1]).pieces[0])
    m.value_transform, m.value_offset = "linear", 0.0
    m.functions = [RationalFunction(f.domain, np.concatenate([f.num_exponents, f.den_exponents]),
                                    np.concatenate([f.num_coef, 5.0 * f.den_coef]), f.den_exponents, f.den_coef)
                   for f in m.functions]
    return m


def lobe3d(X):
    """A synthetic RGB BRDF (1/sr) of (theta_h, theta_d, |phi_d|) rows that depends on phi_d
    and is not reciprocal (cos phi_d changes sign when light and view are swapped)."""
    th, td, pd = X[:, 0], X[:, 1], X[:, 2]
    spec = 2.5 * np.exp(-(th / 0.3) ** 2) * (1.0 + 0.3 * np.cos(pd)) * (1.0 + 0.4 * np.sin(td) ** 2)
    base = np.array([0.1, 0.14, 0.22]) * (1.0 + 0.3 * (np.cos(pd) * np.sin(td))[:, None])
    return base + spec[:, None] * [1.0, 0.85, 0.7]


@functools.lru_cache(maxsize=1)
def _fit3d():
    from fit.rational.fit3d import fit_samples, sample_grid

    tm = np.radians(80.0)
    X = sample_grid(tm, grid=(10, 9, 7), n_random=300, seed=3)
    res = fit_samples(X, lobe3d(X), name="lobe3d", theta_max=tm, degrees=(4, 2), theta_h_edges=[0.2],
                      tol=0.01, time_limit=60.0, grazing_cos=0.0, channel_floor=0.0)
    assert res.valid and is_3d(res.model)
    return res.model


def fit3d_model():
    """A 3-D fit (version 4: two theta_h pieces, log values, sqrt theta_h, vouched ranges, the
    value factor ``"1/cos_theta_i"``) of :func:`lobe3d`, made by the fitter (about 2 s, once per
    session)."""
    m = copy.deepcopy(_fit3d())
    assert m.value_factor == "1/cos_theta_i"
    return m


def fit3d_none_model():
    """:func:`fit3d_model` without its value factor (version 3: the functions' values are rho)."""
    m = fit3d_model()
    m.value_factor = "none"
    return m


def fit3d_flagged_model():
    """:func:`fit3d_model` with the green channel of its peak piece flagged and a measured range
    that cuts into its values (the flagged clamp of a 3-D fit)."""
    m = fit3d_model()
    info = m.pieces[0].function_info
    info[1] = dict(info[1], valid=False, measured_range=[0.2, 1.5])
    return m


MODELS = {"paper_white": lambda: load(FITS[0]), "satin": lambda: load(FITS[1]), "tricky": tricky_model,
          "single_linear": single_linear_model, "fit3d": fit3d_model, "fit3d_flagged": fit3d_flagged_model,
          "fit3d_none": fit3d_none_model}


def reference(model):
    """What every export computes, ``f(wi, wo) -> rho (..., 3)``: the renderer's NumPy reference
    (``warp_rbrdf.materials.rational.evaluate_at_angles``): the file's recipe, on the fit's
    measured domain when it records its grazing cut-off (fit.rational.domain: paper_white,
    satin and tricky record 79 deg; single_linear, a piece, records none); for a 3-D fit
    :func:`fit.rational.variables3d.evaluate_directions` (``wi`` the light, ``wo`` the viewer),
    what the renderer evaluates too."""
    if is_3d(model):
        return functools.partial(evaluate_directions, model)
    from warp_rbrdf.materials.rational import evaluate_at_angles

    return evaluate_at_angles(model, None, measured_domain(model))


def grazing(n, rng, lowest=1e-4, highest=3e-2):
    """``n`` unit directions with z log-uniform in [``lowest``, ``highest``] (a light at the
    horizon: a value factor 1/cos theta_i large, and at its floor 1e-3 below it), uniform azimuth."""
    z = np.exp(rng.uniform(np.log(lowest), np.log(highest), n))
    phi = rng.uniform(-np.pi, np.pi, n)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=-1)


def directions(n, seed=0):
    """(wi, wo) (n, 3): uniform on the upper hemisphere, a tenth near the mirror direction
    (the specular peak), a tenth with one direction below the horizon and a tenth with a
    grazing light (:func:`grazing`)."""
    rng = np.random.default_rng(seed)

    def hemi(k):
        v = rng.normal(size=(k, 3))
        v[:, 2] = np.abs(v[:, 2])
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    wi, wo = hemi(n), hemi(n)
    k = n // 10
    mirror = wi[:k] * [-1, -1, 1] + rng.normal(scale=0.03, size=(k, 3))
    wo[:k] = mirror / np.linalg.norm(mirror, axis=1, keepdims=True)
    wo[:k, 2] = np.abs(wo[:k, 2])
    wo[k:2 * k, 2] *= -1
    wi[2 * k:3 * k] = grazing(k, rng)
    return wi, wo


def compile_c(model, tmp_path, real):
    """The exported C with a batch loop, built as a shared library; ``f(wi, wo) -> rho``."""
    cc = need("cc")
    fn = function_name(model)
    src = to_c(model, header=False) + (
        "\nvoid rbrdf_batch_(const RBRDF_REAL *wi, const RBRDF_REAL *wo, RBRDF_REAL *rho, long n)\n"
        f"{{ long i; for (i = 0; i < n; i++) {fn}(wi + 3 * i, wo + 3 * i, rho + 3 * i); }}\n")
    c = tmp_path / f"{fn}_{real}.c"
    c.write_text(src)
    so = tmp_path / f"{fn}_{real}.so"
    flags = {"double": ["-DRBRDF_REAL_DOUBLE"], "double-expf": ["-DRBRDF_REAL_DOUBLE", "-DRBRDF_EXP_FLOAT"],
             "float": []}[real]
    r = subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O1", "-shared",
                        "-fPIC", *flags, "-o", str(so), str(c), "-lm"], check=False, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    lib = ctypes.CDLL(str(so))
    dt = np.float32 if real == "float" else np.float64
    ptr = np.ctypeslib.ndpointer(dt, flags="C")
    lib.rbrdf_batch_.argtypes = [ptr, ptr, ptr, ctypes.c_long]
    lib.rbrdf_batch_.restype = None

    def f(wi, wo):
        a = np.ascontiguousarray(wi, dt)
        b = np.ascontiguousarray(wo, dt)
        out = np.zeros(a.shape, dt)
        lib.rbrdf_batch_(a, b, out, len(a))
        return out.astype(np.float64), a.astype(np.float64), b.astype(np.float64)

    return f


def agreement(got, ref, above=1e-2):
    """(max relative error where ref is above ``above`` of its channel's max, max absolute
    error / channel max)."""
    top = ref.max(axis=0)
    big = ref > above * top
    rel = np.abs(got - ref)[big] / ref[big]
    return float(rel.max()), float((np.abs(got - ref) / top).max())


# --------------------------------------------------------------------------------------------
# C: compiled, against NumPy
#: models whose float and float-exp builds repeat another's paths (paper_white: satin's; fit3d:
#: fit3d_flagged's, which adds the flagged clamp; fit3d_none: fit3d_flagged's without the value
#: factor): those two builds of them are ``extended``
C_REAL_REPEATS = ("paper_white", "fit3d", "fit3d_none")


@pytest.mark.parametrize("which, real", [
    pytest.param(w, r, id=f"{w}-{r}", marks=[pytest.mark.extended] if r != "double" and w in C_REAL_REPEATS else [])
    for r in ("double", "double-expf", "float") for w in sorted(MODELS)])
def test_c_matches_numpy(tmp_path, which, real):
    """The compiled C of every model against NumPy, in double, double with float exp and float
    (:data:`C_REAL_REPEATS`' float builds ``extended``)."""
    model = MODELS[which]()
    f = compile_c(model, tmp_path, real)
    wi, wo = directions(20000)
    got, a, b = f(wi, wo)
    ref = reference(model)(a, b)         # at the directions as C saw them
    below = (a[:, 2] <= 0) | (b[:, 2] <= 0)
    assert below.sum() > 1000 and np.all(got[below] == 0.0)
    rel, absmax = agreement(got, ref, 1e-2 if real == "float" else 1e-3)
    print(f"{which} {real}: max rel {rel:.3g} (above 1e-2/1e-3 of max), max abs/max {absmax:.3g}")
    if real == "double":
        assert rel < 1e-7 and absmax < 1e-9, (rel, absmax)
    elif real == "double-expf":          # the GLSL double variant's arithmetic: float exp, float cos /
        # acos of the domain edge (rel 2.1e-4), float cos / sin of cos theta_i near the light's horizon
        # (the value factor: rel 7.1e-5, abs 1.5e-5 of the max, where 1e-7 of cos theta_i is 1e-4 of rho)
        assert rel < 1e-3 and absmax < (5e-5 if model.value_factor != "none" else 1e-6), (rel, absmax)
    else:
        assert rel < 1e-2 and absmax < 3e-3, (rel, absmax)


@pytest.mark.parametrize("real", ["double", "float"])
def test_c_3d_keeps_the_roles_of_light_and_view(tmp_path, real):
    """A 3-D fit is not reciprocal: the C export at (wo, wi) is the NumPy fit at (wo, wi), which
    differs from its value at (wi, wo) (median 10 % and more on this lobe); mirrored pairs (y ->
    -y, the isotropy fold |phi_d|) give the same value."""
    model = MODELS["fit3d"]()
    f = compile_c(model, tmp_path, real)
    wi, wo = directions(5000, seed=7)
    got, a, b = f(wi, wo)
    swapped, _, _ = f(wo, wi)
    ref_swapped = reference(model)(b, a)
    rel, _ = agreement(swapped, ref_swapped, 1e-2)
    assert rel < (1e-7 if real == "double" else 1e-2), rel
    lit = (got > 0.05) & (swapped > 0.05)
    assert np.median(np.abs(swapped - got)[lit] / got[lit]) > 0.1
    mirrored, _, _ = f(a * [1, -1, 1], b * [1, -1, 1])
    np.testing.assert_allclose(mirrored, got, rtol=1e-9 if real == "double" else 1e-4, atol=1e-12)


def test_c_3d_value_factor_at_the_horizon(tmp_path):
    """Step 8 in the compiled C (double) at grazing lights (wi.z from 1e-4 to 3e-2): the fit
    with the value factor is its copy without it divided by max(wi.z, 1e-3), with cos theta_i
    of the angles before any clamp (pairs beyond the fitted box, theta_h or theta_d above 80
    deg, included) and at the floor below wi.z = 1e-3. Ignoring the factor, or dividing by cos
    theta_i of the clamped angles, fails it."""
    model, plain = MODELS["fit3d"](), MODELS["fit3d_none"]()
    rng = np.random.default_rng(11)
    n = 4000
    wi = grazing(n, rng)
    wo = np.concatenate([grazing(n // 2, rng, 1e-4, 0.3), rng.normal(size=(n - n // 2, 3))])
    wo[:, 2] = np.abs(wo[:, 2])
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    (tmp_path / "factor").mkdir()
    (tmp_path / "none").mkdir()              # the same function names: one library each
    got, a, b = compile_c(model, tmp_path / "factor", "double")(wi, wo)
    values, _, _ = compile_c(plain, tmp_path / "none", "double")(wi, wo)
    x = half_diff_3d(a, b)
    hi = np.array([v.domain[1] for v in model.variables])
    beyond = np.any(x > hi, axis=1)
    floor = a[:, 2] < M.COS_FLOOR
    assert beyond.sum() > 200 and floor.sum() > 200 and (~floor).sum() > 200, (beyond.sum(), floor.sum())
    assert np.all(values > 0.0)
    np.testing.assert_allclose(got, values / np.maximum(a[:, 2], M.COS_FLOOR)[:, None], rtol=1e-9, atol=0.0)
    np.testing.assert_allclose(got, reference(model)(a, b), rtol=1e-9, atol=0.0)
    clamped = np.maximum(M.cos_theta_i_of(np.minimum(x, hi)), M.COS_FLOOR)[:, None]
    assert np.median(np.abs(values / clamped - got)[beyond] / got[beyond]) > 0.5
    assert np.median(got[~floor] / values[~floor]) > 30


@pytest.mark.parametrize("flags", [[], ["-DRBRDF_REAL_DOUBLE"], ["-DRBRDF_REAL_DOUBLE", "-DRBRDF_EXP_FLOAT"]],
                         ids=["float", "double", "double-expf"])
def test_c_headers_with_and_without_the_factor_include_together(tmp_path, flags):
    """The header of a fit with a value factor (its prelude defines RBRDF_SIN and, when not yet
    defined, RBRDF_COS) and that of a fit with a measured domain (RBRDF_COS, RBRDF_ACOS) in one
    translation unit, in either order: no conflicting macro definitions (-Werror -pedantic)."""
    cc = need("cc")
    fits = {"factor.h": MODELS["fit3d"](), "domain.h": MODELS["satin"]()}
    for name, m in fits.items():
        (tmp_path / name).write_text(to_c(m))
    calls = "".join(f"    {function_name(m)}_angles(0.1, 0.2, {'0.3, ' if is_3d(m) else ''}rho);\n"
                    for m in fits.values())
    for order in (list(fits), list(fits)[::-1]):
        prog = tmp_path / "main.c"
        prog.write_text("".join(f'#include "{h}"\n' for h in order)
                        + f"int main(void)\n{{\n    RBRDF_REAL rho[3];\n{calls}"
                        + "    return rho[0] > 0 ? 0 : 1;\n}\n")
        r = subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", *flags, "-o",
                            str(tmp_path / "main"), str(prog), "-lm"],
                           check=False, capture_output=True, text=True)
        assert r.returncode == 0, (order, r.stderr[-2000:])
        assert subprocess.run([str(tmp_path / "main")], check=False).returncode == 0


def test_c_frame_function_and_cpp(tmp_path):
    """``_frame`` (world-space L, V and a rotated frame) equals the local-frame function, and
    the header compiles as C++."""
    model = MODELS["satin"]()
    fn = function_name(model)
    h = tmp_path / "fit.h"
    h.write_text(to_c(model))
    prog = tmp_path / "main.c"
    prog.write_text(f'#include "fit.h"\n#include <stdio.h>\nint main(void) {{\n'
                    "  double wi[3] = {0.3, 0.1, 0.9486833}, wo[3] = {-0.2, -0.1, 0.9746794}, a[3], b[3];\n"
                    "  double N[3] = {0, 1, 0}, X[3] = {0, 0, 1}, Y[3] = {1, 0, 0}, L[3], V[3];\n"
                    "  L[0] = wi[1]; L[1] = wi[2]; L[2] = wi[0]; V[0] = wo[1]; V[1] = wo[2]; V[2] = wo[0];\n"
                    f"  {fn}(wi, wo, a); {fn}_frame(L, V, N, X, Y, b);\n"
                    '  printf("%.17g %.17g %.17g %.17g %.17g %.17g\\n", a[0], a[1], a[2], b[0], b[1], b[2]);\n'
                    "  return 0;\n}\n")
    exe = tmp_path / "main"
    r = subprocess.run([need("cc"), "-std=c99", "-Wall", "-Werror", "-DRBRDF_REAL_DOUBLE", "-o", str(exe),
                        str(prog), "-lm"], check=False, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    vals = np.array(subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split(), float)
    ref = reference(model)(np.array([0.3, 0.1, 0.9486833]), np.array([-0.2, -0.1, 0.9746794]))
    assert np.allclose(vals[:3], ref, rtol=1e-6) and np.allclose(vals[3:], ref, rtol=1e-6), (vals, ref)
    cxx = shutil.which("c++") or shutil.which("g++")
    if cxx is None:
        missing("no C++ compiler")
    r = subprocess.run([cxx, "-x", "c++", "-Wall", "-Werror", "-fsyntax-only", str(h)], check=False, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]


# --------------------------------------------------------------------------------------------
# GLSL: the C statements, and valid GLSL
def c_to_glsl(line: str) -> str:
    """A C statement of the emitter rewritten with GLSL's names and literals."""
    line = re.sub(r"RBRDF_K\(([0-9.eE+-]+)\)", lambda m: glsl_literal(float(m.group(1))), line)
    for c, g in (("RBRDF_REAL", "float"), ("RBRDF_MIN", "min"), ("RBRDF_MAX", "max"),
                 ("rbrdf_clamp_", "clamp"), ("RBRDF_SQRT", "sqrt"), ("RBRDF_EXP", "exp"),
                 ("RBRDF_ACOS", "acos"), ("RBRDF_COS", "cos"), ("RBRDF_ABS", "abs"), ("RBRDF_SIN", "sin")):
        line = line.replace(c, g)
    return line


@pytest.mark.parametrize("which", sorted(MODELS))
def test_glsl_is_the_c_statements(which):
    """The GLSL body is, statement by statement, the C body (tested numerically above) with
    GLSL's names and float literals: the GLSL computes what the float build of the C does."""
    model = MODELS[which]()
    c = Emitter(C).rho(model)
    g = Emitter(GLSL).rho(model)
    assert len(c) == len(g) > 50
    assert [c_to_glsl(x) for x in c] == g
    assert "\n".join(g) in to_glsl(model)


def glslang(src: str, tmp_path, name="shader.frag"):
    exe = need("glslangValidator")
    p = tmp_path / name
    p.write_text(src)
    return subprocess.run([exe, str(p)], check=False, capture_output=True, text=True)


def fragment(version: str, code: str, call: str, uniforms: str = "") -> str:
    prec = "precision highp float;\n" if version.endswith("es") else ""
    return (f"#version {version}\n{prec}{uniforms}{code}\nout vec4 colour;\n"
            f"void main()\n{{\n    colour = vec4({call}, 1.0);\n}}\n")


@pytest.mark.parametrize("version", ["330 core", "410 core", "300 es"])
def test_glsl_compiles(tmp_path, version):
    model = MODELS["tricky"]()
    fn = "rbrdf_" + model.name
    call = (f"{fn}(normalize(vec3(0.3, 0.1, 0.9)), normalize(vec3(-0.2, 0.1, 0.9))) + "
            f"{fn}_frame(vec3(0.0, 0.0, 1.0), vec3(0.0, 0.6, 0.8), vec3(0.0, 0.0, 1.0), "
            f"vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0)) + {fn}_angles(0.1, 0.2)")
    r = glslang(fragment(version, to_glsl(model), call), tmp_path)
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]


@pytest.mark.parametrize("version", ["330 core", "410 core", "300 es", "400 core double"])
@pytest.mark.parametrize("which", ["fit3d_flagged", "fit3d_none"])
def test_glsl_3d_compiles(tmp_path, version, which):
    """A 3-D fit's GLSL (``_angles`` takes phi_d too; its flagged channel's clamp included; with
    and without the value factor), in float and, as GLSL 4.00, in double (the factor's cos and
    sin through float wrappers: GLSL has no double trigonometry)."""
    model = MODELS[which]()
    fn = "rbrdf_" + model.name
    call = (f"{fn}(normalize(vec3(0.3, 0.1, 0.9)), normalize(vec3(-0.2, 0.1, 0.9))) + "
            f"{fn}_frame(vec3(0.0, 0.0, 1.0), vec3(0.0, 0.6, 0.8), vec3(0.0, 0.0, 1.0), "
            f"vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0)) + {fn}_angles(0.1, 0.2, -2.5)")
    double = version.endswith("double")
    src = to_glsl(model, precision="double" if double else "float")
    assert f"vec3 {fn}_angles(float theta_h, float theta_d, float phi_d)" in src
    assert ("value factor (step 8)" in src) == (which != "fit3d_none")
    assert (f"double {fn}_sin_(double x)" in src) == (double and which != "fit3d_none")
    r = glslang(fragment(version.removesuffix(" double"), src, call), tmp_path)
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]


def test_glsl_double_compiles(tmp_path):
    """The double variant: GLSL 4.00 (the C build with -DRBRDF_REAL_DOUBLE -DRBRDF_EXP_FLOAT runs
    its arithmetic, test_c_matches_numpy)."""
    model = MODELS["tricky"]()
    src = to_glsl(model, precision="double")
    assert "double rho0" in src and "lf" in src
    r = glslang(fragment("400 core", src, f"rbrdf_{model.name}(normalize(vec3(0.3, 0.1, 0.9)), "
                                          "normalize(vec3(-0.2, 0.1, 0.9)))"), tmp_path)
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]
    with pytest.raises(ExportError, match="precision"):
        to_glsl(model, precision="half")


def test_hlsl_compiles(tmp_path):
    """HLSL: the GLSL statements verbatim (so the float C build measures it too), compiled by
    glslang's HLSL front end (``-D``) to SPIR-V as a pixel shader; a broken one is rejected."""
    model = MODELS["tricky"]()
    src = to_hlsl(model)
    assert "\n".join(Emitter(GLSL).rho(model)) in src
    fn = "rbrdf_" + model.name
    main = (f"float4 main(float4 pos : SV_Position) : SV_Target\n{{\n    return float4({fn}(normalize(pos.xyz), "
            f"normalize(float3(-0.2, 0.1, 0.9))) + {fn}_frame(float3(0.0, 0.0, 1.0), float3(0.0, 0.6, 0.8), "
            f"float3(0.0, 0.0, 1.0), float3(1.0, 0.0, 0.0), float3(0.0, 1.0, 0.0)), 1.0);\n}}\n")
    exe = need("glslangValidator")
    for text, ok in ((src, True), (src.replace("return float3(rho0, rho1, rho2);", "return float3(rho0, rho1, rho9);"), False)):
        p = tmp_path / "shader.hlsl"
        p.write_text(text + "\n" + main)
        r = subprocess.run([exe, "-D", "-V", "-e", "main", "-S", "frag", "-o", str(tmp_path / "s.spv"), str(p)],
                           check=False, capture_output=True, text=True)
        assert (r.returncode == 0) == ok, (r.stdout + r.stderr)[-3000:]


@pytest.mark.parametrize("which", ["fit3d", "fit3d_none"])
def test_hlsl_3d_compiles(tmp_path, which):
    """A 3-D fit's HLSL (with and without the value factor): the GLSL statements verbatim,
    compiled by glslang's HLSL front end."""
    model = MODELS[which]()
    src = to_hlsl(model)
    assert "\n".join(Emitter(GLSL).rho(model)) in src
    fn = "rbrdf_" + model.name
    main = (f"float4 main(float4 pos : SV_Position) : SV_Target\n{{\n    return float4({fn}(normalize(pos.xyz), "
            f"normalize(float3(-0.2, 0.1, 0.9))) + {fn}_angles(0.1, 0.2, pos.w), 1.0);\n}}\n")
    p = tmp_path / "shader.hlsl"
    p.write_text(src + "\n" + main)
    r = subprocess.run([need("glslangValidator"), "-D", "-V", "-e", "main", "-S", "frag", "-o",
                        str(tmp_path / "s.spv"), str(p)], check=False, capture_output=True, text=True)
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]


def test_glsl_validator_sees_errors(tmp_path):
    """The compile check can fail: a statement without its semicolon and an undeclared name."""
    model = MODELS["paper_white"]()
    src = to_glsl(model)
    bad = src.replace("return vec3(rho0, rho1, rho2);", "return vec3(rho0, rho1, rho3)", 1)
    r = glslang(fragment("330 core", bad, f"rbrdf_{model.name}_angles(0.1, 0.2)"), tmp_path)
    assert r.returncode != 0 and "ERROR" in r.stdout


def test_brdf_explorer_file(tmp_path):
    """An ``analytic`` file with a parameters block and a shader block whose GLSL (with the
    parameter as a uniform, as BRDF Explorer declares it) compiles and defines BRDF()."""
    model = MODELS["tricky"]()
    text = to_brdf_explorer(model)
    assert text.startswith("analytic\n")
    params = text[text.index("::begin parameters"):text.index("::end parameters")].splitlines()[1:]
    assert params == ["float scale 0.0 4.0 1.0"]
    shader = extract_shader(text)
    assert "vec3 BRDF(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)" in shader
    assert "FLAGGED" in text and "measured range" in text
    call = "BRDF(vec3(0.0, 0.0, 1.0), vec3(0.0, 0.6, 0.8), vec3(0.0, 0.0, 1.0), vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0))"
    for version in ("410 core", "330 core"):
        r = glslang(fragment(version, shader, call, "uniform float scale;\n"), tmp_path)
        assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]


def test_brdf_explorer_file_3d(tmp_path):
    """A 3-D fit's ``.brdf`` file: BRDF(L, V, ...) passes L as the light (the fit's wi), and the
    shader block compiles."""
    model = MODELS["fit3d"]()
    text = to_brdf_explorer(model)
    shader = extract_shader(text)
    assert f"return scale * rbrdf_{model.name}_frame(L, V, N, X, Y);" in shader
    assert "# Fit 'lobe3d': rho(wi, wo) in 1/sr (no cosine), RGB, isotropic, NOT reciprocal:" in text
    assert "\n".join(Emitter(GLSL).rho(model)) in shader and "# Value factor 1/cos(theta_i)" in text
    call = "BRDF(vec3(0.0, 0.0, 1.0), vec3(0.0, 0.6, 0.8), vec3(0.0, 0.0, 1.0), vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0))"
    r = glslang(fragment("410 core", shader, call, "uniform float scale;\n"), tmp_path)
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]


def test_policy_in_comments():
    m = MODELS["tricky"]()
    assert flagged_summary(m) == [(0, [("G", (0.05, 3.0))])]
    for text in (to_glsl(m), to_c(m), to_hlsl(m)):
        assert "below the horizon" in text and "clamped onto it" in text and "piece 0, channel G" in text
    assert "Every piece is valid" in to_glsl(MODELS["paper_white"]())
    m3 = MODELS["fit3d_flagged"]()
    assert flagged_summary(m3) == [(0, [("G", (0.2, 1.5))])]
    for text in (to_glsl(m3), to_c(m3), to_hlsl(m3)):
        assert "NOT reciprocal" in text and "|phi_d| in [0, 180] deg" in text and "piece 0, channel G" in text
        assert "grazing cut-off" not in text and "renderer refuses" in text
    for which in ("fit3d", "fit3d_none"):
        m = MODELS[which]()
        for text in (to_glsl(m), to_c(m), to_hlsl(m), to_brdf_explorer(m), to_mitsuba_plugin(m)):
            lines = [ln.lstrip("/*# ") for ln in text.splitlines()]
            stated = {"Value factor 1/cos(theta_i): the fitted functions give rho cos(theta_i), and the clamps",
                      "and ranges above bound that product; then rho = product / max(cos(theta_i), 0.001),"
                      } <= set(lines)
            plugin = "rho = the clamped value / max(cos theta_i, 0.001), cos theta_i of the" in text
            assert (stated or plugin) == (which == "fit3d"), (which, text[:3000])


def test_unsupported_fit_is_refused():
    m = copy.deepcopy(MODELS["paper_white"]())
    m.variables[0].name = "phi_d"
    with pytest.raises(ExportError, match="theta_h, theta_d"):
        to_glsl(m)


EXPORTS = (to_glsl, to_c, to_hlsl, to_brdf_explorer, to_mitsuba_plugin)


@pytest.mark.parametrize("case", ["unknown", "hostile", "2-D", "piece"])
def test_value_factor_refused(case):
    """Value factors the exports do not translate (set after the model's own checks): an
    unknown one (named in one inert line), one on a 2-D fit, one on a piece."""
    hostile = "x */ int INJECTED = 1; /*\n"
    if case == "2-D":
        m = MODELS["satin"]()
        m.value_factor = "1/cos_theta_i"
        match = r"value factor '1/cos_theta_i' on a fit in \['theta_h', 'theta_d'\]: only 3-D fits"
    elif case == "piece":
        m = MODELS["fit3d_none"]()
        m.pieces[1].value_factor = "1/cos_theta_i"
        match = "a piece has a value factor of its own"
    else:
        m = MODELS["fit3d"]()
        m.value_factor = "1/cos_theta_o" if case == "unknown" else hostile
        match = re.escape(f"value factor {literal(m.value_factor)}: only 'none', '1/cos_theta_i' are exported")
        match = f"^{match}$"
    for export in EXPORTS:
        with pytest.raises(ExportError, match=match) as e:
            export(m)
        assert "\n" not in str(e.value) and "*/" not in str(e.value)


# --------------------------------------------------------------------------------------------
# Mitsuba 3 plugin
def test_mitsuba_plugin_eval_matches_numpy():
    """The plugin's ``eval`` / cos(theta_o) against NumPy at random pairs (scalar_rgb), and its
    pdf and sample (cosine)."""
    MR = need_mitsuba()
    import mitsuba as mi

    from fit.export import mitsuba_plugin as MP

    model = MODELS["tricky"]()
    name = MP.register("rbrdf_test_tricky", model)
    bsdf = mi.load_dict({"type": name})
    wi, wo = directions(400, seed=3)
    a, b = wi.astype(np.float32).astype(float), wo.astype(np.float32).astype(float)
    ref = reference(model)(a, b)
    got = MP.evaluate(model, a, b)
    rel, absmax = agreement(got, ref)
    print(f"plugin vs NumPy: max rel {rel:.3g}, max abs/max {absmax:.3g}")
    assert rel < 1e-4 and absmax < 1e-5, (rel, absmax)
    ctx = mi.BSDFContext()
    for k in range(40):                   # eval and pdf through the BSDF interface (Mitsuba's roles)
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*b[k])
        e = np.array(bsdf.eval(ctx, si, mi.Vector3f(*a[k])), float)
        assert np.allclose(e, ref[k] * max(a[k, 2], 0.0), rtol=1e-4, atol=1e-7), (k, e, ref[k])
        pdf = float(bsdf.pdf(ctx, si, mi.Vector3f(*a[k])))
        assert np.isclose(pdf, max(a[k, 2], 0.0) / np.pi, rtol=1e-5) or b[k, 2] <= 0
        bs, w = bsdf.sample(ctx, si, 0.5, mi.Point2f(0.3, 0.7))
        if b[k, 2] > 0:
            wx = np.array(bs.wo, float)
            assert np.isclose(bs.pdf, wx[2] / np.pi, rtol=1e-5)
            assert np.allclose(np.array(w, float), reference(model)(wx, b[k]) * np.pi, rtol=1e-4, atol=1e-7)
    MR.set_variant(MR.VARIANT)


@pytest.mark.parametrize("which", ["fit3d", "fit3d_flagged", "fit3d_none"])
def test_mitsuba_plugin_3d_eval_matches_numpy(which):
    """A 3-D fit in the plugin (with and without the value factor, whose plan entry is there
    only with it): ``evaluate`` against NumPy, and ``eval`` through the BSDF interface with
    Mitsuba's roles (``si.wi`` the viewer, ``wo`` the light): f(light = wo, view = si.wi)
    cos(theta_wo), grazing lights (:func:`directions`' third tenth) included; the swapped roles
    would differ (not reciprocal)."""
    MR = need_mitsuba()
    import mitsuba as mi

    from fit.export import mitsuba_plugin as MP

    model = MODELS[which]()
    factor = MP.plan(model).get("value_factor")
    assert factor == (None if which == "fit3d_none" else {"kind": "1/cos_theta_i", "cos_floor": M.COS_FLOOR})
    bsdf = mi.load_dict({"type": MP.register(f"rbrdf_test_{which}", model)})
    wi, wo = directions(400, seed=3)
    a, b = wi.astype(np.float32).astype(float), wo.astype(np.float32).astype(float)
    ref = reference(model)(a, b)
    rel, absmax = agreement(MP.evaluate(model, a, b), ref)
    print(f"3-D plugin vs NumPy: max rel {rel:.3g}, max abs/max {absmax:.3g}")
    assert rel < 1e-4 and absmax < 1e-5, (rel, absmax)
    ctx = mi.BSDFContext()
    swapped = reference(model)(b, a)
    differ = 0
    for k in [*range(60), *range(80, 120)]:         # mirror pairs, grazing lights
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*b[k])
        e = np.array(bsdf.eval(ctx, si, mi.Vector3f(*a[k])), float)
        assert np.allclose(e, ref[k] * max(a[k, 2], 0.0), rtol=1e-4, atol=1e-7), (k, e, ref[k])
        differ += not np.allclose(swapped[k], ref[k], rtol=1e-2)
    assert differ > 20
    MR.set_variant(MR.VARIANT)


def test_mitsuba_runtime_refuses_an_unknown_value_factor():
    """A plan whose value factor the runtime does not know (a newer writer's) is refused, not
    evaluated without it."""
    need_mitsuba()
    import drjit as dr
    import mitsuba as mi

    from fit.export import _mitsuba_runtime as RT
    from fit.export import mitsuba_plugin as MP

    plan = MP.plan(MODELS["fit3d"]())
    plan["value_factor"] = dict(plan["value_factor"], kind="1/cos_theta_o")
    with pytest.raises(ValueError, match="unknown value factor '1/cos_theta_o'"):
        RT.evaluate(mi, dr, plan, mi.Vector3f(0.3, 0.1, 0.9486833), mi.Vector3f(-0.2, -0.1, 0.9746794))


@pytest.fixture(scope="module")
def small_cdf():
    """Tabulated inverse CDFs of satin_rosaline_rgb's fit (8 view rows, 16 x 16 cells)."""
    from fit.sampling.cdf_file import table_only

    return table_only(MODELS["satin"]().evaluate, {"n_v": 8, "n_t": 16, "n_p": 16})


def test_mitsuba_plugin_samples_with_the_cdf_tables(small_cdf):
    """With an rbrdf-cdf file the plugin samples its tables: the same directions and pdf as
    :meth:`fit.sampling.table.CDFTable.sample` at the same (mu, tau) (measured: directions
    within 3e-7, pdf within 7e-8 relative in scalar_rgb), its ``pdf(wo)`` equals the sample's
    pdf (measured median 3e-8, max 2.4e-5 relative: float32 angles at cell edges), and the
    weight is f cos / pdf."""
    need_mitsuba()
    import mitsuba as mi

    from fit.export import mitsuba_plugin as MP

    model = MODELS["satin"]()
    bsdf = mi.load_dict({"type": MP.register("rbrdf_test_cdf", model, small_cdf)})
    assert "tabulated inverse CDFs" in str(bsdf)
    rng = np.random.default_rng(5)
    n = 150
    tv, pv = rng.uniform(0.01, 1.55, n), rng.uniform(-3.1, 3.1, n)
    wi = np.stack([np.sin(tv) * np.cos(pv), np.sin(tv) * np.sin(pv), np.cos(tv)], -1)
    mu, tau = rng.uniform(size=n), rng.uniform(size=n)
    tl, pl, pdf = small_cdf.table.sample(tv, mu, tau)
    ref_wo = np.stack([np.sin(tl) * np.cos(pl + pv), np.sin(tl) * np.sin(pl + pv), np.cos(tl)], -1)
    ctx = mi.BSDFContext()
    for k in range(n):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*wi[k])
        bs, w = bsdf.sample(ctx, si, 0.5, mi.Point2f(mu[k], tau[k]))
        wo = np.array(bs.wo, float)
        assert np.abs(wo - ref_wo[k]).max() < 1e-5, (k, wo, ref_wo[k])
        assert np.isclose(bs.pdf, pdf[k], rtol=1e-5), (k, bs.pdf, pdf[k])
        assert np.isclose(float(bsdf.pdf(ctx, si, bs.wo)), bs.pdf, rtol=1e-3)
        if wo[2] > 0:
            f = reference(model)(wo, wi[k]) * wo[2] / pdf[k]
            assert np.allclose(np.array(w, float), f, rtol=1e-3, atol=1e-7)


def import_file(path, name):
    """The module in file ``path``, imported as ``name`` (not left in sys.modules)."""
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    try:
        spec.loader.exec_module(mod)
    finally:
        sys.modules.pop(name, None)
    return mod


def test_standalone_plugin_module(tmp_path):
    """The exported .py needs only Mitsuba: imported from a file, registered, it evaluates the fit."""
    need_mitsuba()
    import mitsuba as mi

    model = MODELS["satin"]()
    path = tmp_path / "satin_plugin.py"
    path.write_text(to_mitsuba_plugin(model))
    text = path.read_text()
    assert "from fit" not in text and "import fit" not in text and "warp_rbrdf" not in text
    name = import_file(path, "satin_plugin").register()
    assert name == "rbrdf_satin_rosaline_rgb"
    bsdf = mi.load_dict({"type": name})
    wi, wo = directions(50, seed=4)
    ctx = mi.BSDFContext()
    for a, b in zip(wi.astype(np.float32).astype(float), wo.astype(np.float32).astype(float)):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*b)
        e = np.array(bsdf.eval(ctx, si, mi.Vector3f(*a)), float)
        assert np.allclose(e, reference(model)(a, b) * max(a[2], 0.0), rtol=1e-4, atol=1e-7)


def test_standalone_plugin_module_3d(tmp_path):
    """The exported .py of a 3-D fit needs only Mitsuba and keeps the roles."""
    need_mitsuba()
    import mitsuba as mi

    model = MODELS["fit3d"]()
    path = tmp_path / "lobe_plugin.py"
    path.write_text(to_mitsuba_plugin(model))
    assert "not reciprocal" in path.read_text()
    bsdf = mi.load_dict({"type": import_file(path, "lobe_plugin").register("rbrdf_test_lobe_standalone")})
    wi, wo = directions(50, seed=4)
    ctx = mi.BSDFContext()
    for a, b in zip(wi.astype(np.float32).astype(float), wo.astype(np.float32).astype(float)):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*b)
        e = np.array(bsdf.eval(ctx, si, mi.Vector3f(*a)), float)
        assert np.allclose(e, reference(model)(a, b) * max(a[2], 0.0), rtol=1e-4, atol=1e-7)


@pytest.fixture(scope="module")
def our_sphere():
    """This project's render of the reference sphere with satin_rosaline_rgb's fit (rational
    material, ``mis``): ``(res, spp, image, variance of the pixel means)``."""
    MR = need_mitsuba()
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import MaterialSpec

    res, spp = (48, 64) if MR.find_libllvm() is not None else (24, 16)
    sc = MR.sphere_scene(("lambert", (0.5, 0.5, 0.5)), data_file(ENVMAP), spp, res, seed=1)
    # the plugin follows the file's recipe everywhere: the renderer too (the shipped satin's flagged
    # band, blue, would show its embedded projected table; here its records say valid)
    model = load(FITS[1])
    model.fallback = None
    for leaf in model.pieces:
        leaf.function_info = [dict(i, valid=True, feasible=True) for i in leaf.function_info]
    sc.materials["obj"] = MaterialSpec(name="obj", type="rational", data=model, sampler="mis")
    sc.integrator.sampler = "mis"
    io, vo = Renderer(sc).render(return_variance=True)
    return res, spp, io, vo / spp


@pytest.mark.parametrize("sampling", ["cosine", "cdf"])
def test_mitsuba_plugin_sphere_matches_our_render(our_sphere, small_cdf, sampling):
    """The reference sphere (lab.mitsuba_reference) in Mitsuba with the plugin (direct
    integrator: environment + BSDF sample, power heuristic; the BSDF sample cosine or from the
    CDF tables) against our renderer's rational material with ``mis`` (environment + cosine)
    and the same fit: channel means within
    4 standard errors, per-pixel z-scores inside the silhouette distributed as noise. Runs in
    ``llvm_ad_rgb`` when a libLLVM is found (48 px, 64 spp: about 1 s), else in ``scalar_rgb``
    at 24 px, 16 spp (the plugin runs in Python per sample there)."""
    MR = need_mitsuba()
    import mitsuba as mi

    from fit.export import mitsuba_plugin as MP

    env = data_file(ENVMAP)
    llvm = MR.find_libllvm() is not None
    res, spp, io, vo = our_sphere
    passes = 8 if llvm else 4
    try:
        if llvm:
            MR.set_variant("llvm_ad_rgb")
        name = MP.register(f"rbrdf_test_sphere_{sampling}", FITS[1],
                           small_cdf if sampling == "cdf" else None)
        d = MR.mitsuba_scene_dict(("lambert", (0.5, 0.5, 0.5)), env, spp // passes, res)
        d["sphere"]["bsdf"] = {"type": name}
        scene = mi.load_dict(d)
        imgs = np.stack([np.array(mi.render(scene, spp=spp // passes, seed=k), np.float64)[..., :3]
                         for k in range(passes)])
    finally:
        MR.set_variant(MR.VARIANT)
    im, vm = imgs.mean(0), imgs.var(0, ddof=1) / passes
    mo, mm = io.reshape(-1, 3).mean(0), im.reshape(-1, 3).mean(0)
    se = np.sqrt(vo.reshape(-1, 3).sum(0) + vm.reshape(-1, 3).sum(0)) / (res * res)
    z = (mo - mm) / se
    mask = MR.sphere_mask(res)
    zp = ((io - im) / np.sqrt(vo + vm + 1e-30))[mask]
    print(f"{sampling}: means ours {mo} mitsuba {mm}: z {z}, rel se {se / mm}; per-pixel z mean {zp.mean():.3f} "
          f"std {zp.std():.3f}")
    assert np.all(mm > 0.05) and np.all(np.abs(z) < 4), (mo, mm, z)
    assert abs(zp.mean()) < 0.2 and 0.7 < zp.std() < 1.5, (zp.mean(), zp.std())


def _mitsuba_sphere(name, res, spp, passes=8):
    """The reference sphere in Mitsuba (llvm_ad_rgb) with BSDF plugin ``name``: ``(mean image,
    variance of the mean)`` over ``passes`` seeds (in the variant set by the caller)."""
    MR = require_mitsuba()
    import mitsuba as mi

    d = MR.mitsuba_scene_dict(("lambert", (0.5, 0.5, 0.5)), data_file(ENVMAP), spp // passes, res)
    d["sphere"]["bsdf"] = {"type": name}
    scene = mi.load_dict(d)
    imgs = np.stack([np.array(mi.render(scene, spp=spp // passes, seed=k), np.float64)[..., :3]
                     for k in range(passes)])
    return imgs.mean(0), imgs.var(0, ddof=1) / passes


def test_mitsuba_plugin_sphere_3d_keeps_the_roles_of_our_render():
    """The light and view roles of a 3-D fit end to end: the reference sphere with the synthetic
    non-reciprocal lobe, our renderer (rational material, ``mis``) against Mitsuba with the plugin
    (``wo`` the light): channel means within 4 standard errors, per-pixel z-scores distributed as
    noise. With the roles swapped in the plugin the same comparison fails (measured: per-pixel
    z mean 0.9, std 2.0, against 0.04 and 1.06): the test can tell the roles apart. llvm_ad_rgb
    only (48 px, 64 spp)."""
    MR = need_mitsuba()
    if MR.find_libllvm() is None:
        missing("no libLLVM: the 3-D sphere comparison runs in llvm_ad_rgb only")
    import drjit as dr
    import mitsuba as mi

    from fit.export import _mitsuba_runtime as RT
    from fit.export import mitsuba_plugin as MP
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import MaterialSpec

    model = MODELS["fit3d"]()
    res, spp = 48, 64
    sc = MR.sphere_scene(("lambert", (0.5, 0.5, 0.5)), data_file(ENVMAP), spp, res, seed=1)
    sc.materials["obj"] = MaterialSpec(name="obj", type="rational", data=model, sampler="mis")
    sc.integrator.sampler = "mis"
    io, vo = Renderer(sc).render(return_variance=True)
    vo = vo / spp
    mask = MR.sphere_mask(res)
    try:
        MR.set_variant("llvm_ad_rgb")
        right = _mitsuba_sphere(MP.register("rbrdf_test_sphere_3d", model), res, spp)
        plan, cls = MP.plan(model), RT.bsdf_class(mi, dr)

        class Swapped(cls):
            def _f(self, si, wo):            # the roles of a 2-D fit: si.wi as the light
                return RT.evaluate(mi, dr, self.plan, si.wi, wo) * self.scale

        mi.register_bsdf("rbrdf_test_sphere_3d_swapped", lambda props: Swapped(props, plan))
        wrong = _mitsuba_sphere("rbrdf_test_sphere_3d_swapped", res, spp)
    finally:
        MR.set_variant(MR.VARIANT)
    stats = []
    for im, vm in (right, wrong):
        se = np.sqrt(vo.reshape(-1, 3).sum(0) + vm.reshape(-1, 3).sum(0)) / (res * res)
        z = (io.reshape(-1, 3).mean(0) - im.reshape(-1, 3).mean(0)) / se
        zp = ((io - im) / np.sqrt(vo + vm + 1e-30))[mask]
        stats.append((z, zp.mean(), zp.std()))
    print(f"3-D sphere: roles kept z {stats[0][0]}, per-pixel {stats[0][1]:.3f} / {stats[0][2]:.3f}; "
          f"swapped z {stats[1][0]}, per-pixel {stats[1][1]:.3f} / {stats[1][2]:.3f}")
    (z, zm, zs), (_, wm, ws) = stats
    assert np.all(np.abs(z) < 4) and abs(zm) < 0.2 and 0.7 < zs < 1.5, stats[0]
    assert abs(wm) > 0.4 or ws > 1.5, stats[1]


# --------------------------------------------------------------------------------------------
# rbrdf-fit export
@pytest.mark.parametrize("ext", ["glsl", "hlsl", "h", "c", "brdf", "py"])
def test_cli_export(tmp_path, capsys, ext):
    out = tmp_path / "sub" / f"satin.{ext}"
    assert cli_main(["export", str(FITS[1]), str(out), "--name", "satin"]) == 0
    text = out.read_text()
    assert "satin" in text and "below the horizon" in text
    assert f"wrote {out}" in capsys.readouterr().out


@pytest.mark.parametrize("ext", ["glsl", "hlsl", "h", "c", "brdf", "py"])
def test_cli_export_3d(tmp_path, capsys, ext):
    """``rbrdf-fit export`` of a version-3 file, every format."""
    from fit.rational.coefficient_file import save

    fit = tmp_path / "lobe3d.json"
    save(MODELS["fit3d"](), fit)
    out = tmp_path / f"lobe.{ext}"
    assert cli_main(["export", str(fit), str(out)]) == 0
    text = out.read_text()
    assert "rbrdf_lobe3d" in text and "not reciprocal" in text.lower()
    assert f"wrote {out}" in capsys.readouterr().out


def test_cli_export_flagged_note(tmp_path, capsys):
    from fit.rational.coefficient_file import save

    fit = tmp_path / "tricky.json"
    save(MODELS["tricky"](), fit)
    assert cli_main(["export", str(fit), str(tmp_path / "t.glsl")]) == 0
    assert "piece 0 channel(s) G flagged" in capsys.readouterr().out


@pytest.mark.parametrize("args, what", [
    (["{fit}", "{tmp}/x.txt"], "expected a file name ending with"),
    (["{tmp}/missing.json", "{tmp}/x.glsl"], "missing.json"),
    (["{bad}", "{tmp}/x.glsl"], "bad.json"),
    (["{fit}", "{tmp}/x.glsl", "--name", "9 bad"], "--name"),
    (["{fit}", "{tmp}/x.h", "--precision", "double"], "--precision"),
])
def test_cli_export_bad_input(tmp_path, capsys, args, what):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "rbrdf-rational", "version": 7}')
    argv = [a.format(fit=FITS[1], tmp=tmp_path, bad=bad) for a in args]
    assert cli_main(["export", *argv]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and what in err and "Traceback" not in err
    assert not any((tmp_path / f"x.{e}").exists() for e in ("glsl", "txt", "h"))


def test_cli_export_plugin_with_cdf(tmp_path, small_cdf):
    cdf = tmp_path / "satin_cdf.json"
    small_cdf.save(cdf)
    out = tmp_path / "p.py"
    assert cli_main(["export", str(FITS[1]), str(out), "--cdf", str(cdf)]) == 0
    text = out.read_text()
    assert '"cdf_theta"' in text and "sampling: tabulated inverse CDFs" in text
    need_mitsuba()
    import mitsuba as mi

    mod = import_file(out, "satin_cdf_plugin")
    bsdf = mi.load_dict({"type": mod.register("rbrdf_test_standalone_cdf"), "scale": 2.0})
    assert "tabulated inverse CDFs" in str(bsdf)
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(0.3, 0.1, 0.9486833)
    bs, w = bsdf.sample(mi.BSDFContext(), si, 0.5, mi.Point2f(0.4, 0.6))
    pdf = small_cdf.table.sample(np.arccos(0.9486833), 0.4, 0.6)[2]
    assert np.isclose(bs.pdf, pdf, rtol=1e-5)
    wo = np.array(bs.wo, float)
    f = 2.0 * reference(MODELS["satin"]())(wo, np.array([0.3, 0.1, 0.9486833])) * wo[2] / pdf
    assert np.allclose(np.array(w, float), f, rtol=1e-3)          # property scale = 2
    assert cli_main(["export", str(FITS[1]), str(tmp_path / "p.glsl"), "--cdf", str(cdf)]) == 2
    assert cli_main(["export", str(FITS[1]), str(tmp_path / "q.py"), "--cdf", str(FITS[0])]) == 2
    assert not (tmp_path / "p.glsl").exists() and not (tmp_path / "q.py").exists()


def test_cli_export_glsl_double(tmp_path):
    out = tmp_path / "d.glsl"
    assert cli_main(["export", str(FITS[0]), str(out), "--precision", "double"]) == 0
    assert "double rho0" in out.read_text()
