"""The scene-file reference printed by ``rbrdf scene-format``: fixed text for the camera,
integrator, shapes and lights, and the material types and samplers listed from
:mod:`warp_rbrdf.registry` (so a registered material or sampler documents itself)."""
from __future__ import annotations

import textwrap

from .. import registry

_HEAD = """\
Scene file format (TOML). Every table and key is optional unless marked required.

[camera]
  origin = [0, 1, 4]        target = [0, 0.5, 0]      up = [0, 1, 0]      (look_at)
  fov = 40.0                full angle in degrees along fov_axis
  fov_axis = "x"            "x" or "y"
  resolution = [256, 256]   [width, height] in pixels

[integrator]
  spp = 16                  camera samples per pixel
  seed = 0                  same seed -> same image
  max_depth = 1             1 = direct lighting; >1 adds indirect bounces
  sampler = <per kind>      default sampler of every material (see [materials.NAME] sampler);
                            unset: each material kind's own (listed under [materials.NAME])
  pattern = "stratified"    sample generator: stratified (correlated multi-jitter) | independent
  hide_environment = false  camera rays that miss all shapes return 0 instead of the environment
  tile_size = 32            image tiles (pixels per side) launched from the thread pool
  ray_epsilon = 0           shadow/bounce ray offset; 0 = automatic (1e-5 x scene size)
  mis_compensation = 0.25   under MIS, the environment is sampled by its luminance less this
                            fraction of its mean (0 = off; never for the `light` sampler)

"""

_TAIL = """\
[[shapes]]                  any number
  type = "mesh"             mesh | sphere | plane   (required)
  material = "NAME"         (required)
  file = "..."              mesh: OBJ / PLY / GLB / STL (loaded with trimesh)
  smooth_normals = true     mesh: interpolate vertex normals (false: flat facets)
  center = [0, 0, 0]        sphere / plane
  radius = 1.0              sphere
  subdivisions = 5          sphere: icosphere level, used only when the transform is not a
                            similarity (then tessellated); otherwise the sphere is analytic
  size = [2, 2]             plane: extent along x and z; its normal is +Y before transform
  transform = { scale = 1, rotate = [angle_deg, ax, ay, az] (or a list of them),
                translate = [x, y, z] }     or  transform = { matrix = [[4x4]] }

[[lights]]                  any number of directional lights, at most one environment
  type = "directional"      directional | envmap | constant | sky   (required)
  irradiance = [1, 1, 1]    directional: W/m^2 on a surface facing the light
  direction = [0, -1, 0]    directional: direction the light travels
  colinear_with_view = false  directional: light travels along the view (target - origin)
  file = "..."              envmap: lat-long .hdr / .exr (read with OpenImageIO)
  scale = 1.0               envmap / sky: radiance multiplier
  rotate = [angle_deg, ax, ay, az]   envmap / sky: rotation of the map (or a list of them)
  radiance = [1, 1, 1]      constant: uniform environment radiance
  sun_elevation = 35.0      sky: degrees above the horizon
  sun_azimuth = 135.0       sky: degrees, 0 = -Z, 90 = +X (the lat-long u convention)
  resolution = [512, 256]   sky: size of the tabulated map

Limits (warp_rbrdf.limits; a value outside is an error, never clamped): every number finite;
  resolution sides <= 16384 and <= 2^24 pixels, spp <= 2^20, pixels x spp <= 2^33, <= 2^16
  tiles; albedo in
  [0, 1]; material scale <= 1e3; irradiance, radiance <= 1e6; envmap/sky scale <= 1e6;
  positions, directions, translations, matrix entries <= 1e6 in magnitude; lengths and scale
  factors in [1e-6, 1e6]; <= 64 materials, 4096 shapes, 64 directional lights, 2^22 triangles;
  scene file <= 1 MiB, meshes and maps <= 256 MiB, maps <= 2^24 texels, each finite, >= 0, <= 1e9.

Paths: "${RBRDF_DATA}/x" or "data:x" resolve through $RBRDF_DATA (a relative one: against the
current directory; run from a source checkout: default ../shared/data next to it; installed: no
default, set it); "pkg:x" is
warp_rbrdf/data/x; other relative paths are relative to the scene.
"""


def _materials_section() -> str:
    lines = ["[materials.NAME]            one table per material, referenced by name from shapes",
             f"  type = \"lambert\"          {' | '.join(registry.MATERIAL_NAMES)}   (required)"]
    for k in registry.MATERIALS:
        suffixes = f" (file: {' '.join(k.suffixes)})" if k.suffixes else ""
        keys = f" keys: {', '.join(k.keys)}" if k.keys else ""
        cdf = f" ({k.default_sampler_cdf} with a cdf)" if k.default_sampler_cdf else ""
        lines += textwrap.wrap(f"{k.name}: {k.summary}{suffixes};{keys}; default sampler "
                               f"{k.default_sampler}{cdf}", 92, break_on_hyphens=False,
                               initial_indent=" " * 28, subsequent_indent=" " * 30)
    lines += ["  sampler = <integrator.sampler, else the type's default sampler (above): its own",
              "            importance sampling with one environment sample, power heuristic>   one of:"]
    for s in registry.STRATEGIES:
        fb = f" (fallback: {s.fallback})" if s.fallback else ""
        lines += textwrap.wrap(f"{s.name}: {s.summary}{fb}", 92,
                               initial_indent=" " * 28, subsequent_indent=" " * 30)
    lines += [
        "  cdf = \"...\"               rbrdf-cdf .json from `rbrdf-fit cdf` (tables + rational inverse",
        "                            CDFs); without it tables are built (and rational CDFs fitted) at load",
        "  albedo = 0.8              number or [r, g, b], in [0, 1]",
        "  file = \"...\"              the material's file (types above); relative to the scene",
        "  statistic = \"median\"      projection of a 3-D file: median | mean | geometric | harmonic | rms",
        "  scale = 1.0               number or [r, g, b] multiplier",
        "  incident = \"view\"         RGL .bsdf files: which direction is the tensors' theta_i: view",
        "                            (the reference implementations', Mitsuba 3 and pbrt-v4) | light",
        "  interpolation = \"linear\"  measured: between the MERL grid's bin centres: linear (trilinear",
        "                            in the grid's coordinates) | nearest (the bin, as MERL's own code)",
        "  unvouched = \"projected\"   rational: where the fit is flagged (not within its bound), the",
        "                            measured projection of its source file (found next to the fit,",
        "                            the scene or in $RBRDF_DATA) clamped to the region's measured",
        "                            range | refuse: fail naming the material, file and region", ""]
    return "\n".join(lines) + "\n"


FORMAT_DOC = _HEAD + _materials_section() + _TAIL
