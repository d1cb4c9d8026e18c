"""warp-rbrdf renderer: Warp direct-lighting renderer for measured, projected and rational BRDFs.

Public API::

    from warp_rbrdf import load_scene, parse_scene, default_scene, render, Renderer
    img = render("scenes/sphere.toml", spp=16, seed=0)   # (H, W, 3) float32 linear RGB

Warp is imported lazily (only when a scene is built), so importing the package is cheap.
"""
from .errors import RenderError, SceneError
from .scene import FORMAT_DOC, Scene, load_scene, parse_scene

__all__ = ["RenderError", "SceneError", "Scene", "load_scene", "parse_scene", "default_scene",
           "render", "Renderer", "FORMAT_DOC"]
__version__ = "0.1.0"


def __getattr__(name):
    if name in ("render", "Renderer", "RenderStats"):
        from . import renderer as _r

        return getattr(_r, name)
    if name == "default_scene":
        from .defaults import default_scene

        return default_scene
    raise AttributeError(name)
