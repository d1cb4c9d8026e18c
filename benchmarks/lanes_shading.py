"""The ``rgl`` material's sample and the two light estimates of one lane, without branches (the
K-lane prototype, :mod:`benchmarks.lanes_prototype`): the arithmetic of the production
material and technique (:mod:`warp_rbrdf.materials.rgl`; the same expressions in the same
order, so the values agree up to float rounding), each ``if`` turned into a ``wp.where`` so
that a lane computes every step and a mask keeps or drops the result. The binary searches are
not here: they run over all lanes at once (:func:`benchmarks.lanes_kernels.make_lane_kernel`),
and these functions take their results (rows, columns).

:func:`env_light_branchy` and :func:`bsdf_light_branchy` are the two light estimates with the
scalar kernel's branches (the ``hybrid`` variant): the work of an unusable sample is skipped.
"""
import importlib

import warp as wp

from warp_rbrdf import fastmath as fm
from warp_rbrdf.materials import rgl as R

from .lanes_scene import (
    Env,
    Tables,
    bitangent,
    env_direction,
    env_lookup,
    env_uv,
    escapes,
    origin,
    power,
    solid_angle_pdf,
    tangent,
    to_local,
)

#: the production rgl sampling functions (``sample_f``, ``eval_pdf``, ``MIN_JACOBIAN``): in the
#: material's module, or in their technique module where the checkout still has one
T = R if hasattr(R, "sample_f") else importlib.import_module("warp_rbrdf.techniques.rgl")


@wp.func
def lerp_at(f: wp.array(dtype=float), i: int, stride: int, w1: float) -> float:
    a = f[i]
    return a + w1 * (f[i + stride] - a)


@wp.func
def corners(f: wp.array(dtype=float), k: int, nx: int, stride: int, w1: float) -> wp.vec4:
    return wp.vec4(lerp_at(f, k, stride, w1), lerp_at(f, k + 1, stride, w1),
                   lerp_at(f, k + nx, stride, w1), lerp_at(f, k + nx + 1, stride, w1))


@wp.func
def cell(u: float, n: int) -> int:
    return wp.min(int(wp.max(u * float(n - 1), 0.0)), n - 2)


@wp.func
def fraction(a: float, b: float, y: float) -> float:
    """The format's linear-density inverse, both cases computed and one selected."""
    flat = 2.0 * y / (a + b)
    slope = (a - wp.sqrt(wp.max(a * a - 2.0 * y * (a - b), 0.0))) / (a - b)
    return wp.where(wp.abs(a - b) < 1.0e-4 * (a + b), flat, slope)


@wp.func
def incidence(tb: Tables, wo: wp.vec3) -> wp.vec4:
    """(t0, w1, phi_t, theta_t) of the view: its theta_i slice interval by a scan over the
    slices (uniform loads), azimuth and elevation (radians)."""
    theta_t = R.elevation(wo)
    t0 = int(0)
    for k in range(1, tb.n_theta - 1):
        t0 = wp.where(tb.f[tb.theta + k] <= theta_t, k, t0)
    p0 = tb.f[tb.theta + t0]
    p1 = tb.f[tb.theta + t0 + 1]
    return wp.vec4(float(t0), wp.clamp((theta_t - p0) / (p1 - p0), 0.0, 1.0), fm.atan2(wo[1], wo[0]), theta_t)


@wp.func
def bilinear(f: wp.array(dtype=float), off: int, ny: int, nx: int, ux: float, uy: float) -> float:
    ix = cell(ux, nx)
    iy = cell(uy, ny)
    fx = ux * float(nx - 1) - float(ix)
    fy = uy * float(ny - 1) - float(iy)
    k = off + iy * nx + ix
    a = f[k] + fx * (f[k + 1] - f[k])
    b = f[k + nx] + fx * (f[k + nx + 1] - f[k + nx])
    return a + fy * (b - a)


@wp.func
def value(tb: Tables, t0: int, w1: float, theta_t: float, phi_t: float, umx: float, umy: float,
          sx: float, sy: float, wiz: float) -> wp.vec3:
    """f_r from the warped coordinates: rgb tensor x ndf / (4 sigma), clamped, / cos(theta_l)."""
    ix = cell(sx, tb.lum_nx)
    iy = cell(sy, tb.lum_ny)
    fx = sx * float(tb.lum_nx - 1) - float(ix)
    fy = sy * float(tb.lum_ny - 1) - float(iy)
    plane = tb.lum_ny * tb.lum_nx
    v = wp.vec3(0.0)
    for c in range(3):
        q = corners(tb.f, tb.rgb + (t0 * 3 + c) * plane + iy * tb.lum_nx + ix, tb.lum_nx, 3 * plane, w1)
        a = q[0] + fx * (q[1] - q[0])
        b = q[2] + fx * (q[3] - q[2])
        v[c] = a + fy * (b - a)
    ndf = bilinear(tb.f, tb.ndf, tb.ndf_ny, tb.ndf_nx, umx, umy)
    sig = bilinear(tb.f, tb.sigma, tb.sigma_ny, tb.sigma_nx, R.theta_to_u(theta_t), R.phi_to_u(phi_t))
    v = v * (ndf / (4.0 * sig))
    return wp.vec3(wp.max(v[0], 0.0), wp.max(v[1], 0.0), wp.max(v[2], 0.0)) / wiz


@wp.func
def eval_pdf(tb: Tables, wi: wp.vec3, wo: wp.vec3, inc: wp.vec4) -> wp.vec4:
    """(f_r, pdf) at one pair: the inverse VNDF warp, the value, the luminance density."""
    t0 = int(inc[0])
    w1 = inc[1]
    sv = wi + wo
    wm = sv / wp.length(sv)
    umx = R.theta_to_u(R.elevation(wm))
    umy = R.phi_to_u(fm.atan2(wm[1], wm[0]) - inc[2])
    ny = tb.vndf_ny
    nx = tb.vndf_nx
    ix = cell(umx, nx)
    iy = cell(umy, ny)
    fx = umx * float(nx - 1) - float(ix)
    fy = umy * float(ny - 1) - float(iy)
    plane = ny * nx
    k = t0 * plane + iy * nx + ix
    v = corners(tb.f, tb.vndf_data + k, nx, plane, w1)
    cc0 = lerp_at(tb.f, tb.vndf_cond + k, plane, w1)
    cc1 = lerp_at(tb.f, tb.vndf_cond + k + nx, plane, w1)
    krow = t0 * plane + iy * nx + nx - 1
    r0 = lerp_at(tb.f, tb.vndf_cond + krow, plane, w1)
    r1 = lerp_at(tb.f, tb.vndf_cond + krow + nx, plane, w1)
    m0 = lerp_at(tb.f, tb.vndf_marg + t0 * ny + iy, ny, w1)
    gy = 1.0 - fy
    c0 = gy * v[0] + fy * v[2]
    c1 = gy * v[1] + fy * v[3]
    pdf_u = (c0 + fx * (c1 - c0)) * float((nx - 1) * (ny - 1))
    rr = gy * r0 + fy * r1
    sx = wp.where(rr > 0.0, (fx * (c0 + 0.5 * fx * (c1 - c0)) + gy * cc0 + fy * cc1) / rr, 0.0)
    sy = fy * (r0 + 0.5 * fy * (r1 - r0)) + m0
    f = value(tb, t0, w1, inc[3], inc[2], umx, umy, sx, sy, wi[2])
    # the luminance warp's density at (sx, sy)
    lx = cell(sx, tb.lum_nx)
    ly = cell(sy, tb.lum_ny)
    gx = sx * float(tb.lum_nx - 1) - float(lx)
    hy = sy * float(tb.lum_ny - 1) - float(ly)
    lplane = tb.lum_ny * tb.lum_nx
    q = corners(tb.f, tb.lum_data + t0 * lplane + ly * tb.lum_nx + lx, tb.lum_nx, lplane, w1)
    a = q[0] + gx * (q[1] - q[0])
    b = q[2] + gx * (q[3] - q[2])
    lum = (a + hy * (b - a)) * float((tb.lum_nx - 1) * (tb.lum_ny - 1))
    st = wp.sqrt(wm[0] * wm[0] + wm[1] * wm[1])
    jac = wp.max(2.0 * wp.pi * wp.pi * umx * st, T.MIN_JACOBIAN) * 4.0 * wp.dot(wo, wm)
    return wp.vec4(f[0], f[1], f[2], wp.where(jac > 0.0, wp.max(pdf_u * lum / jac, 0.0), 0.0))


@wp.func
def row_setup(f: wp.array(dtype=float), mb: int, row: int, ny: int, cb: int, nx: int, stride: int,
              w1: float, sx: float, sy: float) -> wp.vec2:
    """After the row search of a warp sample: (fy, sx scaled to the row's total)."""
    r0 = lerp_at(f, cb + nx - 1, stride, w1)
    r1 = lerp_at(f, cb + nx + nx - 1, stride, w1)
    fy = fraction(r0, r1, sy - lerp_at(f, mb + row, ny, w1))
    return wp.vec2(fy, sx * ((1.0 - fy) * r0 + fy * r1))


@wp.func
def warp_finish(f: wp.array(dtype=float), k: int, cb: int, row: int, col: int, ny: int, nx: int,
                stride: int, w1: float, fy: float, sx: float) -> wp.vec3:
    """After the column search: (u_x, u_y, density) of a warp sample (``k`` its first node)."""
    gy = 1.0 - fy
    sx = sx - (gy * lerp_at(f, cb + col, stride, w1) + fy * lerp_at(f, cb + nx + col, stride, w1))
    v = corners(f, k, nx, stride, w1)
    c0 = gy * v[0] + fy * v[2]
    c1 = gy * v[1] + fy * v[3]
    fx = fraction(c0, c1, sx)
    pdf = ((1.0 - fx) * c0 + fx * c1) * float((nx - 1) * (ny - 1))
    return wp.vec3((float(col) + fx) / float(nx - 1), (float(row) + fy) / float(ny - 1), pdf)


@wp.func
def pc_cell(cdf: wp.array(dtype=float), off: int, i: int, u: float) -> wp.vec2:
    """(fraction of ``u`` inside cell ``i``, the cell's probability) of a piecewise-constant CDF."""
    c0 = cdf[off + i]
    m = cdf[off + i + 1] - c0
    return wp.vec2(wp.where(m > 0.0, wp.clamp((u - c0) / m, 0.0, 1.0), 0.5), m)


@wp.func
def env_light(tb: Tables, env: Env, n: wp.vec3, wo: wp.vec3, inc: wp.vec4, x: float, y: float,
              pdf_uv: float) -> wp.vec3:
    """The environment sample's MIS-weighted contribution (0 where the sample is unusable)."""
    dl = env_direction(x, y)
    wl = wp.vec3(dl[0], dl[1], dl[2])
    pl = solid_angle_pdf(pdf_uv, dl[3])
    wi = to_local(n, wl)
    fp = eval_pdf(tb, wi, wo, inc)
    f = wp.vec3(fp[0], fp[1], fp[2])
    ok = pl > 0.0 and wp.dot(wl, n) > 0.0 and wi[2] > 0.0
    ok = ok and wp.max(f[0], wp.max(f[1], f[2])) > 0.0 and escapes(origin(n), wl)
    return wp.where(ok, wp.cw_mul(f, env_lookup(env, x, y)) * (wi[2] * power(pl, fp[3]) / pl), wp.vec3(0.0))


@wp.func
def bsdf_light(tb: Tables, env: Env, n: wp.vec3, wo: wp.vec3, inc: wp.vec4, s: wp.vec3, u: wp.vec3) -> wp.vec3:
    """The BSDF sample's MIS-weighted contribution from the two warps' outputs ``s``
    (luminance) and ``u`` (VNDF) (0 where the sample is unusable or the ray is blocked)."""
    theta_m = u[0] * u[0] * wp.HALF_PI
    phi_m = (2.0 * u[1] - 1.0) * wp.pi + inc[2]
    sct = fm.sincos(theta_m)
    scp = fm.sincos(phi_m)
    st = sct[0]
    wm = wp.vec3(scp[1] * st, scp[0] * st, sct[1])
    c = wp.dot(wm, wo)
    jac = wp.max(2.0 * wp.pi * wp.pi * u[0] * st, T.MIN_JACOBIAN) * 4.0 * c
    p = u[2] * s[2] / jac
    wi = wm * (2.0 * c) - wo
    ok = c > 0.0 and wi[2] > 0.0 and p > 0.0 and p <= 1.0e30
    fb = value(tb, int(inc[0]), inc[1], inc[3], inc[2], u[0], R.phi_to_u(phi_m - inc[2]), s[0], s[1], wi[2])
    wb = 1.0 / p
    wiw = tangent(n) * wi[0] + bitangent(n) * wi[1] + n * wi[2]
    thr = fb * (wi[2] * wb)
    ok = ok and wp.dot(wiw, n) > 0.0 and wp.max(thr[0], wp.max(thr[1], thr[2])) > 0.0
    ok = ok and escapes(origin(n), wiw)
    uvs = env_uv(wiw)
    row = wp.clamp(int(wp.floor(uvs[1] * float(env.h))), 0, env.h - 1)
    col = wp.clamp(int(wp.floor(uvs[0] * float(env.w))), 0, env.w - 1)
    pdf_uv = (env.marg[row + 1] - env.marg[row]) * float(env.h) * \
        ((env.cond[row * (env.w + 1) + col + 1] - env.cond[row * (env.w + 1) + col]) * float(env.w))
    pe = solid_angle_pdf(wp.where(uvs[1] >= 0.0 and uvs[1] <= 1.0, pdf_uv, 0.0), uvs[2])
    return wp.where(ok, wp.cw_mul(thr, env_lookup(env, uvs[0], uvs[1])) * power(1.0 / wb, pe), wp.vec3(0.0))


@wp.func
def env_light_branchy(tb: Tables, env: Env, n: wp.vec3, wo: wp.vec3, inc: wp.vec4, x: float, y: float,
                      pdf_uv: float) -> wp.vec3:
    """:func:`env_light` with the scalar kernel's branches: f_r, pdf and radiance only for a
    usable sample (about half of them are below the horizon)."""
    dl = env_direction(x, y)
    wl = wp.vec3(dl[0], dl[1], dl[2])
    pl = solid_angle_pdf(pdf_uv, dl[3])
    wi = to_local(n, wl)
    L = wp.vec3(0.0)
    if pl > 0.0 and wp.dot(wl, n) > 0.0 and wi[2] > 0.0:
        fp = eval_pdf(tb, wi, wo, inc)
        f = wp.vec3(fp[0], fp[1], fp[2])
        if wp.max(f[0], wp.max(f[1], f[2])) > 0.0 and escapes(origin(n), wl):
            L = wp.cw_mul(f, env_lookup(env, x, y)) * (wi[2] * power(pl, fp[3]) / pl)
    return L


@wp.func
def bsdf_light_branchy(tb: Tables, env: Env, n: wp.vec3, wo: wp.vec3, inc: wp.vec4, s: wp.vec3,
                       u: wp.vec3) -> wp.vec3:
    """:func:`bsdf_light` with the scalar kernel's branches."""
    theta_m = u[0] * u[0] * wp.HALF_PI
    phi_m = (2.0 * u[1] - 1.0) * wp.pi + inc[2]
    sct = fm.sincos(theta_m)
    scp = fm.sincos(phi_m)
    st = sct[0]
    wm = wp.vec3(scp[1] * st, scp[0] * st, sct[1])
    c = wp.dot(wm, wo)
    jac = wp.max(2.0 * wp.pi * wp.pi * u[0] * st, T.MIN_JACOBIAN) * 4.0 * c
    p = u[2] * s[2] / jac
    wi = wm * (2.0 * c) - wo
    L = wp.vec3(0.0)
    if c > 0.0 and wi[2] > 0.0 and p > 0.0 and p <= 1.0e30:
        fb = value(tb, int(inc[0]), inc[1], inc[3], inc[2], u[0], R.phi_to_u(phi_m - inc[2]), s[0], s[1], wi[2])
        wb = 1.0 / p
        wiw = tangent(n) * wi[0] + bitangent(n) * wi[1] + n * wi[2]
        thr = fb * (wi[2] * wb)
        if wp.dot(wiw, n) > 0.0 and wp.max(thr[0], wp.max(thr[1], thr[2])) > 0.0 and escapes(origin(n), wiw):
            uvs = env_uv(wiw)
            row = wp.clamp(int(wp.floor(uvs[1] * float(env.h))), 0, env.h - 1)
            col = wp.clamp(int(wp.floor(uvs[0] * float(env.w))), 0, env.w - 1)
            pdf_uv = (env.marg[row + 1] - env.marg[row]) * float(env.h) * \
                ((env.cond[row * (env.w + 1) + col + 1] - env.cond[row * (env.w + 1) + col]) * float(env.w))
            pe = solid_angle_pdf(wp.where(uvs[1] >= 0.0 and uvs[1] <= 1.0, pdf_uv, 0.0), uvs[2])
            L = wp.cw_mul(thr, env_lookup(env, uvs[0], uvs[1])) * power(1.0 / wb, pe)
    return L

