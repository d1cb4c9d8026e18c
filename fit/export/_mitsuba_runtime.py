"""Runtime of the Mitsuba 3 plugin (:mod:`fit.export.mitsuba_plugin`): imports nothing from
this project (the exported standalone ``.py`` file is this module's text plus a plan), only
Mitsuba and Dr.Jit, passed in by the caller so that importing it needs neither.

A *plan* is the JSON-able form of a fit that :func:`fit.export.mitsuba_plugin.plan` makes:
``{"name", "box": [[th_lo, th_hi], [td_lo, td_hi]], "root": node}``; a node is either
``{"split": "theta_h" | "theta_d", "edges": [...], "pieces": [node, ...]}`` or a leaf
``{"box", "transforms": [t_h, t_d], "value": {"transform", "offset", "min", "max"},
"functions": [{"domain", "num": [[e_h, e_d, c], ...], "den": [...], "range": [lo, hi] | None}
x 3]}``: the recipe of :mod:`fit.rational.coefficient_file` with each function's step-7 range
already chosen (vouched range if valid, measured range if flagged).

Evaluation is vectorised Dr.Jit arithmetic (every piece is evaluated and the right one
selected), in ``Float64`` for the polynomial part; it works in every variant (scalar or JIT).
The BSDF is rho(theta_h, theta_d) times cos(theta_o) (Mitsuba's ``eval`` includes the
cosine), symmetric in its two directions, 0 below the horizon; it is sampled by the cosine
distribution (``pdf = cos(theta_o) / pi``).
"""
import math


def _rho(mi, dr, plan, th, td):
    """rho (1/sr) as three Float64 at Rusinkiewicz angles (Float64, radians)."""
    (hl, hh), (dl, dh) = plan["box"]
    x = [dr.clip(th, hl, hh), dr.clip(td, dl, dh)]
    return _node(mi, dr, plan["root"], x)


def _node(mi, dr, node, x):
    if "split" not in node:
        return _leaf(mi, dr, node, x)
    v = 0 if node["split"] == "theta_h" else 1
    vals = [_node(mi, dr, p, x) for p in node["pieces"]]
    out = vals[-1]
    for k in range(len(vals) - 2, -1, -1):      # x <= edge k + 1: piece k (the lower at an edge)
        sel = x[v] <= node["edges"][k + 1]
        out = [dr.select(sel, a, b) for a, b in zip(vals[k], out)]
    return out


def _leaf(mi, dr, leaf, x):
    u = []
    for v in range(2):
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
            for eh, ed, c in terms:
                acc = acc + c * table(0, eh)[eh] * table(1, ed)[ed]
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


def evaluate(mi, dr, plan, wi, wo):
    """rho (1/sr) as a Color3f at local unit directions (Vector3f); 0 below the horizon."""
    th, td = angles(mi, dr, wi, wo)
    r = _rho(mi, dr, plan, th, td)
    active = (mi.Frame3f.cos_theta(wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
    c = mi.Color3f(mi.Float(r[0]), mi.Float(r[1]), mi.Float(r[2]))
    return dr.select(active, c, mi.Color3f(0.0))


def bsdf_class(mi, dr):
    """The ``mi.BSDF`` subclass evaluating a plan (``RationalBSDF(props, plan)``)."""

    class RationalBSDF(mi.BSDF):
        def __init__(self, props, plan):
            mi.BSDF.__init__(self, props)
            self.plan = plan
            self.scale = props.get("scale", 1.0) if hasattr(props, "get") else 1.0
            flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            self.m_components = [flags]
            self.m_flags = flags

        def _f(self, si, wo):
            return evaluate(mi, dr, self.plan, si.wi, wo) * self.scale

        def sample(self, ctx, si, sample1, sample2, active=True):
            active = active & (mi.Frame3f.cos_theta(si.wi) > 0)
            bs = mi.BSDFSample3f()
            bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
            bs.sampled_component = mi.UInt32(0)
            ok = active & (bs.pdf > 0)
            weight = self._f(si, bs.wo) * math.pi        # f cos / pdf with pdf = cos / pi
            return bs, dr.select(ok, weight, mi.Color3f(0.0))

        def eval(self, ctx, si, wo, active=True):
            v = self._f(si, wo) * dr.maximum(mi.Frame3f.cos_theta(wo), 0.0)
            return dr.select(active, v, mi.Color3f(0.0))

        def pdf(self, ctx, si, wo, active=True):
            ok = active & (mi.Frame3f.cos_theta(si.wi) > 0)
            return dr.select(ok, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"RationalBSDF[fit={self.plan['name']!r}]"

    return RationalBSDF
