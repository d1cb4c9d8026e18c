"""Parity with the reference implementation (issue 20): Mitsuba 3's ``measured`` plugin (the
RGL-EPFL format authors' code) against our NumPy reader, our Warp ``rgl`` material and its
``rgl`` sampler, and a rendered sphere (:mod:`lab.mitsuba_reference`).

Mitsuba comes with the ``reference`` extra (``pip install -e ".[reference]"``; the ``test``
extra pulls it in). Locally the file skips without it; under CI (``CI=true``) a missing Mitsuba
is a failure, as a missing data file is.

Roles: Mitsuba's ``eval(si.wi = wt, wo = wx)`` indexes the tensors by ``wt`` and returns
``f_r * cos(theta_wx)``. Our NumPy ``RGLBRDF.reference_eval(wt, wx)`` computes the same; our
renderer's ``eval_material(name, wi_light, wo_view)`` returns rho with the view as ``wt``
(``incident = "view"``), so ``eval_material(wx, wt) * wx.z`` is Mitsuba's value.

Tolerances. Mitsuba computes in float32 (inputs rounded to float32, ``elevation`` via asin,
float32 CDFs in its ``Marginal2D`` warps); the NumPy reference computes in float64 and our Warp
kernels in float32. A one-ulp perturbation of the input directions changes the float64 value by
up to 4e-5 relative, and the absolute float32 error scales with the largest value of the table
(a steep interpolant), so tiny values carry large *relative* errors: between 1e-3 and 1e-2 of
the sample's maximum we measured up to 5.7e-4 (NumPy, chm_mint_rgb) and 4.9e-4 (Warp). "Above
noise" is therefore a value above 1e-2 of the channel's maximum over the sample; there the
relative error must be <= 1e-4 (measured max over the 20 shared files: NumPy 8.2e-5, Warp
7.4e-5, both chm_mint_rgb at a view 88.9 deg from the normal, where Mitsuba's own float32 answer
moves by 4e-5 when the pair is turned by pi/2 about the normal), and everywhere the absolute
error must be <= 5e-5 of that maximum (measured max: NumPy 1.3e-5, Warp 4.8e-6).

Mitsuba 3.9.1 leaves ``m_reduction`` uninitialized for isotropic files, so depending on the
heap at load time it rotates the pair by pi about the normal when ``si.wi.y > 0`` before the
lookup (a symmetry of isotropic data; bit-identical results), or, when the garbage reads
exactly 4, mirrors pairs (not a symmetry of measured data; it failed these tests once):
:mod:`lab.mitsuba_reference` detects a mirroring plugin and loads it again
(:class:`GarbageReduction` emulates both cases).

Renders compare channel means within 4 standard errors (the per-pixel variances of both
renderers: ours from its per-sample moments, Mitsuba's from 16 independent passes) and each
pixel fully inside the silhouette (where the image is continuous) by its z-score.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import data_file, missing, require_mitsuba
from fit.formats.angles import spherical_to_direction
from fit.formats.rgl import read_rgl
from lab import mitsuba_reference as MR

pytestmark = pytest.mark.lab  # tests lab code only (the `lab` marker of pyproject.toml)

#: Every RGL material of the shared data folder (isotropic RGB).
ALL_RGL = (
    "acrylic_felt_green_rgb", "acrylic_felt_pink_rgb", "acrylic_felt_purple_rgb",
    "aurora_white_rgb", "cardboard_rgb", "cc_ibiza_sunset_rgb", "cc_iris_purple_gem_rgb",
    "chm_mint_rgb", "cm_toxic_green_rgb", "colodur_azure_4e_rgb", "colodur_connemara_4c_rgb",
    "colodur_napoli_4f_rgb", "ilm_l3_37_matte_rgb", "ilm_solo_m_68_rgb", "paper_blue_rgb",
    "paper_white_rgb", "satin_purple_rgb", "satin_rosaline_rgb", "vch_golden_yellow_rgb",
    "vch_ultra_pink_rgb",
)
ENVMAP = "envmaps/studio_small_03_1k.hdr"
N_PAIRS = 3000
ABOVE_NOISE = 1e-2      # fraction of the channel's maximum over the sample
REL_TOL = 1e-4          # relative error where the value is above noise
ABS_TOL = 5e-5          # absolute error everywhere, as a fraction of that maximum


@pytest.fixture(scope="module", autouse=True)
def _need_mitsuba():
    require_mitsuba()


def rgl_path(name: str) -> Path:
    return data_file(f"rgl/{name}.bsdf")


def direction_pairs(n=N_PAIRS, seed=0):
    """(wt, wx): cosine-distributed pairs, a third of them with one or both directions grazing
    (80 to 89.9 deg from the normal, beyond the last measured incidence of every file)."""
    rng = np.random.default_rng(seed)
    t = np.arccos(rng.random((2, n)))
    g = n // 3
    t[0, :g // 2] = np.radians(rng.uniform(80, 89.9, g // 2))
    t[1, g // 2:g] = np.radians(rng.uniform(80, 89.9, g - g // 2))
    t[:, g:g + g // 4] = np.radians(rng.uniform(80, 89.9, (2, g // 4)))
    p = rng.random((2, n)) * 2 * np.pi
    return spherical_to_direction(t[0], p[0]), spherical_to_direction(t[1], p[1])


def check_close(got, ref, what, rel_tol=REL_TOL, abs_tol=ABS_TOL, above=ABOVE_NOISE):
    """Per channel (columns): relative error <= rel_tol where |ref| > above * max|ref|, and
    absolute error <= abs_tol * max|ref| everywhere. Returns (max rel, max abs/max)."""
    got = np.asarray(got, np.float64).reshape(len(ref), -1)
    ref = np.asarray(ref, np.float64).reshape(len(ref), -1)
    mx = np.abs(ref).max(axis=0)
    assert np.all(mx > 0), f"{what}: reference is zero everywhere"
    err = np.abs(got - ref)
    sel = np.abs(ref) > above * mx
    rel = np.where(sel, err / np.where(sel, np.abs(ref), 1.0), 0.0)
    k = np.unravel_index(np.argmax(rel), rel.shape)
    assert rel.max() <= rel_tol, (f"{what}: relative error {rel.max():.3g} > {rel_tol:g} at pair "
                                  f"{k[0]}, channel {k[1]} ({got[k]:.7g} vs {ref[k]:.7g})")
    a = (err / mx).max()
    assert a <= abs_tol, f"{what}: absolute error {a:.3g} of the maximum > {abs_tol:g}"
    return rel.max(), a


# --------------------------------------------------------------------------------------------
# (a) the NumPy reader
@pytest.mark.parametrize("name", ALL_RGL)
def test_numpy_reference_eval_matches_mitsuba(name):
    path = rgl_path(name)
    wt, wx = direction_pairs()
    ref = MR.eval(path, wt, wx)
    check_close(read_rgl(path).reference_eval(wt, wx), ref, f"{name} NumPy reference_eval")


@pytest.mark.parametrize("name", ["cc_ibiza_sunset_rgb", "satin_rosaline_rgb", "aurora_white_rgb",
                                  "vch_golden_yellow_rgb", "paper_white_rgb"])
def test_mitsuba_indexes_the_tensors_by_si_wi(name):
    """The roles, empirically: Mitsuba's eval(si.wi = a, wo = b) is reference_eval(a, b) (above),
    not the tensors indexed by ``wo``, i.e. rho with the roles swapped times cos(theta_b):
    reference_eval(b, a) * cos(theta_b) / cos(theta_a) differs by a median 4.7-31 % on these
    files (and reference_eval(b, a) itself by 20-70 %), where the values are above noise."""
    path = rgl_path(name)
    a, b = direction_pairs(1000, seed=1)
    m = MR.eval(path, a, b)
    b_rgl = read_rgl(path)
    assert np.allclose(b_rgl.reference_eval(a, b), m, rtol=1e-3, atol=1e-4 * m.max())
    swapped = b_rgl.reference_eval(b, a) * (b[:, 2] / a[:, 2])[:, None]
    sel = m > ABOVE_NOISE * m.max(axis=0)
    assert np.median(np.abs(swapped - m)[sel] / m[sel]) > 0.03


class GarbageReduction:
    """Mitsuba 3.9.1's ``measured`` plugin as it behaves when its uninitialized ``m_reduction``
    (set for anisotropic files only) reads ``garbage`` >= 2 (``measured.cpp``): with
    ``s = (si.wi.x if garbage == 4 else si.wi.y, si.wi.y)``, x is negated where ``s[0]`` has no sign bit
    and y where ``s[1]`` has none (``mulsign_neg``), in ``si.wi`` and ``wo`` before eval and pdf, and in
    ``si.wi`` before sampling and the sampled ``wo`` after. 4 mirrors pairs, which the measured
    data are not symmetric under; any other value rotates by pi, which they are."""

    def __init__(self, bsdf, garbage: int):
        self.bsdf, self.garbage = bsdf, garbage

    def _signs(self, wi):
        return (wi[0] if self.garbage == 4 else wi[1]), wi[1]

    @staticmethod
    def _flip(v, s):
        neg = [c if math.copysign(1.0, t) < 0 else -c for c, t in zip((v[0], v[1]), s)]
        return MR._mi().Vector3f(neg[0], neg[1], v[2])

    def _si(self, si, s):
        out = MR._mi().SurfaceInteraction3f()
        out.wi = self._flip(si.wi, s)
        return out

    def eval(self, ctx, si, wo):
        s = self._signs(si.wi)
        return self.bsdf.eval(ctx, self._si(si, s), self._flip(wo, s))

    def pdf(self, ctx, si, wo):
        s = self._signs(si.wi)
        return self.bsdf.pdf(ctx, self._si(si, s), self._flip(wo, s))

    def sample(self, ctx, si, sample1, sample2):
        s = self._signs(si.wi)
        bs, w = self.bsdf.sample(ctx, self._si(si, s), sample1, sample2)
        bs.wo = self._flip(bs.wo, s)
        return bs, w


@pytest.mark.parametrize("name", ALL_RGL)
def test_mirror_check_tells_the_garbage_apart(name):
    """:func:`MR._mirrors` flags a plugin that mirrors pairs (``m_reduction`` reading 4) and
    passes one that is right or rotates by pi (any other garbage value), on every shared file."""
    real = MR.load_bsdf(rgl_path(name))
    assert not MR._mirrors(real)
    assert MR._mirrors(GarbageReduction(real, 4))
    assert not MR._mirrors(GarbageReduction(real, 2))


def test_reference_reloads_a_mirroring_plugin(monkeypatch):
    """Mitsuba 3.9.1 leaves ``m_reduction`` uninitialized for isotropic files; once in many CI runs
    a plugin read 4 and mirrored pairs, and the parity tests failed on one file (eval 1.1e-4
    relative off at one pair, sampled directions far apart). A plugin that mirrors is loaded
    again (the rejected one kept alive), and given up on with one line after ``MAX_LOADS``."""
    path = rgl_path("acrylic_felt_purple_rgb")
    real = MR.load_bsdf(path)
    wt, wx = direction_pairs(1000, seed=7)
    clean = MR.eval(path, wt, wx)
    loads = []

    def flaky():                     # the first two loads mirror, the third is right
        loads.append(1)
        return GarbageReduction(real, 4) if len(loads) < 3 else real

    assert MR._load_checked(flaky, lambda b: b, "x.bsdf") is real and len(loads) == 3
    # the emulated plugin gives wrong answers: eval through it misses the parity tolerance
    with monkeypatch.context() as m:
        m.setattr(MR, "load_bsdf", lambda *a, **k: GarbageReduction(real, 4))
        mirrored = MR.eval(path, wt, wx)
    with pytest.raises(AssertionError, match="relative error"):
        check_close(mirrored, clean, "mirrored")
    loads.clear()
    with pytest.raises(MR.ReferenceUnavailable, match=r"^x\.bsdf: .*mirrored direction pairs in 8 loads"):
        MR._load_checked(lambda: loads.append(1) or GarbageReduction(real, 4), lambda b: b, "x.bsdf")
    assert len(loads) == MR.MAX_LOADS == 8
    # through the module: a first load that mirrors is replaced, and eval is the clean one
    MR._measured.cache_clear()
    mi, state = MR._mi(), {"n": 0}
    load_dict = mi.load_dict

    def first_mirrors(d):
        state["n"] += 1
        b = load_dict(d)
        return GarbageReduction(b, 4) if state["n"] == 1 else b

    monkeypatch.setattr(mi, "load_dict", first_mirrors)
    try:
        # the clean load, within the parity tolerance the mirrored one misses: two clean loads
        # may differ at float32 rounding (seen once in CI: 2.8e-7 absolute on values ~0.002)
        check_close(MR.eval(path, wt, wx), clean, "reloaded")
        assert state["n"] == 2
    finally:
        MR._measured.cache_clear()


def test_mirror_check_only_for_isotropic_files(tmp_path, monkeypatch):
    """An anisotropic file may set ``m_reduction`` to 4 on purpose (data over a quarter of the
    azimuths): only isotropic files (``phi_i`` with at most 2 entries) are checked."""
    from fit.formats.tensor_file import read_tensor_file, write_tensor_file

    path = rgl_path("paper_white_rgb")
    assert MR._isotropic(path)
    arrays = {k: np.array(f.data) for k, f in read_tensor_file(path).items()}
    arrays["phi_i"] = np.linspace(0, np.pi / 2, 4, dtype=arrays["phi_i"].dtype)
    write_tensor_file(tmp_path / "aniso.bsdf", arrays)
    assert not MR._isotropic(tmp_path / "aniso.bsdf")
    mi, real = MR._mi(), MR.load_bsdf(path)
    monkeypatch.setattr(mi, "load_dict", lambda d: GarbageReduction(real, 4))
    monkeypatch.setattr(MR, "_isotropic", lambda f: False)
    MR._measured.cache_clear()
    try:
        assert isinstance(MR._measured("any.bsdf", MR.VARIANT), GarbageReduction)   # loaded once, not checked
    finally:
        MR._measured.cache_clear()


def test_per_pair_functions_use_the_scalar_variant_whatever_is_selected():
    """eval / pdf / sample give the scalar RGB variant's values when another variant is selected
    (a test or study that rendered in another variant before), and leave that variant selected."""
    path = rgl_path("paper_white_rgb")
    rng = np.random.default_rng(3)
    wt = rng.normal(size=(6, 3)); wt[:, 2] = np.abs(wt[:, 2]) + 0.3
    wx = rng.normal(size=(6, 3)); wx[:, 2] = np.abs(wx[:, 2]) + 0.3
    wt /= np.linalg.norm(wt, axis=1, keepdims=True)
    wx /= np.linalg.norm(wx, axis=1, keepdims=True)
    xi = rng.random((6, 2))
    mi = MR._mi()
    want = MR.eval(path, wt, wx), MR.pdf(path, wt, wx), MR.sample(path, wt, xi)
    mi.set_variant("scalar_spectral")
    try:
        got = MR.eval(path, wt, wx), MR.pdf(path, wt, wx), MR.sample(path, wt, xi)
        assert mi.variant() == "scalar_spectral"
    finally:
        mi.set_variant(MR.VARIANT)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    for g, w in zip(got[2], want[2]):
        np.testing.assert_array_equal(g, w)


def test_negative_entries_clamped_copy(tmp_path, monkeypatch):
    """Mitsuba does not clamp negative rgb entries (its eval goes negative next to them); the
    clamped copy it is given by default matches our reader, which clamps at load."""
    monkeypatch.setenv("RBRDF_REFERENCE_CACHE", str(tmp_path))
    path = rgl_path("chm_mint_rgb")
    from fit.formats.tensor_file import read_tensor_file

    copy = MR.clamped_copy(path)
    assert copy != path and copy.parent == tmp_path
    src, dst = read_tensor_file(path), read_tensor_file(copy)
    assert set(src) == set(dst)
    for k in src:
        a, b = np.asarray(src[k].data), np.asarray(dst[k].data)
        assert a.dtype == b.dtype and a.shape == b.shape
        if k == "rgb":
            assert (a < 0).sum() == read_rgl(path).n_negative_clamped > 0
            np.testing.assert_array_equal(b, np.maximum(a, 0))
        else:
            np.testing.assert_array_equal(a, b)
    assert MR.clamped_copy(rgl_path("paper_white_rgb")) == rgl_path("paper_white_rgb")
    wt, wx = direction_pairs(1000, seed=2)
    raw = MR.eval(path, wt, wx, clamp_negative=False)
    assert raw.min() < 0
    assert MR.eval(copy, wt, wx).min() >= 0


# --------------------------------------------------------------------------------------------
# (b), (c) the Warp rgl material and its sampler
@pytest.fixture(scope="module")
def warp_rgl():
    """One renderer holding every shared RGL file as an ``rgl`` material (sampler mis-rgl)."""
    from lab import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import IntegratorSpec, MaterialSpec, Scene, ShapeSpec

    paths = {n: rgl_path(n) for n in ALL_RGL}
    mats = {n: MaterialSpec(name=n, type="rgl", file=p, sampler="mis-rgl") for n, p in paths.items()}
    shapes = [ShapeSpec(type="plane", material=n, center=(3.0 * k, 0.0, 0.0), size=(1.0, 1.0))
              for k, n in enumerate(ALL_RGL)]
    sc = Scene(camera=T.top_down_camera(4), integrator=IntegratorSpec(spp=1, max_depth=1, tile_size=4),
               materials=mats, shapes=shapes, lights=[T.constant_env(1.0)], path="<parity>")
    return Renderer(sc), paths


@pytest.mark.parametrize("name", ALL_RGL)
def test_warp_rgl_eval_matches_mitsuba(warp_rgl, name):
    """float32 Warp vs float32 Mitsuba: the same tolerances as the float64 NumPy reader
    (measured: <= 7.4e-5 relative above noise, <= 4.8e-6 of the maximum everywhere)."""
    r, paths = warp_rgl
    view, light = direction_pairs()
    ref = MR.eval(paths[name], view, light)             # si.wi = the view
    got = r.eval_material(name, light, view).astype(np.float64) * light[:, 2:3]
    check_close(got, ref, f"{name} Warp rgl eval * cos(theta_light)")


@pytest.mark.parametrize("name", ALL_RGL)
def test_warp_rgl_pdf_matches_mitsuba(warp_rgl, name):
    """The rgl sampler's density (1/sr of the light direction) vs Mitsuba's pdf, both float32:
    measured <= 5.3e-5 relative where the pdf is above 1e-2 of its maximum and <= 7.2e-6 of the
    maximum everywhere (on another set of 3000 pairs up to 1.6e-4 relative, chm_mint_rgb);
    tolerance 2e-4 relative, 5e-5 absolute."""
    r, paths = warp_rgl
    view, light = direction_pairs(seed=4)
    ref = MR.pdf(paths[name], view, light)
    got = r.pdf_material(name, light, view, sampler="rgl")
    check_close(got, ref, f"{name} Warp rgl pdf", rel_tol=2e-4)


@pytest.mark.parametrize("name", ["cc_ibiza_sunset_rgb", "satin_rosaline_rgb", "paper_white_rgb",
                                  "chm_mint_rgb", "ilm_solo_m_68_rgb"])
def test_warp_rgl_sample_matches_mitsuba(warp_rgl, name):
    """Same uniforms, same sample: the Warp sampler feeds (xi[1], xi[0]) to the luminance warp as
    Mitsuba does, so directions agree to float32 (measured per component: median <= 3.6e-7,
    99th percentile <= 7.8e-6, max 2.9e-5; on another set up to 3.9e-4), validity is identical
    and the pdf at the sample agrees (median <= 1.5e-6, 99th percentile <= 1.5e-4 relative)."""
    r, paths = warp_rgl
    view, _ = direction_pairs(seed=5)
    xi = np.random.default_rng(6).random((len(view), 2))
    wx_m, _, pdf_m = MR.sample(paths[name], view, xi)
    wx_w, weight = r.sample_material(name, view, xi, sampler="rgl")
    valid_m, valid_w = wx_m[:, 2] > 0, weight > 0
    assert (valid_m != valid_w).mean() <= 1e-3, f"validity differs on {(valid_m != valid_w).sum()} samples"
    ok = valid_m & valid_w
    d = np.abs(wx_w - wx_m).max(axis=1)[ok]
    assert np.percentile(d, 99) < 1e-4 and d.max() < 2e-3, (np.percentile(d, 99), d.max())
    rel = np.abs(1.0 / weight[ok] / pdf_m[ok] - 1.0)
    assert np.median(rel) < 1e-5 and np.percentile(rel, 99) < 1e-3, (np.median(rel), np.percentile(rel, 99))


# --------------------------------------------------------------------------------------------
# (d) renders of the reference scene
RES, SPP, PASSES = 64, 128, 16


def render_both(material, seed=0, incident="view", sampler=None):
    """(ours, var ours, mitsuba, var mitsuba, seconds): images and variances of the pixel means
    (``incident``, ``sampler``: our material's roles and sampler, default the reference's)."""
    from warp_rbrdf.renderer import Renderer

    env = data_file(ENVMAP)
    t0 = time.perf_counter()
    im, vm = MR.render_sphere(material, env, SPP, RES, seed=seed, passes=PASSES, return_variance=True)
    scene = MR.sphere_scene(material, env, SPP, RES, seed=seed, incident=incident)
    if sampler is not None:
        scene.materials["obj"].sampler = scene.integrator.sampler = sampler
    r = Renderer(scene)
    io, vo = r.render(return_variance=True)
    return io, vo / SPP, im, vm, time.perf_counter() - t0


def render_stats(material, **kw):
    """Agreement statistics of :func:`render_both`: per-channel relative standard error and
    z-score of the image means, and the per-pixel z-scores fully inside the silhouette."""
    io, vo, im, vm, _ = render_both(material, **kw)
    assert io.shape == im.shape == (RES, RES, 3)
    mo, mm = io.reshape(-1, 3).mean(0), im.reshape(-1, 3).mean(0)
    se = np.sqrt(vo.reshape(-1, 3).sum(0) + vm.reshape(-1, 3).sum(0)) / (RES * RES)
    mask = MR.sphere_mask(RES)
    # the two agree on coverage: no pixel inside the silhouette is black in either
    assert np.all(io[mask].max(-1) > 0) and np.all(im[mask].max(-1) > 0)
    zp = ((io - im) / np.sqrt(vo + vm + 1e-30))[mask]
    return dict(mo=mo, mm=mm, rel_se=se / mm, z=(mo - mm) / se, zp=zp)


def check_render(material, what, **kw):
    st = render_stats(material, **kw)
    # channel means over the image: within 4 standard errors
    assert np.all(st["rel_se"] < 0.015), f"{what}: relative standard error {st['rel_se']} too large"
    assert np.all(np.abs(st["z"]) < 4), f"{what}: channel means {st['mo']} vs Mitsuba {st['mm']} (z = {st['z']})"
    # per pixel, fully inside the silhouette (the image is continuous there): z-scores
    # distributed as noise (measured on 5 seeds: mean within 0.035, std 1.00-1.06, at most
    # 0.08 % beyond 4 sigma)
    zp = st["zp"]
    assert abs(np.mean(zp)) < 0.1, f"{what}: mean per-pixel z {np.mean(zp):.3f}"
    assert 0.8 < np.std(zp) < 1.25, f"{what}: per-pixel z std {np.std(zp):.3f}"
    assert np.mean(np.abs(zp) > 4) < 5e-3, f"{what}: {np.mean(np.abs(zp) > 4):.2%} of pixels beyond 4 sigma"


def test_lambert_sphere_matches_mitsuba():
    """The harness itself (camera, map orientation and lookup, MIS): a Lambert sphere."""
    check_render(("lambert", (0.5, 0.5, 0.5)), "lambert")


@pytest.mark.parametrize("name", ["cc_ibiza_sunset_rgb", "paper_white_rgb"])
def test_rgl_sphere_matches_mitsuba(name):
    """A glossy and a matte RGL file: our rgl material with mis-rgl vs Mitsuba's measured
    plugin with its direct integrator (measured at 4096 spp: channel means within 0.13-0.20 %
    (z <= 1.2) on cc_ibiza_sunset_rgb and 0.02 % on paper_white_rgb)."""
    check_render(rgl_path(name), name)


@pytest.mark.slow
def test_render_check_sees_the_roles():
    """The render comparison can tell the roles apart: the glossy film with the light as the
    tensors' incident direction (``incident = "light"``; sampled with env + cosine since mis-rgl
    needs the view) leaves the noise per pixel far more than with the reference roles and the
    same sampler (measured: per-pixel z std 2.9 vs 1.4, 12 % vs 1.7 % of pixels beyond
    4 sigma; the cosine sample of a glossy lobe is heavy-tailed, hence 1.4). The channel
    means barely move (0.1-0.3 %): the roles show per pixel."""
    path = rgl_path("cc_ibiza_sunset_rgb")
    ref = render_stats(path, incident="view", sampler="mis")["zp"]
    swapped = render_stats(path, incident="light", sampler="mis")["zp"]
    assert np.std(swapped) > 1.5 * np.std(ref), (np.std(swapped), np.std(ref))
    assert np.mean(np.abs(swapped) > 4) > 3 * np.mean(np.abs(ref) > 4) + 0.02


# --------------------------------------------------------------------------------------------
# The shared libLLVM of Mitsuba's LLVM variant: a library that aborts the process is never used
def test_libllvm_probe_contains_an_abort_and_names_it(monkeypatch):
    """A test render that aborts (as Dr.Jit's kernels do inside libLLVM 15: "LLVM ERROR: Cannot
    select ... fmaximum", SIGABRT) is reported in one line and this process goes on."""
    require_mitsuba()
    monkeypatch.setattr(MR, "LIBLLVM_PROBE", "import sys; sys.stderr.write('LLVM ERROR: Cannot select: x\\n')\n"
                                             "import os; os.abort()")
    MR.libllvm_problem.cache_clear()
    try:
        why = MR.libllvm_problem("/any/libLLVM-15.so")
    finally:
        MR.libllvm_problem.cache_clear()
    assert why == "a test render with it failed (signal 6: LLVM ERROR: Cannot select: x)"


def test_libllvm_not_a_library_is_refused(tmp_path, monkeypatch):
    """DRJIT_LIBLLVM_PATH naming a file that is no LLVM: find_libllvm gives None (no other
    library is put in its place) and set_variant refuses in one line naming the variable, while
    the scalar variant stays selected."""
    MR_ = require_mitsuba()
    fake = tmp_path / "libLLVM-19.so"
    fake.write_bytes(b"not a shared library")
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", str(fake))
    try:
        assert MR_.find_libllvm() is None
        with pytest.raises(MR_.ReferenceUnavailable) as e:
            MR_.set_variant(MR_.LLVM_VARIANT)
        msg = str(e.value)
        assert msg.startswith(f"DRJIT_LIBLLVM_PATH={fake}: not usable for Mitsuba's 'llvm_ad_rgb' variant: "
                              "a test render with it failed (exit status 1"), msg
        assert "\n" not in msg
        import mitsuba as mi

        assert mi.variant() == MR_.VARIANT
    finally:
        MR_.libllvm_problem.cache_clear()


def test_find_libllvm_skips_a_library_that_fails(tmp_path, monkeypatch):
    """Candidates are tried in LIBLLVM_CANDIDATES' order and the first whose test render
    passes is taken; none passing gives None and set_variant names the first one's problem."""
    MR_ = require_mitsuba()
    bad, good = tmp_path / "libLLVM-15.so", tmp_path / "libLLVM-19.so"
    bad.write_bytes(b"")
    good.write_bytes(b"")
    monkeypatch.delenv("DRJIT_LIBLLVM_PATH", raising=False)
    monkeypatch.setattr(MR_, "LIBLLVM_CANDIDATES", (str(bad), str(tmp_path / "libLLVM-1[6-9].so")))
    problems = {str(bad): "a test render with it failed (signal 6: LLVM ERROR: Cannot select: y)"}
    monkeypatch.setattr(MR_, "libllvm_problem", lambda p: problems.get(p))
    assert MR_.find_libllvm() == str(good)
    problems[str(good)] = "a test render with it failed (exit status 1: z)"
    assert MR_.find_libllvm() is None
    with pytest.raises(MR_.ReferenceUnavailable, match=r"needs a shared libLLVM that it renders with .*"
                                                       r"; .*libLLVM-15\.so: a test render with it failed "
                                                       r"\(signal 6: LLVM ERROR: Cannot select: y\)$"):
        MR_.set_variant(MR_.LLVM_VARIANT)


def test_llvm_variant_renders_with_the_library_found():
    """find_libllvm's library passes its test render and set_variant selects Mitsuba's LLVM
    variant with it. ``.ci/run`` installs libLLVM 19, so under CI a missing or failing library
    is a failure; locally the test skips without one."""
    MR_ = require_mitsuba()
    lib = MR_.find_libllvm()
    if lib is None:
        missing("no libLLVM that Mitsuba renders with (Debian: apt-get install libllvm19)")
    assert MR_.libllvm_problem(lib) is None
    try:
        assert MR_.set_variant(MR_.LLVM_VARIANT) == MR_.LLVM_VARIANT
    finally:
        MR_.set_variant(MR_.VARIANT)
