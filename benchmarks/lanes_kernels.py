"""Warp kernels of the K-lane prototype (:mod:`benchmarks.lanes_prototype`): one camera sample
of the reference sphere scene with an ``rgl`` material under an environment map
(:mod:`benchmarks.lanes_scene`), written two ways over the same random numbers.

The work of a sample (the ``rgl`` material's ``mis-rgl`` estimator, direct light, hidden map):
camera ray -> analytic unit sphere -> one environment sample (2-D piecewise-constant warp of
luminance x sin(theta) over the map's texels: two binary searches) with f_r and the BSDF pdf
at it (inverse VNDF warp, rgb tensor, ndf / sigma, luminance density) and a shadow ray ->
one BSDF sample (luminance warp then VNDF warp, each a binary search over the rows' marginal
CDF and one over the chosen row's conditional CDF, interpolated between theta_i slices) with
f_r, an escape ray and the map's radiance and pdf where it escapes; power-heuristic MIS.

* :func:`make_scalar_kernel`: one sample at a time, as the integrator runs today: the
  production ``rgl`` functions (``sample_f``, ``eval_pdf``), the distribution module's 2-D
  sampler (:func:`warp_rbrdf.distribution.pc2d_sample`: early-exit ``while`` searches), branches.
* :func:`make_lane_kernel`: ``K`` samples of one pixel per step of a Warp thread's loop, the
  lanes' state in fixed-size Warp vectors and matrices (a row per quantity, a column per lane),
  every binary search a fixed sequence of halving steps whose inner loop runs over the lanes
  (the step count depends only on the table size, so it is the same for every lane), and the
  rest a branch-free scalar function called once per lane (:mod:`benchmarks.lanes_shading`).
  ``K = 1`` is the branch-free scalar kernel. The lane loops are unrolled by Warp or left as
  loops for LLVM's loop vectorizer (the module option ``max_unroll``).
"""
import warp as wp

from warp_rbrdf.distribution import pc2d_pdf, pc2d_sample
from warp_rbrdf.materials.data import Materials

from .lanes_scene import (
    Env,
    Tables,
    View,
    bitangent,
    camera_hit,
    env_direction,
    env_lookup,
    env_uv,
    escapes,
    origin,
    power,
    sample_key,
    solid_angle_pdf,
    tangent,
    to_local,
    uniform,
)
from .lanes_shading import (
    T,
    bsdf_light,
    bsdf_light_branchy,
    env_light,
    env_light_branchy,
    incidence,
    lerp_at,
    pc_cell,
    row_setup,
    warp_finish,
)

#: the format's uniform clamp inside its warps (2^-24)
WARP_EPS = 5.9604645e-8


# --------------------------------------------------------------------------------------------
# today's scalar kernel
@wp.func
def scalar_env_light(mats: Materials, env: Env, n: wp.vec3, wo: wp.vec3, key: wp.uint32, L: wp.vec3) -> wp.vec3:
    """``L`` plus the environment sample's contribution, one sample at a time (the scalar
    kernel's: the distribution module's 2-D warp, f_r and the BSDF pdf there, a shadow ray,
    power-heuristic MIS); ``n`` the normal, ``wo`` the local view."""
    org = origin(n)
    x, y, pdf_uv = pc2d_sample(env.marg, 0, env.cond, 0, env.h, env.w, uniform(key, 2), uniform(key, 3))
    dl = env_direction(x, y)
    wl = wp.vec3(dl[0], dl[1], dl[2])
    pl = solid_angle_pdf(pdf_uv, dl[3])
    if pl > 0.0 and wp.dot(wl, n) > 0.0:
        wi = to_local(n, wl)
        if wi[2] > 0.0:
            f, pb, _has = T.eval_pdf(mats, 0, wi, wo)
            if wp.max(f[0], wp.max(f[1], f[2])) > 0.0:
                if escapes(org, wl):
                    L = L + wp.cw_mul(f, env_lookup(env, x, y)) * (wi[2] * power(pl, pb) / pl)
    return L


@wp.func
def scalar_bsdf_light(mats: Materials, env: Env, n: wp.vec3, wo: wp.vec3, key: wp.uint32, L: wp.vec3) -> wp.vec3:
    """``L`` plus the BSDF sample's contribution, one sample at a time (the production
    ``sample_f``, an escape ray, the map's radiance and pdf, power-heuristic MIS)."""
    org = origin(n)
    bs, fb, _hf = T.sample_f(mats, 0, wo, wp.vec2(uniform(key, 4), uniform(key, 5)))
    wi = wp.vec3(bs[0], bs[1], bs[2])
    wb = bs[3]
    if wb > 0.0 and wi[2] > 0.0:
        wiw = tangent(n) * wi[0] + bitangent(n) * wi[1] + n * wi[2]
        if wp.dot(wiw, n) > 0.0:
            thr = fb * (wi[2] * wb)
            if wp.max(thr[0], wp.max(thr[1], thr[2])) > 0.0:
                if escapes(org, wiw):
                    uvs = env_uv(wiw)
                    pe = solid_angle_pdf(pc2d_pdf(env.marg, 0, env.cond, 0, env.h, env.w, uvs[0], uvs[1]), uvs[2])
                    L = L + wp.cw_mul(thr, env_lookup(env, uvs[0], uvs[1])) * power(1.0 / wb, pe)
    return L


def make_scalar_kernel(options: dict, stages: int = 3):
    """One sample per loop iteration, the production functions (module ``options``). ``stages``
    < 3 stops a sample early for the cost breakdown: 1 after the camera ray, hit and frame, 2
    after the environment sample."""

    @wp.func
    def shade(mats: Materials, env: Env, view: View, px: int, py: int, key: wp.uint32) -> wp.vec3:
        hit, n, wo_w = camera_hit(view, px, py, key)
        L = wp.vec3(0.0)
        if hit == 0.0:
            return L
        wo = to_local(n, wo_w)
        if wp.static(stages < 2):
            return wo
        L = scalar_env_light(mats, env, n, wo, key, L)
        if wp.static(stages < 3):
            return L
        return scalar_bsdf_light(mats, env, n, wo, key, L)

    @wp.kernel(module="unique", enable_backward=False, module_options=options)
    def render_scalar(mats: Materials, env: Env, view: View, x0: int, y0: int, tile_w: int,
                      out: wp.array(dtype=wp.vec3)):
        tid = wp.tid()
        px = x0 + tid % tile_w
        py = y0 + tid // tile_w
        if px >= view.res or py >= view.res:
            return
        pix = py * view.res + px
        acc = wp.vec3(0.0)
        for s in range(view.spp):
            acc = acc + shade(mats, env, view, px, py, sample_key(view, pix, s))
        out[pix] = acc / float(view.spp)

    return render_scalar


# --------------------------------------------------------------------------------------------
# K lanes per thread
#: rows of a lane state (one column per lane): hit (1/0), normal, view (local), incidence
#: (t0 as a float, w1, phi_t, theta_t), the environment's and the BSDF's uniforms
(F_HIT, F_NX, F_NY, F_NZ, F_WOX, F_WOY, F_WOZ, F_T0, F_W1, F_PHI, F_THETA, F_EU, F_EV, F_BX,
 F_BY) = (wp.constant(i) for i in range(15))
N_FIELDS = 15


def make_lane_kernel(K: int, options: dict, stages: int = 3, branchy: bool = False):
    """``K`` samples of a pixel per step of a thread's loop (``spp`` a multiple of ``K``);
    ``stages`` as for :func:`make_scalar_kernel` (1: after the incidence). ``branchy``: the
    per-lane shading with the scalar kernel's branches (:func:`env_light_branchy`,
    :func:`bsdf_light_branchy`), the searches still over all lanes."""
    vf = wp.types.vector(length=K, dtype=float)
    vi = wp.types.vector(length=K, dtype=int)

    @wp.func
    def search_pc(cdf: wp.array(dtype=float), off: vi, n: int, u: vf) -> vi:
        """Per lane the last i in [0, n - 1] with ``cdf[off + i] <= u`` (cdf[off] = 0 <= u)."""
        base = vi()
        m = n
        while m > 1:
            half = m // 2
            for i in range(K):
                b = base[i] + half
                base[i] = wp.where(cdf[off[i] + b] <= u[i], b, base[i])
            m = m - half
        return base

    @wp.func
    def search_rows(f: wp.array(dtype=float), off: vi, stride: int, w1: vf, n: int, x: vf) -> vi:
        """Per lane the last i in [0, n - 2] whose CDF, interpolated towards the next slice
        (``stride`` on), is below ``x`` (a warp sample's row)."""
        base = vi()
        m = n - 1
        while m > 1:
            half = m // 2
            for i in range(K):
                b = base[i] + half
                base[i] = wp.where(lerp_at(f, off[i] + b, stride, w1[i]) < x[i], b, base[i])
            m = m - half
        return base

    @wp.func
    def search_cols(f: wp.array(dtype=float), off: vi, nx: int, stride: int, w1: vf, fy: vf, x: vf) -> vi:
        """Per lane the last i in [0, nx - 2] whose conditional CDF, interpolated between the
        row's two node rows (weight ``fy``) and the slices, is below ``x`` (the column)."""
        base = vi()
        m = nx - 1
        while m > 1:
            half = m // 2
            for i in range(K):
                b = base[i] + half
                c = (1.0 - fy[i]) * lerp_at(f, off[i] + b, stride, w1[i]) + fy[i] * lerp_at(f, off[i] + nx + b, stride, w1[i])
                base[i] = wp.where(c < x[i], b, base[i])
            m = m - half
        return base

    @wp.func
    def warp_sample(f: wp.array(dtype=float), data: int, cond: int, marg: int, ny: int, nx: int,
                    t0: vi, w1: vf, sx_in: vf, sy_in: vf):
        """The format's forward warp per lane: (u_x, u_y, density), three lane vectors."""
        plane = ny * nx
        sx = vf()
        sy = vf()
        mb = vi()
        for i in range(K):
            sx[i] = wp.clamp(sx_in[i], WARP_EPS, 1.0 - WARP_EPS)
            sy[i] = wp.clamp(sy_in[i], WARP_EPS, 1.0 - WARP_EPS)
            mb[i] = marg + t0[i] * ny
        row = search_rows(f, mb, ny, w1, ny, sy)
        cb = vi()
        fy = vf()
        for i in range(K):
            cb[i] = cond + t0[i] * plane + row[i] * nx
            r = row_setup(f, mb[i], row[i], ny, cb[i], nx, plane, w1[i], sx[i], sy[i])
            fy[i] = r[0]
            sx[i] = r[1]
        col = search_cols(f, cb, nx, plane, w1, fy, sx)
        ux = vf()
        uy = vf()
        pdf = vf()
        for i in range(K):
            k = data + t0[i] * plane + row[i] * nx + col[i]
            u = warp_finish(f, k, cb[i], row[i], col[i], ny, nx, plane, w1[i], fy[i], sx[i])
            ux[i] = u[0]
            uy[i] = u[1]
            pdf[i] = u[2]
        return ux, uy, pdf

    # the lanes' state: one row per field, one column per lane
    st_t = wp.types.matrix(shape=(N_FIELDS, K), dtype=float)
    rgb_t = wp.types.matrix(shape=(3, K), dtype=float)

    @wp.func
    def setup(view: View, tb: Tables, pix: int, px: int, py: int, s0: int) -> st_t:
        """Camera sample, hit, frame and incidence of samples ``s0 .. s0 + K - 1``."""
        st = st_t()
        for i in range(K):
            key = sample_key(view, pix, s0 + i)
            h, n, wo_w = camera_hit(view, px, py, key)
            wo = to_local(n, wo_w)
            inc = incidence(tb, wo)
            st[F_HIT, i] = h
            st[F_NX, i] = n[0]
            st[F_NY, i] = n[1]
            st[F_NZ, i] = n[2]
            st[F_WOX, i] = wo[0]
            st[F_WOY, i] = wo[1]
            st[F_WOZ, i] = wo[2]
            st[F_T0, i] = inc[0]
            st[F_W1, i] = inc[1]
            st[F_PHI, i] = inc[2]
            st[F_THETA, i] = inc[3]
            st[F_EU, i] = uniform(key, 2)
            st[F_EV, i] = uniform(key, 3)
            st[F_BX, i] = uniform(key, 5)
            st[F_BY, i] = uniform(key, 4)
        return st

    @wp.func
    def env_lanes(tb: Tables, env: Env, st: st_t, erow: vi, ecol: vi) -> rgb_t:
        """The environment samples' contributions, given their rows and columns."""
        out = rgb_t()
        for i in range(K):
            ry = pc_cell(env.marg, 0, erow[i], st[F_EV, i])
            cx = pc_cell(env.cond, erow[i] * (env.w + 1), ecol[i], st[F_EU, i])
            x = (float(ecol[i]) + cx[0]) / float(env.w)
            y = (float(erow[i]) + ry[0]) / float(env.h)
            inc = wp.vec4(st[F_T0, i], st[F_W1, i], st[F_PHI, i], st[F_THETA, i])
            n = wp.vec3(st[F_NX, i], st[F_NY, i], st[F_NZ, i])
            wo = wp.vec3(st[F_WOX, i], st[F_WOY, i], st[F_WOZ, i])
            pdf_uv = ry[1] * cx[1] * float(env.w * env.h)
            c = wp.vec3(0.0)
            if wp.static(branchy):
                c = env_light_branchy(tb, env, n, wo, inc, x, y, pdf_uv)
            else:
                c = env_light(tb, env, n, wo, inc, x, y, pdf_uv)
            ok = st[F_HIT, i] > 0.0
            out[0, i] = wp.where(ok, c[0], 0.0)
            out[1, i] = wp.where(ok, c[1], 0.0)
            out[2, i] = wp.where(ok, c[2], 0.0)
        return out

    @wp.func
    def bsdf_lanes(tb: Tables, env: Env, st: st_t, s0: vf, s1: vf, s2: vf, u0: vf, u1: vf, u2: vf) -> rgb_t:
        """The BSDF samples' contributions, given the two warps' outputs."""
        out = rgb_t()
        for i in range(K):
            inc = wp.vec4(st[F_T0, i], st[F_W1, i], st[F_PHI, i], st[F_THETA, i])
            n = wp.vec3(st[F_NX, i], st[F_NY, i], st[F_NZ, i])
            wo = wp.vec3(st[F_WOX, i], st[F_WOY, i], st[F_WOZ, i])
            sv = wp.vec3(s0[i], s1[i], s2[i])
            uv = wp.vec3(u0[i], u1[i], u2[i])
            c = wp.vec3(0.0)
            if wp.static(branchy):
                c = bsdf_light_branchy(tb, env, n, wo, inc, sv, uv)
            else:
                c = bsdf_light(tb, env, n, wo, inc, sv, uv)
            ok = st[F_HIT, i] > 0.0
            out[0, i] = wp.where(ok, c[0], 0.0)
            out[1, i] = wp.where(ok, c[1], 0.0)
            out[2, i] = wp.where(ok, c[2], 0.0)
        return out

    @wp.func
    def row(st: st_t, r: int) -> vf:
        v = vf()
        for i in range(K):
            v[i] = st[r, i]
        return v

    @wp.func
    def rows_int(st: st_t, r: int) -> vi:
        v = vi()
        for i in range(K):
            v[i] = int(st[r, i])
        return v

    @wp.func
    def count_hits(st: st_t) -> int:
        n = int(0)
        for i in range(K):
            n = n + int(st[F_HIT, i])
        return n

    @wp.func
    def probe(st: st_t) -> rgb_t:
        """What the setup computed, as a value (keeps it from being optimized out)."""
        out = rgb_t()
        for i in range(K):
            out[0, i] = st[F_WOZ, i] * st[F_HIT, i]
            out[1, i] = st[F_W1, i] + st[F_T0, i]
            out[2, i] = st[F_PHI, i] + st[F_THETA, i]
        return out

    @wp.func
    def cond_offsets(erow: vi, w: int) -> vi:
        v = vi()
        for i in range(K):
            v[i] = erow[i] * (w + 1)
        return v

    @wp.kernel(module="unique", enable_backward=False, module_options=options)
    def render_lanes(tb: Tables, env: Env, view: View, x0: int, y0: int, tile_w: int,
                     out: wp.array(dtype=wp.vec3)):
        tid = wp.tid()
        px = x0 + tid % tile_w
        py = y0 + tid // tile_w
        if px >= view.res or py >= view.res:
            return
        pix = py * view.res + px
        acc = rgb_t()
        for j in range(view.spp // K):
            st = setup(view, tb, pix, px, py, j * K)
            if count_hits(st) == 0:
                continue
            if wp.static(stages < 2):
                acc = acc + probe(st)
                continue
            # the environment sample: row, then column
            erow = search_pc(env.marg, vi(), env.h, row(st, F_EV))
            ecol = search_pc(env.cond, cond_offsets(erow, env.w), env.w, row(st, F_EU))
            acc = acc + env_lanes(tb, env, st, erow, ecol)
            if wp.static(stages < 3):
                continue
            # the BSDF sample: luminance warp, then VNDF warp
            t0 = rows_int(st, F_T0)
            w1 = row(st, F_W1)
            s0, s1, s2 = warp_sample(tb.f, tb.lum_data, tb.lum_cond, tb.lum_marg, tb.lum_ny, tb.lum_nx, t0, w1,
                                     row(st, F_BX), row(st, F_BY))
            u0, u1, u2 = warp_sample(tb.f, tb.vndf_data, tb.vndf_cond, tb.vndf_marg, tb.vndf_ny, tb.vndf_nx,
                                     t0, w1, s0, s1)
            acc = acc + bsdf_lanes(tb, env, st, s0, s1, s2, u0, u1, u2)
        total = wp.vec3(0.0)
        for i in range(K):
            total = total + wp.vec3(acc[0, i], acc[1, i], acc[2, i])
        out[pix] = total / float(view.spp)

    return render_lanes
