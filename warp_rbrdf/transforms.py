"""4x4 affine transforms as written in scene files.

A transform table holds either ``matrix`` (4x4, row-major, applied to column vectors) or any of
``scale`` (number or [sx, sy, sz]), ``rotate`` ([angle_deg, ax, ay, az] or a list of them,
applied in order) and ``translate`` ([x, y, z]); they compose as ``T @ R @ S`` (scale first).
"""
from __future__ import annotations

import numpy as np


def rotation(angle_deg: float, axis) -> np.ndarray:
    """4x4 rotation of ``angle_deg`` degrees about ``axis`` (right-handed)."""
    a = np.asarray(axis, float)
    n = np.linalg.norm(a)
    if n == 0:
        raise ValueError("rotation axis is zero")
    x, y, z = a / n
    t = np.radians(angle_deg)
    c, s = np.cos(t), np.sin(t)
    C = 1 - c
    m = np.eye(4)
    m[:3, :3] = [[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                 [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                 [z * x * C - y * s, z * y * C + x * s, c + z * z * C]]
    return m


def scaling(s) -> np.ndarray:
    s = np.broadcast_to(np.asarray(s, float), (3,))
    m = np.eye(4)
    m[0, 0], m[1, 1], m[2, 2] = s
    return m


def translation(t) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = np.asarray(t, float)
    return m


def compose(scale=None, rotate=None, translate=None) -> np.ndarray:
    """``T @ R @ S``; ``rotate`` is one ``[angle, ax, ay, az]`` or a list of them."""
    m = np.eye(4)
    if scale is not None:
        m = scaling(scale) @ m
    if rotate is not None:
        rots = rotate if (len(rotate) and isinstance(rotate[0], (list, tuple))) else [rotate]
        for r in rots:
            m = rotation(r[0], r[1:4]) @ m
    if translate is not None:
        m = translation(translate) @ m
    return m


def apply_points(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ m[:3, :3].T + m[:3, 3]


def apply_normals(m: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Transform normals by the inverse transpose and renormalise."""
    nt = n @ np.linalg.inv(m[:3, :3])
    return nt / np.maximum(np.linalg.norm(nt, axis=-1, keepdims=True), 1e-30)
