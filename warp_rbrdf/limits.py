"""Resource and range limits of everything ``rbrdf`` reads or is asked to render.

Rule (as :mod:`fit.limits`, whose memory budget is shared): an input of at most 10 MB -- a
scene, a mesh, an environment map or a command-line value -- may not make ``rbrdf`` use more
than about 2 GB of memory before it either renders or stops with a one-line error. Every size a
scene file or a flag can set is bounded here and checked *before* anything of that size is
allocated; every number a scene states is finite and within a stated range, so that no product
of them overflows float32 in the kernels (a value beyond a range is refused, never clamped).
docs/robustness.md lists them with the measurements behind them.

Rational and CDF files are read through :mod:`fit` and bounded by :mod:`fit.limits`.
"""
from __future__ import annotations

from fit.limits import MEMORY_BUDGET_BYTES

# --- files -------------------------------------------------------------------------------------
#: Largest scene file (TOML) read, in bytes (the shipped scenes are < 2 kB).
MAX_SCENE_BYTES = 1 << 20
#: Deepest nesting of tables and arrays in a scene file (scenes need 4: rotate lists in a
#: transform table in a shape); deeper values are refused before they are looked at.
MAX_TOML_DEPTH = 16
#: Largest mesh file read, in bytes (the shared meshes are <= 3 MB); a binary PLY of
#: :data:`MAX_TRIANGLES` triangles is about 80 MB.
MAX_MESH_BYTES = 256 << 20
#: Largest environment-map file read, in bytes (the shared 1k maps are 1.6 MB).
MAX_ENV_BYTES = 256 << 20

# --- image and sampling ------------------------------------------------------------------------
#: Largest image side (camera.resolution, --resolution) and pixel count (4096 x 4096).
MAX_RESOLUTION_SIDE = 16384
MAX_PIXELS = 1 << 24
#: Most camera samples per pixel (integrator.spp, --spp): the kernels count samples in 32-bit
#: integers (unchecked, 2^31 wraps into an all-black image).
MAX_SPP = 1 << 20
#: Most camera samples of one render, width x height x spp (e.g. 2048 x 2048 at 2048 spp);
#: at the CPU's ~1-3 M samples/s of a simple scene that is already about a day.
MAX_SAMPLES = 1 << 33
#: Most image tiles of one CPU render, ceil(W / tile_size) x ceil(H / tile_size): each is a
#: launch and a future of the thread pool (measured: ~2 kB and ~0.1 ms each; tile_size = 1 at
#: 512^2 took 796 MB and 27 s, at 4096^2 it would take ~34 GB). The default 32 gives 16384
#: tiles at 4096^2.
MAX_TILES = 1 << 16
#: Estimated bytes per pixel of one render: the two vec3 float32 accumulation buffers (24),
#: the image (12, a copy on a GPU), the EXR writer's copy (12), the PNG (3 + row-block
#: temporaries) and the finite check (3): 64 with margin. Measured on the CPU: 24 B/pixel of
#: peak RSS above a small render at 2048^2 and 4096^2 (docs/robustness.md).
RENDER_BYTES_PER_PIXEL = 64

#: Largest --exposure magnitude (stops) and --threads.
MAX_EXPOSURE_EV = 64.0
MAX_THREADS = 1024

# --- scene values -------------------------------------------------------------------------------
#: Largest magnitude of a position, direction or translation in scene units, and of a 4x4
#: transform-matrix entry.
MAX_COORDINATE = 1e6
#: Range of a length (sphere radius, plane size) and of a transform scale factor's magnitude.
MIN_LENGTH = 1e-6
MAX_LENGTH = 1e6
#: Largest rotation angle magnitude, in degrees.
MAX_ANGLE_DEG = 1e6
#: Largest diffuse albedo (energy conservation: a Lambert surface reflects at most all).
MAX_ALBEDO = 1.0
#: Largest material ``scale`` multiplier of a measured, projected or rational BRDF.
MAX_MATERIAL_SCALE = 1e3
#: Largest directional irradiance (W/m^2; the sun ~1000) and constant radiance (W/(m^2 sr)).
MAX_IRRADIANCE = 1e6
MAX_RADIANCE = 1e6
#: Largest envmap / sky ``scale``, and largest texel value of an environment map (the shared
#: maps peak at 6.9e4; float32 squares of the products must stay finite).
MAX_ENV_SCALE = 1e6
MAX_ENV_TEXEL = 1e9
#: Most texels of an environment map or sky table (8192 x 4096 maps are not accepted: 4096 x
#: 2048 are), and the estimated bytes per texel of reading it and building its sampling
#: distribution (float64 luminance, CDFs, mip levels and the float32 image): measured 59 B per
#: texel of peak RSS for a 4096 x 2048 EXR (docs/robustness.md).
MAX_ENV_PIXELS = 1 << 24
ENV_BYTES_PER_TEXEL = 80
#: Largest ray epsilon (scene units).
MAX_RAY_EPSILON = 1e3
#: Most materials, shapes and directional lights of a scene (each material kind and technique
#: is compiled into the kernel; each light is visited by every sample).
MAX_MATERIALS = 64
MAX_SHAPES = 4096
MAX_DIRECTIONAL_LIGHTS = 64
#: Most inverse-CDF data a scene may have built while it loads: tables tabulated from a material
#: (not found in the shipped or user table cache) plus rational inverse CDFs fitted at load (a
#: ``mis-rational`` material without ``cdf =``). Each takes seconds to tens of seconds (a table
#: ~5 s on an idle core here, 24 s under load; a fit longer), so a small scene file naming many
#: such materials would otherwise run for many minutes before rendering. ``rbrdf-fit cdf`` makes
#: the file once; ``cdf = "file.json"`` then costs a read.
MAX_CDF_BUILDS_AT_LOAD = 4
#: Most triangles of the whole scene (meshes, planes, tessellated spheres), each mesh file
#: included; the shared bunny has 69451.
MAX_TRIANGLES = 1 << 22


def render_memory_estimate(width: int, height: int) -> int:
    """Estimated bytes of the image buffers of a ``width`` x ``height`` render."""
    return int(width) * int(height) * RENDER_BYTES_PER_PIXEL


def check_render_size(width: int, height: int, spp: int) -> str | None:
    """None when a ``width`` x ``height`` render at ``spp`` samples per pixel is within the
    limits above; else the problem, one line naming the limit (callers prefix the flag or the
    scene key)."""
    w, h, n = int(width), int(height), int(spp)
    if not (1 <= w <= MAX_RESOLUTION_SIDE and 1 <= h <= MAX_RESOLUTION_SIDE):
        return (f"resolution {w} x {h}: each side must be in [1, {MAX_RESOLUTION_SIDE}] "
                "(warp_rbrdf.limits.MAX_RESOLUTION_SIDE)")
    if w * h > MAX_PIXELS:
        return (f"resolution {w} x {h} = {w * h} pixels is above the limit {MAX_PIXELS} "
                "(warp_rbrdf.limits.MAX_PIXELS)")
    if not 1 <= n <= MAX_SPP:
        return f"spp {n} is outside [1, {MAX_SPP}] (warp_rbrdf.limits.MAX_SPP)"
    if w * h * n > MAX_SAMPLES:
        return (f"{w} x {h} pixels x {n} spp = {w * h * n} samples is above the limit {MAX_SAMPLES} "
                "(warp_rbrdf.limits.MAX_SAMPLES)")
    est = render_memory_estimate(w, h)
    if est > MEMORY_BUDGET_BYTES:
        return (f"a {w} x {h} image would need about {est / 2**30:.3g} GiB of memory, above the limit "
                f"{MEMORY_BUDGET_BYTES / 2**30:.3g} GiB (fit.limits.MEMORY_BUDGET_BYTES)")
    return None


def check_tiles(width: int, height: int, tile_size: int) -> str | None:
    """None when a ``width`` x ``height`` image in tiles of ``tile_size`` pixels has at most
    :data:`MAX_TILES` tiles, else the problem (one line)."""
    n = -(-int(width) // int(tile_size)) * -(-int(height) // int(tile_size))
    if n > MAX_TILES:
        return (f"tile_size {tile_size} cuts a {width} x {height} image into {n} tiles, above the limit "
                f"{MAX_TILES} (warp_rbrdf.limits.MAX_TILES); use larger tiles")
    return None


def check_env_size(width: int, height: int) -> str | None:
    """None when a ``width`` x ``height`` environment map is within the limits, else the
    problem (one line)."""
    w, h = int(width), int(height)
    if w < 1 or h < 2:
        return f"{w} x {h} texels: expected at least 1 x 2"
    if w * h > MAX_ENV_PIXELS:
        return (f"{w} x {h} = {w * h} texels is above the limit {MAX_ENV_PIXELS} "
                "(warp_rbrdf.limits.MAX_ENV_PIXELS)")
    est = w * h * ENV_BYTES_PER_TEXEL
    if est > MEMORY_BUDGET_BYTES:
        return (f"{w} x {h} texels would need about {est / 2**30:.3g} GiB of memory, above the limit "
                f"{MEMORY_BUDGET_BYTES / 2**30:.3g} GiB (fit.limits.MEMORY_BUDGET_BYTES)")
    return None
