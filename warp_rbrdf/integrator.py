"""Direct-lighting / path-tracing integrator: Warp kernels specialised per scene, and the tiled
launch.

What one sample (one of the ``spp`` camera samples of a pixel) does at each path vertex, by the
strategy of the material hit (:data:`warp_rbrdf.registry.STRATEGIES`, stored as
``Materials.combine`` and ``Materials.technique``):

* every directional light: one shadow ray (delta light, always sampled);
* ``COMBINE_LIGHT`` / ``COMBINE_MIS``: one environment sample (hierarchical warp of the
  looked-up luminance x sin theta, :mod:`warp_rbrdf.lights.env_sampling`) with one shadow ray;
* ``COMBINE_BSDF`` / ``COMBINE_MIS``: one BSDF sample from the material's technique
  (:data:`warp_rbrdf.registry.TECHNIQUES`) with one ray; if it escapes, the environment is
  added, weighted by the power heuristic for ``COMBINE_MIS``. The MIS weights use the
  technique's ``pdf``; for a technique whose pdf is exact that is ``1 / weight`` of the sample
  itself, otherwise (``pdf_exact = False``) the technique's ``pdf`` function -- the same
  density in both weights, so they sum to one;
* ``max_depth = 1`` stops there (direct lighting); ``max_depth > 1`` continues the path along
  the BSDF sample (``COMBINE_LIGHT`` draws it only to continue).

The render kernel takes a pixel's samples :data:`warp_rbrdf.lanes.LANES` at a time: their camera
rays and first hits, the first vertex's environment samples and (where the technique has a lane
form) BSDF samples drawn together, then each sample's path as above with those given
(:mod:`warp_rbrdf.lanes`; the same samples, the same image).

The integrator only calls the material and technique interfaces: :func:`make_kernels` receives
the scene's material evaluations and techniques as Warp functions and builds, with closures and
``wp.static`` dispatch, kernels that contain exactly those (a scene compiles only what it uses).
Each kernel is its own Warp module (``module="unique"``), hashed by its code: the same
configuration loads from Warp's kernel cache in milliseconds. Every kernel is compiled for an
ISA level chosen from the CPU's features (``shipped_kernels.render_module_options``:
``-target-cpu x86-64-v4`` with AVX-512, else ``x86-64-v3``; not ``-march=native``), so its
module hash does not depend on the build machine and the default scene's render kernel can ship
compiled, one object per level (:mod:`warp_rbrdf.shipped_kernels`).
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass

import warp as wp

from . import camera as C
from . import fastmath as fmath
from . import geometry as G
from . import sample_patterns as P
from . import lanes as L
from .distribution.lanes import lane_types, lanes_out_type
from .lights.directional import Directional
from .lights.env_map import EnvMap, env_dir_to_uv, env_eval_uv, env_pdf_uv
from .lights.env_lanes import env_lanes_out_type, make_env_sample_lanes
from .lights.env_sampling import env_sample_uv
from .materials.data import Materials
from .registry import COMBINE_BSDF, COMBINE_LIGHT, COMBINE_MIS
from .shipped_kernels import render_module_options


@wp.func
def power_heuristic(pa: float, pb: float) -> float:
    """pa^2 / (pa^2 + pb^2), computed from the ratio so that huge pdfs (a tabulated density
    near theta_l = 0 grows like 1/sin theta) never overflow float32 into inf/inf = NaN."""
    if pa <= 0.0:
        return 0.0
    if pb <= 0.0:
        return 1.0
    if pa >= pb:
        r = pb / pa
        return 1.0 / (1.0 + r * r)
    r = pa / pb
    return r * r / (1.0 + r * r)


@wp.func
def onb_tangent(n: wp.vec3) -> wp.vec3:
    """Tangent of the branchless orthonormal basis of Duff et al. (2017)."""
    sign = wp.where(n[2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return wp.vec3(1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])


@wp.func
def onb_bitangent(n: wp.vec3) -> wp.vec3:
    sign = wp.where(n[2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return wp.vec3(b, sign + n[1] * n[1] * a, -n[1])


@wp.func
def max3(v: wp.vec3) -> float:
    return fmath.fmax(v[0], fmath.fmax(v[1], v[2]))


@G.inline_func
def shading_frame(d: wp.vec3, ng: wp.vec3, ns: wp.vec3):
    """``(ns', T, B, wo)`` at a hit of the ray direction ``d``: the shading normal (the geometric
    one where the shading normal faces away from the view), its tangent and bitangent, and the
    view in that frame."""
    wo_w = -d
    n = ns
    if wp.dot(n, wo_w) <= 1.0e-6:
        n = ng
    T = onb_tangent(n)
    B = onb_bitangent(n)
    return n, T, B, wp.vec3(wp.dot(wo_w, T), wp.dot(wo_w, B), wp.dot(wo_w, n))


# --------------------------------------------------------------------------------------------
# Dispatch over the scene's materials and techniques
# --------------------------------------------------------------------------------------------
# Each dispatcher is a chain of closures, one link per entry, each testing one code captured with
# ``wp.static`` (a static expression that does not depend on a loop variable: Warp resolves it
# when the function is declared and hashes it with the module; a ``for i in range(wp.static(n))``
# loop over a list of codes was measured to reuse a kernel compiled for other codes of the same
# length, Warp 1.19).
@wp.func
def _no_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    return wp.vec3(0.0)


def make_bsdf_eval(kinds):
    """``bsdf_eval(mats, m, wi, wo) -> vec3`` over ``kinds``: (code, eval function) pairs,
    selected by ``mats.kind[m]``."""
    if not kinds:
        return _no_eval
    code, func = kinds[0]
    rest = make_bsdf_eval(kinds[1:])

    @G.inline_func
    def bsdf_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
        if mats.kind[m] == wp.static(int(code)):
            return wp.static(func)(mats, m, wi, wo)
        return wp.static(rest)(mats, m, wi, wo)

    return bsdf_eval


@wp.func
def _no_sample(mats: Materials, m: int, t: int, wo: wp.vec3, xi: wp.vec2) -> wp.vec4:
    return wp.vec4(0.0)


@wp.func
def _no_pdf(mats: Materials, m: int, t: int, wi: wp.vec3, wo: wp.vec3) -> float:
    return 0.0


@wp.func
def _no_mis_pdf(mats: Materials, m: int, t: int, wi: wp.vec3, wo: wp.vec3, weight: float) -> float:
    return 1.0 / weight


@wp.func
def _no_exact(t: int) -> bool:
    return True


def make_pdf_exact(techniques):
    """``bsdf_pdf_exact(t) -> bool``: whether technique ``t``'s pdf is ``1 / weight`` of its
    samples (``pdf_exact``), over ``techniques`` as for :func:`make_bsdf_sampling`."""
    if not techniques:
        return _no_exact
    code, _, _, exact = techniques[0]
    code, exact = int(code), bool(exact)
    rest = make_pdf_exact(techniques[1:])

    @G.inline_func
    def bsdf_pdf_exact(t: int) -> bool:
        if t == wp.static(code):
            return wp.static(exact)
        return wp.static(rest)(t)

    return bsdf_pdf_exact


def make_bsdf_sampling(techniques):
    """``(bsdf_sample, bsdf_pdf, bsdf_mis_pdf)`` over ``techniques``: (code, sample, pdf,
    pdf_exact) tuples, selected by the technique code ``t``. ``bsdf_mis_pdf(mats, m, t, wi, wo,
    weight)`` is the density MIS uses for a BSDF sample drawn with ``weight``: ``1 / weight``
    when the technique's pdf is exact, its ``pdf`` otherwise."""
    if not techniques:
        return _no_sample, _no_pdf, _no_mis_pdf
    code, sample, pdf, exact = techniques[0]
    code, exact = int(code), bool(exact)
    rest_sample, rest_pdf, rest_mis_pdf = make_bsdf_sampling(techniques[1:])

    @G.inline_func
    def bsdf_sample(mats: Materials, m: int, t: int, wo: wp.vec3, xi: wp.vec2) -> wp.vec4:
        if t == wp.static(code):
            return wp.static(sample)(mats, m, wo, xi)
        return wp.static(rest_sample)(mats, m, t, wo, xi)

    @G.inline_func
    def bsdf_pdf(mats: Materials, m: int, t: int, wi: wp.vec3, wo: wp.vec3) -> float:
        if t == wp.static(code):
            return wp.static(pdf)(mats, m, wi, wo)
        return wp.static(rest_pdf)(mats, m, t, wi, wo)

    @G.inline_func
    def bsdf_mis_pdf(mats: Materials, m: int, t: int, wi: wp.vec3, wo: wp.vec3, weight: float) -> float:
        if t == wp.static(code):
            if wp.static(exact):
                return 1.0 / weight
            return wp.static(pdf)(mats, m, wi, wo)
        return wp.static(rest_mis_pdf)(mats, m, t, wi, wo, weight)

    return bsdf_sample, bsdf_pdf, bsdf_mis_pdf


@wp.func
def _no_eval_pdf(mats: Materials, m: int, t: int, wi: wp.vec3, wo: wp.vec3):
    return wp.vec3(0.0), 0.0, 0


def make_fused(techniques):
    """``(bsdf_sample_f, bsdf_eval_pdf)`` over ``techniques`` (tuples as for
    :func:`make_bsdf_sampling`, optionally with two more entries: the technique's fused
    ``sample_f(mats, m, wo, xi) -> (vec4, vec3 f, 1)`` and ``eval_pdf(mats, m, wi, wo) -> (vec3
    f, float pdf, 0 | 1)``, or None; :func:`warp_rbrdf.materials.rgl.kernel_fused`).

    ``bsdf_sample_f(mats, m, t, wo, xi) -> (sample, f, has_f)``: the technique's sample, with
    f_r at its direction where the technique computes it on the way (``has_f`` 1), else
    ``has_f`` 0 (the caller evaluates the material). ``bsdf_eval_pdf(mats, m, t, wi, wo) -> (f,
    pdf, has)``: f_r and the technique's pdf at one pair where it shares their work (``has``
    1), else ``has`` 0."""
    sample, _, _ = make_bsdf_sampling([t[:4] for t in techniques])
    fused = [(int(t[0]), t[4], t[5]) for t in techniques if len(t) > 5 and t[4] is not None]
    return _sample_f_chain(fused, sample), _eval_pdf_chain(fused)


def _sample_f_chain(fused, sample):
    if not fused:
        @G.inline_func
        def bsdf_sample_f0(mats: Materials, m: int, t: int, wo: wp.vec3, xi: wp.vec2):
            return wp.static(sample)(mats, m, t, wo, xi), wp.vec3(0.0), 0

        return bsdf_sample_f0
    code, sample_f, _ = fused[0]
    rest = _sample_f_chain(fused[1:], sample)

    @G.inline_func
    def bsdf_sample_f(mats: Materials, m: int, t: int, wo: wp.vec3, xi: wp.vec2):
        if t == wp.static(code):
            return wp.static(sample_f)(mats, m, wo, xi)
        return wp.static(rest)(mats, m, t, wo, xi)

    return bsdf_sample_f


def _eval_pdf_chain(fused):
    if not fused:
        return _no_eval_pdf
    code, _, eval_pdf = fused[0]
    rest = _eval_pdf_chain(fused[1:])

    @G.inline_func
    def bsdf_eval_pdf(mats: Materials, m: int, t: int, wi: wp.vec3, wo: wp.vec3):
        if t == wp.static(code):
            return wp.static(eval_pdf)(mats, m, wi, wo)
        return wp.static(rest)(mats, m, t, wi, wo)

    return bsdf_eval_pdf


# --------------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------------
@dataclass
class Kernels:
    render_tile: object
    eval_bsdf: object
    sample_bsdf: object
    pdf_bsdf: object


def make_kernels(kinds, techniques, has_mesh: bool = True, has_spheres: bool = True,
                 lanes: int | None = None) -> Kernels:
    """The scene's kernels: ``kinds`` as for :func:`make_bsdf_eval`, ``techniques`` as for
    :func:`make_bsdf_sampling` (a seventh entry, optional: the technique's ``kernel_lanes``
    factory, or None; :func:`make_lanes_sampling`); ``has_mesh`` / ``has_spheres``: whether the
    scene's :class:`~warp_rbrdf.geometry.SceneGeometry` has triangles / analytic spheres (the ray
    queries of :func:`warp_rbrdf.geometry.make_tracer` test only those); ``lanes``: the samples
    of a pixel the render kernel advances together (0 or 1: one at a time; None:
    :data:`warp_rbrdf.lanes.LANES`; module docstring)."""
    lanes = L.LANES if lanes is None else int(lanes)
    closest_hit, any_hit = G.make_tracer(has_mesh, has_spheres)
    bsdf_eval = make_bsdf_eval(kinds)
    base = [t[:4] for t in techniques]
    bsdf_sample, bsdf_pdf, _ = make_bsdf_sampling(base)
    bsdf_pdf_exact = make_pdf_exact(base)
    bsdf_sample_f, bsdf_eval_pdf = make_fused(techniques)
    sample_2d = P.sample_2d
    lanes_on = lanes > 1
    K = lanes if lanes_on else 1      # the lanes' types do not enter a kernel without them
    lane_techniques = [(int(t[0]), t[6](K)) for t in techniques
                       if lanes_on and len(t) > 6 and t[6] is not None]
    vf, vi = lane_types(K)
    out_t = lanes_out_type(K)
    state_t = wp.types.matrix(shape=(L.N_LANE_STATE, K), dtype=float)
    lanes_sample_f, is_lane_technique = L.make_lanes_sampling(lane_techniques, K)
    env_out_t = env_lanes_out_type(K)
    env_lanes = make_env_sample_lanes(K)

    @G.inline_func
    def radiance_sample(geo: G.SceneGeometry, cam: C.Camera, env: EnvMap, dl: Directional, mats: Materials,
                        pseed: wp.uint32, s: int, spp: int, pattern: int, max_depth: int,
                        hide_env: int, eps: float, px: int, py: int, pre: int, pre_d: wp.vec3,
                        pre_hit: wp.vec3, pre_ng: wp.vec3, pre_ns: wp.vec3, pre_bs: wp.vec4,
                        pre_f: wp.vec3, pre_ls: wp.vec4, pre_luv: wp.vec2) -> wp.vec3:
        # what the lanes of render_tile computed for this sample (``pre``, bits of
        # warp_rbrdf.lanes): PRE_HIT the camera ray ``pre_d`` and its closest hit (``pre_hit`` =
        # (hit, t, material), normals ``pre_ng``, ``pre_ns``); PRE_BSDF the first vertex's BSDF
        # sample ``pre_bs``, PRE_F with f_r there ``pre_f``; PRE_ENV its environment sample
        # ``pre_ls``, ``pre_luv``
        Lsum = wp.vec3(0.0)
        if max_depth < 1:
            return Lsum
        d = pre_d
        if wp.static(lanes_on):
            if (pre & L.PRE_HIT) == 0:
                j = sample_2d(pattern, pseed, s, spp, 0)
                d = C.camera_ray(cam, float(px) + j[0], float(py) + j[1])
        else:
            j = sample_2d(pattern, pseed, s, spp, 0)
            d = C.camera_ray(cam, float(px) + j[0], float(py) + j[1])
        o = cam.origin
        thr = wp.vec3(1.0)
        # how to weight the environment when the ray escapes
        mode = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
        prev_pdf = float(0.0)  # noqa: UP018 - a Warp loop-carried variable
        depth = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
        # 1: the next ray is the last BSDF ray, only tested for escaping (any hit)
        shadow = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
        hit = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
        t = float(0.0)  # noqa: UP018 - a Warp loop-carried variable
        ng = wp.vec3(0.0)
        ns = wp.vec3(0.0)
        m = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
        # one call site per material / environment function (each is inlined where it is
        # called: fewer sites compile faster, docs/architecture.md)
        while True:
            if shadow == 1:
                hit = wp.where(any_hit(geo, o, d, 1.0e30), 1, 0)
            elif wp.static(lanes_on):
                if depth == 0 and (pre & L.PRE_HIT) != 0:
                    hit = int(pre_hit[0])
                    t = pre_hit[1]
                    m = int(pre_hit[2])
                    ng = pre_ng
                    ns = pre_ns
                else:
                    hit, t, ng, ns, m = closest_hit(geo, o, d)
            else:
                hit, t, ng, ns, m = closest_hit(geo, o, d)
            if hit == 0:
                if mode == 1 or mode == 2 or (mode == 0 and hide_env == 0):
                    uv = env_dir_to_uv(env, d)   # once for the radiance and the pdf
                    w = float(1.0)  # noqa: UP018 - a Warp loop-carried variable
                    if mode == 2:
                        w = power_heuristic(prev_pdf, env_pdf_uv(env, uv))
                    Lsum = Lsum + wp.cw_mul(thr, env_eval_uv(env, uv)) * w
                break
            if shadow == 1:
                break
            p = o + d * t
            ns, T, B, wo = shading_frame(d, ng, ns)
            comb = mats.combine[m]
            tech = mats.technique[m]
            org = p + ng * (eps * (1.0 + fmath.fmax(wp.abs(p[0]), fmath.fmax(wp.abs(p[1]), wp.abs(p[2])))))

            # One loop over every directional light (delta: always one shadow ray each), one
            # environment sample, then the BSDF sample; each calls the material's evaluation and
            # pdf at one site (the compile time follows the number of inlined copies).
            dim = 1 + 2 * depth
            last = depth + 1 >= max_depth
            n_dl = dl.count
            n_light = n_dl
            if comb != COMBINE_BSDF and env.can_sample == 1:
                n_light = n_dl + 1
            n_try = n_light + 1
            if comb == COMBINE_LIGHT and last:
                n_try = n_light       # the path ends: no BSDF sample
            go_on = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
            wiw = wp.vec3(0.0)
            for li in range(n_try):
                wi = wp.vec3(0.0)
                wl = wp.vec3(0.0)
                luv = wp.vec2(0.0)   # the environment sample's map coordinates
                pl = float(1.0)  # noqa: UP018 - a Warp loop-carried variable
                wb = float(0.0)  # noqa: UP018 - a Warp loop-carried variable
                ok = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
                if li < n_dl:
                    wl = dl.to_light[li]
                elif li < n_light:
                    if wp.static(lanes_on):
                        ls = pre_ls
                        luv = pre_luv
                        if depth != 0 or (pre & L.PRE_ENV) == 0:
                            ls, luv = env_sample_uv(env, sample_2d(pattern, pseed, s, spp, dim))
                    else:
                        ls, luv = env_sample_uv(env, sample_2d(pattern, pseed, s, spp, dim))
                    wl = wp.vec3(ls[0], ls[1], ls[2])
                    pl = ls[3]
                fv = wp.vec3(0.0)
                pf = float(0.0)  # noqa: UP018 - a Warp loop-carried variable
                has_f = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
                if li < n_light:
                    if pl > 0.0 and wp.dot(wl, ng) > 0.0:
                        wi = wp.vec3(wp.dot(wl, T), wp.dot(wl, B), wp.dot(wl, ns))
                        if wi[2] > 0.0:
                            ok = 1
                            if li >= n_dl and comb == COMBINE_MIS:
                                # f and the MIS pdf together where the technique shares their work
                                fv, pf, has_f = bsdf_eval_pdf(mats, m, tech, wi, wo)
                else:
                    bs = pre_bs
                    if wp.static(lanes_on):
                        fv = pre_f
                        has_f = wp.where((pre & L.PRE_F) != 0, 1, 0)
                        if depth != 0 or (pre & L.PRE_BSDF) == 0:
                            bs, fv, has_f = bsdf_sample_f(mats, m, tech, wo, sample_2d(pattern, pseed, s, spp, dim + 1))
                    else:
                        bs, fv, has_f = bsdf_sample_f(mats, m, tech, wo, sample_2d(pattern, pseed, s, spp, dim + 1))
                    wi = wp.vec3(bs[0], bs[1], bs[2])
                    wb = bs[3]
                    if wb > 0.0 and wi[2] > 0.0:
                        wiw = T * wi[0] + B * wi[1] + ns * wi[2]
                        if wp.dot(wiw, ng) > 0.0:
                            ok = 1
                if ok == 1:
                    if has_f == 0:
                        fv = bsdf_eval(mats, m, wi, wo)
                    want_pdf = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
                    if li < n_light:
                        if max3(fv) > 0.0:  # noqa: SIM102 - Warp evaluates both sides of `and`
                            if not any_hit(geo, org, wl, 1.0e30):
                                ok = 2
                                if li >= n_dl and comb == COMBINE_MIS and has_f == 0:
                                    want_pdf = 1
                    else:
                        thr = wp.cw_mul(thr, fv) * (wi[2] * wb)
                        if max3(thr) > 0.0:
                            ok = 2
                            if comb == COMBINE_MIS and not bsdf_pdf_exact(tech):
                                want_pdf = 1
                    pb = pf
                    if want_pdf == 1:
                        pb = bsdf_pdf(mats, m, tech, wi, wo)
                    if ok == 2:
                        if li < n_dl:
                            Lsum = Lsum + wp.cw_mul(thr, wp.cw_mul(fv, dl.irradiance[li])) * wi[2]
                        elif li < n_light:
                            w = float(1.0)  # noqa: UP018 - a Warp loop-carried variable
                            if comb == COMBINE_MIS:
                                w = power_heuristic(pl, pb)
                            Lsum = Lsum + wp.cw_mul(thr, wp.cw_mul(fv, env_eval_uv(env, luv))) * (wi[2] * w / pl)
                        else:
                            go_on = 1
                            mode = 1
                            if comb == COMBINE_LIGHT:
                                mode = 3
                            elif comb == COMBINE_MIS and env.can_sample == 1:
                                mode = 2
                            # the density MIS uses for the BSDF sample: 1 / weight where the
                            # technique's pdf is exact, its pdf function otherwise
                            prev_pdf = 1.0 / wb
                            if want_pdf == 1:
                                prev_pdf = pb
            if go_on == 0:
                break
            if last:
                if mode == 3 or env.present == 0:
                    break
                shadow = 1   # the last ray: only whether it escapes
            o = org
            d = wiw
            depth = depth + 1
        return Lsum

    @wp.kernel(module="unique", enable_backward=False, module_options=render_module_options())
    def render_tile(geo: G.SceneGeometry, cam: C.Camera, env: EnvMap, dl: Directional, mats: Materials,
                    spp: int, seed: int, pattern: int, max_depth: int, hide_env: int, eps: float,
                    x0: int, y0: int, tile_w: int,
                    out_mean: wp.array(dtype=wp.vec3), out_sq: wp.array(dtype=wp.vec3)):
        tid = wp.tid()
        px = x0 + tid % tile_w
        py = y0 + tid // tile_w
        if px >= cam.width or py >= cam.height:
            return
        pix = py * cam.width + px
        pseed = P.pixel_seed(seed, pix)
        acc = wp.vec3(0.0)
        acc2 = wp.vec3(0.0)
        if wp.static(lanes_on):
            # K samples at a time: their camera rays and first hits, then the first vertex's
            # environment samples and the BSDF samples of the lanes whose technique has a lane
            # form (one material), each drawn for all lanes together, then each sample's radiance
            # as below, given those
            for g in range((spp + K - 1) // K):
                st = state_t()
                wox = vf()
                woy = vf()
                woz = vf()
                xi0 = vf()
                xi1 = vf()
                on = vi()
                exi0 = vf()
                exi1 = vf()
                env_on = vi()
                any_env = int(0)  # noqa: UP018, RUF046 - a Warp variable assigned in a branch
                lane_m = int(-1)  # noqa: UP018, RUF046 - a Warp variable assigned in a branch
                same = int(1)  # noqa: UP018, RUF046 - a Warp variable assigned in a branch
                i = int(0)  # noqa: UP018, RUF046 - a Warp loop variable
                while i < K:
                    s = g * K + i
                    if s < spp and max_depth >= 1:
                        j = sample_2d(pattern, pseed, s, spp, 0)
                        d = C.camera_ray(cam, float(px) + j[0], float(py) + j[1])
                        hit, t, ng, ns, m = closest_hit(geo, cam.origin, d)
                        for c in range(3):
                            st[L.LS_D + c, i] = d[c]
                            st[L.LS_NG + c, i] = ng[c]
                            st[L.LS_NS + c, i] = ns[c]
                        st[L.LS_HIT, i] = float(hit)
                        st[L.LS_T, i] = t
                        st[L.LS_M, i] = float(m)
                        if hit != 0:
                            if env.can_sample == 1 and mats.combine[m] != COMBINE_BSDF:
                                exi = sample_2d(pattern, pseed, s, spp, L.FIRST_LIGHT_DIM)
                                exi0[i] = exi[0]
                                exi1[i] = exi[1]
                                env_on[i] = 1
                                any_env = 1
                            if is_lane_technique(mats.technique[m]):
                                _n, _T, _B, wo = shading_frame(d, ng, ns)
                                xi = sample_2d(pattern, pseed, s, spp, L.FIRST_BSDF_DIM)
                                wox[i] = wo[0]
                                woy[i] = wo[1]
                                woz[i] = wo[2]
                                xi0[i] = xi[0]
                                xi1[i] = xi[1]
                                on[i] = 1
                                if lane_m < 0:
                                    lane_m = m
                                elif lane_m != m:
                                    same = 0
                    i += 1
                drawn = lane_m >= 0 and same == 1
                out = out_t()
                if drawn:
                    out = lanes_sample_f(mats, lane_m, mats.technique[lane_m], wox, woy, woz, xi0, xi1, on)
                eout = env_out_t()
                if any_env == 1:
                    eout = env_lanes(env, exi0, exi1, env_on)
                i = int(0)  # noqa: UP018, RUF046 - a Warp loop variable
                while i < K:
                    s = g * K + i
                    if s < spp:
                        pre = int(L.PRE_HIT)
                        if drawn and on[i] != 0:
                            pre = pre | L.PRE_BSDF
                            if out[7, i] != 0.0:
                                pre = pre | L.PRE_F
                        if env_on[i] != 0:
                            pre = pre | L.PRE_ENV
                        v = radiance_sample(geo, cam, env, dl, mats, pseed, s, spp, pattern, max_depth, hide_env,
                                            eps, px, py, pre, wp.vec3(st[L.LS_D, i], st[L.LS_D + 1, i], st[L.LS_D + 2, i]),
                                            wp.vec3(st[L.LS_HIT, i], st[L.LS_T, i], st[L.LS_M, i]),
                                            wp.vec3(st[L.LS_NG, i], st[L.LS_NG + 1, i], st[L.LS_NG + 2, i]),
                                            wp.vec3(st[L.LS_NS, i], st[L.LS_NS + 1, i], st[L.LS_NS + 2, i]),
                                            wp.vec4(out[0, i], out[1, i], out[2, i], out[3, i]),
                                            wp.vec3(out[4, i], out[5, i], out[6, i]),
                                            wp.vec4(eout[0, i], eout[1, i], eout[2, i], eout[3, i]),
                                            wp.vec2(eout[4, i], eout[5, i]))
                        acc = acc + v
                        acc2 = acc2 + wp.cw_mul(v, v)
                    i += 1
        else:
            for s in range(spp):
                v = radiance_sample(geo, cam, env, dl, mats, pseed, s, spp, pattern, max_depth, hide_env, eps,
                                    px, py, 0, wp.vec3(0.0), wp.vec3(0.0), wp.vec3(0.0), wp.vec3(0.0), wp.vec4(0.0),
                                    wp.vec3(0.0), wp.vec4(0.0), wp.vec2(0.0))
                acc = acc + v
                acc2 = acc2 + wp.cw_mul(v, v)
        inv = 1.0 / float(spp)
        out_mean[pix] = acc * inv
        out_sq[pix] = acc2 * inv

    @wp.kernel(module="unique", enable_backward=False, module_options=render_module_options())
    def eval_bsdf(mats: Materials, m: int, wi: wp.array(dtype=wp.vec3), wo: wp.array(dtype=wp.vec3),
                  out: wp.array(dtype=wp.vec3)):
        """Material ``m`` at local direction pairs (tests, studies)."""
        i = wp.tid()
        out[i] = bsdf_eval(mats, m, wi[i], wo[i])

    @wp.kernel(module="unique", enable_backward=False, module_options=render_module_options())
    def sample_bsdf(mats: Materials, m: int, t: int, wo: wp.array(dtype=wp.vec3),
                    xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4)):
        """Technique ``t`` of material ``m`` at (wo, xi) -> (wi, weight) (tests, benchmarks)."""
        i = wp.tid()
        out[i] = bsdf_sample(mats, m, t, wo[i], xi[i])

    @wp.kernel(module="unique", enable_backward=False, module_options=render_module_options())
    def pdf_bsdf(mats: Materials, m: int, t: int, wi: wp.array(dtype=wp.vec3),
                 wo: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
        """Density (1/sr) the MIS weights use for technique ``t`` of material ``m`` (tests)."""
        i = wp.tid()
        out[i] = bsdf_pdf(mats, m, t, wi[i], wo[i])

    return Kernels(render_tile, eval_bsdf, sample_bsdf, pdf_bsdf)


# --------------------------------------------------------------------------------------------
# Tiled launch
# --------------------------------------------------------------------------------------------
def tiles(width: int, height: int, size: int):
    """(x0, y0, w, h) tiles covering the image, row-major."""
    return [(x, y, min(size, width - x), min(size, height - y))
            for y in range(0, height, size) for x in range(0, width, size)]


def launch_tiles(launch_one, tile_list, threads: int, progress=None):
    """Run ``launch_one(tile)`` for every tile on ``threads`` threads (Warp releases the GIL)."""
    if threads <= 1 or len(tile_list) <= 1:
        for t in tile_list:
            launch_one(t)
            if progress is not None:
                progress.update(1)
        return
    with ThreadPoolExecutor(max_workers=threads) as ex:
        futures = [ex.submit(launch_one, t) for t in tile_list]
        try:
            for f in as_completed(futures):
                f.result()
                if progress is not None:
                    progress.update(1)
        except BaseException:   # Ctrl-C or a failed tile: drop the queued tiles, don't render them
            ex.shutdown(wait=False, cancel_futures=True)
            raise
