"""Small in-memory scenes for tests and examples (no files needed)."""
from __future__ import annotations

import functools

import numpy as np

from warp_rbrdf.scene import CameraSpec, IntegratorSpec, LightSpec, MaterialSpec, Scene, ShapeSpec


def top_down_camera(resolution=16, height=1.0, fov=40.0) -> CameraSpec:
    """A camera above the origin looking straight down (-Y), image up = -Z."""
    return CameraSpec(origin=(0.0, height, 0.0), target=(0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0),
                      fov=fov, resolution=(resolution, resolution))


def plane_scene(material: MaterialSpec, lights=(), resolution=16, spp=16, seed=0, size=100.0,
                max_depth=1, pattern="stratified", hide_environment=False) -> Scene:
    """A large plane (normal +Y) filling the view of a top-down camera."""
    return Scene(camera=top_down_camera(resolution),
                 integrator=IntegratorSpec(spp=spp, seed=seed, max_depth=max_depth, pattern=pattern,
                                           hide_environment=hide_environment, tile_size=8),
                 materials={material.name: material},
                 shapes=[ShapeSpec(type="plane", material=material.name, size=(size, size))],
                 lights=list(lights), path="<test scene>")


def spheres_scene(specs: dict) -> Scene:
    """Every material of ``specs`` (name -> :class:`MaterialSpec`) on a unit sphere of its own, in a
    row out of the view of a 4-pixel top-down camera, under a constant environment, 1 spp: a
    scene whose renderer evaluates, samples and packs them (``Renderer.eval_material``, its
    ``materials``) with one compiled kernel."""
    shapes = [ShapeSpec(type="sphere", material=s.name, center=(3.0 * k, 0.0, -20.0), radius=1.0)
              for k, s in enumerate(specs.values())]
    return Scene(camera=top_down_camera(4), integrator=IntegratorSpec(spp=1, max_depth=1), materials=specs,
                 shapes=shapes, lights=[constant_env(1.0)], path="<test>")


def hide(sc: Scene, specs) -> Scene:
    """``sc`` with the materials ``specs`` (:class:`MaterialSpec`) on small shapes no ray reaches,
    so that the scene's render kernel has their kinds and techniques (a kernel per combination
    of material kinds, techniques and geometry kinds, seconds of compiling each on a cold
    cache): inside the first sphere of ``sc`` (a plane and a sphere in turn, a tenth of its
    radius, at its centre), or else under its first plane (spheres of radius 0.01 whose centres
    lie 0.02 under it, 0.05 apart; the plane's normal is +Y, as :func:`plane_scene`'s). The
    integrator's rays leave a surface on its outer side, and a ray towards them meets the sphere
    or the plane first; the shapes lie inside the scene's bounding box, or extend it by 0.03
    (the automatic ray epsilon, 1e-5 of its diagonal, unchanged to 1e-7 in a scene of size 1 or
    more). A render estimates the scene without them, with the random stream of the scene's set
    of strategies, hidden ones included (``sample_patterns.stream_key``)."""
    specs = list(specs)
    spheres = [sh for sh in sc.shapes if sh.type == "sphere"]
    if spheres:
        sph = spheres[0]
        assert np.array_equal(sph.transform, np.eye(4)), "hide: the first sphere has a transform"
        c, r = np.asarray(sph.center, float), sph.radius
        places = [("plane", c, 0.1 * r), ("sphere", c, 0.1 * r)]
    else:
        plane = next(sh for sh in sc.shapes if sh.type == "plane")
        assert np.array_equal(plane.transform, np.eye(4)), "hide: the first plane has a transform"
        c = np.asarray(plane.center, float)
        places = [("sphere", c + (0.05 * k, -0.02, 0.0), 0.01) for k in range(len(specs))]
    for k, spec in enumerate(specs):
        assert spec.name not in sc.materials, spec.name
        sc.materials[spec.name] = spec
        kind, centre, size = places[k % len(places)]
        sc.shapes.append(ShapeSpec(type=kind, material=spec.name, center=tuple(centre), radius=size,
                                   size=(size, size)))
    return sc


@functools.lru_cache(maxsize=1)
def constant_measured():
    """A ``measured`` table of 0.1 everywhere (the MERL grid) and a small table-only inverse CDF
    of it (4 view rows; nothing to resample or tabulate at load)."""
    from fit.formats.grid import MERL_SHAPE
    from fit.formats.measured import MeasuredBRDF
    from fit.sampling.cdf_file import table_only

    shape = MERL_SHAPE + (3,)
    const = MeasuredBRDF(values=np.full(shape, 0.1), valid=np.ones(shape, bool), name="hidden")
    return const, table_only(const.evaluate, {"n_v": 4, "n_t": 8, "n_p": 8})


@functools.lru_cache(maxsize=1)
def rational_cdf():
    """Verified rational inverse CDFs (pieces layout, 4 view rows) of a white Lambert material:
    what a hidden material with a rational strategy needs (a fit that failed verification
    would fall back to the table)."""
    from fit.sampling.cdf_file import fit_cdf
    from lab.analytic import lambert as lambert_brdf

    cdf = fit_cdf(lambert_brdf((1.0, 1.0, 1.0)), name="hidden", table_params=dict(n_v=4, n_t=16, n_p=16))
    assert cdf.layout == "pieces" and not cdf.fallback, cdf.reason
    return cdf


@functools.lru_cache(maxsize=1)
def rational_model():
    """A constant 2-D rational fit of the degree class of the tests' random fits
    (``tests/test_warp_rational.random_model``: theta_h (sqrt) and theta_d, numerator tensor
    degrees (5, 3), denominator total degree 2, three channels): the kernels' specialised
    function of a scene that holds it and fits of that class is the one of those fits alone."""
    import fit.rational.basis as basis
    import fit.rational.function as function
    import fit.rational.model as model_types

    variables = [model_types.Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2)),
                 model_types.Variable("theta_d", "rad", "identity", (0.0, np.radians(80.0)))]
    dom = np.array([v.rf_domain for v in variables])
    num_e, den_e = basis.tensor_exponents((5, 3)), basis.total_degree_exponents(2, 2)
    funcs = []
    for c in range(3):   # every coefficient non-zero (a zero one is skipped: another class)
        p, q = np.full(len(num_e), 0.01), np.full(len(den_e), 0.01)
        p[0], q[0] = 0.1 * (c + 1), 1.0
        funcs.append(function.RationalFunction(dom, num_e, p, den_e, q))
    return model_types.RationalModel(name="hidden", variables=variables, functions=funcs)


@functools.lru_cache(maxsize=1)
def synthetic_rgl():
    """A tiny constant RGL-EPFL material (:class:`fit.formats.rgl.RGLBRDF`, 3 incidences,
    4 x 4 tables, rho 0.1 / pi-ish; in memory, no data file): what a hidden ``rgl`` material
    needs."""
    from fit.formats.rgl import RGLBRDF
    from fit.formats.tensor_file import TensorField

    def field(name, a, code):   # dtype codes of the tensor format: 1 uint8, 10 float32
        a = np.ascontiguousarray(a)
        return TensorField(name, code, 0, tuple(a.shape), a)

    n, f32 = 3, np.float32
    fields = {"description": field("description", np.frombuffer(b"hidden", np.uint8), 1),
              "jacobian": field("jacobian", np.array([1], np.uint8), 1),
              "phi_i": field("phi_i", np.zeros(1, f32), 10),
              "theta_i": field("theta_i", np.radians(np.array([0.0, 45.0, 90.0], f32)), 10),
              "ndf": field("ndf", np.ones((4, 4), f32), 10),
              "sigma": field("sigma", np.ones((4, 4), f32), 10),
              "vndf": field("vndf", np.ones((1, n, 4, 4), f32), 10),
              "luminance": field("luminance", np.ones((1, n, 4, 4), f32), 10),
              "rgb": field("rgb", np.full((1, n, 3, 4, 4), 0.1, f32), 10)}
    return RGLBRDF(fields, name="hidden")


#: the material kinds and BSDF techniques of :func:`common_kernel`
COMMON_KINDS = ("lambert", "measured", "rational", "rgl")
COMMON_TECHNIQUES = ("cosine", "uniform", "tabulated", "rational", "rgl")


def common_kernel(sc: Scene) -> Scene:
    """``sc`` (``lambert``, ``measured``, ``rational`` and ``rgl`` materials, the rational ones
    of the class of :func:`rational_model`; cosine, uniform, tabulated, rational and rgl BSDF
    samples: :data:`COMMON_KINDS`, :data:`COMMON_TECHNIQUES`) with hidden materials (:func:`hide`) of
    these kinds and techniques, and a hidden sphere or plane: its render kernel is the common
    test kernel of triangles, analytic spheres, these kinds and techniques (or, rendered with
    ``analytic_spheres=False``, of triangles only), which the render tests of several files
    share (each kernel compiles once per kernel cache). The hidden materials: Lambert with
    ``mis`` (environment + cosine), ``tabulated`` (the table of :func:`constant_measured`)
    and ``rational`` (:func:`rational_cdf`; BSDF sample only), the constant ``measured``
    table with ``uniform``, :func:`rational_model` with ``mis``, :func:`synthetic_rgl` with
    ``mis-rgl``."""
    const, table = constant_measured()
    return hide(sc, [lambert(name="hidden-mis", albedo=1.0, sampler="mis"),
                     MaterialSpec(name="hidden-uniform", type="measured", data=const, sampler="uniform"),
                     MaterialSpec(name="hidden-tabulated", type="lambert", albedo=(1.0, 1.0, 1.0),
                                  sampler="tabulated", cdf=table),
                     MaterialSpec(name="hidden-rational", type="lambert", albedo=(1.0, 1.0, 1.0),
                                  sampler="rational", cdf=rational_cdf()),
                     MaterialSpec(name="hidden-fit", type="rational", data=rational_model(), sampler="mis"),
                     MaterialSpec(name="hidden-rgl", type="rgl", data=synthetic_rgl(), sampler="mis-rgl")])


def lambert(name="m", albedo=1.0, sampler="mis") -> MaterialSpec:
    return MaterialSpec(name=name, type="lambert", albedo=tuple(np.broadcast_to(albedo, 3).astype(float)),
                        sampler=sampler)


def constant_env(radiance=1.0) -> LightSpec:
    return LightSpec(type="constant", radiance=tuple(np.broadcast_to(radiance, 3).astype(float)))


def image_env(image, rotation=None) -> LightSpec:
    l = LightSpec(type="envmap", image=np.asarray(image, np.float32))
    if rotation is not None:
        l.rotation = np.asarray(rotation, float)
    return l


def directional(to_light, irradiance=1.0) -> LightSpec:
    d = -np.asarray(to_light, float)
    return LightSpec(type="directional", direction=tuple(d / np.linalg.norm(d)),
                     irradiance=tuple(np.broadcast_to(irradiance, 3).astype(float)))


def project_to_film(camera: CameraSpec, points) -> np.ndarray:
    """Film coordinates (px, py) of world points (inverse of the camera convention)."""
    from warp_rbrdf.camera import camera_frame

    o, r, u, f = camera_frame(camera)
    W, H = camera.resolution
    q = np.asarray(points, float) - o
    z = q @ f
    a = (q @ r) / np.dot(r, r) / z
    b = (q @ u) / np.dot(u, u) / z
    return np.stack([(a + 1) * W / 2, (1 - b) * H / 2], -1)
