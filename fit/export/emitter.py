"""The one expression emitter that the GLSL and C exports share: a rational BRDF fit
(:class:`fit.rational.model.RationalModel` or :class:`~fit.rational.model.PiecewiseRationalModel`,
nested pieces included) as straight-line statements in the C-like subset common to GLSL and
C99 (declarations, ``if``/``else``, ``+=``, calls of ``min``/``max``/``clamp``/``sqrt``/``exp``,
for the measured domain ``cos``/``acos``, for 3-D fits ``abs`` and for a value factor
``cos``/``sin``, through a per-language name table).

Two kinds of fits are exported: 2-D fits of ``(theta_h, theta_d)`` (coefficient file versions
1 and 2) and 3-D fits of ``(theta_h, theta_d, |phi_d|)`` (version 3,
:mod:`fit.rational.variables3d`: phi_d folded by the mirror symmetry of isotropy, not by
reciprocity, so the light and the view keep their roles; version 4: a 3-D fit whose functions
give rho cos theta_i, step 8 below). The block :meth:`Emitter.rho` emits
reads the angles in radians and assigns ``rho0, rho1, rho2``; the direction functions around it
(:mod:`fit.export.glsl`, :mod:`fit.export.c_source`, :mod:`fit.export.hlsl`) compute the angles.

The statements follow the evaluation recipe of :mod:`fit.rational.coefficient_file` step by
step, as :meth:`RationalModel.__call__` does in NumPy:

0. for a 3-D fit, ``phi_d`` folded to ``|phi_d|`` (:func:`fit.rational.variables3d.fold_phi_d`);
   for a 2-D fit that records the grazing cut-off c of its projection
   (:func:`fit.rational.domain.measured_domain`), move the angles onto its measured domain
   ``cos theta_h cos theta_d >= cos c`` as the renderer does
   (:func:`fit.rational.domain.onto_measured_domain`): ``theta_h = min(theta_h, c)``, then
   ``theta_d = min(theta_d, acos(min(cos c / cos theta_h, 1)))`` (the value at the domain's edge
   at the same theta_h; beyond it the fit has no data and would extrapolate). Fits that record
   no cut-off get no such statements (their output holds no domain code);
1. clamp the angles (radians) onto the model's box; pick the piece
   (``x <= edge`` selects the lower piece at a shared edge, recursively for nested splits) and
   clamp onto the piece's box;
2. input transform (``identity`` / ``sqrt``);
3. map onto [-1, 1] with each function's own domain: ``t = (2 u - (lo + hi)) / (hi - lo)``;
4. Chebyshev tables ``T_0 .. T_n`` by the recurrence (unrolled up to the largest exponent
   used), then ``P`` and ``Q`` as explicit sums of coefficient x product terms;
5. ``y = P / Q`` (linear) or ``exp(min(P / Q, log(max + offset))) - offset`` (log);
6. ``max(y, min)``, ``min(y, max)``;
7. the function's step-7 range (:func:`fit.rational.model.output_clamp`: the vouched range
   of a valid function, the measured range of a flagged one);
8. a 3-D fit's value factor (``model.value_factor``, :data:`fit.rational.model.VALUE_FACTORS`;
   only on the top-level model): for ``"1/cos_theta_i"`` every channel, after its step 7, is
   divided by ``max(cos theta_i, COS_FLOOR)`` (:data:`fit.rational.model.COS_FLOOR` = 1e-3, a
   literal), ``cos theta_i = cos(th) cos(td) - sin(th) sin(td) cos(pd)``
   (:func:`fit.rational.model.cos_theta_i_of`) of the angles the block reads, before any clamp
   or fold (``cos`` is even in phi_d). The block computes it from its angles rather than taking
   the direction functions' ``wi.z`` so that every entry point (``_angles`` too) and every
   language (the Mitsuba runtime included) evaluate the same ``model(x)`` of the NumPy
   reference; in float the angles cost about 1e-7 of cos theta_i, a relative 1e-4 of rho at
   the floor. Fits without a factor get no such statements.

Everything runs in the language's ``real`` type (GLSL ``float``; C ``RBRDF_REAL``, float by
default): the coefficients are printed with 17 significant digits so that a double build
reproduces the NumPy evaluation to rounding. Only BRDF fits in ``(theta_h, theta_d)`` or
``(theta_h, theta_d, phi_d)`` with 3 outputs and ``"outside": "clamp"`` are exported
(:func:`check_exportable`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..rational.domain import measured_domain
from ..rational.model import COS_FLOOR, VALUE_FACTORS, flagged, output_clamp
from ..rational.variables3d import VARIABLES_3D
from .escape import comment_text, literal

VARIABLES = ("theta_h", "theta_d")


class ExportError(ValueError):
    """A fit this exporter cannot translate (the message names the problem)."""


@dataclass
class Language:
    """What differs between GLSL and C in the emitted statements."""

    real: str                         # scalar type
    literal: callable                 # float -> source literal
    funcs: dict = field(default_factory=dict)   # min, max, clamp, sqrt, exp, cos, acos, abs, sin -> names

    def call(self, f: str, *args) -> str:
        return f"{self.funcs.get(f, f)}({', '.join(args)})"


def glsl_literal(v: float) -> str:
    """A GLSL float literal (always with a '.' or an exponent; negative ones in parentheses),
    9 significant digits (a float32 round trip)."""
    s = _digits(abs(float(v)), 9)
    return f"(-{s})" if v < 0 else s


def c_literal(v: float) -> str:
    """A C literal through ``RBRDF_K`` (a float or double constant by ``RBRDF_REAL``), 17
    significant digits (a float64 round trip); negative ones in parentheses."""
    s = f"RBRDF_K({_digits(abs(float(v)), 17)})"
    return f"(-{s})" if v < 0 else s


def _digits(v: float, digits: int) -> str:
    if not np.isfinite(v):
        raise ExportError(f"non-finite coefficient {v}")
    s = f"{v:.{digits}g}"
    if "e" not in s and "." not in s:
        s += ".0"
    return s


def leaves(model) -> list:
    """The single-box models of a fit, in the order the emitter visits them."""
    pieces = getattr(model, "pieces", None)
    if pieces is None:
        return [model]
    return [leaf for p in pieces for leaf in leaves(p)]


def sub_models(model) -> list:
    """Every model below the top of a fit (pieces, nested ones and their pieces), depth first."""
    return [m for p in getattr(model, "pieces", None) or [] for m in [p, *sub_models(p)]]


def is_3d(model) -> bool:
    """Whether ``model`` is a 3-D fit (variables ``theta_h, theta_d, phi_d``, file version 3 or 4)."""
    return tuple(v.name for v in model.variables) == VARIABLES_3D


def has_cos_factor(model) -> bool:
    """Whether ``model``'s value factor (step 8) is ``"1/cos_theta_i"`` (file version 4)."""
    return model.value_factor == "1/cos_theta_i"


def check_exportable(model) -> None:
    """ExportError unless ``model`` is a BRDF fit in (theta_h, theta_d) or (theta_h, theta_d,
    phi_d) with 3 outputs and the clamp policy, every leaf in the model's variables with finite
    coefficients, a grazing cut-off record (if any) that is a number, and a value factor of
    :data:`fit.rational.model.VALUE_FACTORS` (other than ``"none"`` only on the top-level model
    of a 3-D fit)."""
    names = [v.name for v in model.variables]
    if getattr(model, "kind", "brdf") != "brdf":
        raise ExportError(f"kind {model.kind!r}: only BRDF fits (kind 'brdf') are exported")
    if names not in (list(VARIABLES), list(VARIABLES_3D)):
        raise ExportError(f"variables {names}: only fits in (theta_h, theta_d) or (theta_h, theta_d, phi_d) "
                          "are exported")
    if len(model.outputs) != 3:
        raise ExportError(f"{len(model.outputs)} outputs: a BRDF fit has 3 (R, G, B)")
    if model.value_factor not in VALUE_FACTORS:
        raise ExportError(f"value factor {literal(model.value_factor, 80)}: only "
                          f"{', '.join(map(repr, VALUE_FACTORS))} are exported")
    if model.value_factor != "none" and not is_3d(model):
        raise ExportError(f"value factor {model.value_factor!r} on a fit in {names}: only 3-D fits "
                          "(theta_h, theta_d, phi_d) have one")
    if any(m.value_factor != "none" for m in sub_models(model)):
        raise ExportError("a piece has a value factor of its own (only the whole fit has one, step 8)")
    for leaf in leaves(model):
        if leaf.domain_policy.get("outside", "clamp") != "clamp":
            raise ExportError("domain policy 'outside' is not 'clamp'")
        if [v.name for v in leaf.variables] != names:
            raise ExportError(f"a piece has variables {[v.name for v in leaf.variables]}")
        for f in leaf.functions:
            for a in (f.num_coef, f.den_coef, f.domain):
                if not np.all(np.isfinite(a)):
                    raise ExportError("a function has non-finite coefficients or domain")
    try:
        measured_domain(model)
    except (TypeError, ValueError):
        raise ExportError("fit.grazing_cutoff_deg is not a number") from None


def flagged_summary(model) -> list:
    """``[(leaf index, channel names, step-7 range or None)]`` of every flagged function."""
    out = []
    for k, leaf in enumerate(leaves(model)):
        chans = [(leaf.outputs[c], output_clamp(i)) for c, i in enumerate(leaf.function_info) if flagged(i)]
        if chans:
            out.append((k, chans))
    return out


class Emitter:
    """Statements of one fit in one :class:`Language`; :meth:`rho` returns the lines of a block
    that reads ``theta_h``, ``theta_d`` (radians) and assigns ``rho0, rho1, rho2`` (1/sr, declared
    by the caller)."""

    def __init__(self, lang: Language, indent: str = "    "):
        self.lang = lang
        self.ind = indent
        self.n = 0

    def _fresh(self, base: str) -> str:
        self.n += 1
        return f"{base}{self.n}"

    def lit(self, v) -> str:
        return self.lang.literal(v)

    def rho(self, model, th: str = "theta_h", td: str = "theta_d",
            out=("rho0", "rho1", "rho2"), depth: int = 1, pd: str = "phi_d") -> list:
        """The block's lines; ``th``, ``td`` (and ``pd`` for a 3-D fit: phi_d in radians, any
        sign, folded here) name the angles it reads (never assigned: step 8 reads them
        unclamped)."""
        check_exportable(model)
        L, R = self.lang, self.lang.real
        pad = self.ind * depth
        lines = []
        th_in, td_in = th, td
        cut = measured_domain(model)
        if cut is not None:
            lines, th, td = self.onto_measured_domain(cut, th, td, depth)
        xh, xd = self._fresh("xh"), self._fresh("xd")
        (hl, hh), (dl, dh) = (v.domain for v in model.variables[:2])
        lines += [f"{pad}{R} {xh} = {L.call('clamp', th, self.lit(hl), self.lit(hh))};",
                  f"{pad}{R} {xd} = {L.call('clamp', td, self.lit(dl), self.lit(dh))};"]
        xs = {"theta_h": xh, "theta_d": xd}
        if is_3d(model):      # |phi_d|: the mirror fold (fit.rational.variables3d)
            xp = self._fresh("xp")
            pl, ph = model.variables[2].domain
            lines.append(f"{pad}{R} {xp} = {L.call('clamp', L.call('abs', pd), self.lit(pl), self.lit(ph))};")
            xs["phi_d"] = xp
        lines += self._node(model, xs, out, depth)
        if has_cos_factor(model):
            lines += self.cos_factor(th_in, td_in, pd, out, depth)
        return lines

    def cos_factor(self, th: str, td: str, pd: str, out, depth: int = 1) -> list:
        """Step 8 of value factor ``"1/cos_theta_i"``: the channels ``out`` divided by
        ``max(cos theta_i, COS_FLOOR)``, cos theta_i of the angles ``th``, ``td``, ``pd``
        (radians, as the block read them: unclamped, phi_d of any sign)."""
        L, R = self.lang, self.lang.real
        pad = self.ind * depth
        ci = self._fresh("cos_i")
        cos_i = (f"{L.call('cos', th)} * {L.call('cos', td)} - "
                 f"{L.call('sin', th)} * {L.call('sin', td)} * {L.call('cos', pd)}")
        return ([f"{pad}/* value factor (step 8): rho = value / max(cos(theta_i), {COS_FLOOR:g}), "
                 "cos(theta_i) of the unclamped angles */",
                 f"{pad}{R} {ci} = {L.call('max', cos_i, self.lit(COS_FLOOR))};"]
                + [f"{pad}{o} = {o} / {ci};" for o in out])

    def onto_measured_domain(self, cutoff_deg: float, th: str, td: str, depth: int = 1):
        """``(lines, theta_h name, theta_d name)``: statements moving ``th``, ``td`` (radians)
        onto the measured domain of grazing cut-off ``cutoff_deg`` (degrees), the rule of
        :func:`fit.rational.domain.onto_measured_domain` (``cos c`` as a literal)."""
        L, R = self.lang, self.lang.real
        pad = self.ind * depth
        mh, md = "theta_h_m", "theta_d_m"     # not counted: the statements after are numbered as without
        c = float(np.radians(float(cutoff_deg)))
        tdmax = L.call("acos", L.call("min", f"{self.lit(np.cos(c))} / {L.call('cos', mh)}", self.lit(1.0)))
        return ([f"{pad}/* measured domain (grazing cut-off {float(cutoff_deg):.6g} deg): "
                 "cos(theta_h) cos(theta_d) >= cos(cut-off) */",
                 f"{pad}{R} {mh} = {L.call('min', th, self.lit(c))};",
                 f"{pad}{R} {md} = {L.call('min', td, tdmax)};"], mh, md)

    def _node(self, model, xs: dict, out, depth) -> list:
        pieces = getattr(model, "pieces", None)
        if pieces is None:
            return self._leaf(model, [xs[v.name] for v in model.variables], out, depth)
        pad = self.ind * depth
        x = xs[model.split_variable]
        lines = []
        for k, piece in enumerate(pieces):
            last = k == len(pieces) - 1
            if k == 0:
                head = f"if ({x} <= {self.lit(model.edges[k + 1])}) {{"
            elif not last:
                head = f"}} else if ({x} <= {self.lit(model.edges[k + 1])}) {{"
            else:
                head = "} else {"
            if len(pieces) == 1:
                head = "{"
            lines.append(pad + head)
            lines += self._node(piece, xs, out, depth + 1)
        lines.append(pad + "}")
        return lines

    def _leaf(self, leaf, xs: list, out, depth) -> list:
        L, R = self.lang, self.lang.real
        pad = self.ind * depth
        nv = len(leaf.variables)
        lines = []
        us = []
        for x, var in zip(xs, leaf.variables):
            u = self._fresh("u")
            v = L.call("clamp", x, self.lit(var.domain[0]), self.lit(var.domain[1]))
            if var.transform == "sqrt":
                v = L.call("sqrt", L.call("max", v, self.lit(0.0)))
            elif var.transform != "identity":
                raise ExportError(f"unknown input transform {var.transform!r}")
            lines.append(f"{pad}{R} {u} = {v};")
            us.append(u)
        tables: dict = {}     # (variable, lo, hi) -> (names of T_0.., degree)

        def table(v, lo, hi, degree):
            key = (v, float(lo), float(hi))
            if key in tables and tables[key][1] >= degree:
                return tables[key][0]
            t = self._fresh("t")
            lines.append(f"{pad}{R} {t}_1 = ({self.lit(2.0)} * {us[v]} - {self.lit(lo + hi)}) * "
                         f"{self.lit(1.0 / (hi - lo))};")
            for k in range(2, degree + 1):
                prev2 = self.lit(1.0) if k == 2 else f"{t}_{k - 2}"
                lines.append(f"{pad}{R} {t}_{k} = {self.lit(2.0)} * {t}_1 * {t}_{k - 1} - {prev2};")
            tables[key] = (t, degree)
            return t

        def poly(f, exps, coefs, name):
            degs = exps.max(axis=0) if len(exps) else np.zeros(nv, int)
            names = [table(v, f.domain[v][0], f.domain[v][1], int(degs[v])) if degs[v] > 0 else None
                     for v in range(nv)]
            lines.append(f"{pad}{R} {name} = {self.lit(0.0)};")
            for e, c in zip(exps, coefs):
                if c == 0.0:
                    continue
                factors = [f"{names[v]}_{int(e[v])}" for v in range(nv) if e[v] > 0]
                lines.append(f"{pad}{name} += {' * '.join([self.lit(c)] + factors)};")

        for f in leaf.functions:        # every table once, at the largest degree used
            exps = np.concatenate([f.num_exponents, f.den_exponents])
            for v in range(nv):
                lo, hi = f.domain[v]
                key = (v, float(lo), float(hi))
                need = int(exps[:, v].max())
                if need > 0 and tables.get(key, (None, 0))[1] < need:
                    tables.pop(key, None)
                    maxdeg = max(int(np.concatenate([g.num_exponents, g.den_exponents])[:, v].max())
                                 for g in leaf.functions if tuple(g.domain[v]) == (lo, hi))
                    table(v, lo, hi, maxdeg)
        vmin, vmax, off = leaf.value_min, leaf.value_max, float(leaf.value_offset)
        for c, (f, info) in enumerate(zip(leaf.functions, leaf.function_info)):
            p, q, y = self._fresh("p"), self._fresh("q"), self._fresh("y")
            state = "FLAGGED (not within its intervals)" if flagged(info) else "valid"
            lines.append(f"{pad}/* {comment_text(leaf.outputs[c])}: {state} */")
            poly(f, f.num_exponents, f.num_coef, p)
            poly(f, f.den_exponents, f.den_coef, q)
            lines.append(f"{pad}{R} {y} = {p} / {q};")
            if leaf.value_transform == "log":
                if vmax is not None:
                    lines.append(f"{pad}{y} = {L.call('min', y, self.lit(np.log(vmax + off)))};")
                lines.append(f"{pad}{y} = {L.call('exp', y)} - {self.lit(off)};")
            elif leaf.value_transform != "linear":
                raise ExportError(f"unknown value transform {leaf.value_transform!r}")
            if vmin is not None:
                lines.append(f"{pad}{y} = {L.call('max', y, self.lit(vmin))};")
            if vmax is not None:
                lines.append(f"{pad}{y} = {L.call('min', y, self.lit(vmax))};")
            rng = output_clamp(info)
            if rng is not None:
                lines.append(f"{pad}{y} = {L.call('clamp', y, self.lit(rng[0]), self.lit(rng[1]))};")
            lines.append(f"{pad}{out[c]} = {y};")
        return lines


def policy_text(model, prefix: str = " * ") -> list:
    """The domain and clamp policy of an exported fit, as comment lines (``prefix`` each); text
    of the file (name, channel names, source, tolerance) only through :mod:`fit.export.escape`.
    ExportError for a fit the emitters do not translate (:func:`check_exportable`)."""
    check_exportable(model)
    three = is_3d(model)
    (hl, hh), (dl, dh) = (v.domain for v in model.variables[:2])
    deg = np.degrees
    if three:
        pl, ph = model.variables[2].domain
        lines = [
            f"Fit {literal(model.name)}: rho(wi, wo) in 1/sr (no cosine), RGB, isotropic, NOT reciprocal:",
            "wi is the direction towards the light, wo towards the viewer (swapping them changes the",
            "value); local shading frame z = normal, unit vectors.",
            (f"Fitted domain: theta_h in [{deg(hl):.4g}, {deg(hh):.4g}] deg, theta_d in [{deg(dl):.4g}, "
             f"{deg(dh):.4g}] deg, |phi_d| in [{deg(pl):.4g}, {deg(ph):.4g}] deg"),
            "(Rusinkiewicz angles of (wi, wo); phi_d folded to |phi_d| by the mirror symmetry of",
            "isotropy, not by reciprocity).",
        ]
    else:
        lines = [
            f"Fit {literal(model.name)}: rho(wi, wo) in 1/sr (no cosine), RGB, isotropic; local shading frame",
            "z = normal; wi towards the light, wo towards the viewer, unit vectors.",
            (f"Fitted domain: theta_h in [{deg(hl):.4g}, {deg(hh):.4g}] deg, theta_d in [{deg(dl):.4g}, "
             f"{deg(dh):.4g}] deg (Rusinkiewicz angles)."),
        ]
    lines += [
        "Policy: below the horizon (wi.z <= 0 or wo.z <= 0): 0. Outside the fitted domain the",
        ("angles are clamped onto it (beyond the largest fitted theta_h or theta_d the value at that"
         if three else "angles are clamped onto it (e.g. theta_d beyond the grazing cut-off returns the value at"),
        ("edge). Values are clamped to [min, max] of the fit and, per function, to its"
         if three else "the cut-off). Values are clamped to [min, max] of the fit and, per function, to its"),
        "vouched range (valid functions) or measured range (flagged ones): never negative, never",
        "above what the data of its piece vouch for.",
    ]
    if three:
        lines += [
            "Bound: every data point of the fit is within its stated bound and Q > 0 is certified on",
            "every piece; between the data points the bound is checked at fresh points, not proved.",
        ]
    if has_cos_factor(model):
        lines += [
            "Value factor 1/cos(theta_i): the fitted functions give rho cos(theta_i), and the clamps",
            "and ranges above bound that product; then rho = product / max(cos(theta_i), "
            f"{COS_FLOOR:g}),",
            "cos(theta_i) (= wi.z) of the unclamped angles: cos(theta_h) cos(theta_d) - sin(theta_h)",
            "sin(theta_d) cos(phi_d). rho grows as 1/cos(theta_i) towards the light's horizon, up to",
            f"{1.0 / COS_FLOOR:g} times the product (from theta_i = "
            f"{np.degrees(np.arccos(COS_FLOOR)):.4g} deg on, where the divisor stays at its floor).",
        ]
    cut = measured_domain(model)
    if cut is not None:
        lines += [
            f"Measured domain: the fit was made from a projection with grazing cut-off c = {cut:.6g} deg",
            "and has data only where cos(theta_h) cos(theta_d) >= cos(c). Beyond it (both directions",
            "grazing) the angles are moved onto its edge first: theta_h = min(theta_h, c), then",
            "theta_d = min(theta_d, acos(min(cos(c) / cos(theta_h), 1))), as warp-rbrdf's renderer",
            "does (fit.rational.domain); the fit is not extrapolated there.",
        ]
    fl = flagged_summary(model)
    if fl and three:
        lines.append("FLAGGED pieces (the fit is not within its bound there; warp-rbrdf's renderer refuses")
        lines.append("such a 3-D fit): this code evaluates the fitted function there, clamped to the")
        lines.append("measured range:")
    elif fl:
        lines.append("FLAGGED pieces (the fit is not within its tolerance there; the renderer of")
        lines.append("warp-rbrdf reads the measured table instead, which is not exported): this")
        lines.append("code evaluates the fitted function there, clamped to the measured range:")
    if fl:
        for k, chans in fl:
            for name, rng in chans:
                r = "no range recorded: unclamped" if rng is None else f"[{rng[0]:.4g}, {rng[1]:.4g}] 1/sr"
                lines.append(f"  piece {k}, channel {comment_text(name)}: {r}")
    else:
        lines.append("Every piece is valid (within its fitted tolerance).")
    src = (getattr(model, "source", None) or {}).get("file") or ""
    tol = (getattr(model, "fit_info", None) or {}).get("tolerance")
    if src or tol is not None:
        tol = (f"{tol:.6g}" if isinstance(tol, (int, float)) and not isinstance(tol, bool)
               else comment_text(tol))
        lines.append(f"Source measurement: {comment_text(src) if src else '?'}; tolerance: {tol}.")
    lines.append("Generated by warp-rbrdf fit.export from an rbrdf-rational coefficient file.")
    return [prefix + s for s in lines]
