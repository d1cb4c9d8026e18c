"""The rational materials' evaluation specialised to degree classes (``warp_rbrdf.chebyshev_dense``,
``warp_rbrdf.materials.rational_kernel.make_rational_eval``) against the NumPy reference.

* the dense form of a class equals the Chebyshev basis (NumPy, and the native Warp function in
  its vector and scalar forms);
* on 120,000 direction pairs per fit (uniform, grazing, near-specular, below the horizon), the
  renderer's evaluation equals the NumPy reference (``fit.rational.vouched`` /
  ``fit.rational.variables3d``) at the angles the kernel computed, within float32 rounding
  (stated tolerance :data:`RTOL`): shipped 2-D fits with their measured domain and a flagged
  piece read from the embedded fallback table, log and linear values, active clamps, vouched
  and measured ranges, nested theta_h pieces, 3-D fits with a phi_d split, a fit whose pieces
  fall back to the packed form, 3-D fits (one box, pieces) with the value factor
  ``"1/cos_theta_i"`` (step 8);
* the value factor: a flag of every leaf (the records otherwise those of the same fit without
  it); at light directions down to cos theta_i = 1e-4 (below ``COS_FLOOR``) both functions give
  their value of the same fit without the factor divided by ``max(wi.z, COS_FLOOR)``;
* against the one generic function (``rational_eval``, the packed form and libm's ``atan2``) at
  the same directions, the values differ only by the angles' float32 rounding;
* the flat records' angles (``rational_flat2d.angles_2d``, ``rational_flat3d.angles_3d``: no
  ``atan2``) against ``frame.half_diff`` and their NumPy forms; which fits get a flat record (2-D
  and 3-D), and what it holds;
* compile once per class: another fit of the same classes reuses the compiled kernels; a fit of
  another class gets other kernels (Warp's module hash tells the classes apart).
"""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from test_warp_rational import piecewise_model, random_model

import fit.rational.basis as basis
import fit.rational.function as function
import fit.rational.model as M
from fit.formats.angles import directions_to_half_diff, spherical_to_direction
from fit.formats.grid import theta_d_index, theta_h_index
from fit.rational.coefficient_file import load as load_coefficients
from fit.rational.domain import measured_domain, onto_measured_domain
from fit.rational.flagged import flagged_regions
from fit.rational.variables3d import evaluate_directions, half_diff_3d, is_3d
from fit.rational.vouched import values_with_table
from lab import testing as T
from warp_rbrdf import chebyshev_dense as D
from warp_rbrdf.materials import rational
from warp_rbrdf.materials import rational_channels as RC
from warp_rbrdf.materials import rational_flat2d as RF
from warp_rbrdf.materials import rational_flat3d as RF3
from warp_rbrdf.materials import rational_kernel as RK
from warp_rbrdf.materials import rational_records
from warp_rbrdf.materials.data import Materials
from warp_rbrdf.paths import PACKAGE_DATA
from warp_rbrdf.renderer import Renderer
from warp_rbrdf.runtime import init_warp
from warp_rbrdf.scene import MaterialSpec
from warp_rbrdf.shipped_kernels import render_module_options

init_warp()

#: relative tolerance of the specialised evaluation against the NumPy reference at the kernel's
#: own float32 angles: float64 sums in another order, P/Q and exp in float64, one float32
#: rounding of the result (and of a moved theta_d) -- a few float32 ulps
RTOL, ATOL = 2e-6, 1e-7
N_PAIRS = 120_000


# --------------------------------------------------------------------------------------------
# The dense form
# --------------------------------------------------------------------------------------------
def _groups(nv, dn, dd, seed):
    """Three numerators (per-channel degrees dn, dn - 1, dn; the second left out: a table
    channel) and three denominators of degree dd, with duplicate rows and zeros."""
    rng = np.random.default_rng(seed)
    nums, dens = [], []
    for c in range(3):
        e = basis.total_degree_exponents(nv, max(dn - (c == 1), 0))
        e = np.vstack([e, e[:2]])
        k = rng.normal(size=len(e))
        k[rng.random(len(e)) < 0.1] = 0.0
        nums.append((e, k))
        e = basis.total_degree_exponents(nv, dd)
        dens.append((e, rng.normal(size=len(e))))
    nums[1] = None
    return nums, dens


def _basis(polys, t, nv, empty):
    out = []
    for p in polys:
        if p is None:
            out.append(np.full(len(t), empty))
        else:
            out.append(basis.chebyshev_basis(t, p[0], np.tile([-1.0, 1.0], (nv, 1))) @ p[1])
    return np.stack(out, -1)


CLASSES = [(2, 12, 6), (2, 4, 3), (3, 5, 2), (3, 7, 3), (1, 6, 2), (2, 0, 0)]


@pytest.mark.parametrize("nv, dn, dd", CLASSES)
def test_dense_form_equals_the_basis(nv, dn, dd):
    nums, dens = _groups(nv, dn, dd, seed=dn + 10 * nv)
    key = D.dense_class(nums, dens, nv)
    assert D.class_of_key(key) == (nv, dn, dd)
    rows = D.pack_dense(nums, dens, nv, key)
    assert rows.shape == (len(D.dense_slots(nv, dn)) + len(D.dense_slots(nv, dd)), 4)
    t = np.random.default_rng(1).uniform(-1, 1, size=(4000, 3))
    ref_p, ref_q = _basis(nums, t[:, 3 - nv:], nv, 0.0), _basis(dens, t[:, 3 - nv:], nv, 1.0)
    p, q = D.evaluate_dense(key, rows, t[:, 3 - nv:])
    np.testing.assert_allclose(p, ref_p, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(q, ref_q, rtol=1e-12, atol=1e-12)
    # the native function (vector form, and the scalar form of a CUDA build) at float offset 3
    cf = wp.array(np.concatenate([[7.0, 7.0, 7.0], rows.reshape(-1), [9.0]]), dtype=wp.float64)
    ta = wp.array(t, dtype=wp.vec3d)
    for scalar in (False, True):
        got = _run_dense(D.make_dense_pq(key, scalar), cf, ta)
        np.testing.assert_allclose(got, np.concatenate([ref_p, ref_q], -1), rtol=1e-12, atol=1e-12)


_DENSE_KERNELS = {}


def _run_dense(f, cf, t):
    if f not in _DENSE_KERNELS:
        @wp.kernel(module="unique")
        def k(cf: wp.array(dtype=wp.float64), t: wp.array(dtype=wp.vec3d), out: wp.array(dtype=D.vec6d)):
            i = wp.tid()
            out[i] = f(wp.address_of(cf[3]), t[i][0], t[i][1], t[i][2])

        _DENSE_KERNELS[f] = k
    out = wp.zeros(t.shape[0], dtype=D.vec6d)
    wp.launch(_DENSE_KERNELS[f], dim=t.shape[0], inputs=[cf, t], outputs=[out])
    return out.numpy()


def test_classes_of_fits_and_the_packed_fallback():
    satin = load_coefficients(PACKAGE_DATA / "satin_rosaline_rgb.json")
    keys = rational.packed_classes(rational.pack_model(satin, False, 79.0)[0])
    assert {D.class_of_key(k) for k in keys} == {(2, 11, 6), (2, 12, 6)} and 0 not in keys
    # as the renderer loads it: the flagged blue of the second piece (degree 12) reads the
    # table, and both pieces are of one class
    keys = rational.packed_classes(rational.pack_model(satin, True, 79.0)[0])
    assert {D.class_of_key(k) for k in keys} == {(2, 11, 6)}
    # tensor degrees (15, 15): total degree 30, beyond the dense form; packed only
    big = random_model(seed=3)
    e = basis.tensor_exponents((15, 15))
    for f in big.functions:
        f.num_exponents, f.num_coef = e, np.r_[1.0, np.full(len(e) - 1, 1e-4)]
    assert rational.packed_classes(rational.pack_model(big)[0]) == {0}        # 0: a leaf without a class
    assert D.dense_class([(e, np.ones(len(e)))] * 3, [None] * 3, 2) is None


def test_flat_records():
    """The shipped 2-D fits, single boxes and 2-D fits of one split of splits (at most
    FLAT_MAX_PIECES boxes) get a flat record (after the domain record) holding each box's ints and
    a copy of its header; deeper nesting, phi_d splits and pieces without a class do not; the
    tree the flat record points to is the same fit's (the generic walk skips to it)."""
    R = rational_records
    satin = load_coefficients(PACKAGE_DATA / "satin_rosaline_rgb.json")
    ints, floats, _ = rational.pack_model(satin, True, 79.0)
    assert ints[0] == rational.NODE_DOMAIN and _is_flat(ints)
    n = int(ints[R.DOMAIN_CHILD])
    k, fo = int(ints[n + R.FLAT_K]), int(ints[n + R.FLAT_FLOATS])
    assert k == 2 and ints[n + R.FLAT_VAR] == R.SUPPORTED_VARIABLES["theta_d"]
    np.testing.assert_array_equal(floats[fo:fo + R.FF_INNER], [np.cos(np.radians(79.0)), np.radians(79.0),
                                                               satin.edges[1], *[np.inf] * (R.FLAT_MAX_OUTER - 2)])
    # no second level: every inner edge +inf, the outer piece j is box j
    assert np.all(floats[fo + R.FF_INNER:fo + R.FF_BASES] == np.inf)
    np.testing.assert_array_equal(floats[fo + R.FF_BASES:fo + R.FF_HEADS], [0.0, 1.0, *[0.0] * (R.FLAT_MAX_OUTER - 1)])
    tree = int(ints[n + R.FLAT_TREE])
    assert ints[tree] == rational.NODE_SPLIT
    for j in range(k):
        leaf = int(ints[tree + R.SPLIT_CHILDREN + j])
        got = ints[n + R.FLAT_PIECES + R.FLAT_NI * j:n + R.FLAT_PIECES + R.FLAT_NI * (j + 1)]
        assert list(got[[0, 2, 3]]) == list(ints[leaf + np.array([R.LEAF_FLAGS, R.LEAF_CLASS, R.LEAF_DENSE])])
        assert got[1] == 1 and list(got[4:7]) == list(ints[leaf + R.LEAF_MODES:leaf + R.LEAF_MODES + 3])
        h = int(ints[leaf + R.LEAF_FH])
        head = fo + R.FF_HEADS + R.N_FH * j
        np.testing.assert_array_equal(floats[head:head + R.N_FH], floats[h:h + R.N_FH])
    assert [m & R.CH_TABLE for m in got[4:7]] == [0, 0, R.CH_TABLE]      # the flagged blue of the band
    plain = rational.pack_model(random_model("log", 2))[0]
    assert plain[0] == rational_records.NODE_FLAT2D and plain[rational_records.FLAT_K] == 1
    for model in (model_3d(), _packed_fallback_model()):
        assert not _is_flat(rational.pack_model(model)[0])
    # three theta_d pieces, the first split in theta_h: four boxes, the second level recorded
    nested = piecewise_model("log")
    ints, floats, _ = rational.pack_model(nested)
    assert ints[0] == R.NODE_FLAT2D and ints[R.FLAT_K] == 4 and ints[R.FLAT_VAR] == R.SUPPORTED_VARIABLES["theta_d"]
    fo = int(ints[R.FLAT_FLOATS])
    inner = floats[fo + R.FF_INNER:fo + R.FF_BASES].reshape(R.FLAT_MAX_OUTER, R.FLAT_MAX_PIECES - 1)
    np.testing.assert_array_equal(inner[0], [nested.pieces[0].edges[1], *[np.inf] * (R.FLAT_MAX_PIECES - 2)])
    assert np.all(inner[1:] == np.inf)
    np.testing.assert_array_equal(floats[fo + R.FF_BASES:fo + R.FF_HEADS],
                                  [0.0, 2.0, 3.0, *[0.0] * (R.FLAT_MAX_OUTER - 3), 1.0 + R.SUPPORTED_VARIABLES["theta_h"]])
    boxes = [*nested.pieces[0].pieces, *nested.pieces[1:]]
    for j, box in enumerate(boxes):
        head = fo + R.FF_HEADS + R.N_FH * j
        np.testing.assert_array_equal(floats[head + R.FH_VARS:head + R.FH_VARS + 2], box.variables[0].domain)
    six = rational.pack_model(_six_boxes_model())[0]
    assert six[0] == R.NODE_FLAT2D and six[R.FLAT_K] == R.FLAT_MAX_PIECES == 6
    # a split of splits in two variables, or three levels: the walk
    mixed = piecewise_model("log")
    e = [mixed.edges[1], 0.7, mixed.edges[2]]
    mixed.pieces[1] = M.PiecewiseRationalModel(
        name="other", variables=mixed.pieces[1].variables, split_variable="theta_d", edges=e,
        pieces=[random_model("log", seed=20 + j, theta_d_range=(e[j], e[j + 1]), value_max=8.0) for j in range(2)])
    assert not _is_flat(rational.pack_model(mixed)[0])
    deep = piecewise_model("log")
    deep.pieces[0].pieces[0] = piecewise_model("log")
    assert not _is_flat(rational.pack_model(deep)[0])
    assert _is_flat(rational.pack_model(_flat_theta_h_model())[0]) == 1
    # 3-D fits of theta_h pieces (the 3-D fitter's layout) and single boxes, with or without the
    # value factor: a 3-D flat record, its edges padded to FLAT3_MAX_PIECES - 1
    for model in (model_3d(phi_split=False), model_3d(phi_split=False, value_factor="1/cos_theta_i"),
                  single_3d(), single_3d(value_factor="none")):
        ints, floats, _ = rational.pack_model(model)
        assert ints[0] == R.NODE_FLAT3D and _is_flat(ints) == 2
        k, fo = int(ints[R.FLAT_K]), int(ints[R.FLAT_FLOATS])
        edges = list(model.edges[1:-1]) if k > 1 else []
        assert k == (2 if k > 1 else 1) and ints[R.FLAT_VAR] == R.SUPPORTED_VARIABLES["theta_h"]
        np.testing.assert_array_equal(floats[fo:fo + R.FF3_HEADS],
                                      [-2.0, 0.0, *edges, *[np.inf] * (R.FLAT3_MAX_PIECES - 1 - len(edges))])
        tree = int(ints[R.FLAT_TREE])
        leaves = [tree] if k == 1 else [int(ints[tree + R.SPLIT_CHILDREN + j]) for j in range(k)]
        for j, leaf in enumerate(leaves):
            got = ints[R.FLAT_PIECES + R.FLAT_NI * j:R.FLAT_PIECES + R.FLAT_NI * (j + 1)]
            assert list(got[[0, 2, 3]]) == list(ints[leaf + np.array([R.LEAF_FLAGS, R.LEAF_CLASS, R.LEAF_DENSE])])
            assert got[1] == 1          # the sqrt bit of theta_h alone
            assert bool(got[0] & R.LEAF_INV_COS) == (model.value_factor != "none")
            h, head = int(ints[leaf + R.LEAF_FH]), fo + R.FF3_HEADS + R.N_FH * j
            np.testing.assert_array_equal(floats[head:head + R.N_FH], floats[h:h + R.N_FH])
    # more theta_h pieces than a 3-D flat record holds: the walk
    many = model_3d(phi_split=False)
    many.pieces = many.pieces * 5
    many.edges = list(np.linspace(0.0, np.pi / 2, len(many.pieces) + 1))
    assert not _is_flat(rational.pack_model(many)[0])


_ANGLE_KERNEL = []


def test_flat_angles_against_half_diff():
    """``angles_2d`` (no atan2) against ``frame.half_diff`` (libm's atan2f) within
    ``ANGLE_ATOL`` on the tests' pairs above the horizon (grazing and near-specular included),
    its NumPy form within float32 rounding, and its third value cos theta_h cos theta_d."""
    from warp_rbrdf.materials.frame import half_diff

    if not _ANGLE_KERNEL:
        @wp.kernel(module="unique", enable_backward=False, module_options=render_module_options())
        def k(wi: wp.array(dtype=wp.vec3), wo: wp.array(dtype=wp.vec3), a: wp.array(dtype=wp.vec3),
              b: wp.array(dtype=wp.vec3)):
            i = wp.tid()
            a[i] = RF.angles_2d(wi[i], wo[i])
            b[i] = half_diff(wi[i], wo[i])

        _ANGLE_KERNEL.append(k)
    wi, wo = _pairs(N_PAIRS, seed=12)
    up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    wi, wo = wi[up], wo[up]
    a, b = (wp.zeros(len(wi), dtype=wp.vec3) for _ in range(2))
    wp.launch(_ANGLE_KERNEL[0], dim=len(wi), inputs=[wp.array(wi, dtype=wp.vec3), wp.array(wo, dtype=wp.vec3)],
              outputs=[a, b])
    got, ref = a.numpy().astype(float), b.numpy().astype(float)
    err = np.abs(got[:, :2] - ref[:, :2])
    assert err.max() <= RF.ANGLE_ATOL, err.max()
    assert np.mean(err == 0) > 0.3
    np.testing.assert_allclose(got, RF.angles_2d_numpy(wi, wo), rtol=1e-6, atol=3e-7)
    np.testing.assert_allclose(got[:, 2], np.cos(ref[:, 0]) * np.cos(ref[:, 1]), rtol=1e-5, atol=1e-6)
    # the float64 angles of the same directions (fit.formats.angles)
    th, _, td, _ = directions_to_half_diff(wi.astype(float), wo.astype(float))
    assert np.abs(got[:, 0] - th).max() < 2 * RF.ANGLE_ATOL and np.abs(got[:, 1] - td).max() < 2 * RF.ANGLE_ATOL


def test_flat_angles_3d_against_half_diff():
    """``angles_3d`` (no atan2): theta_h and theta_d as ``angles_2d`` gives them (up to
    contractions), |phi_d| within ``ANGLE_ATOL_3D`` of the float64 angle of the same float32
    directions on the tests' pairs (grazing, near-mirror, near-retro), closer than
    ``frame.half_diff``'s (float32, libm atan2f); its NumPy form; the fourth value cos theta_h
    cos theta_d; with the half vector on the normal, the shading frame's phi_d."""
    from warp_rbrdf.materials.frame import half_diff

    @wp.kernel(module="unique", enable_backward=False, module_options=render_module_options())
    def k(wi: wp.array(dtype=wp.vec3), wo: wp.array(dtype=wp.vec3), a: wp.array(dtype=wp.vec4),
          a2: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3)):
        i = wp.tid()
        a[i] = RF3.angles_3d(wi[i], wo[i])
        a2[i] = RF.angles_2d(wi[i], wo[i])
        b[i] = half_diff(wi[i], wo[i])

    wi, wo = _pairs(N_PAIRS, seed=12)
    up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    wi, wo = wi[up], wo[up]
    # the half vector on the normal: mirror pairs (wo = wi mirrored about z)
    nm = 1000
    wi = np.vstack([wi, wi[:nm]])
    wo = np.vstack([wo, wi[:nm] * np.float32([-1, -1, 1])])
    a, a2, b = wp.zeros(len(wi), dtype=wp.vec4), wp.zeros(len(wi), dtype=wp.vec3), wp.zeros(len(wi), dtype=wp.vec3)
    wp.launch(k, dim=len(wi), inputs=[wp.array(wi, dtype=wp.vec3), wp.array(wo, dtype=wp.vec3)], outputs=[a, a2, b])
    got, got2, ref = a.numpy().astype(float), a2.numpy().astype(float), b.numpy().astype(float)
    np.testing.assert_allclose(got[:, [0, 1, 3]], got2, rtol=1e-6, atol=3e-7)   # up to contractions
    assert np.all((got[:, 2] >= 0) & (got[:, 2] <= np.float32(np.pi)))
    _, _, _, pd = directions_to_half_diff(wi[:-nm].astype(float), wo[:-nm].astype(float))
    err, err_libm = np.abs(got[:-nm, 2] - np.abs(pd)), np.abs(np.abs(ref[:-nm, 2]) - np.abs(pd))
    assert err.max() <= RF3.ANGLE_ATOL_3D < err_libm.max(), (err.max(), err_libm.max())
    np.testing.assert_allclose(got[-nm:, 2], np.abs(np.arctan2(wi[-nm:, 1], wi[-nm:, 0])), atol=1e-6)
    num = RF3.angles_3d_numpy(wi, wo)
    np.testing.assert_allclose(got, num, rtol=1e-6, atol=RF3.ANGLE_ATOL_3D)


_CHANNEL_KERNELS = {}


def _run_channels(scalar, pq, head, flags, modes, tab):
    """:func:`rational_channels.make_channels` at ``n`` inputs: pq ``(n, 6)``, header ``(26,)``,
    per input its flags ``(n,)`` and modes ``(n, 3)``, table values ``(n, 3)``."""
    f = RC.make_channels(scalar)
    if f not in _CHANNEL_KERNELS:
        @wp.kernel(module="unique")
        def k(pq: wp.array(dtype=D.vec6d), head: wp.array(dtype=wp.float64), flags: wp.array(dtype=int),
              modes: wp.array(dtype=wp.vec3i), tab: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
            i = wp.tid()
            out[i] = f(pq[i], wp.address_of(head[0]), flags[i], modes[i][0], modes[i][1], modes[i][2], tab[i])

        _CHANNEL_KERNELS[f] = k
    n = len(pq)
    out = wp.zeros(n, dtype=wp.vec3)
    wp.launch(_CHANNEL_KERNELS[f], dim=n, inputs=[wp.array(pq, dtype=D.vec6d), wp.array(head, dtype=wp.float64),
                                                   wp.array(flags, dtype=int), wp.array(modes, dtype=wp.vec3i),
                                                   wp.array(tab, dtype=wp.vec3)], outputs=[out])
    return out.numpy()


def test_inline_exp_is_exp():
    """The channels' vector ``exp`` (log values, no clamp) against NumPy's, rounded to float32:
    the same float32 except within one ulp of a rounding tie, over the whole range (subnormal
    and overflowing results included), NaN kept."""
    y = np.concatenate([np.linspace(-760.0, 720.0, 200_001), np.random.default_rng(2).normal(0, 5, 100_000),
                        [0.0, -0.0, 1e-300, -1e-300, np.nan, np.inf, -np.inf]])
    pq = np.zeros((len(y), 6))
    pq[:, :3], pq[:, 3:] = y[:, None], 1.0
    head = np.zeros(26)
    got = _run_channels(False, pq, head, np.full(len(y), rational_records.LEAF_LOG), np.zeros((len(y), 3), int),
                        np.zeros((len(y), 3), np.float32))[:, 0]
    with np.errstate(over="ignore"):
        ref = np.exp(y).astype(np.float32)
    fin = np.isfinite(ref) & (ref > 0)
    ulp = np.abs(got[fin].view(np.int32) - ref[fin].view(np.int32))
    assert ulp.max() <= 1 and np.mean(ulp == 0) > 0.999
    assert np.array_equal(got[~fin & ~np.isnan(ref)], ref[~fin & ~np.isnan(ref)])
    assert np.isnan(got[np.isnan(y)]).all()
    # the lambda itself in float64: within 2 ulps of NumPy's exp on its clamp [-708, 709.4]
    # (one scale factor 2^k, k in [-1021, 1023]); beyond it the clamp's value, which float32
    # rounds as it rounds exp: 0 below, inf above
    x = np.concatenate([np.linspace(-708.0, 709.4, 400_001), np.random.default_rng(3).normal(0, 3, 100_000)])
    e = _exp64(x)
    ref = np.exp(x)
    assert np.max(np.abs(e.view(np.int64) - ref.view(np.int64))) <= 2
    out = _exp64(np.array([-720.0, -708.5, 709.6, 720.0]))
    np.testing.assert_allclose(out, np.exp([-708.0, -708.0, 709.4, 709.4]), rtol=1e-15)
    with np.errstate(over="ignore"):
        far = np.exp(np.array([-720.0, -708.5, 709.6, 720.0])).astype(np.float32)
        assert np.array_equal(out.astype(np.float32), far)


_EXP64 = []


def _exp64(x):
    """``rbrdf_exp`` (:data:`rational_channels.EXP_SOURCE`) of float64 ``x``, lane by lane."""
    if not _EXP64:
        snippet = RC.VECTOR_TYPES + RC.EXP_SOURCE + "rbrdf_v4d v = x;\nreturn rbrdf_exp(v)[0];\n"

        @D.Native.func_native(snippet, "test_exp64")
        def exp64(x: wp.float64) -> wp.float64:
            ...

        @wp.kernel(module="unique")
        def k(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
            i = wp.tid()
            out[i] = exp64(x[i])

        _EXP64.append(k)
    out = wp.zeros(len(x), dtype=wp.float64)
    wp.launch(_EXP64[0], dim=len(x), inputs=[wp.array(x, dtype=wp.float64)], outputs=[out])
    return out.numpy()


def test_vector_and_scalar_channels_agree():
    """The CPU (vector) and CUDA (scalar) forms of the channels, compiled here, on random P, Q,
    headers with active clamps and ranges, every combination of flags and channel modes."""
    rng = np.random.default_rng(5)
    n = 40_000
    pq = np.concatenate([rng.normal(0.5, 2.0, (n, 3)), rng.uniform(0.2, 2.0, (n, 3))], -1)
    head = np.zeros(26)
    head[[rational_records.FH_OFFSET, rational_records.FH_MIN, rational_records.FH_MAX]] = 0.02, 0.05, 3.0
    head[rational_records.FH_LOGMAX] = np.log(3.0 + 0.02) - 0.2
    head[rational_records.FH_RANGES:rational_records.FH_RANGES + 6] = [0.1, 2.0, 0.0, 1.0, 0.3, 0.4]
    flags = rng.integers(0, 32, n)
    modes = rng.integers(0, 4, (n, 3))
    tab = rng.uniform(0, 5, (n, 3)).astype(np.float32)
    vec = _run_channels(False, pq, head, flags, modes, tab)
    sca = _run_channels(True, pq, head, flags, modes, tab)
    np.testing.assert_allclose(vec, sca, rtol=2e-7, atol=0)
    assert np.mean(vec == sca) > 0.999
    # a reference in NumPy of the recipe's steps 5-7 (rational_kernel._channel)
    y = pq[:, :3] / pq[:, 3:]
    log, mn, mx = ((flags & b) != 0 for b in (rational_records.LEAF_LOG, rational_records.LEAF_MIN,
                                              rational_records.LEAF_MAX))
    y = np.where((log & mx)[:, None], np.fmin(y, head[rational_records.FH_LOGMAX]), y)
    y = np.where(log[:, None], np.exp(y) - head[rational_records.FH_OFFSET], y)
    y = np.where(mn[:, None], np.fmax(y, head[rational_records.FH_MIN]), y)
    y = np.where(mx[:, None], np.fmin(y, head[rational_records.FH_MAX]), y)
    y = np.where((modes & rational_records.CH_TABLE) != 0, tab.astype(float), y)
    r = head[rational_records.FH_RANGES:rational_records.FH_RANGES + 6].reshape(3, 2)
    y = np.where((modes & rational_records.CH_RANGE) != 0, np.fmin(np.fmax(r[:, 0], y), r[:, 1]), y)
    np.testing.assert_allclose(vec, y.astype(np.float32), rtol=2e-7, atol=0)


# --------------------------------------------------------------------------------------------
# Fits and their NumPy reference
# --------------------------------------------------------------------------------------------
_TD_3D, _PD_3D = (0.0, np.radians(89.0)), (0.0, np.pi)   # theta_d and |phi_d| boxes of the 3-D fits


def _leaf_3d(rng, th, ph, dn, dd, name, value_factor="none"):
    """A 3-D single-box fit on theta_h in ``th``, |phi_d| in ``ph`` (radians) of total degrees
    (``dn``, ``dd``): log values, clamps, vouched ranges; ``value_factor`` (step 8)."""
    v = [M.Variable("theta_h", "rad", "sqrt", th), M.Variable("theta_d", "rad", "identity", _TD_3D),
         M.Variable("phi_d", "rad", "identity", ph)]
    dom = np.array([x.rf_domain for x in v])
    ne, de = basis.total_degree_exponents(3, dn), basis.total_degree_exponents(3, dd)
    fs = []
    for c in range(3):
        p = rng.normal(size=len(ne)) * 0.3
        p[0] = -0.5 + 0.3 * c
        q = rng.normal(size=len(de)) * 0.03
        q[0] = 1.0
        fs.append(function.RationalFunction(dom, ne, p, de, q))
    info = [{"valid": True, "vouched_range": [0.0, 3.0 + c]} for c in range(3)]
    return M.RationalModel(name=name, variables=v, functions=fs, value_transform="log", value_offset=0.02,
                           value_min=0.0, value_max=2.5, function_info=info, value_factor=value_factor)


def single_3d(seed=1, value_factor="1/cos_theta_i"):
    """A 3-D fit of one box (the whole domain), total degrees (5, 2): :func:`_leaf_3d`."""
    return _leaf_3d(np.random.default_rng(seed), (0.0, np.pi / 2), _PD_3D, 5, 2, "single3d", value_factor)


def model_3d(seed=0, phi_split=True, value_factor="none"):
    """A 3-D fit (theta_h, theta_d, |phi_d|, log values, clamps): theta_h pieces of total degrees
    (4, 2) and (5, 2), the second split again in phi_d (``phi_split``); ``value_factor`` (step 8)
    on the whole model (the same pieces whatever it is)."""
    rng = np.random.default_rng(seed)
    td, pd = _TD_3D, _PD_3D

    def leaf(th, ph, dn, dd, k):
        return _leaf_3d(rng, th, ph, dn, dd, f"leaf{k}")

    def whole(th):
        return [M.Variable("theta_h", "rad", "sqrt", th), M.Variable("theta_d", "rad", "identity", td),
                M.Variable("phi_d", "rad", "identity", pd)]

    edges = [0.0, 0.3, np.pi / 2]
    second = leaf((edges[1], edges[2]), pd, 5, 2, 1)
    if phi_split:
        second = M.PiecewiseRationalModel(name="phi", variables=whole((edges[1], edges[2])), split_variable="phi_d",
                                          edges=[0.0, 1.2, np.pi],
                                          pieces=[leaf((edges[1], edges[2]), (0.0, 1.2), 5, 2, 1),
                                                  leaf((edges[1], edges[2]), (1.2, np.pi), 5, 2, 2)])
    return M.PiecewiseRationalModel(name="fit3d", variables=whole((0.0, np.pi / 2)), split_variable="theta_h",
                                    edges=edges, pieces=[leaf((edges[0], edges[1]), pd, 4, 2, 0), second],
                                    value_factor=value_factor)


def _clamped_piecewise():
    from test_compile_once import _clamped_piecewise as cp

    return cp()


def _packed_fallback_model():
    """A model whose second piece's numerator has total degree 16 (beyond the dense form): it is
    evaluated from the packed form inside the specialised function."""
    m = piecewise_model("log")
    leaf = m.pieces[1]
    e = basis.tensor_exponents((8, 8))
    for f in leaf.functions:
        c = np.zeros(len(e))
        c[: len(f.num_coef)] = f.num_coef[: len(e)]
        c[-1] = 1e-3
        f.num_exponents, f.num_coef = e, c
    return m


def _cases():
    """name -> MaterialSpec (the fits as the renderer loads them)."""
    spec = lambda name, **kw: MaterialSpec(name=name, type="rational", sampler="mis", **kw)  # noqa: E731 - no CDF
    specs = {p.stem: spec(p.stem, file=p) for p in sorted(PACKAGE_DATA.glob("*.json"))}
    specs.update({"linear": spec("linear", data=random_model("linear", 1)),
                  "log": spec("log", data=random_model("log", 2, value_max=4.0)),
                  "nested": spec("nested", data=piecewise_model("log")),
                  "clamped_table": spec("clamped_table", data=_clamped_piecewise()),
                  "fit3d": spec("fit3d", data=model_3d()),
                  "fit3d_cos": spec("fit3d_cos", data=model_3d(value_factor="1/cos_theta_i")),
                  "flat3d_h": spec("flat3d_h", data=model_3d(phi_split=False)),
                  "flat3d_h_cos": spec("flat3d_h_cos", data=model_3d(phi_split=False, value_factor="1/cos_theta_i")),
                  "single3d": spec("single3d", data=single_3d(value_factor="none")),
                  "single3d_cos": spec("single3d_cos", data=single_3d()),
                  "packed": spec("packed", data=_packed_fallback_model()),
                  "flat_h": spec("flat_h", data=_flat_theta_h_model()),
                  "six_boxes": spec("six_boxes", data=_six_boxes_model())})
    return specs


def _six_boxes_model():
    """Two theta_d pieces, the first split in five theta_h pieces (the fitter's refinement of the
    peak and the rest): six boxes, a 2-D flat record's most."""
    e = np.radians([0.0, 60.0, 80.0])
    h = np.radians([0.0, 1.25, 5.0, 20.0, 40.0, 90.0])
    sub = []
    for j in range(len(h) - 1):
        m = random_model("log", seed=30 + j, theta_d_range=(e[0], e[1]), value_max=8.0)
        m.variables[0] = M.Variable("theta_h", "rad", "sqrt", (h[j], h[j + 1]))
        for f in m.functions:
            f.domain[0] = m.variables[0].rf_domain
        sub.append(m)
    core = M.PiecewiseRationalModel(name="core", variables=[M.Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2)),
                                                            M.Variable("theta_d", "rad", "identity", (e[0], e[1]))],
                                    split_variable="theta_h", edges=list(h), pieces=sub)
    band = random_model("log", seed=40, theta_d_range=(e[1], e[2]), value_max=8.0)
    return M.PiecewiseRationalModel(name="six", variables=[M.Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2)),
                                                           M.Variable("theta_d", "rad", "identity", (e[0], e[-1]))],
                                    split_variable="theta_d", edges=list(e), pieces=[core, band])


def _flat_theta_h_model():
    """Three theta_h pieces (a flat record split in theta_h): log values with an active upper
    clamp, vouched ranges in the second, a flagged piece (red and blue) read from the fallback
    table and clamped to its measured range in the third."""
    e = [0.0, np.radians(5.0), np.radians(30.0), np.pi / 2]
    vouched = [{"valid": True, "vouched_range": [1.0 + c, 1.4 + c]} for c in range(3)]
    flagged = [{"valid": False, "measured_range": [0.5, 1.2]}, {"valid": True},
               {"valid": False, "measured_range": [2.0, 2.1]}]
    pieces = [random_model("log", 20 + k, theta_h_range=(e[k], e[k + 1]), value_max=3.0, info=info)
              for k, info in enumerate([None, vouched, flagged])]
    return M.PiecewiseRationalModel(
        name="flat_h", variables=[M.Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2)),
                                  M.Variable("theta_d", "rad", "identity", (0.0, np.radians(80.0)))],
        split_variable="theta_h", edges=e, pieces=pieces)


@pytest.fixture(scope="module")
def scene():
    """``(renderer, specs)``: every case as a material of one scene (one sphere each)."""
    specs = _cases()
    for s in specs.values():
        if s.data is not None and s.name in ("clamped_table", "flat_h"):
            # an in-memory flagged fit carries its fallback table as the fitter embeds it
            s.data.fallback = _fallback_record(s.data)
    sc = T.spheres_scene(specs)
    # the CPU whatever $RBRDF_DEVICE says: this file's own kernels (the vector code, the inline
    # exp) are the CPU build's and run on the CPU (tests/test_flat2d_scalar.py: the scalar form)
    return Renderer(sc, device="cpu"), specs


def _fallback_record(model):
    from fit.rational.fallback import fallback_record

    from types import SimpleNamespace

    table = np.random.default_rng(7).uniform(0.1, 4.0, size=(90, 90, 3))
    return fallback_record(SimpleNamespace(value=table), model)


def _pairs(n, seed=4):
    """``n`` direction pairs: a quarter each uniform over the hemisphere, grazing views (80 to
    89.99 deg), near-specular, and pairs with a direction at or below the horizon."""
    rng = np.random.default_rng(seed)
    q = n // 4
    wi = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    wo = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    wo[q:2 * q] = spherical_to_direction(np.radians(rng.uniform(80, 89.99, q)), rng.random(q) * 2 * np.pi)
    wi[2 * q:3 * q] = wo[2 * q:3 * q] * [-1, -1, 1] + rng.normal(scale=0.01, size=(q, 3))
    below = spherical_to_direction(np.radians(rng.uniform(90, 180, n - 3 * q)), rng.random(n - 3 * q) * 2 * np.pi)
    below[::7, 2] = 0.0
    swap = rng.random(n - 3 * q) < 0.5
    wi[3 * q:][swap] = below[swap]
    wo[3 * q:][~swap] = below[~swap]
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    return wi.astype(np.float32), wo.astype(np.float32)


_EVAL_KERNELS = {}


def _eval_kernel(classes):
    """(specialised value, the kernel's angles (theta_h, theta_d, phi_d), the generic
    ``rational_eval``'s value) per pair, compiled as the render kernels are."""
    if classes not in _EVAL_KERNELS:
        fast = RK.make_rational_eval(classes)

        @wp.kernel(module="unique", enable_backward=False, module_options=render_module_options())
        def k(mats: Materials, m: int, wi: wp.array(dtype=wp.vec3), wo: wp.array(dtype=wp.vec3),
              out: wp.array(dtype=wp.vec3), ang: wp.array(dtype=wp.vec3), gen: wp.array(dtype=wp.vec3),
              flat: int):
            i = wp.tid()
            # the angles first, as the function computes them: the compiler computes each once
            # (an FMA contracted in one copy and not in the other would differ by an ulp)
            f = RF.angles_2d(wi[i], wo[i])
            f3 = RF3.angles_3d(wi[i], wo[i])
            g = RK.half_diff_frame(wi[i], wo[i])
            out[i] = fast(mats, m, wi[i], wo[i])
            if flat == 1:
                ang[i] = f
            elif flat == 2:
                ang[i] = wp.vec3(f3[0], f3[1], f3[2])
            else:
                ang[i] = wp.vec3(g[0], g[1], RK.phi_d_of(g))
            gen[i] = rational.rational_eval(mats, m, wi[i], wo[i])

        _EVAL_KERNELS[classes] = k
    return _EVAL_KERNELS[classes]


def _is_flat(ints) -> int:
    """Whether a packed fit has a flat record (the specialised function reads it): 0 none, 1 a
    2-D one (the angles of ``rational_flat2d.angles_2d``), 2 a 3-D one (``rational_flat3d.angles_3d``)."""
    R = rational_records
    n = int(ints[R.DOMAIN_CHILD]) if ints[0] == rational.NODE_DOMAIN else 0
    return {R.NODE_FLAT2D: 1, R.NODE_FLAT3D: 2}.get(int(ints[n]), 0)


def _evaluate(r, name, wi, wo):
    """(specialised value, the angles it used (theta_h, theta_d, phi_d for the walk; theta_h,
    theta_d, cos theta_h cos theta_d for a 2-D flat record; theta_h, theta_d, |phi_d| for a 3-D
    one), generic value) per pair."""
    md = r.material_data
    classes = set()
    for lm in md.loaded:
        classes |= rational.packed_classes(lm.coefficients[0])
    n = len(wi)
    out, ang, gen = (wp.zeros(n, dtype=wp.vec3) for _ in range(3))
    wp.launch(_eval_kernel(tuple(sorted(classes))), dim=n,
              inputs=[r.materials, r.material_index(name), wp.array(wi, dtype=wp.vec3), wp.array(wo, dtype=wp.vec3)],
              outputs=[out, ang, gen, _is_flat(md.loaded[r.material_index(name)].coefficients[0])])
    return out.numpy().astype(float), ang.numpy().astype(float), gen.numpy().astype(float)


def _reference(lm, ang, wi, wo):
    """The NumPy reference at the kernel's angles ``ang`` of the pairs ``wi``, ``wo``: the 3-D
    recipe's steps 1-7 at (theta_h, theta_d, |phi_d|) and its step 8 (the value factor) at the
    pairs' own float64 angles (:func:`fit.rational.variables3d.evaluate_directions` but for the
    float32 angles of steps 1-7: 1 / cos theta_i near the horizon would magnify their rounding,
    which the kernel's ``wi.z`` does not have), or the 2-D fit moved onto its measured domain
    (the moved theta_d rounded to float32 as the kernel rounds it) with its fallback table in
    flagged pieces (``fit.rational.vouched``)."""
    model, table = lm.data, lm.fallback_table
    if is_3d(model):
        values = model.values(np.stack([ang[:, 0], ang[:, 1], np.abs(ang[:, 2])], -1))
        x64 = half_diff_3d(wi.astype(float), wo.astype(float))
        return M.apply_value_factor(np.asarray(values, float), x64, model.value_factor), None
    x = ang[:, :2]
    cut = measured_domain(model)
    if cut is not None:
        x = onto_measured_domain(x, cut).astype(np.float32).astype(float)
    if table is None:
        return np.asarray(model(x), float), x
    return values_with_table(model, table.astype(np.float64), x), x


def _same_table_bins(model, x):
    """Whether the kernel's float32 binning of the angles clamped onto each piece's box
    (``frame.merl_theta_*_index``) and ``fit.formats.grid``'s float64 binning agree (they may
    not within a float32 rounding of a bin edge)."""
    ok = np.ones(len(x), bool)
    half_pi, f90 = np.float32(np.pi / 2), np.float32(90.0)
    for _, sel, xl in model.leaves(x):
        th, td = xl[:, 0].astype(np.float32), xl[:, 1].astype(np.float32)
        ih = np.clip(np.floor(np.sqrt(np.maximum(th, 0) / half_pi) * f90), 0, 89).astype(int)
        jd = np.clip(np.floor(td / half_pi * f90), 0, 89).astype(int)
        ok &= ~sel | ((ih == theta_h_index(xl[:, 0])) & (jd == theta_d_index(xl[:, 1])))
    return ok


@pytest.mark.parametrize("name", list(_cases()))
def test_specialised_eval_equals_the_numpy_reference(scene, name):
    r, specs = scene
    lm = r.material_data.loaded[r.material_index(name)]
    wi, wo = _pairs(N_PAIRS)
    got, ang, gen = _evaluate(r, name, wi, wo)
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    assert np.all(got[~above] == 0) and np.all(np.isfinite(got))
    ref, x = _reference(lm, ang[above], wi[above], wo[above])
    ok = np.ones(len(ref), bool)
    if lm.fallback_table is not None:
        # flagged channels read the table's cluster of the angles clamped onto the piece's box;
        # where a box edge falls on a bin edge (60 deg), the kernel's float32 binning (the
        # packed function's too) and grid's float64 one may differ: there the other channels
        ok = _same_table_bins(lm.data, x)
        assert ok.mean() > 0.9
        table_channels = sorted({c for reg in flagged_regions(lm.data) for c in reg["channels"]})
        fit_channels = [c for c in range(3) if c not in table_channels]
        np.testing.assert_allclose(got[above][~ok][:, fit_channels], ref[~ok][:, fit_channels], rtol=RTOL,
                                   atol=ATOL, err_msg=name)
    np.testing.assert_allclose(got[above][ok], ref[ok], rtol=RTOL, atol=ATOL, err_msg=name)
    # what the pairs reached: grazing pairs moved onto a measured domain, flagged pieces, pieces
    th, _, td, _ = directions_to_half_diff(wi[above].astype(float), wo[above].astype(float))
    if measured_domain(lm.data) is not None:
        assert np.mean(np.cos(th) * np.cos(td) < np.cos(np.radians(measured_domain(lm.data)))) > 0.01
    # the generic function (packed sums, libm atan2) at the same directions: the values differ
    # only through the float32 rounding of the angles (fastmath.atan2: within 3 ulps; a 3-D
    # flat record's |phi_d| by another formula, as close to the float64 angle: one more ulp)
    rel = (np.abs(got - gen) / np.maximum(np.abs(gen), 1e-6))[above]
    median_tol = 2e-7 if _is_flat(lm.coefficients[0]) == 2 else 1e-7
    assert np.median(rel) < median_tol and np.quantile(rel, 0.999) < 1e-4, (name, np.median(rel),
                                                                             np.quantile(rel, 0.999))
    # and both err from the float64 evaluation at the float64 directions alike
    ref64 = lm.evaluate(wi[above].astype(float), wo[above].astype(float))
    err = [np.abs(v[above] - ref64) / np.maximum(np.abs(ref64), 1e-6) for v in (got, gen)]
    assert np.quantile(err[0], 0.99) <= 2 * np.quantile(err[1], 0.99) + 1e-6, name


def test_clamps_tables_and_pieces_are_reached(scene):
    """The cases above exercise what they name: active upper clamps and ranges, table channels
    (values only the table holds), both phi_d pieces of the 3-D fit, the packed fallback leaf."""
    r, _ = scene
    wi, wo = _pairs(20_000, seed=9)
    got, ang, _ = _evaluate(r, "clamped_table", wi, wo)
    d = np.degrees(ang[:, 1])
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    assert np.any(got[above & (d > 60), 2] == np.float32(2.1)) and np.any(got[above & (d < 30)] == np.float32(3.0))
    tab = r.material_data.loaded[r.material_index("clamped_table")].fallback_table
    assert np.isin(got[above & (d > 61), 1], tab[..., 1]).mean() < 0.01     # green: the fit
    _, ang3, _ = _evaluate(r, "fit3d", wi, wo)
    pd = np.abs(ang3[above, 2])
    assert np.mean(pd < 1.2) > 0.1 and np.mean(pd > 1.2) > 0.1
    leaf = r.material_data.loaded[r.material_index("packed")].data.pieces[1]
    nums = [(f.num_exponents, f.num_coef) for f in leaf.functions]
    assert D.dense_class(nums, [(f.den_exponents, f.den_coef) for f in leaf.functions], 2) is None
    assert np.mean((d > 30) & (d < 60) & above) > 0.1   # the packed leaf's theta_d piece


#: the fits with the value factor "1/cos_theta_i" -> the same fit with "none" (among _cases)
FACTOR_TWINS = {"fit3d_cos": "fit3d", "single3d_cos": "single3d", "flat3d_h_cos": "flat3d_h"}


def _leaf_offsets(ints) -> list:
    """The int offsets of a packed fit's leaf records (:func:`rational_records.pack_model`)."""
    R = rational_records
    out, todo = [], [0]
    while todo:
        n = todo.pop()
        kind = int(ints[n])
        if kind == R.NODE_DOMAIN:
            todo.append(int(ints[n + R.DOMAIN_CHILD]))
        elif kind in (R.NODE_FLAT2D, R.NODE_FLAT3D):
            todo.append(int(ints[n + R.FLAT_TREE]))
        elif kind == R.NODE_SPLIT:
            todo += [int(c) for c in ints[n + R.SPLIT_CHILDREN:n + R.SPLIT_CHILDREN + int(ints[n + R.SPLIT_N])]]
        else:
            out.append(n)
    return sorted(out)


@pytest.mark.parametrize("name", list(FACTOR_TWINS))
def test_value_factor_is_a_flag_of_every_leaf(name):
    """A fit with the value factor packs as its twin without one but for ``LEAF_INV_COS`` in the
    flags of every leaf (the pieces' own factor is "none"; a single box is its own leaf) and of
    the pieces of a 3-D flat record; the kernels' floor is the model's."""
    R = rational_records
    model = _cases()[name].data
    twin = _cases()[FACTOR_TWINS[name]].data
    assert model.value_factor == "1/cos_theta_i" and twin.value_factor == "none"
    ints, floats, rows = rational.pack_model(model)
    ints0, floats0, rows0 = rational.pack_model(twin)
    leaves = _leaf_offsets(ints)
    assert leaves == _leaf_offsets(ints0) and len(leaves) == {"fit3d_cos": 3, "flat3d_h_cos": 2}.get(name, 1)
    assert all(ints[n + R.LEAF_FLAGS] & R.LEAF_INV_COS for n in leaves)
    assert not any(ints0[n + R.LEAF_FLAGS] & R.LEAF_INV_COS for n in leaves)
    flag_slots = np.zeros(len(ints), bool)
    flag_slots[[n + R.LEAF_FLAGS for n in leaves]] = True
    flat = _is_flat(ints)
    assert flat == _is_flat(ints0) == (0 if name == "fit3d_cos" else 2)
    if flat:
        flag_slots[[R.FLAT_PIECES + R.FLAT_NI * j for j in range(int(ints[R.FLAT_K]))]] = True
    np.testing.assert_array_equal(np.where(flag_slots, ints & ~R.LEAF_INV_COS, ints), ints0)
    np.testing.assert_array_equal(floats, floats0)
    np.testing.assert_array_equal(rows, rows0)
    assert RK.COS_FLOOR_F32.value == np.float32(M.COS_FLOOR)
    with pytest.raises(ValueError, match="unknown value factor"):
        bad = single_3d()
        bad.value_factor = "cos_theta_o"
        rational.pack_model(bad)


def _grazing_light_pairs(n, seed):
    """``n`` direction pairs above the horizon, float32: the light's cos theta_i log-uniform in
    [1e-4, 1] (a quarter below ``COS_FLOOR``), the view uniform over the hemisphere (half of
    them) or within about 0.6 deg of the light's mirror direction (its z made positive)."""
    rng = np.random.default_rng(seed)
    wi = spherical_to_direction(np.arccos(10.0 ** rng.uniform(-4.0, 0.0, n)), rng.random(n) * 2 * np.pi)
    wo = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    h = n // 2
    wo[h:] = wi[h:] * [-1, -1, 1] + rng.normal(scale=0.01, size=(n - h, 3))
    wo[h:, 2] = np.abs(wo[h:, 2])
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    return wi.astype(np.float32), wo.astype(np.float32)


@pytest.mark.parametrize("name", list(FACTOR_TWINS))
def test_value_factor_at_grazing_light(scene, name):
    """Step 8 (``value_factor = "1/cos_theta_i"``: rho = y / max(cos theta_i, COS_FLOOR)) at
    light directions from cos theta_i = 1e-4 to 1, a single box and pieces split in theta_h and
    phi_d: the specialised function within float32 rounding (:data:`RTOL`) of the reference
    (steps 1-7 at the kernel's angles, step 8 at the pairs', :func:`_reference`); the
    specialised and the generic function each give their value of the same fit without the
    factor divided by ``max(wi.z, COS_FLOOR)`` in float32 (so the factor is applied, and
    applied once, after the clamps); both against
    :func:`fit.rational.variables3d.evaluate_directions` at the float64 directions."""
    r, _ = scene
    lm = r.material_data.loaded[r.material_index(name)]
    wi, wo = _grazing_light_pairs(40_000, seed=13)
    assert np.all((wi[:, 2] > 0) & (wo[:, 2] > 0)) and np.mean(wi[:, 2] < M.COS_FLOOR) > 0.2
    got, ang, gen = _evaluate(r, name, wi, wo)
    assert np.all(np.isfinite(got)) and np.all(np.isfinite(gen))
    ref, _ = _reference(lm, ang, wi, wo)
    np.testing.assert_allclose(got, ref, rtol=RTOL, atol=ATOL, err_msg=name)
    # the twin without the factor, through the same kernels: one float32 division apart
    got0, _, gen0 = _evaluate(r, FACTOR_TWINS[name], wi, wo)
    assert np.mean(got0 > 0) > 0.5 and np.median(wi[:, 2]) < 0.02
    cos_i = np.maximum(wi[:, 2], np.float32(M.COS_FLOOR))[:, None]
    for v, v0 in ((got, got0), (gen, gen0)):
        np.testing.assert_allclose(v, (v0.astype(np.float32) / cos_i).astype(float), rtol=2.4e-7, atol=0,
                                   err_msg=name)
    # the float64 evaluation at the float64 directions: what the angles' float32 rounding costs
    # (most near values that exp(y) - offset cancels to almost 0), the same with and without
    # the factor
    twin = r.material_data.loaded[r.material_index(FACTOR_TWINS[name])].data
    ref64, ref64_0 = (evaluate_directions(m, wi.astype(float), wo.astype(float)) for m in (lm.data, twin))
    for v, v0 in ((got, got0), (gen, gen0)):
        rel, rel0 = (np.abs(a - b) / np.maximum(np.abs(b), 1e-6) for a, b in ((v, ref64), (v0, ref64_0)))
        assert np.quantile(rel, 0.99) < 1e-5, (name, np.quantile(rel, 0.99))
        for q in (0.999, 1.0):
            assert np.quantile(rel, q) <= 1.5 * np.quantile(rel0, q) + 1e-6, (name, q, np.quantile(rel, q))


def test_a_fit_of_compiled_classes_compiles_nothing():
    """Fits of the same degree classes share the specialised function and the kernels' module
    hash (the cache serves them); a fit of another class gets another hash. (The cosine
    technique of ``mis``: the kind's default, ``mis-tabulated``, would tabulate each fit's
    inverse CDFs at load, seconds each, and its technique has no code specialised to a fit.)"""
    def renderer(model):
        spec = MaterialSpec(name="m", type="rational", data=model, sampler="mis")
        return Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=4, spp=1))

    def hashes(r):
        k = r.kernels
        return [x.module.hash_module() for x in (k.render_tile, k.eval_bsdf, k.sample_bsdf, k.pdf_bsdf)]

    a, b = renderer(random_model("linear", 0)), renderer(random_model("log", 5, value_max=2.0))
    assert hashes(a) == hashes(b)
    satin = renderer(load_coefficients(PACKAGE_DATA / "satin_rosaline_rgb.json"))
    assert hashes(satin) != hashes(a)
    wi, wo = _pairs(2000, seed=11)
    for r in (a, b, satin):
        np.testing.assert_allclose(r.eval_material("m", wi, wo), r.material_data.loaded[0].evaluate(wi, wo),
                                   rtol=2e-4, atol=1e-6)
