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
