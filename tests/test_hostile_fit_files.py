"""Hostile input files for every reader of the fitter (issue 22): MERL ``.binary``, RGL
``.bsdf``, ``rbrdf-rational`` and ``rbrdf-cdf`` JSON, projected ``.npz``.

Every case is one corrupt, truncated, absurd or oversized file. The reader must refuse it
with one :class:`fit.errors.BRDFFileError` line that names the file and the problem (and the
key, for JSON), never accept it silently, never raise anything else. The cases that reach
``rbrdf-fit`` are also run through the command line (exit status 2, one stderr line, no output
written). Each case carries the class of the issue it belongs to (``CLASSES``), counted in
docs/robustness.md.
"""
from __future__ import annotations

import copy
import io
import json
import os
import zipfile

import numpy as np
import pytest
from conftest import data_file
from hostile import (
    CLASSES,
    assert_bad_input,
    assert_one_line,
    assert_unchanged,
    run,
    small_cdf_dict,
    small_rational_dict,
    snapshot,
    write_json,
)

from fit.errors import BRDFFileError
from fit.formats import load_measured
from fit.projection.projected import ProjectedBRDF
from fit.formats.merl import MERL_FILE_BYTES, MERL_SHAPE, read_merl
from fit.formats.rgl import read_rgl
from fit.formats.tensor_file import read_tensor_file, write_tensor_file
from fit.rational.coefficient_file import load as load_rational
from fit.sampling.cdf_file import load as load_cdf

N = int(np.prod(MERL_SHAPE))


# ----------------------------------------------------------------------------------------------
# MERL .binary
# ----------------------------------------------------------------------------------------------
def _merl_bytes(stored: np.ndarray) -> bytes:
    """A MERL file of stored (scaled) values, shape (3, 90, 90, 180)."""
    return np.asarray(MERL_SHAPE, "<i4").tobytes() + np.ascontiguousarray(stored, "<f8").tobytes()


def _stored(fill=1.0):
    return np.full((3,) + MERL_SHAPE, fill)


def _with(idx, value, base=1.0):
    s = _stored(base)
    s[idx] = value
    return _merl_bytes(s)


MERL_CASES = [
    ("empty", "traceback", lambda: b"", "truncated MERL file"),
    ("header-only", "traceback", lambda: np.asarray(MERL_SHAPE, "<i4").tobytes(), "truncated MERL file"),
    ("short-header", "traceback", lambda: b"\x5a\x00\x00", "truncated MERL file"),
    ("wrong-dims", "traceback", lambda: np.asarray([90, 90, 360], "<i4").tobytes() + b"\0" * 64, "wrong MERL header"),
    ("negative-dims", "traceback", lambda: np.asarray([-1, 90, 180], "<i4").tobytes(), "wrong MERL header"),
    ("huge-dims", "memory", lambda: np.asarray([2**31 - 1] * 3, "<i4").tobytes() + b"\0" * 64, "wrong MERL header"),
    ("truncated-data", "traceback", lambda: _merl_bytes(_stored())[:MERL_FILE_BYTES // 2], "truncated MERL file"),
    ("one-byte-short", "traceback", lambda: _merl_bytes(_stored())[:-1], "truncated MERL file"),
    ("trailing-data", "silent", lambda: _merl_bytes(_stored()) + b"\0" * 8, "oversized MERL file"),
    ("nan-value", "silent", lambda: _with((1, 3, 4, 5), np.nan), "NaN/inf values (first in channel G"),
    ("inf-value", "silent", lambda: _with((2, 0, 0, 0), np.inf), "NaN/inf"),
    ("no-valid-sample", "silent", lambda: _merl_bytes(_stored(-1.0)), "no valid sample in channel R"),
    ("blue-channel-empty", "silent", lambda: _with(2, -1.0), "no valid sample in channel B"),
    ("absurd-value", "silent", lambda: _with((0, 10, 10, 10), 1e300), "absurd BRDF value"),
    ("absurd-1e12", "silent", lambda: _with((1, 5, 5, 5), 1e12), "absurd BRDF value"),
]


@pytest.fixture(scope="module")
def merl_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("merl")


@pytest.mark.parametrize("name, klass, make, fragment", MERL_CASES, ids=[c[0] for c in MERL_CASES])
def test_merl_reader_refuses(merl_dir, name, klass, make, fragment):
    p = merl_dir / f"{name}.binary"
    p.write_bytes(make())
    with pytest.raises(BRDFFileError) as e:
        read_merl(p)
    assert_one_line(str(e.value), p, fragment)
    p.unlink()


def test_merl_special_paths(tmp_path, capsys):
    """A folder, a device and a missing file named like MERL files: refused at once, one line
    (a named pipe is test_hostile_fit_limits.py's: it would block a reader that opens it)."""
    d = tmp_path / "folder.binary"
    d.mkdir()
    dev = tmp_path / "zero.binary"
    dev.symlink_to("/dev/zero")
    for p, frag in ((d, "is a directory"), (dev, "is a device"), (tmp_path / "nope.binary", "file not found"),
                    (tmp_path / "sub" / "x.binary", "file not found")):
        with pytest.raises(BRDFFileError) as e:
            load_measured(p)
        assert_one_line(str(e.value), p, frag)
        rc, _, err = run(capsys, ["info", p])
        assert_bad_input(rc, err, p, frag, out="")


def test_merl_negative_values_are_no_sample_and_loaded(tmp_path):
    """What the format allows is accepted: negative stored values are 'no sample', the rest loads."""
    s = _stored(0.5)
    s[:, :, :, :90] = -1.0
    p = tmp_path / "half.binary"
    p.write_bytes(_merl_bytes(s))
    b = read_merl(p)
    assert b.valid.mean() == pytest.approx(0.5) and np.all(b.values[~b.valid] == 0)


# ----------------------------------------------------------------------------------------------
# RGL .bsdf
# ----------------------------------------------------------------------------------------------
def _paper():
    return data_file("rgl/paper_white_rgb.bsdf")


def _fields():
    return {k: np.array(v.data) for k, v in read_tensor_file(_paper()).items()}


def _set(name, value):
    def edit(f):
        f[name] = value(f) if callable(value) else value
        return f
    return edit


def _drop(name):
    def edit(f):
        del f[name]
        return f
    return edit


def _poke(name, idx, value):
    def edit(f):
        a = f[name].astype(np.float64) if f[name].dtype.kind != "f" else f[name].copy()
        a = a.astype(f[name].dtype)
        a[idx] = value
        f[name] = a
        return f
    return edit


RGL_EDITS = [
    ("missing-rgb", "traceback", _drop("rgb"), "missing field(s) rgb"),
    ("missing-vndf", "traceback", _drop("vndf"), "missing field(s) vndf"),
    ("spectral-only", "traceback", lambda f: {**{k: v for k, v in f.items() if k != "rgb"},
                                              "spectra": f["rgb"]}, "spectral-only"),
    ("anisotropic", "silent", _set("phi_i", np.zeros(4, np.float32)), "anisotropic"),
    ("theta-decreasing", "silent", _set("theta_i", lambda f: f["theta_i"][::-1].copy()), "not strictly increasing"),
    ("theta-beyond-90", "silent", _poke("theta_i", -1, 3.0), "outside [0, 90] deg"),
    ("nan-rgb", "silent", _poke("rgb", (0, 2, 1, 5, 5), np.nan), "field 'rgb' contains NaN"),
    ("inf-ndf", "silent", _poke("ndf", (0, 3), np.inf), "field 'ndf' contains NaN"),
    ("nan-luminance", "silent", _poke("luminance", (0, 1, 2, 2), np.nan), "field 'luminance' contains NaN"),
    ("absurd-rgb", "silent", _poke("rgb", (0, 1, 0, 3, 3), 1e30), "absurd value"),
    ("absurd-ndf", "silent", _poke("ndf", (1, 7), -3e20), "absurd value"),
    ("tiny-sigma", "silent", _poke("sigma", (0, 0), 1e-30), "field 'sigma' holds"),
    ("zero-sigma", "silent", _poke("sigma", (1, 5), 0.0), "'sigma' > 0"),
    ("negative-vndf", "silent", _poke("vndf", (0, 2, 4, 4), -1.0), "must be >= 0"),
    ("zero-vndf-slice", "silent", _set("vndf", lambda f: np.zeros_like(f["vndf"])), "vndf"),
    ("rgb-wrong-channels", "traceback", _set("rgb", lambda f: np.ascontiguousarray(f["rgb"][:, :, :2])),
     "field 'rgb' has shape"),
    ("rgb-wrong-slices", "traceback", _set("rgb", lambda f: np.ascontiguousarray(f["rgb"][:, :3])),
     "field 'rgb' has shape"),
    ("luminance-mismatch", "traceback", _set("luminance", lambda f: np.ascontiguousarray(f["luminance"][..., :7])),
     "field 'luminance' has shape"),
    ("vndf-3d", "traceback", _set("vndf", lambda f: np.ascontiguousarray(f["vndf"][0])), "must have 4 dimension"),
    ("ndf-1-row", "traceback", _set("ndf", lambda f: np.ascontiguousarray(f["ndf"][:1])), "at least 2 x 2"),
    ("integer-rgb", "silent", _set("rgb", lambda f: f["rgb"].astype(np.int32)), "must be floating point"),
    ("description-2d", "traceback", _set("description", np.zeros((2, 2), np.uint8)), "description"),
    ("jacobian-array", "traceback", _set("jacobian", np.ones(3, np.uint8)), "jacobian"),
    ("theta-empty", "traceback", _set("theta_i", np.zeros(0, np.float32)), "theta_i"),
    ("phi-empty", "traceback", _set("phi_i", np.zeros(0, np.float32)), "phi_i"),
    ("too-many-slices", "memory", _set("theta_i", np.linspace(0, 1.5, 300, dtype=np.float32)), "theta_i"),
    ("huge-f16-vndf", "memory", _set("vndf", np.ones((1, 8, 1500, 1500), np.float16)), "MAX_RGL_TABLE_SIDE"),
    ("huge-f16-total", "memory", _set("vndf", np.ones((1, 8, 1024, 1024), np.float16)), "MAX_RGL_ELEMENTS"),
]


@pytest.mark.parametrize("name, klass, edit, fragment", RGL_EDITS, ids=[c[0] for c in RGL_EDITS])
def test_rgl_reader_refuses(tmp_path, name, klass, edit, fragment):
    p = tmp_path / f"{name}.bsdf"
    write_tensor_file(p, edit(_fields()))
    with pytest.raises(BRDFFileError) as e:
        read_rgl(p)
    assert_one_line(str(e.value), p, fragment)


def test_rgl_oversized_and_special_files(tmp_path, capsys):
    """A file above MAX_RGL_FILE_BYTES is refused from its size (sparse: nothing is read), a
    folder and a device at once."""
    from fit.limits import MAX_RGL_FILE_BYTES

    big = tmp_path / "big.bsdf"
    with open(big, "wb") as f:
        f.truncate(MAX_RGL_FILE_BYTES + 1)
    d = tmp_path / "dir.bsdf"
    d.mkdir()
    dev = tmp_path / "null.bsdf"
    dev.symlink_to("/dev/null")
    for p, frag in ((big, "above the limit"), (d, "is a directory"), (dev, "is a device")):
        with pytest.raises(BRDFFileError) as e:
            read_rgl(p)
        assert_one_line(str(e.value), p, frag)
        rc, _, err = run(capsys, ["info", p])
        assert_bad_input(rc, err, p, frag, out="")


# ----------------------------------------------------------------------------------------------
# rbrdf-rational JSON
# ----------------------------------------------------------------------------------------------
def _edit_json(fn):
    def make():
        d = small_rational_dict()
        fn(d)
        return json.dumps(d)
    return make


def _fn(d, piece=0, k=0):
    return d["pieces"][piece]["functions"][k]


def _deep(text="[" * 100000 + "]" * 100000):
    return lambda: text


def _many_terms(d):
    f = _fn(d)
    f["numerator"]["exponents"] = [[i % 20, i // 20 % 20] for i in range(14400)]
    f["numerator"]["coefficients"] = [0.0] * 14400


def _exponent(e):
    def fn(d):
        _fn(d)["numerator"]["exponents"][1] = [e, 0]
    return fn


def _pole(d):
    # Q = 0.2 + 1.0 T_1: negative on part of the box, while the record says certified
    _fn(d)["denominator"]["coefficients"] = [0.2, 1.0]


def _nested_pieces(depth):
    def fn(d):
        piece = copy.deepcopy(d["pieces"][0])
        node = d
        for _ in range(depth):
            node["pieces"][0] = {"variables": piece["variables"], "split": {"variable": "theta_h",
                                                                            "edges": [0.0, 1.5707963267948966]},
                                 "pieces": [copy.deepcopy(piece)]}
            node = node["pieces"][0]
    return fn


RATIONAL_CASES = [
    ("empty", "traceback", lambda: "", "not valid JSON"),
    ("not-json", "traceback", lambda: "hello", "not valid JSON"),
    ("truncated", "traceback", lambda: json.dumps(small_rational_dict())[:200], "not valid JSON"),
    ("nan-literal", "silent", lambda: json.dumps(small_rational_dict()).replace("0.2", "NaN", 1), "NaN"),
    ("infinity-literal", "silent", lambda: json.dumps(small_rational_dict()).replace("-0.05", "-Infinity", 1),
     "Infinity"),
    ("overflowing-number", "silent", lambda: json.dumps(small_rational_dict()).replace("0.02", "1e999", 1),
     "overflows"),
    ("huge-integer", "traceback", lambda: '{"format": "rbrdf-rational", "version": ' + "9" * 5000 + "}", "digits"),
    ("deep-nesting", "traceback", _deep(), "nested"),
    ("deep-objects", "traceback", _deep('{"a":' * 5000 + "1" + "}" * 5000), "nested"),
    ("not-utf8", "traceback", lambda: b'{"format": "\xff\xfe"}', "not UTF-8"),
    ("top-level-list", "traceback", lambda: "[1, 2]", "not an rbrdf-rational"),
    ("wrong-format", "traceback", _edit_json(lambda d: d.update(format="rbrdf-cdf")), "not an rbrdf-rational"),
    ("version-99", "traceback", _edit_json(lambda d: d.update(version=99)), "unsupported rbrdf-rational version 99"),
    ("version-string", "traceback", _edit_json(lambda d: d.update(version="2")), "unsupported"),
    ("version-true", "silent", _edit_json(lambda d: d.update(version=True)), "unsupported"),
    ("v1-with-pieces", "silent", _edit_json(lambda d: d.update(version=1)), "version"),
    ("missing-pieces", "traceback", _edit_json(lambda d: d.pop("pieces")), "key pieces: missing"),
    ("string-coefficient", "silent", _edit_json(lambda d: _fn(d)["numerator"]["coefficients"].__setitem__(0, "1.0")),
     "key pieces[0].functions[0].numerator.coefficients[0]: expected a number"),
    ("null-coefficient", "traceback", _edit_json(lambda d: _fn(d)["denominator"]["coefficients"].__setitem__(0, None)),
     "denominator.coefficients[0]"),
    ("bool-coefficient", "silent", _edit_json(lambda d: _fn(d)["numerator"]["coefficients"].__setitem__(1, True)),
     "numerator.coefficients[1]"),
    ("float-exponent", "silent", _edit_json(lambda d: _fn(d)["numerator"]["exponents"].__setitem__(1, [1.5, 0])),
     "numerator.exponents[1][0]: expected an integer"),
    ("negative-exponent", "traceback", _edit_json(_exponent(-1)), "exponent -1 outside"),
    ("exponent-1e5", "hang", _edit_json(_exponent(100000)), "MAX_RATIONAL_EXPONENT"),
    ("exponent-1e9", "memory", _edit_json(_exponent(10**9)), "MAX_RATIONAL_EXPONENT"),
    ("exponent-2e62", "traceback", _edit_json(_exponent(2**63)), "expected an integer"),
    ("14400-terms", "hang", _edit_json(_many_terms), "MAX_RATIONAL_TERMS"),
    ("ragged-exponents", "traceback", _edit_json(lambda d: _fn(d)["numerator"]["exponents"].__setitem__(0, [0])),
     "exponents[0]"),
    ("count-mismatch", "traceback", _edit_json(lambda d: _fn(d)["numerator"]["coefficients"].pop()),
     "numerator.exponents: has 3 entries, expected 2"),
    ("three-var-exponents", "traceback",
     _edit_json(lambda d: _fn(d)["numerator"].update(exponents=[[0, 0, 0], [1, 0, 0], [0, 1, 0]])), "exponents"),
    ("no-denominator-term", "traceback",
     _edit_json(lambda d: _fn(d)["denominator"].update(exponents=[], coefficients=[])), "at least one term"),
    ("pole-certified-true", "silent", _edit_json(_pole), "although the file says it is certified"),
    ("zero-denominator", "silent", _edit_json(lambda d: _fn(d)["denominator"].update(coefficients=[0.0, 0.0])),
     "denominator has a zero"),
    ("negative-denominator", "silent",
     _edit_json(lambda d: _fn(d, 1, 2)["denominator"].update(coefficients=[-1.0, 0.1])), "pieces[1].functions[2]"),
    ("domain-mismatch", "silent", _edit_json(lambda d: _fn(d).update(domain=[[0, 1], [0, 0.6]])), "does not match"),
    ("domain-strings", "silent", _edit_json(lambda d: _fn(d).update(domain=[["0", "1"], [0, 0.6]])),
     "expected a number"),
    ("variables-empty", "traceback", _edit_json(lambda d: d.update(variables=[])), "variables"),
    ("variable-transform", "traceback", _edit_json(lambda d: d["variables"][0].update(transform="cube")),
     "variables[0].transform"),
    ("domain-reversed", "traceback", _edit_json(lambda d: d["variables"][1].update(domain=[1.3, 0.0])),
     "empty domain"),
    ("brdf-variable-names", "silent", _edit_json(lambda d: d["variables"][0].update(name="theta_i")),
     "theta_h, theta_d"),
    ("brdf-domain-beyond-90", "silent", _edit_json(lambda d: d["variables"][0].update(domain=[0.0, 3.0])),
     "is not inside [0, pi/2]"),
    ("brdf-outputs", "silent", _edit_json(lambda d: d.update(outputs=["R", "G", "X"])), "outputs"),
    ("brdf-negative-min", "silent", _edit_json(lambda d: d["value"].update(min=-1.0)), "value.min"),
    ("brdf-no-min", "silent", _edit_json(lambda d: d["value"].update(min=None)), "value.min"),
    ("value-max-below-min", "silent", _edit_json(lambda d: d["value"].update(max=-1.0)), "max"),
    ("value-max-absurd", "silent", _edit_json(lambda d: d["value"].update(max=1e300)), "value.max"),
    ("value-transform", "traceback", _edit_json(lambda d: d["value"].update(transform="exp")), "value.transform"),
    ("offset-string", "silent", _edit_json(lambda d: d["value"].update(offset="0.1")), "value.offset"),
    ("extrapolate", "silent", _edit_json(lambda d: d["domain_policy"].update(outside="extrapolate")),
     "domain_policy.outside"),
    ("valid-string", "silent", _edit_json(lambda d: _fn(d).update(valid="no")), "functions[0].valid"),
    ("certified-string", "silent", _edit_json(lambda d: _fn(d)["q_certificate"].update(certified="yes")),
     "q_certificate.certified"),
    ("range-reversed", "silent", _edit_json(lambda d: _fn(d).update(measured_range=[2.0, 1.0])),
     "measured_range"),
    ("range-strings", "silent", _edit_json(lambda d: _fn(d).update(vouched_range=["a", "b"])), "vouched_range"),
    ("edges-decreasing", "silent", _edit_json(lambda d: d["split"].update(edges=[0.0, 1.0, 0.6])), "pieces"),
    ("edges-wrong-count", "traceback", _edit_json(lambda d: d["split"].update(edges=[0.0, 1.3])), "split.edges"),
    ("split-variable", "traceback", _edit_json(lambda d: d["split"].update(variable="phi_d")), "split.variable"),
    ("too-many-pieces", "hang", _edit_json(lambda d: d.update(pieces=d["pieces"] * 40)), "MAX_PIECES"),
    ("nested-too-deep", "traceback", _edit_json(_nested_pieces(6)), "MAX_SPLIT_DEPTH"),
    ("piece-not-object", "traceback", _edit_json(lambda d: d["pieces"].__setitem__(1, 7)), "pieces[1]"),
    ("fit-not-object", "traceback", _edit_json(lambda d: d.update(fit=[1, 2])), "fit"),
    ("log-no-max-overflow", "silent", _edit_json(lambda d: (d["value"].update(transform="log", max=None),
                                                           _fn(d)["numerator"].update(coefficients=[900.0, 0, 0]))),
     "exp would overflow"),
]


@pytest.mark.parametrize("name, klass, make, fragment", RATIONAL_CASES, ids=[c[0] for c in RATIONAL_CASES])
def test_rational_reader_refuses(tmp_path, name, klass, make, fragment):
    p = tmp_path / f"{name}.json"
    data = make()
    (p.write_bytes if isinstance(data, bytes) else p.write_text)(data)
    with pytest.raises(BRDFFileError) as e:
        load_rational(p)
    assert_one_line(str(e.value), p, fragment)


def test_rational_valid_files_load_and_special_paths(tmp_path):
    """The small valid files load (both versions), the shipped fits too; a folder, a device and
    an oversized (sparse) file are refused without being read."""
    from fit.limits import MAX_JSON_BYTES
    from fit.rational.coefficient_file import load

    for piecewise in (True, False):
        m = load(write_json(tmp_path / f"ok{piecewise}.json", small_rational_dict(piecewise)))
        assert np.all(np.isfinite(m.evaluate_brdf(np.linspace(0, 1.5, 7), 0.3)))
    for name in ("paper_white_rgb", "satin_rosaline_rgb"):
        load(os.path.join(os.path.dirname(__file__), "..", "warp_rbrdf", "data", f"{name}.json"))
    big = tmp_path / "big.json"
    with open(big, "wb") as f:
        f.truncate(MAX_JSON_BYTES + 1)
    d = tmp_path / "d.json"
    d.mkdir()
    dev = tmp_path / "z.json"
    dev.symlink_to("/dev/zero")
    for p, frag in ((big, "above the limit"), (d, "is a directory"), (dev, "is a device"),
                    (tmp_path / "none.json", "file not found")):
        with pytest.raises(BRDFFileError) as e:
            load(p)
        assert_one_line(str(e.value), p, frag)


# ----------------------------------------------------------------------------------------------
# rbrdf-cdf JSON
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cdf_dict():
    return small_cdf_dict()


def _cdf(fn):
    def make(base):
        d = copy.deepcopy(base)
        fn(d)
        return json.dumps(d)
    return make


def _td(d):
    return d["table_data"]


def _decreasing(d):
    row = _td(d)["cdf_theta"][1]
    row[3], row[4] = row[4], row[3]


def _zero_mass(d):
    row = _td(d)["cdf_phi"][0][2]
    row[5] = row[4]


def _global_folding(d):
    """A global-layout file that says 'no fallback' with a theta map that decreases in mu."""
    from fit.rational.coefficient_file import to_dict
    from fit.rational.function import RationalFunction
    from fit.rational.model import RationalModel, Variable

    def model(names, n_out, out, coef):
        dom = [[0.0, np.pi / 2]] * (len(names) - 1) + [[0.0, 1.0]]
        e = [[0] * (len(names) - 1) + [k] for k in range(len(coef))]
        f = RationalFunction(dom, e, coef, [[0] * len(names)], [1.0])
        m = RationalModel(name=out, kind="function", variables=[Variable(n, "rad", "identity", tuple(r))
                                                                for n, r in zip(names, dom)],
                          functions=[f], outputs=(out,), value_min=None)
        return to_dict(m)

    d.update(layout="global", pieces=None, fallback=False,
             theta=model(("theta_v", "mu"), 2, "theta_l", [0.0, 1.0, 0.9]),   # F' < 0 for mu < 0.36
             phi=model(("theta_v", "theta_l", "u"), 3, "phi_abs", [1.5, 1.5]))


CDF_CASES = [
    ("empty", "traceback", lambda b: "", "not valid JSON"),
    ("truncated", "traceback", lambda b: json.dumps(b)[:5000], "not valid JSON"),
    ("wrong-format", "traceback", _cdf(lambda d: d.update(format="rbrdf-rational")), "not an rbrdf-cdf"),
    ("version-3", "traceback", _cdf(lambda d: d.update(version=3)), "unsupported rbrdf-cdf version 3"),
    ("n_mu-1e6", "memory", _cdf(lambda d: d["pieces"].update(n_mu=10**6)), "MAX_CDF_PIECES"),
    ("n_u-1e5", "memory", _cdf(lambda d: d["pieces"].update(n_u=100000)), "MAX_CDF_PIECES"),
    ("n_u-0", "traceback", _cdf(lambda d: d["pieces"].update(n_u=0)), "n_u = 0"),
    ("n_mu-string", "silent", _cdf(lambda d: d["pieces"].update(n_mu="64")), "pieces.n_mu: expected an integer"),
    ("n_mu-fraction", "silent", _cdf(lambda d: d["pieces"].update(n_mu=8.5)), "pieces.n_mu"),
    ("row_ok-short", "traceback", _cdf(lambda d: d["pieces"].update(row_ok=[True])), "pieces.row_ok"),
    ("row_ok-ints", "silent", _cdf(lambda d: d["pieces"].update(row_ok=[1, 1, 1, 1])), "pieces.row_ok[0]"),
    ("cdf-decreasing", "silent", _cdf(_decreasing), "table_data.cdf_theta: not strictly increasing"),
    ("zero-mass-cell", "silent", _cdf(_zero_mass), "table_data.cdf_phi: not strictly increasing"),
    ("cdf-null", "silent", _cdf(lambda d: _td(d)["cdf_theta"][0].__setitem__(3, None)), "cdf_theta[0][3]"),
    ("cdf-not-to-1", "silent", _cdf(lambda d: _td(d)["cdf_theta"][2].__setitem__(-1, 0.9)), "from 0 to 1"),
    ("cdf-phi-wrong-shape", "silent", _cdf(lambda d: _td(d)["cdf_phi"].pop()), "cdf_phi"),
    ("cdf-theta-wrong-nt", "silent", _cdf(lambda d: [r.pop() for r in _td(d)["cdf_theta"]]), "cdf_phi"),
    ("cdf-phi-ragged", "traceback", _cdf(lambda d: _td(d)["cdf_phi"][1][3].pop()), "ragged"),
    ("theta_v-wrong", "silent", _cdf(lambda d: _td(d)["theta_v"].__setitem__(0, 0.0)), "row centres"),
    ("theta_v-one-row", "traceback", _cdf(lambda d: _td(d).update(theta_v=[0.7])), "MAX_CDF_ROWS"),
    ("rows-129", "memory", _cdf(lambda d: _td(d).update(theta_v=[0.0] * 129)), "MAX_CDF_ROWS"),
    ("eps-zero", "silent", _cdf(lambda d: _td(d).update(eps=0.0)), "table_data.eps"),
    ("eps-two", "silent", _cdf(lambda d: _td(d).update(eps=2.0)), "table_data.eps"),
    ("albedo-negative", "silent", _cdf(lambda d: _td(d)["albedo"].__setitem__(0, -0.5)), "albedo"),
    ("row_fallback-ints", "silent", _cdf(lambda d: _td(d).update(row_fallback=[0, 0, 0, 0])), "row_fallback[0]"),
    ("layout-rows", "traceback", _cdf(lambda d: d.update(layout="rows")), "layout 'rows'"),
    ("layout-bogus", "traceback", _cdf(lambda d: d.update(layout="magic")), "key layout"),
    ("fallback-missing", "traceback", _cdf(lambda d: d.pop("fallback")), "key fallback: missing"),
    ("fallback-string", "silent", _cdf(lambda d: d.update(fallback="false")), "key fallback: expected true or false"),
    ("no-maps-no-fallback", "silent", _cdf(lambda d: d.update(pieces=None)), "maps are missing"),
    ("table-missing", "traceback", _cdf(lambda d: d.pop("table_data")), "table_data: missing"),
    ("global-folding-map", "silent", _cdf(_global_folding), "fail verification"),
    ("global-theta-3-vars", "traceback", _cdf(lambda d: (_global_folding(d), d.update(theta=d["phi"]))),
     "needs 2 variables"),
    ("global-phi-huge-bernstein", "hang", _cdf(lambda d: (_global_folding(d), d["phi"]["functions"][0]["denominator"]
                                                           .update(exponents=[[0, 0, 0], [20, 20, 20]],
                                                                   coefficients=[1.0, 0.1]))),
     "MAX_BERNSTEIN_COEFFICIENTS"),
    ("global-theta-pole", "silent", _cdf(lambda d: (_global_folding(d), d["theta"]["functions"][0]["denominator"]
                                                     .update(coefficients=[-1.0]))), "key functions[0]"),
]


@pytest.mark.parametrize("name, klass, make, fragment", CDF_CASES, ids=[c[0] for c in CDF_CASES])
def test_cdf_reader_refuses(tmp_path, cdf_dict, name, klass, make, fragment):
    p = tmp_path / f"{name}.json"
    p.write_text(make(cdf_dict))
    with pytest.raises(BRDFFileError) as e:
        load_cdf(p)
    assert_one_line(str(e.value), p, fragment)


@pytest.mark.parametrize("name", ["n_mu-1e6", "cdf-decreasing", "pole"])
def test_cdf_reader_errors_through_the_cli(tmp_path, capsys, cdf_dict, name):
    """plot-cdf and cdf given a bad CDF file: exit 2, one line, no output folder or file made."""
    make = {c[0]: c[2] for c in CDF_CASES}
    make["pole"] = CDF_CASES[-1][2]
    p = tmp_path / "in" / "bad.json"
    p.parent.mkdir()
    p.write_text(make[name](cdf_dict))
    before = snapshot(tmp_path)
    rc, _, err = run(capsys, ["plot-cdf", p, "--out", tmp_path / "plots"])
    assert_bad_input(rc, err, p, out="")
    rc, _, err = run(capsys, ["cdf", p, "--out", tmp_path / "again.json"])
    assert_bad_input(rc, err, p, out="")
    assert_unchanged(before, tmp_path)


def test_cdf_valid_small_file_loads(tmp_path, cdf_dict):
    fit = load_cdf(write_json(tmp_path / "ok.json", cdf_dict))
    assert not fit.fallback and fit.maps.n_mu == 8 and fit.table.n_v == 4


# ----------------------------------------------------------------------------------------------
# projected .npz
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def npz_arrays():
    from lab.analytic import lambert
    from fit.formats.measured import MeasuredBRDF
    from fit.projection.project import project

    return project(MeasuredBRDF.from_function(lambert((0.5, 0.4, 0.3))), grazing_cutoff_deg=80.0)


def _npz_bytes(p, **override) -> bytes:
    arrays = {"format": "rbrdf-projected", "version": 1, "value": p.value, "median": p.median, "mean": p.mean,
              "variance": p.variance, "count": p.count, "n_below_horizon": p.n_below_horizon,
              "theta_h": p.theta_h, "theta_d": p.theta_d, "statistic": p.statistic,
              "grazing_cutoff_deg": p.grazing_cutoff_deg, "grazing_angle": p.grazing_angle, "name": p.name,
              "source": p.source, "source_sha256": p.source_sha256, "n_phi_d": p.n_phi_d}
    drop = override.pop("_drop", ())
    arrays.update(override)
    for k in drop:
        arrays.pop(k)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def _npz(**override):
    return lambda p: _npz_bytes(p, **override)


def _mod(key, fn):
    return lambda p: _npz_bytes(p, **{key: fn(getattr(p, key).copy())})


def _bomb(p):
    """A member whose header claims a (100000, 100000, 3) float64 array (240 GB)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        with zipfile.ZipFile(io.BytesIO(_npz_bytes(p))) as src:
            for n in src.namelist():
                if n != "value.npy":
                    z.writestr(n, src.read(n))
        hdr = io.BytesIO()
        np.lib.format.write_array_header_1_0(hdr, {"descr": "<f8", "fortran_order": False,
                                                   "shape": (100000, 100000, 3)})
        z.writestr("value.npy", hdr.getvalue() + b"\0" * 4096)
    return buf.getvalue()


def _zip_bomb(p):
    """A member that inflates to 64 MB (above MAX_NPZ_MEMBER_BYTES) from a few kB."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        with zipfile.ZipFile(io.BytesIO(_npz_bytes(p))) as src:
            for n in src.namelist():
                if n != "mean.npy":
                    z.writestr(n, src.read(n))
        z.writestr("mean.npy", b"\0" * (64 << 20))
    return buf.getvalue()


NPZ_CASES = [
    ("not-zip", "traceback", lambda p: b"PK but not a zip", "cannot read projected BRDF"),
    ("truncated", "traceback", lambda p: _npz_bytes(p)[:3000], "cannot read projected BRDF"),
    ("missing-value", "traceback", _npz(_drop=("value",)), "no array 'value'"),
    ("wrong-shape", "silent", _npz(value=np.zeros((90, 91, 3))), "array 'value' has shape [90, 91, 3]"),
    ("wrong-count-shape", "silent", _npz(count=np.zeros((45, 90, 3), np.int32)), "array 'count' has shape"),
    ("object-array", "traceback", _npz(median=np.array([None] * 10, dtype=object)), "array 'median' has dtype"),
    ("string-values", "silent", _npz(mean=np.full((90, 90, 3), "1.0")), "array 'mean' has dtype"),
    ("negative-count", "silent", _mod("count", lambda a: a - 400), "array 'count' holds values outside"),
    ("count-too-big", "silent", _mod("count", lambda a: a + 1000), "array 'count'"),
    ("n_phi_d-7", "silent", _npz(n_phi_d=7), "array 'n_phi_d' is 7"),
    ("statistic-bogus", "silent", _npz(statistic="maximum"), "array 'statistic'"),
    ("grazing-angle-bogus", "silent", _npz(grazing_angle="theta_x"), "array 'grazing_angle'"),
    ("cutoff-negative", "silent", _npz(grazing_cutoff_deg=-5.0), "grazing_cutoff_deg"),
    ("negative-values", "silent", _mod("value", lambda a: a - 1.0), "array 'value' holds values outside"),
    ("nan-on-data", "silent", _mod("median", lambda a: np.where(np.isfinite(a), np.nan, a)), "array 'median' holds NaN"),
    ("value-on-empty", "silent", _mod("mean", lambda a: np.nan_to_num(a, nan=0.5)), "on empty clusters"),
    ("all-empty", "silent", _npz(count=np.zeros((90, 90, 3), np.int32)), "every cluster is empty"),
    ("version-2", "traceback", _npz(version=2), "unsupported projected-BRDF version"),
    ("format-other", "traceback", _npz(format="npz"), "not an rbrdf projected-BRDF file"),
    ("header-bomb", "memory", _bomb, "array 'value'"),
    ("zip-bomb", "memory", _zip_bomb, "MAX_NPZ_MEMBER_BYTES"),
]


@pytest.mark.parametrize("name, klass, make, fragment", NPZ_CASES, ids=[c[0] for c in NPZ_CASES])
def test_npz_reader_refuses(tmp_path, npz_arrays, name, klass, make, fragment):
    p = tmp_path / f"{name}.npz"
    p.write_bytes(make(npz_arrays))
    with pytest.raises(BRDFFileError) as e:
        ProjectedBRDF.load(p)
    assert_one_line(str(e.value), p, fragment)


def test_npz_round_trip_still_loads(tmp_path, npz_arrays):
    p = tmp_path / "ok.npz"
    p.write_bytes(_npz_bytes(npz_arrays))
    q = ProjectedBRDF.load(p)
    np.testing.assert_array_equal(q.value, npz_arrays.value)
    assert q.grazing_cutoff_deg == 80.0 and q.n_phi_d == 180


def case_counts() -> dict:
    """Cases of this module per class."""
    out = dict.fromkeys(CLASSES, 0)
    for cases in (MERL_CASES, RGL_EDITS, RATIONAL_CASES, CDF_CASES, NPZ_CASES):
        for c in cases:
            out[c[1]] += 1
    return out
