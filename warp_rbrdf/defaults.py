"""The embedded default scene: a sphere on a plane under a procedural sky.

It needs no file outside the package, so ``rbrdf render`` works on a fresh clone. The sphere
uses a rational BRDF shipped in ``warp_rbrdf/data/*.json`` when one exists; otherwise a Lambert
fallback. No sampler is named, so every material uses its kind's default strategy
(:func:`warp_rbrdf.registry.default_strategy`): the rational sphere ``mis-tabulated`` (its
inverse-CDF table is tabulated from the fit at load), the floor ``mis``.
"""
from __future__ import annotations

from .paths import PACKAGE_DATA
from .scene import Scene, parse_scene

DEFAULT_TOML = """
[camera]
origin = [0.0, 1.6, 4.2]
target = [0.0, 0.8, 0.0]
up = [0.0, 1.0, 0.0]
fov = 35.0
resolution = [256, 256]

[integrator]
spp = 16
seed = 0
max_depth = 1

[materials.sphere]
{sphere_material}

[materials.floor]
type = "lambert"
albedo = [0.45, 0.45, 0.45]

[[shapes]]
type = "sphere"
center = [0.0, 0.8, 0.0]
radius = 0.8
material = "sphere"

[[shapes]]
type = "plane"
size = [8.0, 8.0]
material = "floor"

[[lights]]
type = "sky"
sun_elevation = 40.0
sun_azimuth = 140.0
"""

LAMBERT_FALLBACK = 'type = "lambert"\nalbedo = [0.7, 0.35, 0.2]'


#: The shipped fit the default sphere prefers (glossy, fitted by ``rbrdf-fit brdf``).
PREFERRED_DEFAULT = "satin_rosaline_rgb.json"


def shipped_coefficient_files():
    """Shipped coefficient files, the preferred default first."""
    files = sorted(PACKAGE_DATA.glob("*.json")) if PACKAGE_DATA.is_dir() else []
    return sorted(files, key=lambda p: p.name != PREFERRED_DEFAULT)


def default_material_toml() -> str:
    files = shipped_coefficient_files()
    if files:
        return f'type = "rational"\nfile = "pkg:{files[0].name}"'
    return LAMBERT_FALLBACK


def default_scene() -> Scene:
    return parse_scene(DEFAULT_TOML.format(sphere_material=default_material_toml()),
                       path="<default scene>")
