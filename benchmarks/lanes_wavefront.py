"""The ``wavefront`` variant of the K-lane prototype (:mod:`benchmarks.lanes_prototype`): the
scalar kernel's camera sample (:func:`benchmarks.lanes_kernels.make_scalar_kernel`, the same
production functions in the same order) cut into breadth-first stages, one Warp kernel per
stage over every camera sample of a tile, the state between stages in arrays:

1. ``camera``: ray, hit, frame: per sample the normal, the local view and the hit flag;
2. ``env``: the environment sample (2-D warp, f_r and the BSDF pdf there, shadow ray, MIS):
   its contribution;
3. ``bsdf``: the BSDF sample (the two warps, f_r, escape ray, the map's radiance and pdf, MIS),
   added to it;
4. ``gather``: per pixel the mean over its samples, in sample order.

A stage's kernel is again Warp's scalar loop over its threads, but a short one: consecutive
samples are independent, so the core can overlap one sample's dependent loads (the binary
searches) with the next one's, as far as its reorder window reaches; what it costs is the state
written and read between stages. The samples of a pixel are consecutive threads (thread
``p * spp + s``), so neighbours share the view and the tables' rows. Each sample computes what
the scalar kernel computes, so the image is the scalar kernel's (sums in the same order).

:class:`WavefrontRenderer` is the variant's "kernel" for the prototype's driver: one call per
tile, with scratch arrays per worker thread.
"""
import threading
import time

import warp as wp

from warp_rbrdf.distribution import pc2d_pdf, pc2d_sample
from warp_rbrdf.materials.data import Materials

from .lanes_scene import (
    Env,
    View,
    bitangent,
    camera_hit,
    env_direction,
    env_lookup,
    env_uv,
    escapes,
    origin,
    power,
    sample_key,
    solid_angle_pdf,
    tangent,
    to_local,
    uniform,
)
from .lanes_shading import T


def make_stage_kernels(options: dict):
    """``(camera, env, bsdf, gather)``: the four stage kernels (module ``options``)."""

    @wp.kernel(module="unique", enable_backward=False, module_options=options)
    def camera(view: View, x0: int, y0: int, tile_w: int, hit: wp.array(dtype=int),
               normal: wp.array(dtype=wp.vec3), wo_local: wp.array(dtype=wp.vec3)):
        tid = wp.tid()
        p = tid // view.spp
        px = x0 + p % tile_w
        py = y0 + p // tile_w
        hit[tid] = 0
        if px >= view.res or py >= view.res:
            return
        key = sample_key(view, py * view.res + px, tid % view.spp)
        h, n, wo_w = camera_hit(view, px, py, key)
        if h == 0.0:
            return
        hit[tid] = 1
        normal[tid] = n
        wo_local[tid] = to_local(n, wo_w)

    @wp.kernel(module="unique", enable_backward=False, module_options=options)
    def env_stage(mats: Materials, env: Env, view: View, x0: int, y0: int, tile_w: int,
                  hit: wp.array(dtype=int), normal: wp.array(dtype=wp.vec3), wo_local: wp.array(dtype=wp.vec3),
                  radiance: wp.array(dtype=wp.vec3)):
        tid = wp.tid()
        L = wp.vec3(0.0)
        if hit[tid] != 0:
            p = tid // view.spp
            key = sample_key(view, (y0 + p // tile_w) * view.res + x0 + p % tile_w, tid % view.spp)
            n = normal[tid]
            wo = wo_local[tid]
            org = origin(n)
            x, y, pdf_uv = pc2d_sample(env.marg, 0, env.cond, 0, env.h, env.w, uniform(key, 2), uniform(key, 3))
            dl = env_direction(x, y)
            wl = wp.vec3(dl[0], dl[1], dl[2])
            pl = solid_angle_pdf(pdf_uv, dl[3])
            if pl > 0.0 and wp.dot(wl, n) > 0.0:
                wi = to_local(n, wl)
                if wi[2] > 0.0:
                    f, pb, _has = T.eval_pdf(mats, 0, wi, wo)
                    if wp.max(f[0], wp.max(f[1], f[2])) > 0.0:
                        if escapes(org, wl):
                            L = L + wp.cw_mul(f, env_lookup(env, x, y)) * (wi[2] * power(pl, pb) / pl)
        radiance[tid] = L

    @wp.kernel(module="unique", enable_backward=False, module_options=options)
    def bsdf_stage(mats: Materials, env: Env, view: View, x0: int, y0: int, tile_w: int,
                   hit: wp.array(dtype=int), normal: wp.array(dtype=wp.vec3), wo_local: wp.array(dtype=wp.vec3),
                   radiance: wp.array(dtype=wp.vec3)):
        tid = wp.tid()
        if hit[tid] == 0:
            return
        p = tid // view.spp
        key = sample_key(view, (y0 + p // tile_w) * view.res + x0 + p % tile_w, tid % view.spp)
        n = normal[tid]
        wo = wo_local[tid]
        org = origin(n)
        L = radiance[tid]
        bs, fb, _hf = T.sample_f(mats, 0, wo, wp.vec2(uniform(key, 4), uniform(key, 5)))
        wi = wp.vec3(bs[0], bs[1], bs[2])
        wb = bs[3]
        if wb > 0.0 and wi[2] > 0.0:
            wiw = tangent(n) * wi[0] + bitangent(n) * wi[1] + n * wi[2]
            if wp.dot(wiw, n) > 0.0:
                thr = fb * (wi[2] * wb)
                if wp.max(thr[0], wp.max(thr[1], thr[2])) > 0.0:
                    if escapes(org, wiw):
                        uvs = env_uv(wiw)
                        pe = solid_angle_pdf(pc2d_pdf(env.marg, 0, env.cond, 0, env.h, env.w, uvs[0], uvs[1]),
                                             uvs[2])
                        L = L + wp.cw_mul(thr, env_lookup(env, uvs[0], uvs[1])) * power(1.0 / wb, pe)
                        radiance[tid] = L

    @wp.kernel(module="unique", enable_backward=False, module_options=options)
    def gather(view: View, x0: int, y0: int, tile_w: int, radiance: wp.array(dtype=wp.vec3),
               out: wp.array(dtype=wp.vec3)):
        p = wp.tid()
        px = x0 + p % tile_w
        py = y0 + p // tile_w
        if px >= view.res or py >= view.res:
            return
        acc = wp.vec3(0.0)
        for s in range(view.spp):
            acc = acc + radiance[p * view.spp + s]
        out[py * view.res + px] = acc / float(view.spp)

    return camera, env_stage, bsdf_stage, gather


class WavefrontRenderer:
    """The ``wavefront`` variant as the driver calls a kernel: ``launch(mats, env, view, x0,
    y0, tile_w, tile_h, out)`` renders one tile through the four stages; each worker thread has
    its own scratch arrays (sized for the largest tile of ``spp`` samples per pixel).
    ``stage_seconds``: CPU seconds of the launching threads per stage, summed over every call
    (:data:`STAGES`)."""

    STAGES = ("camera", "env", "bsdf", "gather")

    def __init__(self, options: dict, tile: int):
        self.kernels = make_stage_kernels(options)
        self.tile = tile
        self._local = threading.local()
        self._lock = threading.Lock()
        self.stage_seconds = dict.fromkeys(self.STAGES, 0.0)

    def _scratch(self, n: int):
        s = getattr(self._local, "arrays", None)
        if s is None or s[0].shape[0] < n:
            s = (wp.zeros(n, dtype=int), wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=wp.vec3),
                 wp.zeros(n, dtype=wp.vec3))
            self._local.arrays = s
        return s

    def launch(self, mats, env, view, x0: int, y0: int, tile_w: int, tile_h: int, out):
        camera, env_stage, bsdf_stage, gather = self.kernels
        n = tile_w * tile_h * view.spp
        hit, normal, wo, radiance = self._scratch(self.tile * self.tile * view.spp)
        launches = ((camera, n, [view, x0, y0, tile_w, hit, normal, wo]),
                    (env_stage, n, [mats, env, view, x0, y0, tile_w, hit, normal, wo, radiance]),
                    (bsdf_stage, n, [mats, env, view, x0, y0, tile_w, hit, normal, wo, radiance]),
                    (gather, tile_w * tile_h, [view, x0, y0, tile_w, radiance, out]))
        spent = []
        for kernel, dim, inputs in launches:
            c0 = time.thread_time()
            wp.launch(kernel, dim=dim, inputs=inputs)
            spent.append(time.thread_time() - c0)
        with self._lock:
            for name, sec in zip(self.STAGES, spent):
                self.stage_seconds[name] += sec
