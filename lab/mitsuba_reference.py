"""Mitsuba 3 as the reference implementation of the RGL-EPFL ``.bsdf`` format and of a reference
scene (parity with the reference implementation).

Mitsuba 3's ``measured`` plugin (``src/bsdfs/measured.cpp``) is the format authors' own code.
This module wraps it, in the ``scalar_rgb`` variant (no LLVM or CUDA needed), for the parity
tests (``tests/test_parity_mitsuba.py``) and the fidelity study:

* :func:`eval`, :func:`pdf`, :func:`sample`: the plugin's BSDF interface at local directions,
  with Mitsuba's roles: ``wt`` is ``si.wi`` (the direction the tensors are indexed by, their
  ``theta_i``; in radiance transport the direction towards the **camera**), ``wx`` is ``wo``
  (towards the light). ``eval`` returns ``f_r * cos(theta_wx)`` as Mitsuba does, i.e.
  ``fit.formats.rgl.RGLBRDF.reference_eval(wt, wx)``; our renderer's
  ``eval_material(name, wi_light=wx, wo_view=wt) * wx.z`` is the same number.
* :func:`render_sphere`: the reference scene of Mitsuba's ``measured`` plugin documentation
  (unit sphere at the origin, camera at (0, 0, 4) looking at the origin, +Y up, 30 deg vertical
  field of view, an environment map at scale 1, hidden), rendered by Mitsuba's ``direct``
  integrator with one emitter sample and one BSDF sample combined by the power heuristic and a
  box pixel filter (pixel = plain mean of its samples, conventions.md);
  :func:`sphere_scene` builds the **same** scene for our renderer (a :class:`Scene`), so that
  tests and studies share one definition.

Mitsuba is an optional dependency (``pip install warp-rbrdf[reference]``, pinned to the version
the parity numbers were measured with); it is imported on first use and a missing install is
a one-line :class:`ReferenceUnavailable`. :func:`available` says whether it can be used.

Negative table entries. Some RGL files hold negative ``rgb`` entries (measurement noise; 7 of
the 20 shared files, e.g. 5174 of 24576 entries down to -0.62 in ``chm_mint_rgb``, 1118 down to
-0.04 in ``vch_golden_yellow_rgb``). Mitsuba does **not** clamp them: its ``Marginal2D``
interpolant is plain bilinear, so ``eval`` (and the BSDF-sample weight) can be negative next to
such entries, and a render can receive negative contributions. Our reader clamps the entries to
0 at load (conventions.md). To compare like with like, every function here gives Mitsuba, by
default (``clamp_negative=True``), a copy of the file whose negative ``rgb`` entries are set to 0
(:func:`clamped_copy`; the other fields, including ``luminance`` which drives sampling, are
unchanged, so the sampling densities are those of the original file). With
``clamp_negative=False`` Mitsuba reads the file as it is.

Precision. Mitsuba computes in float32; :mod:`fit.formats.rgl` in float64. They agree to
<= 8.2e-5 relative where a value is above 1e-2 of the sample's maximum and to <= 1.3e-5 of that
maximum everywhere (all 20 shared files, grazing pairs included; ``tests/test_parity_mitsuba.py``
states the measurements). A known quirk of Mitsuba 3.9.1's ``measured`` plugin: it leaves
its member ``m_reduction`` uninitialized for isotropic files (``measured.cpp`` sets it for
anisotropic files only), so the plugin's behaviour depends on the heap at load time. A garbage
value >= 2 rotates ``si.wi`` and ``wo`` by pi about the normal when ``si.wi.y > 0`` before the
lookup, a symmetry of isotropic data (results bit-identical). A garbage value of exactly 4
instead mirrors x where ``si.wi.x > 0`` and y where ``si.wi.y > 0``, which measured data are
not symmetric under: eval then differs by up to 1e-2 relative on the shared files, and sampled
directions by far more. That happened once in many CI runs, on one file, and failed the parity
tests. Every plugin this module loads (alone or in a scene) is therefore checked by
:func:`_mirrors` and loaded again, up to :data:`MAX_LOADS` times, while it mirrors
(:func:`_load_checked`; ``tests/test_parity_mitsuba.py`` emulates the garbage value).
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np

from warp_rbrdf.errors import RenderError

#: The Mitsuba variant used (CPU, no LLVM / CUDA needed).
VARIANT = "scalar_rgb"
#: The install command named by :class:`ReferenceUnavailable`.
INSTALL_HINT = "pip install warp-rbrdf[reference]"

#: The reference scene (Mitsuba's ``measured`` plugin documentation scene).
CAMERA_ORIGIN = (0.0, 0.0, 4.0)
CAMERA_TARGET = (0.0, 0.0, 0.0)
CAMERA_UP = (0.0, 1.0, 0.0)
FOV_Y_DEG = 30.0
SPHERE_RADIUS = 1.0
#: Icosphere subdivisions of the sphere's mesh fallback. Our renderer intersects the sphere
#: analytically, as Mitsuba does (``Renderer(..., analytic_spheres=False)`` renders this
#: icosphere instead: 40962 vertices, edges of about 1.1 deg, chord error <= 1e-4 of the radius).
SPHERE_SUBDIVISIONS = 6


class ReferenceUnavailable(RenderError):
    """Mitsuba 3 (the reference implementation) is not installed."""


# --------------------------------------------------------------------------------------------
# Mitsuba
@functools.lru_cache(maxsize=1)
def _mi():
    try:
        import mitsuba as mi
    except ImportError:
        raise ReferenceUnavailable(f"Mitsuba 3 is not installed (the reference implementation): "
                                   f"{INSTALL_HINT}") from None
    try:
        mi.set_variant(VARIANT)
    except Exception as e:  # noqa: BLE001 - an install without the scalar RGB variant
        raise ReferenceUnavailable(f"Mitsuba {getattr(mi, '__version__', '?')} has no variant "
                                   f"{VARIANT!r} ({e}): {INSTALL_HINT}") from None
    return mi


@contextlib.contextmanager
def _scalar_variant():
    """Mitsuba with the :data:`VARIANT` selected for the per-pair functions (:func:`eval`,
    :func:`pdf`, :func:`sample`), whatever variant another caller (a render in ``llvm_ad_rgb``)
    left selected; that variant is selected again on the way out."""
    mi = _mi()
    before = mi.variant()
    if before != VARIANT:
        mi.set_variant(VARIANT)
    try:
        yield mi
    finally:
        if before != VARIANT:
            mi.set_variant(before)


def available() -> bool:
    """True when Mitsuba 3 can be imported and its ``scalar_rgb`` variant set."""
    try:
        _mi()
    except ReferenceUnavailable:
        return False
    return True


def version() -> str:
    """Mitsuba's version string."""
    return _mi().__version__


def _cache_dir() -> Path:
    d = Path(os.environ.get("RBRDF_REFERENCE_CACHE",
                            Path(tempfile.gettempdir()) / f"rbrdf-mitsuba-reference-{os.getuid()}"))
    d.mkdir(parents=True, exist_ok=True)
    return d


def clamped_copy(path) -> Path:
    """``path`` itself when its ``rgb`` field has no negative entry, else a copy (in a cache
    folder under the system temp dir, or ``$RBRDF_REFERENCE_CACHE``) whose negative ``rgb``
    entries are 0, as our reader clamps them; every other field is copied unchanged (same
    dtypes). The copy is named by the source's SHA-256, so it is written once."""
    from fit.formats.tensor_file import read_tensor_file, write_tensor_file

    path = Path(path)
    fields = read_tensor_file(path)
    if "rgb" not in fields or not np.any(np.asarray(fields["rgb"].data) < 0):
        return path
    sha = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
    out = _cache_dir() / f"{path.stem}.clamped-{sha}.bsdf"
    if not out.exists():
        arrays = {k: np.array(f.data) for k, f in fields.items()}
        rgb = arrays["rgb"]
        arrays["rgb"] = np.where(rgb < 0, np.zeros((), rgb.dtype), rgb)
        tmp = out.with_suffix(f".tmp{os.getpid()}")
        write_tensor_file(tmp, arrays)
        os.replace(tmp, out)
    return out


def _file_for_mitsuba(path, clamp_negative: bool) -> str:
    return str(clamped_copy(path) if clamp_negative else Path(path))


#: Loads of a ``measured`` plugin (or a scene holding one) tried before giving up on one that
#: mirrors direction pairs (module docstring, :func:`_load_checked`).
MAX_LOADS = 8

#: Probe pairs of :func:`_mirrors` (unit vectors, z = normal): ``si.wi`` with x > 0 > y, so that
#: a plugin whose ``m_reduction`` reads 4 mirrors x (only), and ``wo`` spread over the hemisphere.
_PROBE_WT = np.array([[0.5, -0.3, 0.8], [0.7, -0.2, 0.6], [0.3, -0.6, 0.7], [0.2, -0.1, 0.97]])
_PROBE_WX = np.array([[-0.2, 0.5, 0.8], [0.4, 0.4, 0.8], [-0.5, -0.3, 0.8], [0.6, 0.6, 0.5]])
_PROBE_WT /= np.linalg.norm(_PROBE_WT, axis=1, keepdims=True)
_PROBE_WX /= np.linalg.norm(_PROBE_WX, axis=1, keepdims=True)


def _mirrors(bsdf) -> bool:
    """True when the loaded ``measured`` plugin ``bsdf`` (current variant) mirrors direction
    pairs as Mitsuba 3.9.1's does when its uninitialized ``m_reduction`` reads 4: at every probe
    pair (``si.wi`` with x > 0 > y) its eval equals, bit for bit, its eval at the pair mirrored in
    x (``si.wi`` with x, y < 0, which the plugin evaluates as it is whatever ``m_reduction``
    holds). A correct plugin differs there, as measured data are not mirror-symmetric (all 20
    shared files; data that were would make the mirror harmless)."""
    mi = _mi()
    ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    for a, b in zip(_PROBE_WT, _PROBE_WX):
        vals = []
        for s in (1.0, -1.0):
            si.wi = mi.Vector3f(float(s * a[0]), float(a[1]), float(a[2]))
            wo = mi.Vector3f(float(s * b[0]), float(b[1]), float(b[2]))
            vals.append(np.array(bsdf.eval(ctx, si, wo), np.float64).ravel())
        if not np.array_equal(vals[0], vals[1]):
            return False
    return True


def _load_checked(load, bsdf_of, what):
    """``load()`` (a ``measured`` plugin, or a scene holding one: ``bsdf_of(loaded)`` is the
    plugin), again while the plugin :func:`_mirrors` pairs, up to :data:`MAX_LOADS` loads; the
    rejected ones are kept alive until then, so that each new load gets other memory. Raises
    :class:`ReferenceUnavailable` naming ``what`` when every load mirrors."""
    rejected = []
    for _ in range(MAX_LOADS):
        loaded = load()
        if not _mirrors(bsdf_of(loaded)):
            return loaded
        rejected.append(loaded)
    raise ReferenceUnavailable(f"{what}: Mitsuba's measured plugin mirrored direction pairs in "
                               f"{MAX_LOADS} loads (its m_reduction is uninitialized for isotropic "
                               f"files in Mitsuba 3.9.1)")


def _isotropic(filename) -> bool:
    """Whether the ``.bsdf`` file is isotropic as the plugin decides it (``phi_i`` with at most
    2 entries): only then is ``m_reduction`` left uninitialized (an anisotropic file may set it
    to 4 on purpose, its data covering a quarter of the azimuths)."""
    from fit.formats.tensor_file import read_tensor_file

    phi_i = read_tensor_file(filename).get("phi_i")
    return phi_i is not None and int(np.prod(phi_i.shape)) <= 2


@functools.lru_cache(maxsize=32)
def _measured(filename: str, variant: str):
    """The ``measured`` plugin of ``filename`` loaded in ``variant`` (the current one; part of
    the cache key, as a plugin keeps the variant it was loaded in)."""
    load = lambda: _mi().load_dict({"type": "measured", "filename": filename})  # noqa: E731
    return _load_checked(load, lambda bsdf: bsdf, filename) if _isotropic(filename) else load()


def _load_scene(scene_dict: dict, material):
    """``mi.load_dict(scene_dict)`` of a reference scene; an RGL ``material``'s plugin checked by
    :func:`_load_checked`."""
    mi = _mi()
    if _material_kind(material)[0] != "rgl" or not _isotropic(scene_dict["sphere"]["bsdf"]["filename"]):
        return mi.load_dict(scene_dict)
    return _load_checked(lambda: mi.load_dict(scene_dict), lambda scene: scene.shapes()[0].bsdf(),
                         str(material))


def load_bsdf(path, clamp_negative: bool = True):
    """Mitsuba's ``measured`` BSDF of an RGL ``.bsdf`` file in the current variant (cached per
    file and variant)."""
    return _measured(_file_for_mitsuba(path, clamp_negative), _mi().variant())


def _directions(a, name):
    a = np.asarray(a, np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {a.shape}")
    return a


def eval(path, wt, wx, clamp_negative: bool = True) -> np.ndarray:  # noqa: A001 - Mitsuba's name
    """Mitsuba ``measured`` ``eval`` with ``si.wi = wt`` and ``wo = wx`` (local unit directions,
    (N, 3), z = normal): ``f_r * cos(theta_wx)`` as (N, 3) float64 (Mitsuba computes in float32).
    0 where either direction is at or below the tangent plane."""
    with _scalar_variant() as mi:
        wt, wx = _directions(wt, "wt"), _directions(wx, "wx")
        bsdf = load_bsdf(path, clamp_negative)
        ctx = mi.BSDFContext()
        si = mi.SurfaceInteraction3f()
        out = np.empty((len(wt), 3))
        for k in range(len(wt)):   # the scalar variant takes one direction pair per call
            si.wi = mi.Vector3f(wt[k])
            v = bsdf.eval(ctx, si, mi.Vector3f(wx[k]))
            out[k] = (v[0], v[1], v[2])
        return out


def pdf(path, wt, wx, clamp_negative: bool = True) -> np.ndarray:
    """Mitsuba ``measured`` ``pdf`` (1/sr of ``wx``) of its BSDF sample at ``si.wi = wt``,
    ``wo = wx``: luminance warp, then VNDF warp, then reflection about the micro-normal."""
    with _scalar_variant() as mi:
        wt, wx = _directions(wt, "wt"), _directions(wx, "wx")
        bsdf = load_bsdf(path, clamp_negative)
        ctx = mi.BSDFContext()
        si = mi.SurfaceInteraction3f()
        out = np.empty(len(wt))
        for k in range(len(wt)):
            si.wi = mi.Vector3f(wt[k])
            out[k] = bsdf.pdf(ctx, si, mi.Vector3f(wx[k]))
        return out


def sample(path, wt, xi, clamp_negative: bool = True):
    """Mitsuba ``measured`` ``sample`` at ``si.wi = wt`` (N, 3) with uniforms ``xi`` (N, 2)
    passed as Mitsuba's ``sample2`` (the plugin swaps them: its luminance warp receives
    ``(xi[:, 1], xi[:, 0])``). Returns ``(wx (N, 3), weight (N, 3), pdf (N,))``: the sampled
    direction (towards the light), Mitsuba's sample weight ``f_r * cos(theta_wx) / pdf`` (0
    where the sample is invalid) and the pdf in 1/sr of ``wx``."""
    with _scalar_variant() as mi:
        wt = _directions(wt, "wt")
        xi = np.asarray(xi, np.float64)
        if xi.shape != (len(wt), 2):
            raise ValueError(f"xi must have shape ({len(wt)}, 2), got {xi.shape}")
        bsdf = load_bsdf(path, clamp_negative)
        ctx = mi.BSDFContext()
        si = mi.SurfaceInteraction3f()
        wx = np.zeros((len(wt), 3))
        weight = np.zeros((len(wt), 3))
        p = np.zeros(len(wt))
        for k in range(len(wt)):
            si.wi = mi.Vector3f(wt[k])
            bs, w = bsdf.sample(ctx, si, 0.5, mi.Point2f(xi[k]))
            wx[k] = (bs.wo[0], bs.wo[1], bs.wo[2])
            weight[k] = (w[0], w[1], w[2])
            p[k] = bs.pdf
        return wx, weight, p


# --------------------------------------------------------------------------------------------
# The reference scene
def _material_kind(material):
    """('rgl', path) or ('lambert', (r, g, b)) from a .bsdf path or ('lambert', albedo)."""
    if isinstance(material, (tuple, list)) and len(material) == 2 and material[0] == "lambert":
        return "lambert", tuple(float(x) for x in np.broadcast_to(np.asarray(material[1], float), 3))
    if isinstance(material, (str, os.PathLike)) and Path(material).suffix == ".bsdf":
        return "rgl", Path(material)
    raise ValueError(f"material must be an RGL .bsdf path or ('lambert', albedo), got {material!r}")


def mitsuba_scene_dict(material, envmap, spp: int, resolution: int = 256,
                       clamp_negative: bool = True) -> dict:
    """The reference scene as a Mitsuba scene dictionary (see :func:`render_sphere`)."""
    mi = _mi()
    kind, m = _material_kind(material)
    if kind == "lambert":
        bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(m)}}
    else:
        bsdf = {"type": "measured", "filename": _file_for_mitsuba(m, clamp_negative)}
    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 1,
                       "hide_emitters": True},
        "sensor": {
            "type": "perspective", "fov": FOV_Y_DEG, "fov_axis": "y",
            "to_world": T().look_at(origin=list(CAMERA_ORIGIN), target=list(CAMERA_TARGET),
                                    up=list(CAMERA_UP)),
            "film": {"type": "hdrfilm", "width": int(resolution), "height": int(resolution),
                     "rfilter": {"type": "box"}, "pixel_format": "rgb",
                     "component_format": "float32"},
            "sampler": {"type": "independent", "sample_count": int(spp)},
        },
        "sphere": {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": SPHERE_RADIUS,
                   "bsdf": bsdf},
        "environment": {"type": "envmap", "filename": str(envmap), "scale": 1.0},
    }


def render_sphere(material, envmap, spp: int, resolution: int = 256, seed: int = 0,
                  passes: int = 1, clamp_negative: bool = True, return_variance: bool = False):
    """Render the reference scene with Mitsuba 3 (``scalar_rgb``, all cores).

    Unit sphere at the origin; perspective camera at (0, 0, 4) looking at the origin, +Y up,
    30 deg vertical field of view, ``resolution`` x ``resolution`` pixels, box filter (a pixel
    is the plain mean of its samples), independent sampler; the ``envmap`` (lat-long file,
    identity transform, scale 1) hidden from camera rays; Mitsuba's ``direct`` integrator with
    ``emitter_samples = bsdf_samples = 1``: per camera sample one environment sample and one
    BSDF sample, each with a shadow ray, combined by the power heuristic. ``material``: an RGL
    ``.bsdf`` path (``measured`` plugin, with :func:`clamped_copy` unless ``clamp_negative`` is
    False) or ``("lambert", albedo)`` (``diffuse`` plugin).

    The ``spp`` samples are taken in ``passes`` renders of ``spp / passes`` samples with seeds
    ``seed * passes + k``; the image is their mean. With ``return_variance=True`` (needs
    ``passes >= 2``) also returns the variance of each pixel's mean estimated from the spread of
    the passes, (H, W, 3). Returns (H, W, 3) float32 linear RGB, row 0 at the top.
    """
    mi = _mi()
    spp, passes = int(spp), int(passes)
    if passes < 1 or spp % passes:
        raise ValueError(f"spp ({spp}) must be a positive multiple of passes ({passes})")
    if return_variance and passes < 2:
        raise ValueError("return_variance needs passes >= 2")
    scene = _load_scene(mitsuba_scene_dict(material, envmap, spp // passes, resolution, clamp_negative),
                        material)
    imgs = np.stack([np.array(mi.render(scene, spp=spp // passes, seed=int(seed) * passes + k),
                              dtype=np.float64)[..., :3] for k in range(passes)])
    img = imgs.mean(axis=0)
    if return_variance:
        var = imgs.var(axis=0, ddof=1) / passes
        return img.astype(np.float32), var.astype(np.float32)
    return img.astype(np.float32)


def sphere_scene(material, envmap, spp: int, resolution: int = 256, seed: int = 0,
                 incident: str = "view", pattern: str = "independent", tile_size: int = 16,
                 subdivisions: int = SPHERE_SUBDIVISIONS):
    """The reference scene of :func:`render_sphere` for **our** renderer, as a
    :class:`warp_rbrdf.scene.Scene`: the same camera (``fov_axis = "y"``), unit sphere
    (analytic; ``subdivisions`` only for the icosphere fallback), hidden environment map at scale 1
    (identity rotation) and direct lighting (``max_depth = 1``). An RGL material is the ``rgl``
    type (the file evaluated exactly, ``incident`` = the tensors' incident direction, default
    the reference's "view") with the ``mis-rgl`` sampler (environment sample + the format's own
    BSDF sample, power heuristic: Mitsuba's estimator, but for the environment sample's MIS
    compensation, ``integrator.mis_compensation``, docs/sampling.md); ``("lambert", albedo)`` is the
    ``lambert`` type with ``mis`` (environment + cosine sample). ``pattern`` defaults to
    independent samples as Mitsuba's sampler (so the per-pixel variance estimates the error of
    the mean). The material is named ``"obj"``."""
    from warp_rbrdf.scene import CameraSpec, IntegratorSpec, LightSpec, MaterialSpec, Scene, ShapeSpec

    kind, m = _material_kind(material)
    if kind == "lambert":
        mat = MaterialSpec(name="obj", type="lambert", albedo=m, sampler="mis")
    else:
        mat = MaterialSpec(name="obj", type="rgl", file=m, sampler="mis-rgl", incident=incident)
    cam = CameraSpec(origin=CAMERA_ORIGIN, target=CAMERA_TARGET, up=CAMERA_UP, fov=FOV_Y_DEG,
                     fov_axis="y", resolution=(int(resolution), int(resolution)))
    return Scene(camera=cam,
                 integrator=IntegratorSpec(spp=int(spp), seed=int(seed), max_depth=1,
                                           sampler=mat.sampler, pattern=pattern,
                                           hide_environment=True, tile_size=int(tile_size)),
                 materials={"obj": mat},
                 shapes=[ShapeSpec(type="sphere", material="obj", center=(0.0, 0.0, 0.0),
                                   radius=SPHERE_RADIUS, subdivisions=int(subdivisions))],
                 lights=[LightSpec(type="envmap", file=Path(envmap), scale=1.0)],
                 path="<mitsuba reference sphere>")


def sphere_mask(resolution: int, margin: float = 1.0) -> np.ndarray:
    """(H, W) bool: pixels whose whole footprint lies on the sphere's image, at least
    ``margin`` pixels inside its silhouette (so partial coverage, where the analytic and the
    tessellated sphere differ, is excluded)."""
    n = int(resolution)
    t = np.tan(np.radians(FOV_Y_DEG) / 2)
    c = np.arange(n) + 0.5
    x = (2 * c / n - 1) * t
    X, Y = np.meshgrid(x, -x)
    # angle of a pixel's ray from the optical axis vs the sphere's angular radius
    ang = np.arctan(np.hypot(X, Y))
    alpha = np.arcsin(SPHERE_RADIUS / np.linalg.norm(CAMERA_ORIGIN))
    pix = np.arctan(2 * t / n)   # angular size of a pixel at the centre (an upper bound off it)
    return ang < alpha - (margin + 0.75) * pix


# --------------------------------------------------------------------------------------------
# Variants and timed renders (benchmarks/bench_vs_mitsuba.py)
#: Mitsuba's LLVM variant (vectorized, JIT-compiled with LLVM; needs a system libLLVM).
LLVM_VARIANT = "llvm_ad_rgb"
#: Where :func:`find_libllvm` looks for the shared LLVM library Dr.Jit loads (Debian's
#: ``libllvm19`` package first; ``DRJIT_LIBLLVM_PATH`` wins when set). Every candidate must also
#: pass :func:`libllvm_problem`: some LLVM versions abort the whole process on Dr.Jit's kernels.
LIBLLVM_CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19*", "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
                      "/usr/lib/llvm-19/lib/libLLVM*.so*", "/usr/lib/aarch64-linux-gnu/libLLVM.so.19*",
                      "/usr/lib/x86_64-linux-gnu/libLLVM-1[5-8].so", "/usr/lib/x86_64-linux-gnu/libLLVM.so.1[5-8]*")
#: The child process of :func:`libllvm_problem`: Mitsuba's LLVM variant renders an 8 x 8 diffuse
#: sphere under a constant emitter with the library named by ``DRJIT_LIBLLVM_PATH``.
LIBLLVM_PROBE = """
import drjit as dr
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
if not dr.has_backend(dr.JitBackend.LLVM):
    raise SystemExit("Dr.Jit could not load it")
scene = mi.load_dict({"type": "scene", "integrator": {"type": "direct"},
                      "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 8, "height": 8}},
                      "sphere": {"type": "sphere", "center": [0, 0, -3], "bsdf": {"type": "diffuse"}},
                      "light": {"type": "constant"}})
image = mi.render(scene, spp=4)
import numpy as np
if not float(np.mean(np.asarray(image))) > 0.0:
    raise SystemExit("the test render is black")
"""
#: Seconds the child process of :func:`libllvm_problem` may take (measured here: 0.4 s with
#: libLLVM 19 and a warm Dr.Jit kernel cache, 0.25 s for libLLVM 15 to abort).
LIBLLVM_PROBE_TIMEOUT_S = 120.0


@functools.lru_cache(maxsize=None)
def libllvm_problem(path: str) -> str | None:
    """None when Mitsuba's LLVM variant renders with the shared LLVM library ``path``, else one
    line saying why not. The test render (:data:`LIBLLVM_PROBE`) runs in a child process: a
    library that Dr.Jit loads but whose code generation aborts (libLLVM 15 cannot select the
    ``fmaximum`` Dr.Jit emits: "LLVM ERROR: Cannot select", then SIGABRT) would otherwise take
    the calling process with it. Remembered per path for the process's life."""
    import subprocess
    import sys

    env = dict(os.environ, DRJIT_LIBLLVM_PATH=str(path))
    try:
        r = subprocess.run([sys.executable, "-c", LIBLLVM_PROBE], env=env, capture_output=True,
                           text=True, timeout=LIBLLVM_PROBE_TIMEOUT_S, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return f"a test render with it did not end within {LIBLLVM_PROBE_TIMEOUT_S:.0f} s"
    if r.returncode == 0:
        return None
    lines = [ln.strip() for ln in (r.stderr + "\n" + r.stdout).splitlines() if ln.strip()]
    why = next((ln for ln in lines if "ERROR" in ln), lines[-1] if lines else "no message")
    how = f"signal {-r.returncode}" if r.returncode < 0 else f"exit status {r.returncode}"
    return f"a test render with it failed ({how}: {why[:160]})"


def find_libllvm() -> str | None:
    """The shared LLVM library for Dr.Jit's LLVM backend: ``$DRJIT_LIBLLVM_PATH`` when set, else
    the first existing match of :data:`LIBLLVM_CANDIDATES` (LLVM 19 preferred), provided that
    Mitsuba renders with it (:func:`libllvm_problem`); else None. A ``DRJIT_LIBLLVM_PATH`` that
    fails is not replaced by another library (None; :func:`set_variant` says why)."""
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env:
        return env if libllvm_problem(env) is None else None
    return next((p for p in libllvm_candidates() if libllvm_problem(p) is None), None)


def libllvm_candidates() -> list[str]:
    """The existing files matching :data:`LIBLLVM_CANDIDATES`, in its order (not yet tested)."""
    import glob

    return [hit for pattern in LIBLLVM_CANDIDATES for hit in sorted(glob.glob(pattern))]


def set_variant(variant: str = VARIANT) -> str:
    """Select Mitsuba's ``variant`` for the functions of this module that build and render
    scenes (:func:`timing_scene`, :func:`render_timed`, :func:`render_sphere`) and return it.

    An ``llvm_*`` variant needs a shared libLLVM that Mitsuba renders with (:func:`find_libllvm`):
    when ``DRJIT_LIBLLVM_PATH`` is unset it is set to that library before the variant is
    selected. Raises :class:`ReferenceUnavailable` when Mitsuba or the variant's backend cannot
    be used (a ``DRJIT_LIBLLVM_PATH`` whose test render fails is named with the reason). The
    cached ``measured`` plugins of :func:`load_bsdf` (``eval`` / ``pdf`` / ``sample``) are those
    of the variant they were first loaded with: call ``set_variant(VARIANT)`` before using them
    again."""
    mi = _mi()
    if variant.startswith("llvm"):
        lib = find_libllvm()
        if lib is None:
            env = os.environ.get("DRJIT_LIBLLVM_PATH")
            if env:
                raise ReferenceUnavailable(f"DRJIT_LIBLLVM_PATH={env}: not usable for Mitsuba's {variant!r} "
                                           f"variant: {libllvm_problem(env)}")
            tried = "".join(f"; {p}: {libllvm_problem(p)}" for p in libllvm_candidates()[:1])
            raise ReferenceUnavailable(f"Mitsuba's {variant!r} variant needs a shared libLLVM that it renders "
                                       f"with (Debian: apt-get install libllvm19) or DRJIT_LIBLLVM_PATH{tried}")
        os.environ.setdefault("DRJIT_LIBLLVM_PATH", lib)
    try:
        mi.set_variant(variant)
        if variant.startswith("llvm"):
            import drjit as dr

            if not dr.has_backend(dr.JitBackend.LLVM):
                raise RuntimeError(f"Dr.Jit could not load LLVM from {os.environ['DRJIT_LIBLLVM_PATH']}")
    except Exception as e:  # noqa: BLE001 - unknown variant, missing backend: one line
        mi.set_variant(VARIANT)    # back to the variant this module's other functions expect
        raise ReferenceUnavailable(f"Mitsuba variant {variant!r} is not usable: {e}") from None
    return mi.variant()


def set_thread_count(threads: int) -> None:
    """Number of worker threads Mitsuba renders with (Dr.Jit's thread pool, used by every
    variant's ``mi.render`` on the CPU)."""
    import drjit as dr

    _mi()
    dr.set_thread_count(int(threads))


def timing_scene(material, envmap, spp: int, resolution: int = 256, sampler: str = "multijitter",
                 clamp_negative: bool = True):
    """The reference scene of :func:`render_sphere` loaded in the **current** variant (see
    :func:`set_variant`), with Mitsuba's ``sampler`` plugin (``independent``, ``stratified``,
    ``multijitter``, ``orthogonal``, ``ldsampler``) drawing ``spp`` samples per pixel. The
    loaded ``mi.Scene`` for :func:`render_timed`."""
    d = mitsuba_scene_dict(material, envmap, spp, resolution, clamp_negative)
    d["sensor"]["sampler"] = {"type": sampler, "sample_count": int(spp)}
    return _load_scene(d, material)


def render_timed(scene, spp: int, seed: int) -> tuple[np.ndarray, float]:
    """One ``mi.render`` of a loaded scene at ``spp`` samples per pixel and ``seed``: the
    (H, W, 3) float64 image (row 0 at the top) and the wall-clock seconds of the render call
    including the transfer of the image to NumPy (which forces a JIT variant to finish; a JIT
    variant compiles its kernel on the first render of a new ``spp`` / scene layout, so warm up
    before timing)."""
    import time

    mi = _mi()
    t0 = time.perf_counter()
    img = np.array(mi.render(scene, spp=int(spp), seed=int(seed)), dtype=np.float64)[..., :3]
    return img, time.perf_counter() - t0
