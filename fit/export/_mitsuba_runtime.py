"""Runtime of the Mitsuba 3 plugin (:mod:`fit.export.mitsuba_plugin`): imports nothing from
this project (the exported standalone ``.py`` file is this module's text plus a plan), only
Mitsuba and Dr.Jit, passed in by the caller so that importing it needs neither.

A *plan* is the JSON-able form of a fit that :func:`fit.export.mitsuba_plugin.plan` makes:
``{"name", "box": [[th_lo, th_hi], [td_lo, td_hi]], "root": node}``; a node is either
``{"split": "theta_h" | "theta_d", "edges": [...], "pieces": [node, ...]}`` or a leaf
``{"box", "transforms": [t_h, t_d], "value": {"transform", "offset", "min", "max"},
"functions": [{"domain", "num": [[e_h, e_d, c], ...], "den": [...], "range": [lo, hi] | None}
x 3]}``: the recipe of :mod:`fit.rational.coefficient_file` with each function's step-7 range
already chosen (vouched range if valid, measured range if flagged). A 3-D fit (coefficient file
version 3) has a third variable, ``|phi_d|``, everywhere: a third box entry and transform, a
third exponent in each term (``[e_h, e_d, e_p, c]``), ``"phi_d"`` as a split variable; phi_d
is folded by the mirror symmetry of isotropy (:mod:`fit.rational.variables3d`), and since such
a fit is not reciprocal the light and the view keep their roles: the BSDF evaluates it with
Mitsuba's sampled direction ``wo`` as the light and ``si.wi`` as the viewer. A fit that records the
grazing cut-off of its projection adds ``"cutoff_deg": c``: the angles are moved onto its
measured domain first (:func:`fit.rational.domain.onto_measured_domain`: ``theta_h = min(theta_h,
c)``, then ``theta_d = min(theta_d, acos(min(cos c / cos theta_h, 1)))``); without the key they
are not moved. A 3-D fit whose functions give rho cos theta_i (coefficient file version 4) adds
``"value_factor": {"kind": "1/cos_theta_i", "cos_floor": f}``: after the step-7 ranges every
channel is divided by ``max(cos theta_i, f)``, cos theta_i = cos th cos td - sin th sin td cos pd
of the angles before any clamp (the recipe's step 8, :func:`fit.rational.model.cos_theta_i_of`);
another kind is refused (ValueError).

Evaluation is vectorised Dr.Jit arithmetic (every piece is evaluated and the right one
selected), in ``Float64`` for the polynomial part; it works in every variant (scalar or JIT).
The BSDF is rho(theta_h, theta_d) (a 3-D fit: rho(theta_h, theta_d, |phi_d|)) times
cos(theta_o) (Mitsuba's ``eval`` includes the cosine; theta_o is the angle of its ``wo``), 0
below the horizon; a 2-D fit is symmetric in its two directions. It is sampled by the cosine
distribution (``pdf = cos(theta_o) / pi``), or, when the plan holds ``"cdf"``, by the tabulated
inverse CDFs of an ``rbrdf-cdf`` file (:class:`fit.sampling.table.CDFTable`: rows by the view
angle ``theta_v`` of ``si.wi``, ``theta_l`` by the row's marginal CDF, ``|phi_l - phi_v|`` by
the symmetric conditional CDF, linear inside cells; ``pdf`` in closed form, as MIS needs):
``{"n_v", "n_t", "n_p", "cdf_theta": (n_v (n_t + 1)) floats, "cdf_phi": (n_v n_t (n_p + 1))
floats}``.
"""
import bisect
import math


VARIABLE_INDEX = {"theta_h": 0, "theta_d": 1, "phi_d": 2}


def _rho(mi, dr, plan, th, td, pd=None):
    """rho (1/sr) as three Float64 at Rusinkiewicz angles (Float64, radians; ``pd``: phi_d of
    a 3-D plan, folded here)."""
    th_in, td_in = th, td                   # unclamped: the value factor's cos theta_i
    if plan.get("cutoff_deg") is not None:
        th, td = _onto_measured_domain(dr, plan["cutoff_deg"], th, td)
    box = plan["box"]
    x = [dr.clip(th, box[0][0], box[0][1]), dr.clip(td, box[1][0], box[1][1])]
    if len(box) == 3:
        x.append(dr.clip(dr.abs(pd), box[2][0], box[2][1]))
    rho = _node(mi, dr, plan["root"], x)
    factor = plan.get("value_factor")
    if factor is None:
        return rho
    if factor["kind"] != "1/cos_theta_i":
        raise ValueError(f"unknown value factor {factor['kind']!r}")
    cos_i = dr.maximum(dr.cos(th_in) * dr.cos(td_in) - dr.sin(th_in) * dr.sin(td_in) * dr.cos(pd),
                       factor["cos_floor"])
    return [r / cos_i for r in rho]


def _onto_measured_domain(dr, cutoff_deg, th, td):
    """(theta_h, theta_d) (Float64, radians) moved onto the measured domain of grazing cut-off
    ``cutoff_deg`` (degrees): cos theta_h cos theta_d >= cos c (module docstring)."""
    c = math.radians(cutoff_deg)
    th = dr.minimum(th, c)
    td = dr.minimum(td, dr.acos(dr.minimum(math.cos(c) / dr.cos(th), 1.0)))
    return th, td


def _node(mi, dr, node, x):
    if "split" not in node:
        return _leaf(mi, dr, node, x)
    v = VARIABLE_INDEX[node["split"]]
    vals = [_node(mi, dr, p, x) for p in node["pieces"]]
    out = vals[-1]
    for k in range(len(vals) - 2, -1, -1):      # x <= edge k + 1: piece k (the lower at an edge)
        sel = x[v] <= node["edges"][k + 1]
        out = [dr.select(sel, a, b) for a, b in zip(vals[k], out)]
    return out


def _leaf(mi, dr, leaf, x):
    u = []
    for v in range(len(leaf["box"])):
        lo, hi = leaf["box"][v]
        xv = dr.clip(x[v], lo, hi)
        if leaf["transforms"][v] == "sqrt":
            xv = dr.sqrt(dr.maximum(xv, 0.0))
        u.append(xv)
    val = leaf["value"]
    out = []
    for f in leaf["functions"]:
        tabs = {}

        def table(v, deg, f=f, tabs=tabs):
            lo, hi = f["domain"][v]
            key = (v, lo, hi)
            t = tabs.get(key)
            if t is None:
                s = (2.0 * u[v] - (lo + hi)) / (hi - lo)
                t = tabs[key] = [1.0, s]
            while len(t) <= deg:
                t.append(2.0 * t[1] * t[-1] - t[-2])
            return t

        def poly(terms):
            acc = 0.0
            for term in terms:          # [e_h, e_d, (e_p,) c]
                p = term[-1]
                for v, e in enumerate(term[:-1]):
                    p = p * table(v, e)[e]
                acc = acc + p
            return acc

        y = poly(f["num"]) / poly(f["den"])
        if val["transform"] == "log":
            if val["max"] is not None:
                y = dr.minimum(y, math.log(val["max"] + val["offset"]))
            y = dr.exp(y) - val["offset"]
        if val["min"] is not None:
            y = dr.maximum(y, val["min"])
        if val["max"] is not None:
            y = dr.minimum(y, val["max"])
        if f["range"] is not None:
            y = dr.clip(y, f["range"][0], f["range"][1])
        out.append(y + 0.0 * u[0])                # a Float64 even where y is a constant
    return out


def angles(mi, dr, wi, wo):
    """(theta_h, theta_d) in radians (Float64) of local directions."""
    h = dr.normalize(wi + wo)
    th = dr.atan2(dr.sqrt(h.x * h.x + h.y * h.y), h.z)
    td = dr.atan2(dr.norm(dr.cross(wi, h)), dr.dot(wi, h))
    return mi.Float64(th), mi.Float64(td)


def angles_3d(mi, dr, wi, wo):
    """(theta_h, theta_d, phi_d) in radians (Float64; phi_d in (-pi, pi], 0 where undefined) of
    local directions ``wi`` (the light) and ``wo`` (the viewer): ``wi`` rotated by ``-phi_h``
    about z, then by ``-theta_h`` about y (the rotations of the renderer and of
    ``fit.formats.angles.directions_to_half_diff``)."""
    h = dr.normalize(wi + wo)
    r = dr.sqrt(h.x * h.x + h.y * h.y)
    th = dr.atan2(r, h.z)
    ok = r > 1e-12
    cp = dr.select(ok, h.x / dr.select(ok, r, 1.0), 1.0)
    sp = dr.select(ok, h.y / dr.select(ok, r, 1.0), 0.0)
    x1 = cp * wi.x + sp * wi.y
    y1 = cp * wi.y - sp * wi.x
    x2 = h.z * x1 - r * wi.z
    z2 = r * x1 + h.z * wi.z
    td = dr.atan2(dr.sqrt(x2 * x2 + y1 * y1), z2)
    pd = dr.select(dr.abs(x2) + dr.abs(y1) > 1e-12, dr.atan2(y1, x2), 0.0)
    return mi.Float64(th), mi.Float64(td), mi.Float64(pd)


def evaluate(mi, dr, plan, wi, wo):
    """rho (1/sr) as a Color3f at local unit directions (Vector3f) ``wi`` (the light) and ``wo``
    (the viewer); 0 below the horizon."""
    if len(plan["box"]) == 3:
        r = _rho(mi, dr, plan, *angles_3d(mi, dr, wi, wo))
    else:
        r = _rho(mi, dr, plan, *angles(mi, dr, wi, wo))
    active = (mi.Frame3f.cos_theta(wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
    c = mi.Color3f(mi.Float(r[0]), mi.Float(r[1]), mi.Float(r[2]))
    return dr.select(active, c, mi.Color3f(0.0))


class _CDF:
    """The tabulated inverse CDFs of a plan (module docstring), sampled and evaluated with
    Dr.Jit gathers (Python lists in scalar variants)."""

    def __init__(self, mi, dr, t):
        self.mi, self.dr = mi, dr
        self.n_v, self.n_t, self.n_p = int(t["n_v"]), int(t["n_t"]), int(t["n_p"])
        self.scalar = mi.variant().startswith("scalar")
        conv = (lambda a: [float(x) for x in a]) if self.scalar else mi.Float
        self.ct = conv(t["cdf_theta"])
        self.cp = conv(t["cdf_phi"])

    def _get(self, arr, i):
        return arr[int(i)] if self.scalar else self.dr.gather(self.mi.Float, arr, i)

    def _cell(self, arr, off, n, x):
        """Index of the cell of ``x`` in the CDF ``arr[off:off + n + 1]``: (number of entries
        <= x) - 1, clipped to [0, n - 1]."""
        if self.scalar:
            c = bisect.bisect_right(arr, x, int(off), int(off) + n + 1) - int(off)
        else:
            c = self.dr.binary_search(0, n, lambda i: self.dr.gather(self.mi.Float, arr, off + i) <= x)
        return self.dr.clip(self.mi.Int32(c) - 1, 0, n - 1)

    def _row(self, wi):
        tv = self.dr.acos(self.dr.clip(wi.z, -1.0, 1.0))
        v = self.dr.clip(self.mi.Int32(self.dr.floor(tv / (0.5 * math.pi) * self.n_v)), 0, self.n_v - 1)
        return v, self.dr.atan2(wi.y, wi.x)

    def sample(self, wi, sample2):
        """(wo, pdf in 1/sr) for the view ``wi`` and uniform ``sample2`` (mu, tau)."""
        mi, dr = self.mi, self.dr
        v, phi_v = self._row(wi)
        mu, tau = sample2.x, sample2.y
        nt, np_ = self.n_t, self.n_p
        ot = v * (nt + 1)
        j = self._cell(self.ct, ot, nt, mu)
        c0, c1 = self._get(self.ct, ot + j), self._get(self.ct, ot + j + 1)
        m_t = c1 - c0
        dt = 0.5 * math.pi / nt
        frac = dr.select(m_t > 0, (mu - c0) / dr.select(m_t > 0, m_t, 1.0), 0.5)
        tl = (mi.Float(j) + dr.clip(frac, 0.0, 1.0)) * dt
        u = dr.abs(2.0 * tau - 1.0)
        op = (v * nt + j) * (np_ + 1)
        k = self._cell(self.cp, op, np_, u)
        q0, q1 = self._get(self.cp, op + k), self._get(self.cp, op + k + 1)
        m_p = q1 - q0
        fp = dr.select(m_p > 0, (u - q0) / dr.select(m_p > 0, m_p, 1.0), 0.5)
        dp = math.pi / np_
        pa = (mi.Float(k) + dr.clip(fp, 0.0, 1.0)) * dp
        phi = phi_v + dr.select(tau < 0.5, -pa, pa)
        st = dr.sin(tl)
        wo = mi.Vector3f(st * dr.cos(phi), st * dr.sin(phi), dr.cos(tl))
        pdf = (m_t / dt) * (0.5 * m_p / dp) / dr.maximum(st, 1e-30)
        return wo, pdf

    def pdf(self, wi, wo):
        """Density (1/sr) of :meth:`sample` at ``wo``; 0 below the horizon."""
        mi, dr = self.mi, self.dr
        v, phi_v = self._row(wi)
        nt, np_ = self.n_t, self.n_p
        tl = dr.acos(dr.clip(wo.z, -1.0, 1.0))
        d = dr.atan2(wo.y, wo.x) - phi_v
        pl = dr.abs(dr.atan2(dr.sin(d), dr.cos(d)))          # |phi_l - phi_v| in [0, pi]
        dt, dp = 0.5 * math.pi / nt, math.pi / np_
        j = dr.clip(mi.Int32(dr.floor(tl / dt)), 0, nt - 1)
        k = dr.clip(mi.Int32(dr.floor(pl / dp)), 0, np_ - 1)
        ot = v * (nt + 1) + j
        op = (v * nt + j) * (np_ + 1) + k
        m_t = self._get(self.ct, ot + 1) - self._get(self.ct, ot)
        m_p = self._get(self.cp, op + 1) - self._get(self.cp, op)
        p = (m_t / dt) * (0.5 * m_p / dp) / dr.maximum(dr.sin(tl), 1e-30)
        return dr.select(wo.z > 0, p, 0.0)


def bsdf_class(mi, dr):
    """The ``mi.BSDF`` subclass evaluating a plan (``RationalBSDF(props, plan)``)."""

    class RationalBSDF(mi.BSDF):
        def __init__(self, props, plan):
            mi.BSDF.__init__(self, props)
            self.plan = plan
            self.cdf = _CDF(mi, dr, plan["cdf"]) if plan.get("cdf") else None
            self.scale = props.get("scale", 1.0) if hasattr(props, "get") else 1.0
            flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            self.m_components = [flags]
            self.m_flags = flags

        def _f(self, si, wo):
            # Mitsuba's si.wi points to the viewer, wo to the light: a 3-D fit keeps these roles
            # (a 2-D fit is symmetric in them)
            if len(self.plan["box"]) == 3:
                return evaluate(mi, dr, self.plan, wo, si.wi) * self.scale
            return evaluate(mi, dr, self.plan, si.wi, wo) * self.scale

        def sample(self, ctx, si, sample1, sample2, active=True):
            active = active & (mi.Frame3f.cos_theta(si.wi) > 0)
            bs = mi.BSDFSample3f()
            if self.cdf is None:
                bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
                bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            else:
                bs.wo, bs.pdf = self.cdf.sample(si.wi, sample2)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
            bs.sampled_component = mi.UInt32(0)
            ok = active & (bs.pdf > 0) & (mi.Frame3f.cos_theta(bs.wo) > 0)
            cos_o = dr.maximum(mi.Frame3f.cos_theta(bs.wo), 0.0)
            weight = self._f(si, bs.wo) * cos_o / dr.select(ok, bs.pdf, 1.0)   # f cos / pdf
            return bs, dr.select(ok, weight, mi.Color3f(0.0))

        def eval(self, ctx, si, wo, active=True):
            v = self._f(si, wo) * dr.maximum(mi.Frame3f.cos_theta(wo), 0.0)
            return dr.select(active, v, mi.Color3f(0.0))

        def pdf(self, ctx, si, wo, active=True):
            ok = active & (mi.Frame3f.cos_theta(si.wi) > 0)
            if self.cdf is None:
                return dr.select(ok, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)
            return dr.select(ok, self.cdf.pdf(si.wi, wo), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            pass

        def to_string(self):
            return (f"RationalBSDF[fit={self.plan['name']!r}, sampling="
                    f"{'tabulated inverse CDFs' if self.cdf else 'cosine'}]")

    return RationalBSDF
