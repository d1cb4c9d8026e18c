"""Shared helpers of the hostile-input suites (tests/test_hostile_fit*.py, issue 22).

* :func:`run` runs ``rbrdf-fit`` in-process and returns ``(status, stdout, stderr)``;
* :func:`assert_bad_input` is the project principle as an assertion: exit status 2, exactly one
  stderr line, naming what it must name, no traceback, no warning;
* :func:`snapshot` / :func:`assert_unchanged`: every file of a folder, bytes and all, so that a
  failing run can be shown to leave existing outputs as they were and no partial file behind;
* small valid inputs (:func:`lambert_merl`, :func:`small_rational_dict`, :func:`small_cdf_dict`)
  and seeded mutators (:func:`truncations`, :func:`bit_flips`, :func:`json_mutations`).
"""
from __future__ import annotations

import copy
import hashlib
import json
import os
from pathlib import Path

import numpy as np

from fit.cli import main

#: failure classes of the hostile-input cases (docs/robustness.md)
CLASSES = ("lost", "hang", "memory", "silent", "traceback", "unclear")


def run(capsys, argv) -> tuple:
    """``(status, stdout, stderr)`` of ``rbrdf-fit argv`` run in this process."""
    capsys.readouterr()
    rc = main([str(a) if isinstance(a, Path) else a for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def assert_one_line(message: str, *names) -> None:
    """``message`` (an exception's ``str``) is one line naming each of ``names``."""
    assert "\n" not in message.strip(), message
    assert "Traceback" not in message
    for n in names:
        assert str(n) in message, (n, message)


def assert_bad_input(rc: int, err: str, *names, out: str | None = None) -> None:
    """Exit status 2, exactly one line on stderr (an ``error:`` line naming each of ``names``),
    no traceback or warning; nothing printed on stdout when ``out`` is given."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, (rc, err)
    assert len(lines) == 1, err
    assert "error:" in lines[0] and "Traceback" not in err and "Warning" not in err, err
    for n in names:
        assert str(n) in lines[0], (n, lines[0])
    if out is not None:
        assert out == "", out


def snapshot(folder) -> dict:
    """``{relative path: sha256 or "<dir>"}`` of everything under ``folder`` (hidden files too)."""
    folder = Path(folder)
    snap = {}
    for root, dirs, files in os.walk(folder):
        for d in dirs:
            snap[str(Path(root, d).relative_to(folder))] = "<dir>"
        for f in files:
            p = Path(root, f)
            if p.is_fifo():
                snap[str(p.relative_to(folder))] = "<fifo>"
            else:
                snap[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return snap


def assert_unchanged(before: dict, folder) -> None:
    """No file of ``folder`` changed, none appeared (no partial or temporary file) and none
    disappeared since :func:`snapshot` gave ``before``."""
    after = snapshot(folder)
    assert after == before, {"new": sorted(set(after) - set(before)), "gone": sorted(set(before) - set(after)),
                             "changed": sorted(k for k in set(after) & set(before) if after[k] != before[k])}


# ----------------------------------------------------------------------------------------------
# Valid inputs
# ----------------------------------------------------------------------------------------------
def lambert_merl(path, albedo=(0.8, 0.5, 0.2)) -> Path:
    """An exact-layout MERL file of a Lambertian BRDF (35 MB)."""
    from lab.analytic import lambert
    from fit.formats.measured import MeasuredBRDF
    from fit.formats.merl import write_merl

    write_merl(MeasuredBRDF.from_function(lambert(albedo)), path)
    return Path(path)


def glossy_merl(path) -> Path:
    """A MERL ``.binary`` of the analytic glossy lobe (:func:`lab.analytic.glossy_lobe`) at
    ``path``: a fit of it at a tight tolerance is infeasible at low degree."""
    from lab.analytic import glossy_lobe
    from fit.formats.measured import MeasuredBRDF
    from fit.formats.merl import write_merl

    write_merl(MeasuredBRDF.from_function(glossy_lobe(), name="glossy"), path)
    return Path(path)


def small_rational_dict(piecewise: bool = True) -> dict:
    """The JSON object of a small valid BRDF coefficient file (version 2 with two theta_d
    pieces, or version 1): Q = 1 + 0.2 T_1(t_h) > 0."""
    from fit.rational.coefficient_file import to_dict
    from fit.rational.function import RationalFunction
    from fit.rational.model import PiecewiseRationalModel, RationalModel, Variable

    def model(lo, hi, scale):
        th = Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2))
        td = Variable("theta_d", "rad", "identity", (lo, hi))
        fs = []
        for c in range(3):
            fs.append(RationalFunction([th.rf_domain, td.rf_domain], [[0, 0], [1, 0], [0, 1]],
                                       [scale * (0.2 + 0.1 * c), -0.05, 0.02], [[0, 0], [1, 0]], [1.0, 0.2]))
        info = [{"valid": True, "feasible": True, "q_certificate": {"certified": True},
                 "measured_range": [0.0, 1.0], "vouched_range": [0.0, 1.0]} for _ in range(3)]
        return RationalModel(name="small", variables=[th, td], functions=fs, kind="brdf",
                             value_max=2.0, function_info=info)

    if not piecewise:
        return to_dict(model(0.0, 1.3, 1.0))
    th = Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2))
    td = Variable("theta_d", "rad", "identity", (0.0, 1.3))
    m = PiecewiseRationalModel(name="small", variables=[th, td], split_variable="theta_d",
                               edges=[0.0, 0.6, 1.3], pieces=[model(0.0, 0.6, 1.0), model(0.6, 1.3, 0.8)])
    return to_dict(m)


def small_cdf_dict() -> dict:
    """The JSON object of a small valid ``rbrdf-cdf`` file, pieces layout (a glossy lobe on a
    4 x 8 x 8 table; the pieces are built from the table, no variance gate)."""
    from lab.analytic import glossy_lobe
    from fit.sampling.cdf_file import DEFAULTS, CDFFit
    from fit.sampling.pieces import build_pieces
    from fit.sampling.table import tabulate

    params = dict(DEFAULTS, n_v=4, n_t=8, n_p=8)
    table = tabulate(glossy_lobe(), **params)
    maps = build_pieces(table, n_mu=8, n_u=4)
    fit = CDFFit(table=table, table_params=params, maps=maps, verification={}, fallback=False,
                 reason="test", name="small")
    return fit.to_dict()


def write_json(path, obj) -> Path:
    Path(path).write_text(json.dumps(obj), encoding="utf-8")
    return Path(path)


# ----------------------------------------------------------------------------------------------
# Seeded mutators
# ----------------------------------------------------------------------------------------------
def truncations(data: bytes, n: int, seed: int, header: int = 0) -> list:
    """``n`` prefixes of ``data``: half of them cut inside the first ``header`` bytes (when
    given), the others anywhere."""
    rng = np.random.default_rng(seed)
    cuts = set()
    while len(cuts) < n:
        hi = header if (header and len(cuts) % 2 == 0) else len(data)
        cuts.add(int(rng.integers(0, max(hi, 1))))
    return [data[:c] for c in sorted(cuts)]


def bit_flips(data: bytes, n: int, seed: int, flips: int = 3, region: tuple | None = None) -> list:
    """``n`` copies of ``data`` with ``flips`` random bits flipped each (inside ``region`` =
    (start, end) when given)."""
    rng = np.random.default_rng(seed)
    lo, hi = region or (0, len(data))
    out = []
    for _ in range(n):
        b = bytearray(data)
        for pos in rng.integers(lo, hi, flips):
            b[int(pos)] ^= 1 << int(rng.integers(0, 8))
        out.append(bytes(b))
    return out


_REPLACEMENTS = (None, True, "1.0", [], {}, -1, 0, 1e308, -1e308, 1e-308, 2**70, 12345678, "x" * 50,
                 [1, 2, 3], [[0, 0]], 0.5)


def _paths(obj, prefix=()):
    """Every (path, value) of a JSON tree (long lists sampled: first, last and one inside)."""
    yield prefix, obj
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        idx = range(len(obj)) if len(obj) <= 4 else (0, len(obj) // 2, len(obj) - 1)
        for i in idx:
            yield from _paths(obj[i], prefix + (i,))


def json_mutations(obj, n: int, seed: int) -> list:
    """``n`` structurally mutated copies of the JSON tree ``obj`` (seeded): one value replaced
    by another type or an extreme number, a key deleted, a number scaled or negated, a list
    shortened or grown."""
    rng = np.random.default_rng(seed)
    paths = [p for p, _ in _paths(obj) if p]
    out = []
    for _ in range(n):
        d = copy.deepcopy(obj)
        p = paths[int(rng.integers(len(paths)))]
        parent = d
        for k in p[:-1]:
            parent = parent[k]
        key = p[-1]
        v = parent[key]
        op = int(rng.integers(6))
        if op == 0:
            parent[key] = copy.deepcopy(_REPLACEMENTS[int(rng.integers(len(_REPLACEMENTS)))])
        elif op == 1 and isinstance(parent, dict):
            del parent[key]
        elif op == 2 and isinstance(v, (int, float)) and not isinstance(v, bool):
            parent[key] = v * float(rng.choice([-1.0, 1e6, 1e-6, 3.0]))
        elif op == 3 and isinstance(v, list) and v:
            parent[key] = v[:-1] if rng.random() < 0.5 else v + [copy.deepcopy(v[-1])]
        elif op == 4 and isinstance(v, bool):
            parent[key] = not v
        else:
            parent[key] = copy.deepcopy(_REPLACEMENTS[int(rng.integers(len(_REPLACEMENTS)))])
        out.append(d)
    return out


# ----------------------------------------------------------------------------------------------
# The renderer's side (tests/test_hostile_render_*.py)
# ----------------------------------------------------------------------------------------------
#: A tiny valid scene: 8 x 8 pixels, 1 spp, a Lambert sphere under a constant environment (the
#: kernel configuration of tests/test_render_cli.py, so a render reuses its compiled kernels).
TINY_SCENE = """\
[camera]
resolution = [8, 8]
[integrator]
spp = 1
[materials.m]
type = "lambert"
albedo = 0.5
[[shapes]]
type = "sphere"
material = "m"
center = [0, 0.5, 0]
radius = 0.5
[[lights]]
type = "constant"
radiance = 0.5
"""


def render_work_folder(tmp_path) -> Path:
    """An output folder holding the EXR and PNG of an earlier render (``old.exr``,
    ``old_ev+0.0.png``): what a failing ``rbrdf render`` must leave as it was."""
    w = tmp_path / "work"
    w.mkdir()
    (w / "old.exr").write_bytes(b"earlier exr")
    (w / "old_ev+0.0.png").write_bytes(b"earlier png")
    return w


def render_run(capsys, argv) -> tuple:
    """``(status, stdout, stderr)`` of ``rbrdf argv`` run in this process."""
    from warp_rbrdf.cli import main as rbrdf_main

    capsys.readouterr()
    rc = rbrdf_main([os.fspath(a) if isinstance(a, Path) else a for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def write_image_file(path, pixels) -> Path:
    """Write float32 ``pixels`` (H, W, C) as ``path`` (.exr or .hdr, by OpenImageIO) as they are:
    NaN, infinite and negative values included (EXR keeps them; RGBE cannot hold them)."""
    import OpenImageIO as oiio

    px = np.ascontiguousarray(np.asarray(pixels, np.float32))
    H, W, C = px.shape
    out = oiio.ImageOutput.create(str(path))
    assert out is not None and out.open(str(path), oiio.ImageSpec(W, H, C, oiio.FLOAT)), oiio.geterror()
    assert out.write_image(px)
    out.close()
    return Path(path)


def obj_text(vertices, faces) -> bytes:
    """A Wavefront OBJ of ``vertices`` (V, 3) and 1-based ``faces`` (F, 3), values as written."""
    lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [f"f {a} {b} {c}" for a, b, c in faces]
    return ("\n".join(lines) + "\n").encode()


def ply_binary(vertices, faces, n_vertices=None, n_faces=None, normals=None) -> bytes:
    """A binary little-endian PLY of float32 ``vertices`` (and vertex ``normals`` ``nx ny nz``
    when given) and int32 ``faces`` (0-based); the header may state other counts
    (``n_vertices``, ``n_faces``) than the data hold."""
    nv = len(vertices) if n_vertices is None else n_vertices
    nf = len(faces) if n_faces is None else n_faces
    props = "xyz" if normals is None else ("x", "y", "z", "nx", "ny", "nz")
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {nv}\n"
            + "".join(f"property float {p}\n" for p in props)
            + f"element face {nf}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    v = np.asarray(vertices, float).reshape(-1, 3)
    if normals is not None:
        v = np.concatenate([v, np.asarray(normals, float).reshape(-1, 3)], axis=1)
    f = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    f["n"], f["i"] = 3, np.asarray(faces, np.int64).reshape(-1, 3)
    return head + v.astype("<f4").tobytes() + f.tobytes()


#: A unit quad as two triangles (OBJ faces 1-based).
QUAD_V = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 1.0), (0.0, 0.0, 1.0)]
QUAD_F = [(1, 2, 3), (1, 3, 4)]
