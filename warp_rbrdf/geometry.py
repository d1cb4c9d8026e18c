"""Scene geometry: triangle meshes (trimesh) and planes in one BVH, spheres intersected
analytically, and the Warp ray queries over both.

NumPy side (:func:`build_geometry` -> :class:`Geometry`):

* meshes and planes are flattened into one triangle soup in world space: ``points`` (N, 3),
  ``indices`` (M*3,), per-triangle ``material`` ids and ``smooth`` flags, and per-vertex shading
  ``normals`` (interpolated with the hit's barycentrics where the triangle is smooth; the
  geometric normal otherwise). One :class:`warp.Mesh` holds them all (:func:`make_warp_mesh`);
* a ``sphere`` shape whose transform is a *similarity* (``M^T M = s^2 I`` for the 3x3 part:
  uniform scale, any rotation or reflection, any translation) stays a sphere: world centre
  ``transform(center)``, world radius ``s * radius``, intersected analytically with its exact
  normal; ``spheres`` (K, 4) holds ``(cx, cy, cz, r)`` and ``sphere_material`` (K,) its
  material. A sphere under any other transform (non-uniform scale, shear) is no longer a sphere:
  it falls back to the icosphere of ``subdivisions`` (its vertices mapped by the transform,
  normals by the inverse transpose) in the triangle soup. ``subdivisions`` means nothing to an
  analytic sphere. ``analytic_spheres=False`` tessellates every sphere (comparisons, tests).

Warp side: :class:`SceneGeometry` (the BVH's id, the triangle attributes and the spheres, as a
Warp struct) and :func:`make_tracer`, which builds the closest-hit and any-hit queries over both,
specialised (``wp.static``) to what the scene has: a scene of spheres only never touches a
BVH, a scene without spheres never loops over them. Spheres are tested one after the other
(linear in their number: meant for the handful a scene states, not for particle clouds).

Ray-sphere intersection: the robust quadratic of Haines et al., "Precision Improvements for
Ray/Sphere Intersection" (Ray Tracing Gems, ch. 7, 2019): the discriminant from the distance
of the centre to the ray's line (no cancellation of ``b^2 - 4ac`` for a far sphere), the root
of the larger magnitude first and the other from Vieta's formula ``t0 t1 = c / a`` (no
cancellation of ``-b + sqrt``). Hits are accepted at ``t > 0`` (triangles: Warp's
``t >= 0``); the integrator offsets every secondary ray's origin off the surface along the
geometric normal (``ray_epsilon``), which for a sphere leaves ``|o - c|^2 - r^2`` with the sign
of the side the ray starts on, so a ray leaving the surface cannot hit it again at ``t > 0``.
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass

import numpy as np
import warp as wp

from fit.errors import BRDFFileError, display_path
from fit.inputs import check_regular_file

from . import fastmath as fmath
from . import limits, mesh_checks, transforms
from .errors import SceneError
from .scene import Scene, ShapeSpec

#: Relative tolerance on ``M^T M = s^2 I`` for a transform to keep a sphere a sphere.
SIMILARITY_RTOL = 1e-6

_HAS_INLINE = "inline" in inspect.signature(wp.func).parameters


def inline_func(f):
    """``wp.func`` forced inline into its callers where Warp offers it (the ``inline`` argument
    of Warp 1.19): Warp passes structs to functions by value, and inlining lets the compiler
    drop the copies (the integrator's per-sample functions and dispatch links: 1.18-1.29x
    samples/s on a Lambert sphere, 1.10x on the bunny, measured side by side on one core)."""
    return wp.func(f, inline=True) if _HAS_INLINE else wp.func(f)


@dataclass
class Geometry:
    points: np.ndarray      # (N, 3) float32
    indices: np.ndarray     # (M*3,) int32
    normals: np.ndarray     # (N, 3) float32 shading normals (unit)
    material: np.ndarray    # (M,) int32 index into the scene's material list
    smooth: np.ndarray      # (M,) int32 1 = interpolate vertex normals
    bbox_min: np.ndarray    # (3,) over triangles and spheres
    bbox_max: np.ndarray
    spheres: np.ndarray = None          # (K, 4) float32 world (cx, cy, cz, radius)
    sphere_material: np.ndarray = None  # (K,) int32

    def __post_init__(self):
        if self.spheres is None:
            self.spheres = np.zeros((0, 4), np.float32)
        if self.sphere_material is None:
            self.sphere_material = np.zeros(0, np.int32)

    @property
    def num_triangles(self) -> int:
        return len(self.material)

    @property
    def num_spheres(self) -> int:
        return len(self.sphere_material)

    @property
    def empty(self) -> bool:
        return self.num_triangles == 0 and self.num_spheres == 0

    @property
    def diagonal(self) -> float:
        return 1.0 if self.empty else float(np.linalg.norm(self.bbox_max - self.bbox_min))


def load_mesh_file(path, file="<scene>", key="file"):
    """(vertices (V, 3) float64, faces (F, 3) int64, vertex_normals (V, 3) float64) of a mesh
    file read with trimesh (all parts merged), in the file's units. A PLY file's own vertex
    normals (``nx ny nz``) are used as written (normalised; a zero or non-finite one replaced by
    the normal trimesh computes from the vertex's faces) and its vertices kept as written, as
    Mitsuba 3 reads a PLY; otherwise duplicate vertices are merged and trimesh computes the
    normals (angle-weighted face normals). An OBJ's ``vn`` lines are not read.

    Checked before reading: a regular file (a named pipe or folder is refused, never opened) of
    at most :data:`~warp_rbrdf.limits.MAX_MESH_BYTES`. Checked after reading, before trimesh
    merges vertices (which would silently drop or keep bad data): at least one triangle, at most
    :data:`~warp_rbrdf.limits.MAX_TRIANGLES`, every vertex finite and within
    :data:`~warp_rbrdf.limits.MAX_COORDINATE`, every face index in range. Before trimesh parses
    it, an OBJ's face indices and an ASCII PLY's element counts (:func:`_check_structure`). Each
    problem is a one-line :class:`SceneError` naming the scene key and the file."""
    import trimesh

    shown = display_path(path)
    try:
        check_regular_file(path, limits.MAX_MESH_BYTES, "mesh file")
    except BRDFFileError as e:
        raise SceneError(file, key, f"mesh {shown}: {e.problem}") from None
    _check_structure(path, shown, file, key)
    try:
        m = trimesh.load(str(path), force="mesh", process=False)
    except MemoryError:
        raise SceneError(file, key, f"mesh {shown}: out of memory while reading it (corrupt counts?)") from None
    except Exception as e:  # noqa: BLE001 - trimesh raises many kinds
        msg = " ".join(str(e).split())[:120]
        raise SceneError(file, key, f"cannot load mesh {shown} ({e.__class__.__name__}: {msg})") from None
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise SceneError(file, key, f"mesh {shown} has no triangles")
    v = np.asarray(m.vertices, float)
    f = np.asarray(m.faces)
    if f.ndim != 2 or f.shape[1] != 3 or v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise SceneError(file, key, f"mesh {shown}: expected triangles over 3-D vertices, got faces "
                                    f"{f.shape} and vertices {v.shape}")
    if len(f) > limits.MAX_TRIANGLES:
        raise SceneError(file, key, f"mesh {shown} has {len(f)} triangles, above the limit "
                                    f"{limits.MAX_TRIANGLES} (warp_rbrdf.limits.MAX_TRIANGLES)")
    finite = np.isfinite(v).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise SceneError(file, key, f"mesh {shown}: {len(bad)} of {len(v)} vertices are not finite "
                                    f"(NaN or infinity; first: vertex {bad[0]})")
    if np.abs(v).max() > limits.MAX_COORDINATE:
        raise SceneError(file, key, f"mesh {shown}: a vertex coordinate of magnitude {np.abs(v).max():.3g} is "
                                    f"above the limit {limits.MAX_COORDINATE:g} (warp_rbrdf.limits.MAX_COORDINATE)")
    if not np.issubdtype(f.dtype, np.integer) or f.min() < 0 or f.max() >= len(v):
        bad = int(np.flatnonzero(((f < 0) | (f >= len(v))).any(axis=1))[0]) \
            if np.issubdtype(f.dtype, np.integer) else 0
        raise SceneError(file, key, f"mesh {shown}: face {bad} has a vertex index outside [0, {len(v) - 1}]")
    own = _ply_vertex_normals(m, len(v))
    try:
        if own is not None:         # the file's own normals, its vertices as written (not merged)
            length = np.linalg.norm(own, axis=1, keepdims=True)
            usable = (np.isfinite(length) & (length > 0))[:, 0]
            normals = own / np.where(usable[:, None], length, 1.0)
            if not usable.all():    # a zero or non-finite one: the vertex's normal from its faces
                normals[~usable] = np.asarray(m.vertex_normals, float)[~usable]
            return v, np.asarray(f, np.int64), normals
        m.process(validate=False)   # merge duplicate vertices, as trimesh.load(process=True) did
        normals = np.asarray(m.vertex_normals, float)
    except MemoryError:
        raise SceneError(file, key, f"mesh {shown}: out of memory while processing it") from None
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64), normals


def _ply_vertex_normals(mesh, n_vertices: int):
    """A PLY file's own vertex normals (its vertex element's ``nx``, ``ny``, ``nz``), ``(V, 3)``
    float64, or None (not a PLY, no such properties, or not one per vertex): read from the
    element data trimesh keeps with the mesh (``metadata["_ply_raw"]``), since trimesh itself
    does not use them. Mitsuba 3 shades with a PLY's normals when it has them."""
    try:
        data = mesh.metadata["_ply_raw"]["vertex"]["data"]
        n = np.stack([np.asarray(data[k], np.float64).reshape(-1) for k in ("nx", "ny", "nz")], axis=1)
    except (AttributeError, KeyError, TypeError, ValueError, IndexError):
        return None
    return n if n.shape == (n_vertices, 3) else None


def _check_structure(path, shown, file, key) -> None:
    """What trimesh accepts silently (:mod:`warp_rbrdf.mesh_checks`): an OBJ face index of 0 or
    beyond the vertices, an ASCII PLY whose body does not hold the elements its header
    declares; one-line :class:`SceneError` naming the key and the file."""
    suffix = str(path).lower().rsplit(".", 1)[-1]
    try:
        if suffix == "obj":
            with open(path, "rb") as fh:
                mesh_checks.check_obj(fh.read())
        elif suffix == "ply":
            with open(path, "rb") as fh:
                head = fh.read(mesh_checks.PLY_HEADER_BYTES)
                mesh_checks.check_ply(head, lambda: head + fh.read())
    except ValueError as e:
        raise SceneError(file, key, f"mesh {shown}: {e}") from None
    except OSError as e:
        raise SceneError(file, key, f"cannot read mesh {shown} ({e.strerror or e.__class__.__name__})") from None


def sphere_mesh(center, radius, subdivisions):
    """Icosphere of ``subdivisions`` (20 * 4^subdivisions triangles): (vertices, faces, normals)."""
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


def similarity_scale(m: np.ndarray) -> float | None:
    """``s`` when the 4x4 affine ``m`` is a similarity (its 3x3 part ``A`` has ``A^T A = s^2 I``
    to :data:`SIMILARITY_RTOL`), else None."""
    a = np.asarray(m, float)[:3, :3]
    g = a.T @ a
    s2 = np.trace(g) / 3.0
    if not np.isfinite(s2) or s2 <= 0 or np.abs(g - s2 * np.eye(3)).max() > SIMILARITY_RTOL * s2:
        return None
    return float(np.sqrt(s2))


def analytic_sphere(shape: ShapeSpec):
    """World ``(center (3,), radius)`` of a ``sphere`` shape whose transform keeps it a sphere;
    None when the transform does not (the shape is then tessellated)."""
    s = similarity_scale(shape.transform)
    if s is None:
        return None
    c = transforms.apply_points(shape.transform, np.asarray(shape.center, float)[None])[0]
    return c, s * float(shape.radius)


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


def _check_triangles(total: int, file, i: int) -> None:
    """One-line error when the scene's triangles up to shape ``i`` exceed the limit."""
    if total > limits.MAX_TRIANGLES:
        raise SceneError(file, f"shapes[{i}]", f"the scene's triangles reach {total} here, above the limit "
                                               f"{limits.MAX_TRIANGLES} (warp_rbrdf.limits.MAX_TRIANGLES)")


def build_geometry(scene: Scene, material_index: dict, analytic_spheres: bool = True) -> Geometry:
    """The scene's shapes in world space: triangles (meshes, planes, spheres that are not
    similarity-transformed or all spheres when ``analytic_spheres`` is False) and analytic
    spheres; ``material_index`` maps a material name to its index in the kernels' arrays."""
    pts, idx, nrm, mat, smooth = [], [], [], [], []
    sph, sph_mat = [], []
    base = 0
    n_triangles = 0
    for i, shape in enumerate(scene.shapes):
        if shape.type == "sphere" and analytic_spheres:
            cr = analytic_sphere(shape)
            if cr is not None:
                sph.append((*cr[0], cr[1]))
                sph_mat.append(material_index[shape.material])
                continue
        if shape.type == "sphere":   # tessellated: check the count before building it
            n_triangles += 20 * 4 ** int(shape.subdivisions)
            _check_triangles(n_triangles, scene.path, i)
        v, f, n = shape_triangles(shape, scene.path, f"shapes[{i}]")
        if shape.type != "sphere":
            n_triangles += len(f)
            _check_triangles(n_triangles, scene.path, i)
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
    spheres = np.array(sph, np.float64).reshape(-1, 4)
    lo = [spheres[:, :3] - spheres[:, 3:]] if len(sph) else []
    hi = [spheres[:, :3] + spheres[:, 3:]] if len(sph) else []
    if pts:
        P = np.concatenate(pts)
        lo.append(P)
        hi.append(P)
        tri = {"points": P.astype(np.float32), "indices": np.concatenate(idx).astype(np.int32).ravel(),
               "normals": np.concatenate(nrm).astype(np.float32), "material": np.concatenate(mat),
               "smooth": np.concatenate(smooth)}
    else:
        tri = {"points": np.zeros((0, 3), np.float32), "indices": np.zeros(0, np.int32),
               "normals": np.zeros((0, 3), np.float32), "material": np.zeros(0, np.int32),
               "smooth": np.zeros(0, np.int32)}
    bmin = np.concatenate(lo).min(axis=0) if lo else np.zeros(3)
    bmax = np.concatenate(hi).max(axis=0) if hi else np.zeros(3)
    return Geometry(**tri, bbox_min=bmin, bbox_max=bmax, spheres=spheres.astype(np.float32),
                    sphere_material=np.array(sph_mat, np.int32))


#: BVH of the triangle meshes on the CPU: Warp's constructor and leaf size, chosen by
#: ``benchmarks/bench_render.py --bvh`` (docs/rendering.md).
BVH_CONSTRUCTOR = "sah"
BVH_LEAF_SIZE = 4
#: The same on a CUDA device (Warp's own default there is a 4-triangle LBVH): on an H100 the
#: bunny renders at 446 M samples/s with SAH / 1 against 319 M with the default, the teapot
#: 1,288 against 1,081 M (docs/cuda.md).
BVH_CONSTRUCTOR_CUDA = "sah"
BVH_LEAF_SIZE_CUDA = 1


def make_warp_mesh(geom: Geometry, device, constructor: str | None = None, leaf_size: int | None = None):
    """One :class:`warp.Mesh` for the scene's triangles (unless given: CPU :data:`BVH_CONSTRUCTOR`,
    :data:`BVH_LEAF_SIZE`; CUDA :data:`BVH_CONSTRUCTOR_CUDA`, :data:`BVH_LEAF_SIZE_CUDA`); None
    if there is no triangle."""
    if geom.num_triangles == 0:
        return None
    points = wp.array(geom.points, dtype=wp.vec3, device=device)
    indices = wp.array(geom.indices, dtype=wp.int32, device=device)
    cpu = str(device) == "cpu"
    constructor = constructor or (BVH_CONSTRUCTOR if cpu else BVH_CONSTRUCTOR_CUDA)
    leaf_size = leaf_size or (BVH_LEAF_SIZE if cpu else BVH_LEAF_SIZE_CUDA)
    return wp.Mesh(points=points, indices=indices, bvh_constructor=constructor, bvh_leaf_size=leaf_size)


# --------------------------------------------------------------------------------------------
# Warp side
@wp.struct
class SceneGeometry:
    """What the ray queries read: the triangles' BVH (``mesh``: a :class:`warp.Mesh` id, 0 when
    the scene has no triangle) with their vertex indices, vertex shading normals, material and
    smooth flags, and the analytic spheres ``(cx, cy, cz, r)`` with their materials."""
    mesh: wp.uint64
    indices: wp.array(dtype=int)
    normals: wp.array(dtype=wp.vec3)
    tri_mat: wp.array(dtype=int)
    tri_smooth: wp.array(dtype=int)
    spheres: wp.array(dtype=wp.vec4)
    sphere_mat: wp.array(dtype=int)
    num_spheres: int


def make_geometry_struct(geom: Geometry, mesh, device) -> SceneGeometry:
    """The :class:`SceneGeometry` of ``geom`` and its BVH ``mesh`` (None: no triangle). Empty
    parts get one-element placeholder arrays (never read: the queries are specialised)."""
    def arr(a, dtype, n, fill):
        a = np.asarray(a)
        if len(a) == 0:
            a = np.full((1, n) if n > 1 else 1, fill, a.dtype)
        return wp.array(a, dtype=dtype, device=device)

    g = SceneGeometry()
    g.mesh = wp.uint64(mesh.id if mesh is not None else 0)
    g.indices = arr(geom.indices, wp.int32, 1, 0)
    g.normals = arr(geom.normals, wp.vec3, 3, 0.0)
    g.tri_mat = arr(geom.material, wp.int32, 1, 0)
    g.tri_smooth = arr(geom.smooth, wp.int32, 1, 0)
    g.spheres = arr(geom.spheres, wp.vec4, 4, 0.0)
    g.sphere_mat = arr(geom.sphere_material, wp.int32, 1, 0)
    g.num_spheres = int(geom.num_spheres)
    return g


@inline_func
def ray_sphere(o: wp.vec3, d: wp.vec3, s: wp.vec4):
    """The two ray parameters ``(t_lo, t_hi)``, ``t_lo <= t_hi``, where ``o + t d`` meets the
    sphere ``s = (cx, cy, cz, r)`` (``d`` need not be unit), by the robust formulation of Ray
    Tracing Gems ch. 7; ``(1e30, 1e30)`` when the line misses it."""
    f = o - wp.vec3(s[0], s[1], s[2])
    r = s[3]
    a = wp.dot(d, d)
    b = wp.dot(f, d)                       # half of the quadratic's b
    l = f - d * (b / a)                    # centre -> closest point of the line, negated
    disc = a * (r * r - wp.dot(l, l))      # (b^2 - a c) without cancellation
    if disc < 0.0:
        return 1.0e30, 1.0e30
    c = wp.dot(f, f) - r * r
    q = -b - wp.where(b >= 0.0, 1.0, -1.0) * wp.sqrt(disc)
    if q == 0.0:                           # tangent line through the origin: t = 0 only
        return 0.0, 0.0
    t0 = c / q
    t1 = q / a
    return fmath.fmin(t0, t1), fmath.fmax(t0, t1)


def make_tracer(has_mesh: bool, has_spheres: bool):
    """``(closest_hit, any_hit)`` Warp functions over a :class:`SceneGeometry` with (or without)
    triangles and spheres:

    * ``closest_hit(g, o, d) -> (hit, t, ng, ns, material)``: ``hit`` 1 or 0; ``ng`` the unit
      geometric normal facing the ray's origin side (``dot(ng, d) <= 0``), ``ns`` the unit
      shading normal on the same side as ``ng`` (a smooth triangle's interpolated vertex
      normals; a flat triangle's or a sphere's is ``ng`` -- a sphere's is exact);
    * ``any_hit(g, o, d, tmax) -> bool``: whether any surface lies at ``0 < t < tmax``."""
    has_mesh, has_spheres = bool(has_mesh), bool(has_spheres)

    @inline_func
    def closest_hit(g: SceneGeometry, o: wp.vec3, d: wp.vec3):
        best = float(1.0e30)  # noqa: UP018 - a Warp loop-carried variable
        hit = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
        ng = wp.vec3(0.0, 0.0, 1.0)
        ns = ng
        m = int(0)  # noqa: UP018, RUF046 - a Warp loop-carried variable
        if wp.static(has_mesh):
            q = wp.mesh_query_ray(g.mesh, o, d, 1.0e30)
            if q.result:
                hit = 1
                best = q.t
                f = q.face
                ng = q.normal
                if wp.dot(ng, d) > 0.0:
                    ng = -ng
                ns = ng
                m = g.tri_mat[f]
                if g.tri_smooth[f] == 1:
                    nn = (g.normals[g.indices[3 * f + 0]] * q.u + g.normals[g.indices[3 * f + 1]] * q.v
                          + g.normals[g.indices[3 * f + 2]] * (1.0 - q.u - q.v))
                    ln = wp.length(nn)
                    if ln > 1.0e-12:
                        ns = nn / ln
                        if wp.dot(ns, ng) < 0.0:
                            ns = -ns
        if wp.static(has_spheres):
            k_best = int(-1)  # noqa: UP018, RUF046 - a Warp loop-carried variable
            for k in range(g.num_spheres):
                t_lo, t_hi = ray_sphere(o, d, g.spheres[k])
                t = wp.where(t_lo > 0.0, t_lo, t_hi)
                if t > 0.0 and t < best:
                    best = t
                    k_best = k
            if k_best >= 0:
                s = g.spheres[k_best]
                n = (o + d * best - wp.vec3(s[0], s[1], s[2])) * (1.0 / s[3])
                n = wp.normalize(n)
                if wp.dot(n, d) > 0.0:
                    n = -n
                hit = 1
                ng = n
                ns = n
                m = g.sphere_mat[k_best]
        return hit, best, ng, ns, m

    @inline_func
    def any_hit(g: SceneGeometry, o: wp.vec3, d: wp.vec3, tmax: float) -> bool:
        if wp.static(has_spheres):
            for k in range(g.num_spheres):
                t_lo, t_hi = ray_sphere(o, d, g.spheres[k])
                t = wp.where(t_lo > 0.0, t_lo, t_hi)
                if t > 0.0 and t < tmax:
                    return True
        if wp.static(has_mesh):
            return wp.mesh_query_ray_anyhit(g.mesh, o, d, tmax)
        return False

    return closest_hit, any_hit
