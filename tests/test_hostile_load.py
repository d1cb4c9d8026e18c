"""Values and structure checked on load: coefficient files (versions 1, 2, 3), CDF files, RGL
tensor shapes and meshes whose values are out of the project's own range or whose headers
disagree with their data.

* A BRDF fit without a ``value.max`` clamp must be proven bounded by
  :data:`fit.limits.MAX_BRDF_VALUE` on its whole box (:mod:`fit.rational.value_bound`): a
  P/Q of 1e30 (or 1e8, or exp(P/Q) of 5e8) rendered with exit status 0 before.
* Integer fields (versions, degrees, counts, table sizes) are JSON integers: ``3.0`` is refused.
* Records agree with their data: ``num_degrees``/``den_degrees``/``n_coefficients`` with the
  polynomials, a CDF file's ``table.n_v/n_t/n_p/eps`` with its tables.
* Names hold no control characters and at most 256 characters (:func:`fit.jsonfields.name`).
* An RGL tensor shape with a zero side and absurd others is one line (was a ``ValueError``
  traceback from NumPy); an OBJ face index 0 and an ASCII PLY whose body does not hold the
  elements its header declares are refused (trimesh accepted both silently).

Each case carries the class of the failure it was before (``CLASSES``, tests/hostile.py),
counted by :func:`case_counts`.
"""
from __future__ import annotations

import copy
import json
import struct

import numpy as np
import pytest
from hostile import (
    CLASSES,
    TINY_SCENE,
    assert_bad_input,
    assert_one_line,
    assert_unchanged,
    obj_text,
    ply_binary,
    render_run,
    render_work_folder,
    run,
    small_cdf_dict,
    small_rational_dict,
    snapshot,
    write_json,
)

from fit.errors import BRDFFileError
from fit.formats.tensor_file import MAGIC, parse_tensor_file
from fit.limits import MAX_BRDF_VALUE
from fit.rational.coefficient_file import from_dict, load
from fit.rational.coefficient_file import to_dict as model_to_dict
from fit.rational.function import RationalFunction
from fit.rational.model import RationalModel, Variable
from fit.sampling.cdf_file import from_dict as cdf_from_dict
from fit.sampling.cdf_file import load as load_cdf
from warp_rbrdf.errors import SceneError
from warp_rbrdf.geometry import load_mesh_file

HALF_PI = np.pi / 2


# ----------------------------------------------------------------------------------------------
# Coefficient files
# ----------------------------------------------------------------------------------------------
def _v3_dict() -> dict:
    """A small valid version-3 file (theta_h, theta_d, phi_d; one box), Q = 1 + 0.2 T_1(t_h)."""
    vs = [Variable("theta_h", "rad", "sqrt", (0.0, HALF_PI)), Variable("theta_d", "rad", "identity", (0.0, 1.3)),
          Variable("phi_d", "rad", "identity", (0.0, np.pi))]
    fs = [RationalFunction([v.rf_domain for v in vs], [[0, 0, 0], [0, 0, 1]], [0.2 + 0.1 * c, 0.01],
                           [[0, 0, 0], [1, 0, 0]], [1.0, 0.2]) for c in range(3)]
    d = model_to_dict(RationalModel(name="small3", variables=vs, functions=fs, kind="brdf", value_max=2.0))
    assert d["version"] == 3
    return d


def _functions(d):
    """Every function record of a coefficient file (any version, pieces included)."""
    if "functions" in d:
        return list(d["functions"])
    return [f for p in d["pieces"] for f in _functions(p)]


def _unclamped(d: dict, numerator=None, denominator=None, **value) -> dict:
    """``d`` without its ``max`` clamp and step-7 ranges; every function's numerator (and
    denominator) coefficients replaced when given (exponents as in the small files)."""
    d = copy.deepcopy(d)
    d["value"].update(max=None, **value)
    for f in _functions(d):
        f.pop("measured_range", None)
        f.pop("vouched_range", None)
        if numerator is not None:
            f["numerator"]["coefficients"] = list(numerator) + [0.0] * (len(f["numerator"]["coefficients"])
                                                                        - len(numerator))
        if denominator is not None:
            f["denominator"].update(denominator)
            f.pop("den_degrees"), f.pop("n_coefficients")
    return d


def _peak_inside() -> dict:
    """P = 1000, Q = 1 + 0.99999 T_2(t_h) (> 0, 1e-5 at t_h = 0): P/Q is 500 at every corner
    of the box and 1e8 in its middle, t_h = 0 (found by subdividing)."""
    return _unclamped(small_rational_dict(False), numerator=[1000.0, 0.0, 0.0],
                      denominator={"exponents": [[0, 0], [2, 0]], "coefficients": [1.0, 0.99999]})


def _edit(base, fn):
    def make():
        d = copy.deepcopy(base() if callable(base) else base)
        fn(d)
        return d
    return make


def _v2():
    return small_rational_dict()


def _v1():
    return small_rational_dict(False)


def _fn0(d):
    return _functions(d)[0]


RATIONAL_CASES = [
    # (id, class before, make the JSON object, text the one line must hold)
    ("v2-pq-1e30-no-max", "silent", lambda: _unclamped(_v2(), numerator=[1e30]), "MAX_BRDF_VALUE"),
    ("v1-pq-1e8-no-max", "silent", lambda: _unclamped(_v1(), numerator=[1e8]), "MAX_BRDF_VALUE"),
    ("v3-pq-1e30-no-max", "silent", lambda: _unclamped(_v3_dict(), numerator=[1e30]), "MAX_BRDF_VALUE"),
    ("v2-log-no-max-5e8", "silent", lambda: _unclamped(_v2(), numerator=[20.0], transform="log"),
     "exp(P/Q) - offset = "),
    ("v1-peak-inside-box", "silent", _peak_inside, "theta_h = 0.3927,"),
    ("v2-version-float", "silent", _edit(_v2, lambda d: d.update(version=2.0)), "version 2.0"),
    ("v1-version-float", "silent", _edit(_v1, lambda d: d.update(version=1.0)), "version 1.0"),
    ("v3-version-float", "silent", _edit(_v3_dict, lambda d: d.update(version=3.0)), "version 3.0"),
    ("num-degrees-float", "silent", _edit(_v2, lambda d: _fn0(d).update(num_degrees=[1.0, 1])), "num_degrees[0]"),
    ("den-degrees-wrong", "silent", _edit(_v2, lambda d: _fn0(d).update(den_degrees=[9, 0])), "den_degrees"),
    ("n-coefficients-float", "silent", _edit(_v1, lambda d: _fn0(d).update(n_coefficients=5.0)), "n_coefficients"),
    ("n-coefficients-wrong", "silent", _edit(_v3_dict, lambda d: _fn0(d).update(n_coefficients=99)),
     "n_coefficients: 99"),
    ("vouched-range-1e30", "silent", _edit(_v2, lambda d: _fn0(d).update(vouched_range=[0.0, 1e30])),
     "vouched_range"),
    ("measured-range-negative", "silent", _edit(_v1, lambda d: _fn0(d).update(measured_range=[-5.0, 1.0])),
     "measured_range"),
    ("min-1e30-no-max", "silent", _edit(_v2, lambda d: d["value"].update(min=1e30, max=None)), "value.min"),
    ("offset-1e30", "silent", _edit(_v2, lambda d: d["value"].update(offset=1e30, transform="log")), "value.offset"),
    ("grazing-cutoff-string", "traceback", _edit(_v2, lambda d: d.setdefault("fit", {}).update(grazing_cutoff_deg="79")),
     "fit.grazing_cutoff_deg"),
    ("grazing-cutoff-200", "silent", _edit(_v1, lambda d: d.setdefault("fit", {}).update(grazing_cutoff_deg=200.0)),
     "fit.grazing_cutoff_deg"),
    ("name-nul", "unclear", _edit(_v2, lambda d: d.update(name="a\u0000b")), "key name"),
    ("name-escape", "unclear", _edit(_v1, lambda d: d.update(name="x\u001b[2J")), "U+001B"),
    ("name-newline", "unclear", _edit(_v3_dict, lambda d: d.update(name="a\nb")), "key name"),
    ("name-300-chars", "unclear", _edit(_v2, lambda d: d.update(name="n" * 300)), "at most 256"),
    ("name-bidi-override", "unclear", _edit(_v2, lambda d: d.update(name="abc\u202edcba")), "U+202E"),
    ("variable-unit-control", "unclear", _edit(_v1, lambda d: d["variables"][0].update(unit="rad\u0007")),
     "variables[0].unit"),
    ("output-control", "unclear", _edit(_v2, lambda d: _fn0(d).update(output="R\r")), "output"),
    ("source-file-newline", "unclear", _edit(_v2, lambda d: d.update(source={"file": "a\nb.bsdf", "sha256": ""})),
     "source.file"),
    ("source-sha-not-hex", "unclear", _edit(_v1, lambda d: d.update(source={"file": "a.bsdf", "sha256": "<x>"})),
     "source.sha256"),
]


@pytest.mark.parametrize("name, klass, make, fragment", RATIONAL_CASES, ids=[c[0] for c in RATIONAL_CASES])
def test_rational_load_refuses(tmp_path, name, klass, make, fragment):
    assert klass in CLASSES
    p = write_json(tmp_path / f"{name}.json", make())
    with pytest.raises(BRDFFileError) as e:
        load(p)
    assert_one_line(str(e.value), p, fragment)


def test_rational_bound_message_names_value_and_point():
    """The refusal says where the value is reached and how large it is, in the file's units."""
    with pytest.raises(BRDFFileError) as e:
        from_dict(_peak_inside(), "peak.json")
    msg = str(e.value)
    # t_h = 0, the middle of the sqrt-mapped box: theta_h = (sqrt(pi/2) / 2)^2 = pi/8
    assert "key functions[0] (R)" in msg and "theta_h = 0.3927, theta_d = " in msg and "P/Q = 1e+08" in msg, msg


def test_rational_bounded_without_max_loads():
    """Positive controls: without ``max`` a fit loads when its bound is proven. The small files
    (|P| <= 0.4, Q >= 0.8: the cheap bound), and a P whose coefficients sum to 1.6e7 but whose
    maximum is 8e6 (P = 4e6 (1 + a + b - a b), a = T_2(t_h), b = T_2(t_d): proven by its
    Bernstein coefficients, not by the coefficient sum)."""
    for d in (_v1(), _v2(), _v3_dict()):
        m = from_dict(_unclamped(d))
        assert m.value_max is None
    d = _unclamped(_v1())
    for f in _functions(d):
        f["numerator"] = {"exponents": [[0, 0], [2, 0], [0, 2], [2, 2]], "coefficients": [4e6, 4e6, 4e6, -4e6]}
        f["denominator"] = {"exponents": [[0, 0]], "coefficients": [1.0]}
        f.pop("num_degrees"), f.pop("den_degrees"), f.pop("n_coefficients")
    m = from_dict(d)
    x = np.stack(np.meshgrid(np.linspace(0, HALF_PI, 41), np.linspace(0, 1.3, 41)), -1).reshape(-1, 2)
    v = m(x)
    assert v.max() <= MAX_BRDF_VALUE and abs(v.max() - 8e6) < 1.0


@pytest.mark.parametrize("path", ["warp_rbrdf/data/paper_white_rgb.json", "warp_rbrdf/data/satin_rosaline_rgb.json",
                                  "tests/data/cm_toxic_green_rgb_tol0p05.json",
                                  "tests/data/ilm_solo_m_68_rgb_tol0p05.json"])
def test_shipped_fits_still_load(path):
    from conftest import ROOT

    m = load(ROOT / path)
    assert m.value_max is not None and m.value_max <= MAX_BRDF_VALUE


def test_bad_fit_through_the_cli(tmp_path, capsys):
    """``rbrdf-fit export`` of an unbounded fit: one line, exit 2, nothing written."""
    (tmp_path / "in").mkdir()
    p = write_json(tmp_path / "in" / "fit.json", _unclamped(_v2(), numerator=[1e30]))
    before = snapshot(tmp_path)
    rc, _, err = run(capsys, ["export", p, tmp_path / "out.glsl"])
    assert_bad_input(rc, err, p, "MAX_BRDF_VALUE", out="")
    assert_unchanged(before, tmp_path)


# ----------------------------------------------------------------------------------------------
# CDF files
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cdf_dict():
    return small_cdf_dict()


def _cdf(fn):
    def make(base):
        d = copy.deepcopy(base)
        fn(d)
        return d
    return make


CDF_CASES = [
    ("version-float", "silent", _cdf(lambda d: d.update(version=2.0)), "version 2.0"),
    ("n_v-disagrees", "silent", _cdf(lambda d: d["table"].update(n_v=32)), "table.n_v: 32"),
    ("n_t-disagrees", "silent", _cdf(lambda d: d["table"].update(n_t=64)), "table.n_t"),
    ("n_p-disagrees", "silent", _cdf(lambda d: d["table"].update(n_p=7)), "table.n_p"),
    ("n_t-float", "silent", _cdf(lambda d: d["table"].update(n_t=8.0)), "table.n_t: expected an integer"),
    ("sub-string", "silent", _cdf(lambda d: d["table"].update(sub="3")), "table.sub"),
    ("eps-disagrees", "silent", _cdf(lambda d: d["table"].update(eps=0.5)), "table.eps"),
    ("n_mu-float", "silent", _cdf(lambda d: d["pieces"].update(n_mu=8.0)), "pieces.n_mu"),
    ("name-escape", "unclear", _cdf(lambda d: d.update(name="m\u001b]0;x\u0007")), "key name"),
    ("name-300-chars", "unclear", _cdf(lambda d: d.update(name="n" * 300)), "at most 256"),
    ("reason-nul", "unclear", _cdf(lambda d: d.update(reason="ok\u0000")), "key reason"),
    ("source-file-newline", "unclear", _cdf(lambda d: d.update(source={"file": "x\ny", "sha256": ""})),
     "source.file"),
    ("source-incident", "silent", _cdf(lambda d: d.update(source={"file": "x", "incident": "up"})),
     "source.incident"),
]


@pytest.mark.parametrize("name, klass, make, fragment", CDF_CASES, ids=[c[0] for c in CDF_CASES])
def test_cdf_load_refuses(tmp_path, cdf_dict, name, klass, make, fragment):
    assert klass in CLASSES
    p = write_json(tmp_path / f"{name}.json", make(cdf_dict))
    with pytest.raises(BRDFFileError) as e:
        load_cdf(p)
    assert_one_line(str(e.value), p, fragment)


def test_cdf_valid_file_loads(cdf_dict):
    fit = cdf_from_dict(copy.deepcopy(cdf_dict))
    assert fit.table_params["n_v"] == fit.table.n_v == 4 and fit.name == "small"


# ----------------------------------------------------------------------------------------------
# RGL tensor shapes
# ----------------------------------------------------------------------------------------------
def _tensor(shape, code=10, payload=b"") -> bytes:
    """A tensor file of one field ``rgb`` of ``shape`` (dtype code ``code``), data after the header."""
    head = MAGIC + bytes([1, 0]) + struct.pack("<I", 1)
    off = len(head) + 2 + 3 + 11 + 8 * len(shape)
    head += struct.pack("<H", 3) + b"rgb" + struct.pack("<HBQ", len(shape), code, off)
    head += struct.pack(f"<{len(shape)}Q", *shape)
    return head + payload


TENSOR_CASES = [
    ("zero-and-2^62", "traceback", (0, 8, 3, 2**62, 32), "absurd shape"),
    ("zero-and-2^40-squared", "traceback", (0, 2**40, 2**40), "absurd shape"),
    ("zero-and-2^63", "traceback", (2**63, 0), "absurd shape"),
]


@pytest.mark.parametrize("name, klass, shape, fragment", TENSOR_CASES, ids=[c[0] for c in TENSOR_CASES])
def test_tensor_shape_refused(tmp_path, capsys, name, klass, shape, fragment):
    assert klass in CLASSES
    with pytest.raises(BRDFFileError) as e:
        parse_tensor_file(_tensor(shape), "x.bsdf")
    assert_one_line(str(e.value), "x.bsdf", fragment, "'rgb'")
    p = tmp_path / "x.bsdf"
    p.write_bytes(_tensor(shape))
    rc, _, err = run(capsys, ["info", p])
    assert_bad_input(rc, err, p, fragment, out="")


def test_tensor_empty_field_still_parses():
    """A zero side with sane others is a valid empty field of the container (the RGL reader
    then refuses the fields it needs empty)."""
    f = parse_tensor_file(_tensor((0, 4)), "x.bsdf")["rgb"]
    assert f.shape == (0, 4) and f.data.size == 0


def test_rgl_zero_side_refused(tmp_path):
    from conftest import data_file

    from fit.formats.rgl import read_rgl
    from fit.formats.tensor_file import read_tensor_file, write_tensor_file

    fields = {k: v.data for k, v in read_tensor_file(data_file("rgl/paper_white_rgb.bsdf")).items()}
    rgb = fields["rgb"]
    fields["rgb"] = np.zeros(rgb.shape[:3] + (0, rgb.shape[4]), rgb.dtype)
    p = tmp_path / "z.bsdf"
    write_tensor_file(p, fields)
    with pytest.raises(BRDFFileError) as e:
        read_rgl(p)
    assert_one_line(str(e.value), p, "'rgb'")


# ----------------------------------------------------------------------------------------------
# Meshes
# ----------------------------------------------------------------------------------------------
_PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n"
             "property float z\nelement face {nf}\nproperty list uchar int vertex_indices\nend_header\n")
_TRI = "0 0 0\n1 0 0\n0 0 1\n"
_QUAD = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 1.0), (0.0, 0.0, 1.0)]

MESH_CASES = [
    ("obj-index-zero", "silent", "m.obj", obj_text(_QUAD, [(0, 1, 2)]), "line 5: face vertex index '0' is 0"),
    ("obj-index-zero-slashes", "silent", "m.obj", obj_text(_QUAD, [("1/1", "2/1", "0/1")]), "is 0"),
    ("obj-negative-before-vertices", "silent", "m.obj", b"f -1 -2 -3\n" + obj_text(_QUAD, []), "counts back past"),
    ("obj-index-not-integer", "silent", "m.obj", obj_text(_QUAD, [(1, 2, "x")]), "not an integer"),
    ("obj-index-beyond", "unclear", "m.obj", obj_text(_QUAD, [(1, 2, 5)]), "beyond the file's 4 vertices"),
    ("ply-ascii-10M-faces-holding-1", "silent", "m.ply",
     (_PLY_HEAD.format(nv=3, nf=10_000_000) + _TRI + "3 0 1 2\n").encode(), "declares 10000003 elements"),
    ("ply-ascii-fewer-faces-declared", "silent", "m.ply",
     (_PLY_HEAD.format(nv=3, nf=1) + _TRI + "3 0 1 2\n3 0 2 1\n").encode(), "holds 5 data lines"),
    ("ply-ascii-more-vertices-declared", "silent", "m.ply",
     (_PLY_HEAD.format(nv=4, nf=1) + _TRI + "3 0 1 2\n").encode(), "(4 vertex, 1 face)"),
]


@pytest.mark.parametrize("name, klass, fname, data, fragment", MESH_CASES, ids=[c[0] for c in MESH_CASES])
def test_mesh_structure_refused(tmp_path, name, klass, fname, data, fragment):
    assert klass in CLASSES
    p = tmp_path / fname
    p.write_bytes(data)
    with pytest.raises(SceneError) as e:
        load_mesh_file(p, "s.toml", "shapes[0].file")
    assert_one_line(str(e.value), "shapes[0].file", fname, fragment)


def test_valid_mesh_variants_load(tmp_path):
    """Positive controls: negative (relative) OBJ indices, ``v/vt/vn`` groups, a comment line, and an
    ASCII PLY with a trailing blank line."""
    p = tmp_path / "n.obj"
    p.write_bytes(obj_text(_QUAD, []) + b"vt 0 0\nf -4/1 -3/1 -2/1\n# a comment\nf 1//1 3//1 4//1\n")
    v, f, _ = load_mesh_file(p)
    assert len(f) == 2
    p = tmp_path / "t.ply"
    p.write_bytes((_PLY_HEAD.format(nv=3, nf=1) + _TRI + "3 0 1 2\n\n").encode())
    v, f, _ = load_mesh_file(p)
    assert f.tolist() == [[0, 1, 2]]


def test_a_ply_files_own_normals_are_used(tmp_path):
    """A PLY's ``nx ny nz`` (as Mitsuba 3 reads them): used normalised, its vertices as written
    (a duplicate vertex with its own normal stays), a zero or NaN normal replaced by the one
    computed from the vertex's faces; without them the computed normals, duplicates merged."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]], float)
    f = np.array([[0, 2, 1], [1, 2, 3], [4, 2, 3]])
    odd = np.array([[0.6, 0.8, 0.0], [0, 2.0, 0], [0.0, 0.0, 0.0], [np.nan, 1, 0], [0.0, 0.6, -0.8]])
    p = tmp_path / "own.ply"
    p.write_bytes(ply_binary(v, f, normals=odd))
    got_v, got_f, n = load_mesh_file(p)
    assert len(got_v) == 5 and got_f.tolist() == f.tolist()          # not merged
    np.testing.assert_allclose(n[[0, 1, 4]], [[0.6, 0.8, 0], [0, 1, 0], [0, 0.6, -0.8]], atol=1e-7)
    np.testing.assert_allclose(np.abs(n[[2, 3]]), [[0, 1, 0], [0, 1, 0]], atol=1e-7)   # from the faces
    p = tmp_path / "plain.ply"
    p.write_bytes((_PLY_HEAD.format(nv=3, nf=1) + _TRI + "3 0 1 2\n").encode())
    _, _, n_plain = load_mesh_file(p)
    assert n_plain.shape == (3, 3) and np.allclose(np.linalg.norm(n_plain, axis=1), 1.0)


def test_a_ply_files_normals_shade_the_render(tmp_path):
    """The same flat quad lit by a directional light at normal incidence: with its file's normals
    tilted 60 degrees the Lambert radiance is cos 60 of the untilted one (shading follows the
    file's normals, as in Mitsuba 3)."""
    from lab import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import CameraSpec, IntegratorSpec, Scene, ShapeSpec

    v = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float)
    f = np.array([[0, 2, 1], [0, 3, 2]])
    up = np.tile([0.0, 1.0, 0.0], (4, 1))
    tilt = np.tile([np.sin(np.pi / 3), np.cos(np.pi / 3), 0.0], (4, 1))
    out = []
    for name, n in (("up", up), ("tilt", tilt)):
        (tmp_path / f"{name}.ply").write_bytes(ply_binary(v, f, normals=n))
        sc = Scene(camera=CameraSpec(origin=(0, 3, 0.01), target=(0, 0, 0), fov=20, resolution=(8, 8)),
                   integrator=IntegratorSpec(spp=1, hide_environment=True),
                   materials={"m": T.lambert(albedo=1.0, sampler="cosine")},
                   shapes=[ShapeSpec(type="mesh", material="m", file=tmp_path / f"{name}.ply")],
                   lights=[T.directional((0, 1, 0), 1.0)])
        out.append(Renderer(sc).render()[2:6, 2:6].mean())
    assert out[0] > 0.1 and out[1] / out[0] == pytest.approx(0.5, rel=1e-3)


# ----------------------------------------------------------------------------------------------
# The renderer: a scene naming such a file fails in one line at load
# ----------------------------------------------------------------------------------------------
RENDER_CASES = [
    ("rational-1e30", "silent", 'type = "rational"\nfile = "r.json"', "r.json",
     lambda: json.dumps(_unclamped(_v2(), numerator=[1e30])), "MAX_BRDF_VALUE"),
    ("rational-v3-version-float", "silent", 'type = "rational"\nfile = "r.json"', "r.json",
     lambda: json.dumps(_edit(_v3_dict, lambda d: d.update(version=3.0))()), "version 3.0"),
    ("cdf-n_v-disagrees", "silent", 'type = "lambert"\nalbedo = 0.5\nsampler = "mis-tabulated"\ncdf = "c.json"',
     "c.json", lambda: json.dumps(_cdf(lambda d: d["table"].update(n_v=5))(small_cdf_dict())), "table.n_v"),
]


@pytest.mark.parametrize("name, klass, mat, fname, make, fragment", RENDER_CASES, ids=[c[0] for c in RENDER_CASES])
def test_render_refuses_at_load(capsys, tmp_path, name, klass, mat, fname, make, fragment):
    assert klass in CLASSES
    work = render_work_folder(tmp_path)
    (tmp_path / fname).write_text(make())
    scene = tmp_path / "s.toml"
    scene.write_text(TINY_SCENE.replace('type = "lambert"\nalbedo = 0.5', mat))
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress"])
    assert_bad_input(rc, err, "materials.m", fname, fragment, out=out)
    assert_unchanged(before, work)


def test_render_refuses_obj_index_zero(capsys, tmp_path):
    work = render_work_folder(tmp_path)
    (tmp_path / "m.obj").write_bytes(obj_text(_QUAD, [(0, 1, 2)]))
    scene = tmp_path / "s.toml"
    scene.write_text(TINY_SCENE + '\n[[shapes]]\ntype = "mesh"\nmaterial = "m"\nfile = "m.obj"\n')
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress"])
    assert_bad_input(rc, err, "shapes[1].file", "m.obj", "is 0", out=out)
    assert_unchanged(before, work)


def case_counts() -> dict:
    """Named cases of this module per class (the parametrized ones, and the two one-off CLI /
    render cases: an unbounded fit through ``rbrdf-fit export``, an OBJ index 0 through
    ``rbrdf render``)."""
    out = dict.fromkeys(CLASSES, 0)
    for cases in (RATIONAL_CASES, CDF_CASES, TENSOR_CASES, MESH_CASES, RENDER_CASES):
        for c in cases:
            out[c[1]] += 1
    out["silent"] += 2
    return out
