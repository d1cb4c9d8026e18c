"""Scene geometry: meshes (trimesh), procedural spheres and planes, merged into one BVH.

All shapes are flattened into one triangle soup in world space: ``points`` (N, 3),
``indices`` (M*3,), per-triangle ``material`` ids and ``smooth`` flags, and per-vertex shading
``normals`` (interpolated with the hit's barycentrics where the triangle is smooth; the geometric
normal otherwise). One :class:`warp.Mesh` (SAH BVH) holds them all.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import transforms
from .errors import SceneError
from .scene import Scene, ShapeSpec


@dataclass
class Geometry:
    points: np.ndarray      # (N, 3) float32
    indices: np.ndarray     # (M*3,) int32
    normals: np.ndarray     # (N, 3) float32 shading normals (unit)
    material: np.ndarray    # (M,) int32 index into the scene's material list
    smooth: np.ndarray      # (M,) int32 1 = interpolate vertex normals
    bbox_min: np.ndarray
    bbox_max: np.ndarray

    @property
    def num_triangles(self) -> int:
        return len(self.material)

    @property
    def diagonal(self) -> float:
        return float(np.linalg.norm(self.bbox_max - self.bbox_min)) if len(self.points) else 1.0


def load_mesh_file(path, file="<scene>", key="file"):
    """(vertices, faces, vertex_normals) of a mesh file read with trimesh (all parts merged)."""
    import trimesh

    try:
        m = trimesh.load(str(path), force="mesh", process=True)
    except Exception as e:  # noqa: BLE001 - trimesh raises many kinds
        raise SceneError(file, key, f"cannot load mesh {path} ({e.__class__.__name__}: {e})") from None
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise SceneError(file, key, f"mesh {path} has no triangles")
    return (np.asarray(m.vertices, float), np.asarray(m.faces, np.int64),
            np.asarray(m.vertex_normals, float))


def sphere_mesh(center, radius, subdivisions):
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    v = np.asarray(s.vertices, float)
    n = v / np.linalg.norm(v, axis=1, keepdims=True)
    return n * radius + np.asarray(center, float), np.asarray(s.faces, np.int64), n


def plane_mesh(center, size):
    x, z = 0.5 * size[0], 0.5 * size[1]
    v = np.array([[-x, 0, -z], [-x, 0, z], [x, 0, z], [x, 0, -z]], float) + np.asarray(center, float)
    f = np.array([[0, 1, 2], [0, 2, 3]], np.int64)
    n = np.tile([0.0, 1.0, 0.0], (4, 1))
    return v, f, n


def shape_triangles(shape: ShapeSpec, file="<scene>", key="shapes"):
    if shape.type == "mesh":
        v, f, n = load_mesh_file(shape.file, file, f"{key}.file")
    elif shape.type == "sphere":
        v, f, n = sphere_mesh(shape.center, shape.radius, shape.subdivisions)
    else:
        v, f, n = plane_mesh(shape.center, shape.size)
    m = shape.transform
    v = transforms.apply_points(m, v)
    n = transforms.apply_normals(m, n)
    return v, f, n


def build_geometry(scene: Scene, material_index: dict) -> Geometry:
    pts, idx, nrm, mat, smooth = [], [], [], [], []
    base = 0
    for i, shape in enumerate(scene.shapes):
        v, f, n = shape_triangles(shape, scene.path, f"shapes[{i}]")
        bad = ~np.isfinite(n).all(axis=1) | (np.linalg.norm(n, axis=1) < 0.5)
        if bad.any():  # isolated / degenerate vertices: any unit vector, never used for shading
            n[bad] = (0.0, 1.0, 0.0)
        pts.append(v)
        nrm.append(n)
        idx.append(f + base)
        mat.append(np.full(len(f), material_index[shape.material], np.int32))
        flag = 1 if (shape.type != "mesh" or shape.smooth_normals) and shape.type != "plane" else 0
        smooth.append(np.full(len(f), flag, np.int32))
        base += len(v)
    if not pts:
        return Geometry(np.zeros((0, 3), np.float32), np.zeros(0, np.int32), np.zeros((0, 3), np.float32),
                        np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(3), np.zeros(3))
    P = np.concatenate(pts)
    return Geometry(points=P.astype(np.float32), indices=np.concatenate(idx).astype(np.int32).ravel(),
                    normals=np.concatenate(nrm).astype(np.float32), material=np.concatenate(mat),
                    smooth=np.concatenate(smooth), bbox_min=P.min(axis=0), bbox_max=P.max(axis=0))


def make_warp_mesh(geom: Geometry, device):
    """One :class:`warp.Mesh` (SAH BVH) for the whole scene; None if there is no triangle."""
    import warp as wp

    if geom.num_triangles == 0:
        return None
    points = wp.array(geom.points, dtype=wp.vec3, device=device)
    indices = wp.array(geom.indices, dtype=wp.int32, device=device)
    ctor = "sah" if str(device) == "cpu" else None
    return wp.Mesh(points=points, indices=indices, bvh_constructor=ctor)
