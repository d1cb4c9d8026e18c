"""Per-pixel geometry of the studies' camera rays, from n x n sub-pixel rays through the
renderer's BVH and camera convention: object coverage (the fraction of rays that hit a shape:
the mask of the studies' error metrics) and the view angle theta_o (the comparison's bins)."""
from __future__ import annotations

import numpy as np
import warp as wp

from warp_rbrdf import camera as C


@wp.kernel
def _pixel_hits(mesh: wp.uint64, indices: wp.array(dtype=int), normals: wp.array(dtype=wp.vec3),
                tri_smooth: wp.array(dtype=int), cam: C.Camera, n: int,
                cover: wp.array(dtype=float), cos_view: wp.array(dtype=float)):
    """Per pixel: the fraction of the n x n sub-pixel rays that hit (``cover``) and the mean
    cosine between the shading normal and the ray back to the camera over those (``cos_view``;
    -1 where none hits)."""
    tid = wp.tid()
    px = tid % cam.width
    py = tid // cam.width
    acc = float(0.0)
    hits = int(0)
    for i in range(n):
        for j in range(n):
            d = C.camera_ray(cam, float(px) + (float(i) + 0.5) / float(n), float(py) + (float(j) + 0.5) / float(n))
            q = wp.mesh_query_ray(mesh, cam.origin, d, 1.0e30)
            if q.result:
                # the shading normal exactly as the integrator builds it
                ng = q.normal
                if wp.dot(ng, d) > 0.0:
                    ng = -ng
                ns = ng
                f = q.face
                if tri_smooth[f] == 1:
                    nn = (normals[indices[3 * f + 0]] * q.u + normals[indices[3 * f + 1]] * q.v
                          + normals[indices[3 * f + 2]] * (1.0 - q.u - q.v))
                    ln = wp.length(nn)
                    if ln > 1.0e-12:
                        ns = nn / ln
                        if wp.dot(ns, ng) < 0.0:
                            ns = -ns
                if wp.dot(ns, -d) <= 1.0e-6:
                    ns = ng
                acc = acc + wp.dot(ns, -d)
                hits = hits + 1
    cover[tid] = float(hits) / float(n * n)
    if hits > 0:
        cos_view[tid] = acc / float(hits)
    else:
        cos_view[tid] = -1.0


def _pixel_hits_numpy(renderer, n: int):
    """``(cover, cos_view)`` of :func:`_pixel_hits` as (H, W) arrays."""
    W, H = renderer.scene.camera.resolution
    cover = wp.zeros(W * H, dtype=float, device=renderer.device)
    cos_view = wp.zeros(W * H, dtype=float, device=renderer.device)
    wp.launch(_pixel_hits, dim=W * H,
              inputs=[renderer.mesh.id, renderer.indices, renderer.normals, renderer.tri_smooth,
                      renderer.camera, n], outputs=[cover, cos_view], device=renderer.device)
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
