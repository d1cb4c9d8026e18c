"""Per-pixel geometry of the studies' camera rays, from n x n sub-pixel rays through the
renderer's ray queries (warp_rbrdf.geometry) and camera convention: object coverage (the fraction of rays that hit a shape:
the mask of the studies' error metrics) and the view angle theta_o (the comparison's bins)."""
from __future__ import annotations

import numpy as np
import warp as wp

from warp_rbrdf import camera as C
from warp_rbrdf import geometry as G


_KERNELS = {}


def _pixel_hits_kernel(has_mesh: bool, has_spheres: bool):
    """The kernel below for a scene with (or without) triangles and analytic spheres."""
    key = (bool(has_mesh), bool(has_spheres))
    if key in _KERNELS:
        return _KERNELS[key]
    closest_hit, _ = G.make_tracer(*key)

    @wp.kernel(module="unique", enable_backward=False)
    def _pixel_hits(geo: G.SceneGeometry, cam: C.Camera, n: int,
                    cover: wp.array(dtype=float), cos_view: wp.array(dtype=float)):
        """Per pixel: the fraction of the n x n sub-pixel rays that hit (``cover``) and the mean
        cosine between the shading normal and the ray back to the camera over those
        (``cos_view``; -1 where none hits)."""
        tid = wp.tid()
        px = tid % cam.width
        py = tid // cam.width
        acc = float(0.0)
        hits = int(0)
        for i in range(n):
            for j in range(n):
                d = C.camera_ray(cam, float(px) + (float(i) + 0.5) / float(n), float(py) + (float(j) + 0.5) / float(n))
                hit, t, ng, ns, m = closest_hit(geo, cam.origin, d)
                if hit == 1:
                    # the shading normal exactly as the integrator uses it
                    if wp.dot(ns, -d) <= 1.0e-6:
                        ns = ng
                    acc = acc + wp.dot(ns, -d)
                    hits = hits + 1
        cover[tid] = float(hits) / float(n * n)
        if hits > 0:
            cos_view[tid] = acc / float(hits)
        else:
            cos_view[tid] = -1.0

    _KERNELS[key] = _pixel_hits
    return _pixel_hits


def _pixel_hits_numpy(renderer, n: int):
    """``(cover, cos_view)`` of :func:`_pixel_hits` as (H, W) arrays."""
    W, H = renderer.scene.camera.resolution
    cover = wp.zeros(W * H, dtype=float, device=renderer.device)
    cos_view = wp.zeros(W * H, dtype=float, device=renderer.device)
    g = renderer.geometry
    wp.launch(_pixel_hits_kernel(g.num_triangles > 0, g.num_spheres > 0), dim=W * H,
              inputs=[renderer.scene_geometry, renderer.camera, n], outputs=[cover, cos_view],
              device=renderer.device)
    return cover.numpy().reshape(H, W), cos_view.numpy().reshape(H, W).astype(float)


def coverage(renderer, n: int = 4) -> np.ndarray:
    """(H, W) fraction of sub-pixel rays hitting a shape, for a built ``warp_rbrdf.Renderer``."""
    return _pixel_hits_numpy(renderer, n)[0]


def view_angle(renderer, n: int = 4) -> np.ndarray:
    """(H, W) view angle theta_o in degrees: the angle between the shading normal and the
    direction back to the camera (each pixel's own ray, not the camera axis), from the mean
    cosine over the n x n sub-pixel rays that hit; NaN where no ray hits."""
    c = _pixel_hits_numpy(renderer, n)[1]
    return np.where(c < 0.0, np.nan, np.degrees(np.arccos(np.clip(c, 0.0, 1.0))))
