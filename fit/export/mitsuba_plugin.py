"""Mitsuba 3 export of a rational BRDF fit: a BSDF plugin written in Python
(``mi.register_bsdf``), either imported from this project::

    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    from fit.export.mitsuba_plugin import register
    register("rbrdf_satin", "satin_rosaline_rgb.json")      # or a loaded model
    bsdf = mi.load_dict({"type": "rbrdf_satin"})

or written as a standalone module (:func:`to_mitsuba_plugin`, ``rbrdf-fit export FIT.json
OUT.py``) that needs only Mitsuba: ``import OUT; OUT.register()`` registers the plugin under
``rbrdf_<name>``.

What it evaluates: exactly the NumPy evaluation (:meth:`fit.rational.model.RationalModel.evaluate`)
-- the recipe of :mod:`fit.rational.coefficient_file` with its clamps, on the fit's measured
domain when it records its grazing cut-off (:func:`fit.rational.domain.onto_measured_domain`,
as the renderer's NumPy reference ``evaluate_at_angles``), 0 below the horizon,
flagged functions clamped to their measured range (the renderer's projected table is not
exported) -- times ``cos(theta_o)`` as Mitsuba's ``eval`` includes it; property ``scale``
(float, default 1) multiplies it. A 3-D fit (coefficient file version 3, ``(theta_h, theta_d,
|phi_d|)``, :func:`fit.rational.variables3d.evaluate_directions`) is not reciprocal: the plugin
evaluates it with Mitsuba's ``wo`` (the sampled direction, towards the light) as the fit's
light and ``si.wi`` as its viewer; one with the value factor ``"1/cos_theta_i"`` (version 4)
divides by max(cos theta_i, 1e-3), cos theta_i of the unclamped angles (emitter step 8), before
``eval``'s cosine. Sampling: cosine-weighted (``pdf = cos(theta_o) / pi``), or,
given an ``rbrdf-cdf`` file (``cdf=``, ``--cdf``), its tabulated inverse CDFs
(:class:`fit.sampling.table.CDFTable`, sample and closed-form pdf, as Mitsuba's MIS needs;
the file's rational maps give a pdf only by inversion and are not used). The runtime
(:mod:`fit.export._mitsuba_runtime`) computes the polynomials in Float64 and the directions in
the variant's Float (float32).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..rational.domain import measured_domain
from ..rational.model import COS_FLOOR, output_clamp
from . import _mitsuba_runtime
from .emitter import check_exportable, has_cos_factor
from .escape import identifier, literal, python_string


def _load(fit):
    if isinstance(fit, (str, Path)):
        from ..rational.coefficient_file import load

        return load(fit)
    return fit


def _load_cdf(cdf):
    if cdf is None:
        return None
    if isinstance(cdf, (str, Path)):
        from ..sampling.cdf_file import load

        return load(cdf)
    return cdf


def cdf_plan(cdf) -> dict | None:
    """The ``"cdf"`` entry of a plan: the tables of an ``rbrdf-cdf`` file (a path or a
    :class:`fit.sampling.cdf_file.CDFFit`), flattened; None for None."""
    cdf = _load_cdf(cdf)
    if cdf is None:
        return None
    t = cdf.table
    return {"n_v": int(t.n_v), "n_t": int(t.n_t), "n_p": int(t.n_p),
            "cdf_theta": [float(x) for x in np.asarray(t.cdf_theta, np.float64).ravel()],
            "cdf_phi": [float(x) for x in np.asarray(t.cdf_phi, np.float64).ravel()]}


def plan(model, cdf=None) -> dict:
    """The JSON-able plan of a fit that the runtime evaluates (:mod:`fit.export._mitsuba_runtime`);
    ``cdf``: an ``rbrdf-cdf`` file or fit whose tables sample it (None: cosine sampling)."""
    check_exportable(model)

    def node(m):
        pieces = getattr(m, "pieces", None)
        if pieces is not None:
            return {"split": m.split_variable, "edges": [float(e) for e in m.edges],
                    "pieces": [node(p) for p in pieces]}
        funcs = []
        for f, info in zip(m.functions, m.function_info):
            rng = output_clamp(info)
            funcs.append({
                "domain": [[float(a), float(b)] for a, b in f.domain],
                "num": [[*(int(x) for x in e), float(c)] for e, c in zip(f.num_exponents, f.num_coef) if c != 0],
                "den": [[*(int(x) for x in e), float(c)] for e, c in zip(f.den_exponents, f.den_coef) if c != 0],
                "range": None if rng is None else [float(rng[0]), float(rng[1])]})
        return {"box": [list(map(float, v.domain)) for v in m.variables],
                "transforms": [v.transform for v in m.variables],
                "value": {"transform": m.value_transform, "offset": float(m.value_offset),
                          "min": None if m.value_min is None else float(m.value_min),
                          "max": None if m.value_max is None else float(m.value_max)},
                "functions": funcs}

    out = {"name": str(model.name), "box": [list(map(float, v.domain)) for v in model.variables],
           "root": node(model), "cdf": cdf_plan(cdf)}
    cut = measured_domain(model)
    if cut is not None:                  # a fit without a cut-off: no domain rule in the plan
        out["cutoff_deg"] = cut
    if has_cos_factor(model):            # a fit without a factor: no factor in the plan
        out["value_factor"] = {"kind": model.value_factor, "cos_floor": COS_FLOOR}
    return out


def plugin_name(model, name: str | None = None) -> str:
    return "rbrdf_" + identifier(name or model.name)


def register(name: str, fit, cdf=None) -> str:
    """Register ``fit`` (a model or a coefficient file path) as Mitsuba BSDF plugin ``name``
    in the current variant (set it first), sampled with the tables of ``cdf`` (an
    ``rbrdf-cdf`` path or fit; None: cosine); returns ``name``."""
    import drjit as dr
    import mitsuba as mi

    p = plan(_load(fit), cdf)
    cls = _mitsuba_runtime.bsdf_class(mi, dr)
    mi.register_bsdf(name, lambda props: cls(props, p))
    return name


def evaluate(fit, wi, wo):
    """rho (1/sr) ``(n, 3)`` of the plugin's evaluation at local unit directions ``(n, 3)``
    (``wi`` the light, ``wo`` the viewer) in the current Mitsuba variant (one call per pair in a
    scalar variant): what ``bsdf.eval`` returns divided by cos(theta_o), with ``si.wi = wo``
    and ``wi`` as its direction."""
    import drjit as dr
    import mitsuba as mi

    p = plan(_load(fit))
    wi = np.asarray(wi, np.float64)
    wo = np.asarray(wo, np.float64)
    if mi.variant().startswith("scalar"):
        out = [_mitsuba_runtime.evaluate(mi, dr, p, mi.Vector3f(*a), mi.Vector3f(*b)) for a, b in zip(wi, wo)]
        return np.array([[c[0], c[1], c[2]] for c in out], np.float64)
    v = _mitsuba_runtime.evaluate(mi, dr, p, mi.Vector3f(wi.T.astype(np.float32)),
                                  mi.Vector3f(wo.T.astype(np.float32)))
    return np.array(v, np.float64).T


def to_mitsuba_plugin(model, name: str | None = None, cdf=None) -> str:
    """A standalone Python module (the runtime's text, the fit's plan, ``register(name)``) that
    needs only Mitsuba 3 and Dr.Jit; ``cdf``: an ``rbrdf-cdf`` file or fit whose tables it
    samples with (embedded; None: cosine sampling)."""
    p = plan(model, cdf)
    pname = plugin_name(model, name)
    runtime = Path(_mitsuba_runtime.__file__).read_text(encoding="utf-8")
    doc = (f'"""Mitsuba 3 BSDF plugin of the rational BRDF fit {literal(model.name)} (generated by warp-rbrdf\n'
           f"fit.export). Usage::\n\n    import mitsuba as mi\n    mi.set_variant('scalar_rgb')\n"
           f"    import {pname}  # this file\n    {pname}.register()   # plugin "
           f"{python_string(pname)}\n    bsdf = mi.load_dict({{'type': {python_string(pname)}}})\n\n"
           "rho in 1/sr times cos(theta_o); 0 below the horizon; angles clamped onto the fitted\n"
           "domain, values to the fit's clamps and per-function ranges; "
           + ("" if p.get("cutoff_deg") is None else
              f"angles first moved onto\nthe measured domain (grazing cut-off c = {p['cutoff_deg']:.6g} deg: "
              "cos theta_h cos theta_d >= cos c); ")
           + ("" if len(p["box"]) != 3 else
              "a 3-D fit of (theta_h, theta_d, |phi_d|), not reciprocal: eval's wo is the light,\n"
              "si.wi the viewer; ")
           + ("" if p.get("value_factor") is None else
              "rho = the clamped value / max(cos theta_i, "
              f"{p['value_factor']['cos_floor']:g}), cos theta_i of the\nunclamped angles "
              "(the functions give rho cos theta_i); ")
           + "sampling: "
           f"{'tabulated inverse CDFs' if p['cdf'] else 'cosine'}.\n"
           'Property ``scale`` (float) multiplies it."""\n')
    # the plan (the fit's name included) is data: one ASCII string literal, read by json.loads
    tail = (f"\n\nPLAN = json.loads({python_string(json.dumps(p))})\nNAME = {python_string(pname)}\n\n\n"
            "def register(name=NAME):\n"
            '    """Register the plugin (set the Mitsuba variant first); returns its name."""\n'
            "    import drjit as dr\n    import mitsuba as mi\n\n"
            "    cls = bsdf_class(mi, dr)\n"
            "    mi.register_bsdf(name, lambda props: cls(props, PLAN))\n    return name\n")
    body = runtime.split('"""', 2)[2]          # drop the runtime's own docstring
    return doc + "import json\n" + body.rstrip("\n") + tail
