"""Pinhole camera (conventions.md): ``look_at(origin, target, up)``, full ``fov`` in degrees
along ``fov_axis``, film (0, 0) at the top-left, x right, y down; the camera looks down -Z in
its own frame, image right is camera +X and image up is camera +Y:

    d = normalize(((2 px / W - 1) tx, (1 - 2 py / H) ty, -1))
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp


@wp.struct
class Camera:
    origin: wp.vec3
    right: wp.vec3     # camera +X scaled by tx
    up: wp.vec3        # camera +Y scaled by ty
    forward: wp.vec3   # camera -Z (unit)
    width: int
    height: int


def camera_frame(spec):
    """(origin, right*tx, up*ty, forward) as float64 NumPy vectors."""
    o = np.asarray(spec.origin, float)
    f = np.asarray(spec.target, float) - o
    f /= np.linalg.norm(f)
    r = np.cross(f, np.asarray(spec.up, float))
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    W, H = spec.resolution
    t = math.tan(math.radians(spec.fov) / 2)
    if spec.fov_axis == "x":
        tx, ty = t, t * H / W
    else:
        tx, ty = t * W / H, t
    return o, r * tx, u * ty, f


def make_camera_struct(spec) -> Camera:
    o, r, u, f = camera_frame(spec)
    c = Camera()
    c.origin = wp.vec3(*o.astype(np.float32))
    c.right = wp.vec3(*r.astype(np.float32))
    c.up = wp.vec3(*u.astype(np.float32))
    c.forward = wp.vec3(*f.astype(np.float32))
    c.width, c.height = int(spec.resolution[0]), int(spec.resolution[1])
    return c


def camera_rays_numpy(spec, px, py):
    """World ray directions for film points (px, py) (reference implementation)."""
    o, r, u, f = camera_frame(spec)
    W, H = spec.resolution
    a = (2.0 * np.asarray(px, float) / W - 1.0)[..., None]
    b = (1.0 - 2.0 * np.asarray(py, float) / H)[..., None]
    d = a * r + b * u + f
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


@wp.func
def camera_ray(cam: Camera, px: float, py: float) -> wp.vec3:
    a = 2.0 * px / float(cam.width) - 1.0
    b = 1.0 - 2.0 * py / float(cam.height)
    return wp.normalize(cam.right * a + cam.up * b + cam.forward)
