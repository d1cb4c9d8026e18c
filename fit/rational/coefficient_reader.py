"""Reading ``rbrdf-rational`` coefficient files: :func:`load` and :func:`from_dict` trust nothing
in the file: every value is checked for type, shape and range, the sizes against
:mod:`fit.limits`, and Q > 0 of every function is proved again
(:func:`fit.rational.coefficient_certify.recertify`). Every problem is one
:class:`fit.errors.BRDFFileError` line naming the file and the key. The format and what is
checked: docs/formats.md ("Rational coefficients", "Reading").
"""
from __future__ import annotations

import math

import numpy as np

from .. import jsonfields as F
from ..errors import BRDFFileError
from ..formats.angles import HALF_PI
from ..inputs import read_json
from ..limits import (
    MAX_BERNSTEIN_COEFFICIENTS,
    MAX_BRDF_VALUE,
    MAX_FILE_COEFFICIENTS,
    MAX_PIECES,
    MAX_RATIONAL_EXPONENT,
    MAX_RATIONAL_TERMS,
    MAX_RATIONAL_VARIABLES,
    MAX_SPLIT_DEPTH,
)
from .coefficient_certify import FileBudget, recertify
from .coefficient_format import (
    BRDF_VARIABLES_3D,
    FORMAT,
    SAMPLER_KEY,
    VERSION,
    VERSION_3D,
    VERSION_3D_FACTOR,
    VERSION_PIECEWISE,
    VERSIONS,
    content_sha256,
)
from .fallback import table_from_record
from .function import RationalFunction
from .model import (
    INPUT_TRANSFORMS,
    VALUE_FACTORS,
    VALUE_TRANSFORMS,
    PiecewiseRationalModel,
    RationalModel,
    Variable,
)


def _variables(v, key: str, kind: str, three_d: bool = False) -> list:
    vs = v
    if not isinstance(vs, list) or not 1 <= len(vs) <= MAX_RATIONAL_VARIABLES:
        raise F.Invalid(key, f"expected a list of 1 to {MAX_RATIONAL_VARIABLES} variables")
    out = []
    for i, vd in enumerate(vs):
        k = F.sub(key, i)
        F.obj(vd, k)
        name = F.name(F.get(vd, "name", k), F.sub(k, "name"), max_len=64)
        unit = F.name(vd.get("unit", ""), F.sub(k, "unit"), max_len=64)
        transform = F.string(vd.get("transform", "identity"), F.sub(k, "transform"), choices=INPUT_TRANSFORMS)
        lo, hi = F.array(F.get(vd, "domain", k), F.sub(k, "domain"), (2,))
        if not hi > lo:
            raise F.Invalid(F.sub(k, "domain"), f"empty domain [{lo:g}, {hi:g}]")
        if transform == "sqrt" and lo < 0:
            raise F.Invalid(F.sub(k, "domain"), f"starts at {lo:g} < 0 under the sqrt transform")
        out.append(Variable(name=name, unit=unit, transform=transform, domain=(float(lo), float(hi))))
    names = [v.name for v in out]
    if len(set(names)) != len(names):
        raise F.Invalid(key, f"variable names repeat: {names}")
    if kind == "brdf":
        want = BRDF_VARIABLES_3D if three_d else ["theta_h", "theta_d"]
        if names != want:
            raise F.Invalid(key, f"a {'version-3 ' if three_d else ''}BRDF's variables are {', '.join(want)}, "
                                 f"not {', '.join(names)}")
        for i, var in enumerate(out):
            top = math.pi if var.name == "phi_d" else HALF_PI
            if var.domain[0] < 0 or var.domain[1] > top + 1e-9:
                raise F.Invalid(F.sub(F.sub(key, i), "domain"), f"[{var.domain[0]:g}, {var.domain[1]:g}] rad "
                                                                f"is not inside [0, {'pi' if top > 2 else 'pi/2'}]")
    return out


def _polynomial(pd, key: str, n_vars: int, denominator: bool):
    F.obj(pd, key)
    kc = F.sub(key, "coefficients")
    ke = F.sub(key, "exponents")
    raw_c = F.get(pd, "coefficients", key)
    if not isinstance(raw_c, list):
        raise F.Invalid(kc, "expected a list of numbers")
    if len(raw_c) > MAX_RATIONAL_TERMS:
        raise F.Invalid(kc, f"{len(raw_c)} terms, above the limit {MAX_RATIONAL_TERMS} "
                            "(fit.limits.MAX_RATIONAL_TERMS)")
    if denominator and not raw_c:
        raise F.Invalid(kc, "the denominator needs at least one term")
    coef = F.array(raw_c, kc, (None,))
    exps = F.array(F.get(pd, "exponents", key), ke, (len(coef), n_vars), kind="int")
    if exps.size == 0:
        exps = np.zeros((0, n_vars), np.int64)
    if exps.size and (exps.min() < 0 or exps.max() > MAX_RATIONAL_EXPONENT):
        bad = int(exps.max()) if exps.max() > MAX_RATIONAL_EXPONENT else int(exps.min())
        raise F.Invalid(ke, f"exponent {bad} outside [0, {MAX_RATIONAL_EXPONENT}] "
                            "(fit.limits.MAX_RATIONAL_EXPONENT)")
    return exps, coef


def _degrees_record(fd, key: str, f: RationalFunction) -> None:
    """The informative ``num_degrees``, ``den_degrees`` and ``n_coefficients`` of a function
    record, when present: JSON integers that agree with its polynomials."""
    for k, want in (("num_degrees", list(f.num_degrees)), ("den_degrees", list(f.den_degrees))):
        if fd.get(k) is not None:
            got = F.array(fd[k], F.sub(key, k), (f.n_vars,), kind="int").tolist()
            if got != want:
                raise F.Invalid(F.sub(key, k), f"{got} does not match the exponents (their maxima are {want})")
    if fd.get("n_coefficients") is not None:
        got = F.integer(fd["n_coefficients"], F.sub(key, "n_coefficients"))
        if got != f.n_coefficients:
            raise F.Invalid(F.sub(key, "n_coefficients"), f"{got}, but the numerator and denominator hold "
                                                          f"{f.n_coefficients} coefficients")


def _function(fd, key: str, variables: list, budget: FileBudget, kind: str = "function"):
    F.obj(fd, key)
    n = len(variables)
    F.name(fd.get("output", ""), F.sub(key, "output"), max_len=64)
    basis = F.string(fd.get("basis", "chebyshev"), F.sub(key, "basis"))
    if basis != "chebyshev":
        raise F.Invalid(F.sub(key, "basis"), f"unsupported basis {basis[:40]!r}")
    dom = F.array(F.get(fd, "domain", key), F.sub(key, "domain"), (n, 2))
    expected = np.array([v.rf_domain for v in variables])
    if not np.allclose(dom, expected, rtol=1e-12, atol=1e-12):
        raise F.Invalid(F.sub(key, "domain"), f"{dom.tolist()} does not match the transformed "
                                              f"variable domains {expected.tolist()}")
    ne, nc = _polynomial(F.get(fd, "numerator", key), F.sub(key, "numerator"), n, False)
    de, dc = _polynomial(F.get(fd, "denominator", key), F.sub(key, "denominator"), n, True)
    size = int(np.prod(de.max(axis=0) + 1))
    if size > MAX_BERNSTEIN_COEFFICIENTS:
        raise F.Invalid(F.sub(key, "denominator"), f"degrees {de.max(axis=0).tolist()} give {size} Bernstein "
                                                   f"coefficients, above {MAX_BERNSTEIN_COEFFICIENTS} "
                                                   "(fit.limits.MAX_BERNSTEIN_COEFFICIENTS)")
    budget.coefficients += len(nc) + len(dc)
    if budget.coefficients > MAX_FILE_COEFFICIENTS:
        raise F.Invalid(key, f"the file holds more than {MAX_FILE_COEFFICIENTS} coefficients "
                             "(fit.limits.MAX_FILE_COEFFICIENTS)")
    # the record of the fit (what flagged() and the output clamps read), strictly typed
    info = {k: v for k, v in fd.items() if k not in (
        "output", "domain", "numerator", "denominator", "num_degrees", "den_degrees", "n_coefficients",
        "basis")}
    for k in ("valid", "feasible"):
        if k in info:
            F.flag(info[k], F.sub(key, k))
    if "q_certificate" in info:
        F.obj(info["q_certificate"], F.sub(key, "q_certificate"))
        if "certified" in info["q_certificate"]:
            F.flag(info["q_certificate"]["certified"], F.sub(F.sub(key, "q_certificate"), "certified"))
    for k in ("measured_range", "vouched_range"):
        if info.get(k) is not None:
            lo, hi = F.array(info[k], F.sub(key, k), (2,))
            if not lo <= hi:
                raise F.Invalid(F.sub(key, k), f"[{lo:g}, {hi:g}] is empty")
            if kind == "brdf" and (lo < 0 or hi > MAX_BRDF_VALUE):
                raise F.Invalid(F.sub(key, k), f"[{lo:g}, {hi:g}] 1/sr is not inside [0, {MAX_BRDF_VALUE:g}] "
                                               "(fit.limits.MAX_BRDF_VALUE)")
    f = RationalFunction(domain=dom, num_exponents=ne, num_coef=nc, den_exponents=de, den_coef=dc,
                         var_names=tuple(v.name for v in variables))
    _degrees_record(fd, key, f)
    return f, info


def _value(d, key: str, kind: str) -> dict:
    v = d.get("value", {})
    F.obj(v, key)
    out = {
        "value_transform": F.string(v.get("transform", "linear"), F.sub(key, "transform"), choices=VALUE_TRANSFORMS),
        "value_offset": F.number(v.get("offset", 0.0) if v.get("offset") is not None else 0.0,
                                 F.sub(key, "offset"), lo=0.0),
        "value_min": F.number(v.get("min"), F.sub(key, "min"), optional=True),
        "value_max": F.number(v.get("max"), F.sub(key, "max"), optional=True),
        "value_name": F.name(v.get("name", "y"), F.sub(key, "name"), max_len=64),
        "value_unit": F.name(v.get("unit", ""), F.sub(key, "unit"), max_len=64),
        "value_factor": F.string(v.get("factor", "none"), F.sub(key, "factor"), choices=VALUE_FACTORS),
    }
    lo, hi = out["value_min"], out["value_max"]
    if lo is not None and hi is not None and not hi > lo:
        raise F.Invalid(key, f"max {hi:g} is not above min {lo:g}")
    if kind == "brdf":
        if lo is None or lo < 0:
            raise F.Invalid(F.sub(key, "min"), "a BRDF needs a clamp min >= 0 (it is never negative)")
        if hi is not None and hi > MAX_BRDF_VALUE:
            raise F.Invalid(F.sub(key, "max"), f"{hi:g} 1/sr is above {MAX_BRDF_VALUE:g} (fit.limits.MAX_BRDF_VALUE)")
        if lo > MAX_BRDF_VALUE:
            raise F.Invalid(F.sub(key, "min"), f"{lo:g} 1/sr is above {MAX_BRDF_VALUE:g} (fit.limits.MAX_BRDF_VALUE)")
        if out["value_offset"] > MAX_BRDF_VALUE:
            raise F.Invalid(F.sub(key, "offset"), f"{out['value_offset']:g} 1/sr is above {MAX_BRDF_VALUE:g} "
                                                  "(fit.limits.MAX_BRDF_VALUE)")
    return out


def _source(d, key: str) -> dict:
    """The ``source`` record (informative), its ``file`` a name and its ``sha256`` hex when given."""
    return F.source_record(d.get("source", {"file": "", "sha256": ""}), key)


def _domain_policy(d, key: str) -> dict:
    pol = d.get("domain_policy", {"outside": "clamp"})
    F.obj(pol, key)
    # Q > 0 is proved on the box only: evaluating outside it (no clamp) could meet a pole
    F.string(pol.get("outside", "clamp"), F.sub(key, "outside"), choices=("clamp",))
    return dict(pol)


def _model(d: dict, path, key: str, depth: int, budget: FileBudget, three_d: bool = False):
    """A RationalModel (version 1 body) or PiecewiseRationalModel (version 2 body) from ``d``."""
    F.obj(d, key or "(top level)")
    kind = F.string(d.get("kind", "function"), F.sub(key, "kind"), choices=("brdf", "function"))
    variables = _variables(F.get(d, "variables", key), F.sub(key, "variables"), kind, three_d)
    if "split" in d or "pieces" in d:
        return _piecewise(d, path, key, depth, budget, kind, variables, three_d)
    value = _value(d, F.sub(key, "value"), kind)
    raw = F.get(d, "functions", key)
    if not isinstance(raw, list) or not 1 <= len(raw) <= 16:
        raise F.Invalid(F.sub(key, "functions"), "expected a list of 1 to 16 functions")
    functions, infos = [], []
    for i, fd in enumerate(raw):
        f, info = _function(fd, F.sub(F.sub(key, "functions"), i), variables, budget, kind)
        functions.append(f)
        infos.append(info)
    outputs = d.get("outputs")
    if outputs is None:
        outputs = [fd.get("output", "") for fd in raw]
    if not isinstance(outputs, list) or len(outputs) != len(functions):
        raise F.Invalid(F.sub(key, "outputs"), f"expected a list of {len(functions)} output names")
    outputs = [F.name(o, F.sub(F.sub(key, "outputs"), i), max_len=64) for i, o in enumerate(outputs)]
    if kind == "brdf" and outputs != ["R", "G", "B"]:
        raise F.Invalid(F.sub(key, "outputs"), f"a BRDF's outputs are R, G, B, not {', '.join(outputs)}")
    basis = F.string(d.get("basis", "chebyshev"), F.sub(key, "basis"))
    if basis != "chebyshev":
        raise F.Invalid(F.sub(key, "basis"), f"unsupported basis {basis[:40]!r}")
    return RationalModel(
        name=F.name(d.get("name", ""), F.sub(key, "name")), variables=variables,
        functions=functions, outputs=tuple(outputs), kind=kind, **value,
        domain_policy=_domain_policy(d, F.sub(key, "domain_policy")),
        fit_info=_fit_info(d, key), function_info=infos,
        source=_source(d, F.sub(key, "source")))


def _fit_info(d: dict, key: str) -> dict:
    """The file's ``fit`` record (how the fit was made), with the fields that readers act on
    checked: ``grazing_cutoff_deg`` (the projection's grazing cut-off, degrees, in [0, 90] or
    null: :mod:`fit.rational.domain`, :mod:`fit.rational.fallback`). Other fields are kept as
    they are (what reaches generated code is escaped by :mod:`fit.export.escape`)."""
    info = dict(F.obj(d.get("fit", {}), F.sub(key, "fit")))
    fkey = F.sub(key, "fit")
    if info.get("grazing_cutoff_deg") is not None:
        info["grazing_cutoff_deg"] = F.number(info["grazing_cutoff_deg"], F.sub(fkey, "grazing_cutoff_deg"),
                                              lo=0.0, hi=90.0)
    if "bound" in info:
        _bound_records(info["bound"], F.sub(fkey, "bound"))
    return info


def _bound_records(recs, key: str) -> None:
    """The ``bound`` records (:mod:`fit.rational.proved_bound`): per piece and channel ``proved``
    (>= 0 or null), ``proved_fraction`` in [0, 1], ``verified`` >= 0 and never above ``proved``."""
    if not isinstance(recs, list) or len(recs) > 3 * MAX_PIECES:
        raise F.Invalid(key, f"expected a list of at most {3 * MAX_PIECES} records")
    for i, r in enumerate(recs):
        ki = F.sub(key, i)
        F.obj(r, ki)
        F.string(F.get(r, "channel", ki), F.sub(ki, "channel"), choices=["R", "G", "B"])
        F.string(F.get(r, "unit", ki), F.sub(ki, "unit"))
        F.number(F.get(r, "proved_fraction", ki), F.sub(ki, "proved_fraction"), lo=0.0, hi=1.0)
        verified = F.number(F.get(r, "verified", ki), F.sub(ki, "verified"), lo=0.0)
        if F.get(r, "proved", ki) is not None:
            proved = F.number(r["proved"], F.sub(ki, "proved"), lo=0.0)
            if verified > proved * (1 + 1e-9):
                raise F.Invalid(F.sub(ki, "proved"), f"{proved:.6g} is below the error verified, {verified:.6g}")


def _piecewise(d, path, key, depth, budget, kind, variables, three_d=False):
    if depth >= MAX_SPLIT_DEPTH:
        raise F.Invalid(key, f"pieces nested more than {MAX_SPLIT_DEPTH} deep (fit.limits.MAX_SPLIT_DEPTH)")
    name = F.name(d.get("name", ""), F.sub(key, "name"))    # before the pieces, which inherit it
    ks = F.sub(key, "split")
    split = F.obj(F.get(d, "split", key), ks)
    var = F.string(F.get(split, "variable", ks), F.sub(ks, "variable"), choices=[v.name for v in variables])
    raw = F.get(d, "pieces", key)
    kp = F.sub(key, "pieces")
    if not isinstance(raw, list) or not 1 <= len(raw) <= MAX_PIECES:
        raise F.Invalid(kp, f"expected a list of 1 to {MAX_PIECES} pieces (fit.limits.MAX_PIECES)")
    edges = F.array(F.get(split, "edges", ks), F.sub(ks, "edges"), (len(raw) + 1,))
    pieces, infos = [], []
    for i, pd in enumerate(raw):
        ki = F.sub(kp, i)
        F.obj(pd, ki)
        sub = {k: d[k] for k in ("name", "kind", "value", "basis", "outputs") if k in d}
        if isinstance(sub.get("value"), dict):      # the value factor is the whole model's (step 8)
            sub["value"] = {k: v for k, v in sub["value"].items() if k != "factor"}
        sub.update(variables=F.get(pd, "variables", ki), domain_policy=d.get("domain_policy", {"outside": "clamp"}))
        if "split" in pd:
            sub.update(split=pd["split"], pieces=F.get(pd, "pieces", ki))
        else:
            sub.update(functions=F.get(pd, "functions", ki))
        pieces.append(_model(sub, path, ki, depth + 1, budget, three_d))
        infos.append(dict(F.obj(pd.get("info", {}), F.sub(ki, "info"))))
    factor = _value(d, F.sub(key, "value"), kind)["value_factor"] if depth == 0 else "none"
    try:
        return PiecewiseRationalModel(
            name=name, variables=variables, value_factor=factor,
            split_variable=var, edges=[float(e) for e in edges], pieces=pieces, kind=kind,
            domain_policy=_domain_policy(d, F.sub(key, "domain_policy")),
            fit_info=_fit_info(d, key), piece_info=infos,
            source=_source(d, F.sub(key, "source")))
    except ValueError as e:
        raise F.Invalid(key or "pieces", str(e)) from None



def from_dict(d: dict, path=None, certify: bool = True):
    """Build a model from a parsed file (:class:`RationalModel` for version 1,
    :class:`PiecewiseRationalModel` for version 2) after checking every value's type, shape and
    range and the limits of :mod:`fit.limits`, and (``certify``) re-proving Q > 0 of every
    function (:func:`recertify`): a file's ``certified: true`` is never trusted.
    :class:`BRDFFileError` naming the file and the key on any problem."""
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        got = d.get("format") if isinstance(d, dict) else None
        raise BRDFFileError(path, f"not an {FORMAT} coefficient file (format key is "
                                  f"{str(got)[:40] if got is not None else None!r})")
    ver = d.get("version")
    if type(ver) is not int or ver not in VERSIONS:   # 3.0 or true is not the integer 3 or 1
        raise BRDFFileError(path, f"key version: unsupported {FORMAT} version "
                                  f"{ver if type(ver) is int else repr(ver)[:20]} (this reader knows the "
                                  f"integers {', '.join(map(str, VERSIONS))})")
    budget = FileBudget()
    label = {VERSION_PIECEWISE: "version-2 ", VERSION_3D: "version-3 ", VERSION_3D_FACTOR: "version-4 "}.get(ver, "")
    try:
        if ver == VERSION and ("split" in d or "pieces" in d):
            raise F.Invalid("version", "a version-1 file has no 'split' or 'pieces' (version 2)")
        if ver == VERSION_PIECEWISE and "split" not in d:
            raise F.Invalid("split", "missing (a version-2 file is piecewise)")
        model = _model(d, path, "", 0, budget, three_d=ver in (VERSION_3D, VERSION_3D_FACTOR))
        if (model.value_factor != "none") != (ver == VERSION_3D_FACTOR):
            raise F.Invalid("value.factor", f"{model.value_factor!r} in a version-{ver} file (a value factor "
                                            f"other than 'none' is version {VERSION_3D_FACTOR}, and version "
                                            f"{VERSION_3D_FACTOR} has one)")
        if "fallback" in d:       # optional (flagged 2-D fits): checked whole, kept as written
            table = table_from_record(d["fallback"], model, "fallback")
            if table.max(initial=0.0) > MAX_BRDF_VALUE:
                raise F.Invalid("fallback.blocks", f"holds {float(table.max()):.3g} 1/sr, above {MAX_BRDF_VALUE:g} "
                                                   "(fit.limits.MAX_BRDF_VALUE)")
            model.fallback = d["fallback"]
        if SAMPLER_KEY in d:      # optional: the fit's own inverse CDFs, bound to this content
            rec = F.obj(d[SAMPLER_KEY], SAMPLER_KEY)
            if rec.get("fit_sha256") != content_sha256(d):
                raise F.Invalid(f"{SAMPLER_KEY}.fit_sha256", "not the sha256 of this fit: the sampler was made "
                                                             "from other coefficients (make it again: rbrdf-fit "
                                                             "cdf FIT.json --out FIT.json)")
            model.sampler = rec   # checked whole where it is used (fit.sampling.embedded)
    except F.Invalid as e:
        raise BRDFFileError(path, f"invalid {FORMAT} {label}coefficient file: {e}") from None
    except (KeyError, TypeError, ValueError, IndexError, ArithmeticError) as e:
        raise BRDFFileError(path, f"invalid {FORMAT} {label}coefficient file ({e.__class__.__name__}: {e})") from None
    if certify:
        recertify(model, path, budget)
    return model


def load(path):
    """Read an ``rbrdf-rational`` JSON file (:func:`fit.inputs.read_json`: a regular file of at
    most :data:`fit.limits.MAX_JSON_BYTES`, strict JSON) and build its model
    (:func:`from_dict`, Q > 0 re-proved); :class:`BRDFFileError` if missing, corrupt, of an
    unknown version, beyond a limit or with a denominator that is not positive."""
    return from_dict(read_json(path, "coefficient file"), path)
