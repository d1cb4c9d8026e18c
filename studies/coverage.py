"""Object coverage per pixel (fraction of n x n sub-pixel camera rays that hit a shape): the
mask of the studies' error metrics. Uses the renderer's BVH and camera convention."""
from __future__ import annotations

import numpy as np
import warp as wp

from warp_rbrdf import camera as C


@wp.kernel
def _coverage(mesh: wp.uint64, cam: C.Camera, n: int, out: wp.array(dtype=float)):
    tid = wp.tid()
    px = tid % cam.width
    py = tid // cam.width
    hits = int(0)
    for i in range(n):
        for j in range(n):
            d = C.camera_ray(cam, float(px) + (float(i) + 0.5) / float(n), float(py) + (float(j) + 0.5) / float(n))
            q = wp.mesh_query_ray(mesh, cam.origin, d, 1.0e30)
            if q.result:
                hits = hits + 1
    out[tid] = float(hits) / float(n * n)


def coverage(renderer, n: int = 4) -> np.ndarray:
    """(H, W) fraction of sub-pixel rays hitting a shape, for a built ``warp_rbrdf.Renderer``."""
    W, H = renderer.scene.camera.resolution
    out = wp.zeros(W * H, dtype=float, device=renderer.device)
    wp.launch(_coverage, dim=W * H, inputs=[renderer.mesh.id, renderer.camera, n], outputs=[out],
              device=renderer.device)
    return out.numpy().reshape(H, W)


@wp.kernel
def _view_cosine(mesh: wp.uint64, indices: wp.array(dtype=int), normals: wp.array(dtype=wp.vec3),
                 tri_smooth: wp.array(dtype=int), cam: C.Camera, n: int, out: wp.array(dtype=float)):
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
    if hits > 0:
        out[tid] = acc / float(hits)
    else:
        out[tid] = -1.0


def view_angle(renderer, n: int = 4) -> np.ndarray:
    """(H, W) view angle theta_o in degrees: the angle between the shading normal and the
    direction back to the camera (each pixel's own ray, not the camera axis), from the mean
    cosine over the n x n sub-pixel rays that hit; NaN where no ray hits."""
    W, H = renderer.scene.camera.resolution
    out = wp.zeros(W * H, dtype=float, device=renderer.device)
    wp.launch(_view_cosine, dim=W * H,
              inputs=[renderer.mesh.id, renderer.indices, renderer.normals, renderer.tri_smooth,
                      renderer.camera, n], outputs=[out], device=renderer.device)
    c = out.numpy().reshape(H, W).astype(float)
    return np.where(c < 0.0, np.nan, np.degrees(np.arccos(np.clip(c, 0.0, 1.0))))
