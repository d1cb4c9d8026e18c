"""Small in-memory scenes for tests and examples (no files needed)."""
from __future__ import annotations

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
