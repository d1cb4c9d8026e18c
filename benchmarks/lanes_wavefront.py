"""The ``wavefront`` variant of the K-lane prototype (:mod:`benchmarks.lanes_prototype`): the
scalar kernel's camera sample (:func:`benchmarks.lanes_kernels.make_scalar_kernel`: its
:func:`~benchmarks.lanes_kernels.scalar_env_light` and
:func:`~benchmarks.lanes_kernels.scalar_bsdf_light`, in the same order) cut into breadth-first
stages, one Warp kernel per stage over every camera sample of a tile, the state between stages
in arrays:

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

from warp_rbrdf.materials.data import Materials

from .lanes_kernels import scalar_bsdf_light, scalar_env_light
from .lanes_scene import Env, View, camera_hit, sample_key, to_local


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
            L = scalar_env_light(mats, env, normal[tid], wo_local[tid], key, L)
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
        radiance[tid] = scalar_bsdf_light(mats, env, normal[tid], wo_local[tid], key, radiance[tid])

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
