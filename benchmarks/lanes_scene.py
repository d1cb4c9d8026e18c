"""The scene of the K-lane prototype (:mod:`benchmarks.lanes_prototype`) as Warp data and
branch-free scalar functions shared by every variant: the reference sphere (unit sphere at the
origin, camera at (0, 0, 4) looking down -z, y up), an ``rgl`` material's tables, a lat-long
map with its sampling CDFs, the random numbers and rays.

Directions: ``wo`` the view, ``wi`` the light, local frame z = normal; the map is lat-long
(``u = atan2(x, -z) / 2pi``, ``v = theta / pi`` from +Y, the conventions of
:mod:`warp_rbrdf.lights.latlong`), its radiance bilinear (columns texel-centred and periodic,
rows clamped), its sampling density piecewise constant over the texel cells.
"""
import warp as wp

from warp_rbrdf import fastmath as fm
from warp_rbrdf.sample_patterns import hash3, hash_u32

#: camera of the reference scene: origin (0, 0, 4) looking down -z, y up
CAMERA_Z = 4.0
#: ray offset off the surface (scaled by 1 + max |p|, as the integrator's)
EPS = 1.0e-4
#: the golden-ratio constant that spreads dimensions apart in the hash (uint32: no int32 overflow)
GOLDEN = wp.constant(wp.uint32(0x9E3779B1))


@wp.struct
class Tables:
    """An ``rgl`` material's float tables (:func:`warp_rbrdf.materials.rgl.pack`) and the
    header's offsets (fields named as ``RGL_*``); two or more theta_i slices, Jacobian on."""

    f: wp.array(dtype=float)
    n_theta: int
    theta: int
    vndf_ny: int
    vndf_nx: int
    vndf_data: int
    vndf_cond: int
    vndf_marg: int
    lum_ny: int
    lum_nx: int
    lum_data: int
    lum_cond: int
    lum_marg: int
    rgb: int
    ndf_ny: int
    ndf_nx: int
    ndf: int
    sigma_ny: int
    sigma_nx: int
    sigma: int


@wp.struct
class Env:
    """Lat-long map: ``rgb`` (H, W, 3) flat, float32; its sampling distribution over the
    H x W texel cells, ``marg`` (H + 1) and ``cond`` (H rows of W + 1), CDFs in float32."""

    rgb: wp.array(dtype=float)
    marg: wp.array(dtype=float)
    cond: wp.array(dtype=float)
    h: int
    w: int


@wp.struct
class View:
    res: int           # square image, pixels
    spp: int
    seed: int
    tan_half: float    # tan(vertical fov / 2)


# --------------------------------------------------------------------------------------------
# shared scalar pieces (branch-free)
@wp.func
def uniform(key: wp.uint32, dim: int) -> float:
    """A uniform in [0, 1) of a sample's key and a dimension."""
    return float(hash_u32(key ^ hash_u32(wp.uint32(dim) * GOLDEN)) >> wp.uint32(8)) \
        * (1.0 / 16777216.0)


@wp.func
def sample_key(view: View, pix: int, s: int) -> wp.uint32:
    return hash3(wp.uint32(view.seed), wp.uint32(pix), wp.uint32(s))


@wp.func
def camera_hit(view: View, px: int, py: int, key: wp.uint32):
    """(hit 1/0, normal = hit point, wo world) of the camera sample; a miss returns a dummy
    upward frame so that the lanes compute finite values."""
    a = 2.0 * (float(px) + uniform(key, 0)) / float(view.res) - 1.0
    b = 1.0 - 2.0 * (float(py) + uniform(key, 1)) / float(view.res)
    d = wp.normalize(wp.vec3(a * view.tan_half, b * view.tan_half, -1.0))
    o = wp.vec3(0.0, 0.0, CAMERA_Z)
    bb = wp.dot(o, d)
    disc = bb * bb - (wp.dot(o, o) - 1.0)
    t = -bb - wp.sqrt(wp.max(disc, 0.0))
    hit = disc > 0.0 and t > 0.0
    n = wp.normalize(o + d * t)
    return wp.where(hit, 1.0, 0.0), wp.where(hit, n, wp.vec3(0.0, 0.0, 1.0)), wp.where(hit, -d, n)


@wp.func
def tangent(n: wp.vec3) -> wp.vec3:
    """Duff et al.'s branchless orthonormal basis (the integrator's)."""
    sign = wp.where(n[2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[2])
    return wp.vec3(1.0 + sign * n[0] * n[0] * a, sign * n[0] * n[1] * a, -sign * n[0])


@wp.func
def bitangent(n: wp.vec3) -> wp.vec3:
    sign = wp.where(n[2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[2])
    return wp.vec3(n[0] * n[1] * a, sign + n[1] * n[1] * a, -n[1])


@wp.func
def to_local(n: wp.vec3, w: wp.vec3) -> wp.vec3:
    return wp.vec3(wp.dot(w, tangent(n)), wp.dot(w, bitangent(n)), wp.dot(w, n))


@wp.func
def origin(n: wp.vec3) -> wp.vec3:
    """Shadow-ray origin off the unit sphere's point ``n``."""
    return n + n * (EPS * (1.0 + wp.max(wp.abs(n[0]), wp.max(wp.abs(n[1]), wp.abs(n[2])))))


@wp.func
def escapes(o: wp.vec3, d: wp.vec3) -> bool:
    """The ray misses the unit sphere (the shadow / escape test, analytic)."""
    b = wp.dot(o, d)
    disc = b * b - (wp.dot(o, o) - 1.0)
    sq = wp.sqrt(wp.max(disc, 0.0))
    return not (disc > 0.0 and (-b + sq) > 1.0e-6)


@wp.func
def power(pa: float, pb: float) -> float:
    """The integrator's power heuristic pa^2 / (pa^2 + pb^2), branch-free."""
    big = wp.max(pa, pb)
    r = wp.min(pa, pb) / wp.where(big > 0.0, big, 1.0)
    w = wp.where(pa >= pb, 1.0 / (1.0 + r * r), r * r / (1.0 + r * r))
    return wp.where(pa <= 0.0, 0.0, wp.where(pb <= 0.0, 1.0, w))


@wp.func
def env_lookup(env: Env, u: float, v: float) -> wp.vec3:
    """Bilinear radiance at (u, v) (columns texel-centred and periodic, rows clamped)."""
    x = u * float(env.w) - 0.5
    y = wp.clamp(v * float(env.h - 1), 0.0, float(env.h - 1))
    xf = wp.floor(x)
    fx = x - xf
    c0 = int(xf)
    c0 = wp.where(c0 < 0, c0 + env.w, wp.where(c0 >= env.w, c0 - env.w, c0))
    c1 = wp.where(c0 + 1 >= env.w, 0, c0 + 1)
    r0 = wp.min(int(y), env.h - 1)
    r1 = wp.min(r0 + 1, env.h - 1)
    fy = y - float(r0)
    k00 = 3 * (r0 * env.w + c0)
    k01 = 3 * (r0 * env.w + c1)
    k10 = 3 * (r1 * env.w + c0)
    k11 = 3 * (r1 * env.w + c1)
    out = wp.vec3(0.0)
    for c in range(3):
        top = env.rgb[k00 + c] + fx * (env.rgb[k01 + c] - env.rgb[k00 + c])
        bot = env.rgb[k10 + c] + fx * (env.rgb[k11 + c] - env.rgb[k10 + c])
        out[c] = top + fy * (bot - top)
    return out


@wp.func
def env_direction(u: float, v: float) -> wp.vec4:
    """(direction, sin theta) of map coordinates."""
    st = fm.sincos(v * wp.pi)
    sp = fm.sincos(u * (2.0 * wp.pi))
    return wp.vec4(sp[0] * st[0], st[1], -sp[1] * st[0], st[0])


@wp.func
def env_uv(d: wp.vec3) -> wp.vec3:
    """(u, v, sin theta) of a world direction."""
    u = fm.atan2(d[0], -d[2]) * (0.5 / wp.pi)
    st = wp.sqrt(d[0] * d[0] + d[2] * d[2])
    return wp.vec3(u - wp.floor(u), fm.atan2(st, d[1]) * (1.0 / wp.pi), st)


@wp.func
def solid_angle_pdf(pdf_uv: float, st: float) -> float:
    return wp.where(st > 0.0, pdf_uv / (2.0 * wp.pi * wp.pi * wp.max(st, 1.0e-30)), 0.0)
