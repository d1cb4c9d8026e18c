"""Coefficients are data (issue 21, item 4): rational fits and inverse-CDF files reach the kernels
through arrays, so the kernels' source does not depend on them.

* the packed Chebyshev form (:mod:`warp_rbrdf.chebyshev`) equals the basis of
  :mod:`fit.rational.basis`, in NumPy and in Warp (six polynomials at once; two with their
  derivative and ends);
* the one Warp function of the rational materials equals the fits' NumPy evaluation at the
  same (float32) angles, for real fits (the shipped coefficient files), linear / log values,
  nested pieces with an active upper clamp, valid functions clamped to their vouched range,
  flagged functions clamped to their measured range and flagged channels read from the
  fallback table;
* a different fit of the same degree classes, or a different CDF file (global or pieces
  layout), gives kernels with the same module hash: this process compiles nothing new (Warp reports no module load as
  compiled; another test process sharing the kernel cache may add modules to it meanwhile).
"""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import pytest
import warp as wp
from test_warp_rational import random_model

import fit.rational.basis as basis
import fit.rational.function as function
import fit.rational.model as model_types
from fit.formats.angles import spherical_to_direction
from fit.rational.coefficient_file import load as load_coefficients
from warp_rbrdf import chebyshev
from warp_rbrdf.materials import frame as F
from warp_rbrdf.materials import rational
from warp_rbrdf.materials.data import (
    CDF_MAPS,
    LoadedMaterial,
    MaterialData,
    Materials,
    Pool,
    make_materials_struct,
)
from warp_rbrdf.paths import PACKAGE_DATA
from warp_rbrdf.runtime import init_warp
from warp_rbrdf.techniques import cdf_data
from warp_rbrdf.techniques import rational as technique

init_warp()


# --------------------------------------------------------------------------------------------
# The packed Chebyshev form
# --------------------------------------------------------------------------------------------
def _random_groups(width, seed=0):
    """Groups of ``width`` polynomials ``(exponents, coefficients)`` (or None) of 1-3 variables:
    tensor and total-degree sets of different degrees in one group, sparse sets with gaps, zero
    coefficients and duplicate rows."""
    rng = np.random.default_rng(seed)
    sets = {1: [basis.tensor_exponents((7,)), basis.tensor_exponents((3,))],
            2: [basis.tensor_exponents((5, 3)), basis.total_degree_exponents(2, 12),
                basis.total_degree_exponents(2, 4), basis.tensor_exponents((0, 0))],
            3: [basis.total_degree_exponents(3, 4), basis.tensor_exponents((2, 1, 3))]}
    groups = []
    for nv, fixed in sets.items():
        for g in range(3):
            members = []
            for w in range(width):
                if g == 2 and w == 0:
                    members.append(None)
                    continue
                e = fixed[(w + g) % len(fixed)] if g < 2 else rng.integers(0, 7, size=(25, nv))
                e = np.vstack([e, e[:2]])                    # duplicates: summed
                c = rng.normal(size=len(e))
                c[rng.random(len(e)) < 0.2] = 0.0            # zeros: skipped
                members.append((e, c))
            groups.append((nv, members))
    return groups


def _basis_values(member, t):
    if member is None:
        return np.zeros(len(t))
    e, c = member
    return basis.chebyshev_basis(t, e, np.tile([-1.0, 1.0], (t.shape[1], 1))) @ c


def test_packed_form_equals_the_basis_numpy():
    rng = np.random.default_rng(1)
    for nv, members in _random_groups(6):
        t = rng.uniform(-1, 1, size=(500, nv))
        ints, rows = chebyshev.pack_polynomials(members, nv)
        got = chebyshev.evaluate_packed(ints, rows, t)
        for w, member in enumerate(members):
            np.testing.assert_allclose(got[:, w], _basis_values(member, t), rtol=1e-12, atol=1e-12)
    # one slot per exponent row of the group's union
    for e in (basis.tensor_exponents((5, 3)), basis.total_degree_exponents(2, 12)):
        c = np.ones(len(e))
        assert chebyshev.pack_polynomials([(e, c), (e[: len(e) // 2], c[: len(e) // 2])], 2)[1].shape == (len(e), 2)


@wp.kernel
def _cheb_kernel(rows6: wp.array(dtype=chebyshev.vec6d), rows2: wp.array(dtype=wp.vec2d), iv: wp.array(dtype=int),
                 t: wp.array(dtype=wp.vec3d), out6: wp.array(dtype=chebyshev.vec6d),
                 out2: wp.array(dtype=chebyshev.vec8d), width: int):
    i = wp.tid()
    if width == 6:
        out6[i] = chebyshev.cheb_sum6(rows6, iv, 1, 2, t[i][0], t[i][1], t[i][2])
    else:
        out2[i] = chebyshev.cheb_sum2_d(rows2, iv, 1, 2, t[i][0], t[i][1], t[i][2])


def _run_cheb(members, nv, t3, width):
    """The group packed after one row and two ints of other data (offsets as in the kernels)."""
    ints, rows = chebyshev.pack_polynomials(members, nv)
    rows = np.concatenate([np.full((1, width), 7.0), rows, np.zeros((1, width))])
    n = len(t3)
    out6 = wp.zeros(n, dtype=chebyshev.vec6d, device="cpu")
    out2 = wp.zeros(n, dtype=chebyshev.vec8d, device="cpu")
    wp.launch(_cheb_kernel, dim=n, device="cpu",
              inputs=[wp.array(rows if width == 6 else np.zeros((1, 6)), dtype=chebyshev.vec6d, device="cpu"),
                      wp.array(rows if width == 2 else np.zeros((1, 2)), dtype=wp.vec2d, device="cpu"),
                      wp.array(np.concatenate([[5, 5], ints]), dtype=int, device="cpu"),
                      wp.array(t3, dtype=wp.vec3d, device="cpu")],
              outputs=[out6, out2, width])
    return (out6 if width == 6 else out2).numpy()


def test_packed_form_equals_the_basis_warp():
    """Six polynomials at once (a BRDF piece), and two with their derivative in the last
    variable and their values at its ends (an inverse-CDF map), against :mod:`fit.rational.basis`."""
    rng = np.random.default_rng(2)
    for nv, members in _random_groups(6, 3):
        t = rng.uniform(-1, 1, size=(400, nv))
        t3 = np.concatenate([rng.uniform(-1, 1, size=(400, 3 - nv)), t], axis=1)   # padded: any value
        got = _run_cheb(members, nv, t3, 6)
        for w, member in enumerate(members):
            ref = _basis_values(member, t)
            np.testing.assert_allclose(got[:, w], ref, rtol=1e-12, atol=1e-12 * (np.abs(ref).max() + 1))
        pair = [m for m in members if m is not None][:2]
        got = _run_cheb(pair, nv, t3, 2)
        for w, (e, c) in enumerate(pair):
            f = function.RationalFunction(np.tile([-1.0, 1.0], (nv, 1)), e, c, np.zeros((1, nv), int), [1.0])
            scale = np.abs(c).sum() * (1 + e.max() ** 2)
            np.testing.assert_allclose(got[:, w], f(t), rtol=1e-12, atol=1e-13 * scale)
            np.testing.assert_allclose(got[:, 2 + w], f.derivative(t, nv - 1), rtol=1e-11, atol=1e-12 * scale)
            for k, end in ((4, -1.0), (6, 1.0)):
                te = t.copy()
                te[:, -1] = end
                np.testing.assert_allclose(got[:, k + w], f(te), rtol=1e-12, atol=1e-13 * scale)


# --------------------------------------------------------------------------------------------
# Rational fits: the Warp function against the NumPy evaluation at the same angles
# --------------------------------------------------------------------------------------------
def _model(value_transform="linear", seed=0, th=(0.0, np.pi / 2), td=(0.0, np.radians(80.0)),
           value_max=None, info=None):
    return random_model(value_transform, seed, theta_d_range=td, value_max=value_max, theta_h_range=th,
                        name=f"m{seed}", info=info)


def _clamped_piecewise(flag=True):
    """Log-valued theta_d pieces: a piece split again in theta_h with an active upper clamp, a piece
    whose valid functions are clamped to a narrow vouched range, and a flagged piece (blue and
    red; ``flag`` False: the same coefficients vouched for) clamped to its measured range."""
    e = np.radians([0.0, 30.0, 60.0, 80.0])
    h = [0.0, np.radians(5.0), np.pi / 2]
    sub = [_model("log", 10 + j, th=(h[j], h[j + 1]), td=(e[0], e[1]), value_max=3.0) for j in range(2)]
    peak = model_types.PiecewiseRationalModel(
        name="peak", variables=[model_types.Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2)),
                                model_types.Variable("theta_d", "rad", "identity", (e[0], e[1]))],
        split_variable="theta_h", edges=h, pieces=sub)
    vouched = [{"valid": True, "vouched_range": [1.0 + c, 1.4 + c]} for c in range(3)]
    flagged = [{"valid": not flag, "measured_range": [0.5, 1.2]}, {"valid": True},
               {"valid": not flag, "measured_range": [2.0, 2.1]}]
    pieces = [peak, _model("log", 2, td=(e[1], e[2]), info=vouched),
              _model("log", 3, td=(e[2], e[3]), info=flagged)]
    return model_types.PiecewiseRationalModel(
        name="clamped", variables=[model_types.Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2)),
                                   model_types.Variable("theta_d", "rad", "identity", (e[0], e[-1]))],
        split_variable="theta_d", edges=list(e), pieces=pieces)


def _table(seed=7):
    return np.random.default_rng(seed).uniform(0.1, 4.0, size=(90 * 90, 3)).astype(np.float32)


def _cases():
    """(name, model, fallback table or None)."""
    shipped = [(p.stem, load_coefficients(p), None) for p in sorted(PACKAGE_DATA.glob("*.json"))]
    assert shipped, "no shipped coefficient file"
    return shipped + [("linear", _model("linear"), None), ("log", _model("log", 1, value_max=4.0), None),
                      ("clamped", _clamped_piecewise(), None), ("table", _clamped_piecewise(), _table())]


def _material_struct(cases):
    """A :class:`Materials` of rational materials only, packed as the renderer packs them."""
    n = len(cases)
    tables = Pool(width=3)
    loaded, param = [], np.zeros(n, np.int32)
    for m, (_, model, table) in enumerate(cases):
        loaded.append(LoadedMaterial(None, model, None, coefficients=rational.pack_model(model, table is not None),
                                     fallback_table=table))
        if table is not None:
            param[m] = tables.add(table)
    md = MaterialData(names=[c[0] for c in cases], kind=np.full(n, 3, np.int32), technique=np.zeros(n, np.int32),
                      combine=np.zeros(n, np.int32), scale=np.ones((n, 3), np.float32),
                      offset=np.arange(n, dtype=np.int32), tables=tables.array(), loaded=loaded,
                      strategies=["mis"] * n, param=param)
    return make_materials_struct(md, "cpu")


@wp.kernel
def _eval_kernel(mats: Materials, m: int, wi: wp.array(dtype=wp.vec3), wo: wp.array(dtype=wp.vec3),
                 out: wp.array(dtype=wp.vec3), angles: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = rational.rational_eval(mats, m, wi[i], wo[i])
    angles[i] = F.half_diff(wi[i], wo[i])


def _pairs(n, seed):
    rng = np.random.default_rng(seed)
    wi = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    wo = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    # grazing and near-specular pairs too (clamps, the theta_h split, the last piece)
    wo[: n // 4] = spherical_to_direction(np.radians(rng.uniform(80, 89.9, n // 4)), rng.random(n // 4) * 2 * np.pi)
    wi[n // 4: n // 2] = wo[n // 4: n // 2] * [-1, -1, 1] + rng.normal(scale=0.02, size=(n // 2 - n // 4, 3))
    return wi / np.linalg.norm(wi, axis=1, keepdims=True), wo


def _same_table_bin(x, td_box):
    """Whether the float32 binning of the kernel (:func:`frame.merl_theta_h_index`, ``..._d_index``
    of the angles clamped onto the flagged piece's box) and :mod:`fit.formats.grid`'s float64
    binning agree (they may not at a clamped box edge that falls on a bin edge)."""
    from fit.formats.grid import theta_d_index, theta_h_index

    th = np.clip(x[:, 0], 0.0, np.pi / 2)
    td = np.clip(x[:, 1], *td_box)
    h32, d32 = np.float32(th), np.float32(td)
    half_pi = np.float32(np.pi / 2)
    ih = np.clip(np.floor(np.sqrt(h32 / half_pi) * np.float32(90.0)), 0, 89).astype(int)
    jd = np.clip(np.floor(d32 / half_pi * np.float32(90.0)), 0, 89).astype(int)
    return (x[:, 1] <= td_box[0]) | ((ih == theta_h_index(th)) & (jd == theta_d_index(td)))


def test_rational_eval_equals_numpy_at_the_same_angles():
    cases = _cases()
    mats = _material_struct(cases)
    wi, wo = _pairs(8000, 4)
    n = len(wi)
    results = {}
    for m, (name, model, table) in enumerate(cases):
        out = wp.zeros(n, dtype=wp.vec3, device="cpu")
        ang = wp.zeros(n, dtype=wp.vec3, device="cpu")
        wp.launch(_eval_kernel, dim=n, device="cpu", inputs=[mats, m, wp.array(wi, dtype=wp.vec3, device="cpu"),
                                                             wp.array(wo, dtype=wp.vec3, device="cpu")],
                  outputs=[out, ang])
        got, x = out.numpy().astype(float), ang.numpy()[:, :2].astype(float)
        above = (wi[:, 2].astype(np.float32) > 0) & (wo[:, 2].astype(np.float32) > 0)
        ref = model(x) if table is None else rational.values_with_table(model, table, x)
        ref = np.where(above[:, None], ref, 0.0)
        assert np.all(got[~above] == 0)
        same_bin = np.ones(n, bool)
        if table is not None:   # the kernel bins the clamped angles in float32 (as it always did)
            same_bin = _same_table_bin(x, np.radians([60.0, 80.0]))
            assert same_bin.mean() > 0.9
            np.testing.assert_allclose(got[~same_bin, 1], ref[~same_bin, 1], rtol=2e-6, atol=1e-7)
        # float64 sums in another order, one float32 rounding
        np.testing.assert_allclose(got[same_bin], ref[same_bin], rtol=2e-6, atol=1e-7, err_msg=name)
        if name == "clamped":    # the clamps are active on part of the pairs
            d = np.degrees(x[:, 1])
            assert np.any(got[d > 60, 2] == np.float32(2.1)) and np.any(got[(d > 30) & (d < 60), 0] == np.float32(1.4))
            assert np.any(got[d < 30] == np.float32(3.0))
        results[name] = got
    # the table replaces the flagged channels (red, blue) of the last piece, nothing else
    last = np.degrees(x[:, 1]) > 60.0
    np.testing.assert_array_equal(results["table"][:, 1], results["clamped"][:, 1])
    np.testing.assert_array_equal(results["table"][~last], results["clamped"][~last])
    assert np.mean(results["table"][last & above, 0] != results["clamped"][last & above, 0]) > 0.1


# --------------------------------------------------------------------------------------------
# Compile once: other fits and other CDF files reuse the kernels
# --------------------------------------------------------------------------------------------
class _LoadLog:
    """A Warp logger (``wp.set_logger``) that keeps the module-load lines, which Warp writes at
    ``LOG_INFO`` and ends with ``(compiled)`` or ``(cached)``; warnings and errors go on to
    ``previous``."""

    def __init__(self, previous):
        self.loads, self.previous = [], previous

    def debug(self, message):
        pass

    def info(self, message):
        if message.startswith("Module "):
            self.loads.append(message)

    def warning(self, message, category=None, stacklevel=1):
        self.previous.warning(message, category, stacklevel + 1)

    def error(self, message):
        self.previous.error(message)

    def compiled(self):
        return [m for m in self.loads if m.rstrip().endswith("(compiled)")]


@wp.kernel(module="unique", enable_backward=False)
def _log_probe(a: wp.array(dtype=float)):
    a[wp.tid()] = 1.0


@contextmanager
def _compiles_in_this_process():
    """Record the Warp modules this process loads inside the block (a :class:`_LoadLog`); the
    log is checked to work: a probe kernel's module, unloaded first, loads at the end and its
    line is removed. (The kernel cache folder cannot answer this: test processes share it.)"""
    previous, level = wp.get_logger(), wp.config.log_level
    log = _LoadLog(previous)
    wp.set_logger(log)
    wp.config.log_level = wp.LOG_INFO
    try:
        yield log
        n = len(log.loads)
        _log_probe.module.unload()
        wp.launch(_log_probe, dim=1, inputs=[wp.zeros(1, dtype=float, device="cpu")], device="cpu")
        assert len(log.loads) == n + 1 and "_log_probe" in log.loads[-1], log.loads[n:]
        log.loads.pop()
    finally:
        wp.config.log_level = level
        wp.set_logger(previous)


def _hashes(r):
    k = r.kernels
    return [x.module.hash_module() for x in (k.render_tile, k.eval_bsdf, k.sample_bsdf, k.pdf_bsdf)]


def test_a_new_fit_compiles_nothing():
    from lab import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import MaterialSpec

    def renderer(model):
        # the cosine-MIS strategy: the kernels are the fit's (the default, mis-tabulated, would
        # tabulate each fit first; a CDF file's kernels: the test below); the hidden materials
        # of lab.testing.common_kernel, whose rational fit has the degree class of these: the
        # render kernel is the common test kernel of other files
        spec = MaterialSpec(name="m", type="rational", data=model, sampler="mis")
        r = Renderer(T.common_kernel(T.plane_scene(spec, [T.constant_env(1.0)], resolution=4, spp=1)))
        assert r.material_data.strategies[r.material_index("m")] == "mis"
        return r

    first = renderer(_model("linear", 0))
    first.compile()
    wi, wo = _pairs(2000, 9)
    first.eval_material("m", wi, wo)
    with _compiles_in_this_process() as log:
        # fits of one degree class (other classes: tests/test_rational_classes.py)
        for model in (_model("log", 5, value_max=2.0), _clamped_piecewise(flag=False)):
            r = renderer(model)
            assert _hashes(r) == _hashes(first)
            r.compile()
            got = r.eval_material("m", wi, wo)
            ref = r.material_data.loaded[r.material_index("m")].evaluate(wi, wo)
            np.testing.assert_allclose(got, ref, rtol=2e-4, atol=1e-6)
    assert not log.compiled(), log.compiled()


@pytest.fixture(scope="module")
def global_fits():
    """Two different verified global-layout fits (a Lambert material's CDFs on two tables; made
    once per test session, tests/test_cdf_samplers.py)."""
    from test_cdf_samplers import lambert_global_fit

    fits = [lambert_global_fit(n_v) for n_v in (8, 6)]
    for c in fits:
        assert c.layout == "global" and not c.fallback, c.reason
    assert not np.array_equal(fits[0].maps.theta.num_coef, fits[1].maps.theta.num_coef)
    return fits


def test_a_new_cdf_file_compiles_nothing(global_fits):
    """Global-layout fits and a pieces-layout fit of the same material: the same kernels, and
    the Warp samples equal the NumPy reference for each."""
    from lab.analytic import lambert
    from fit.sampling.cdf_file import fit_cdf
    from lab import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.techniques import rational as technique

    pieces = fit_cdf(lambert((0.8, 0.6, 0.4)), name="lambert", table_params=dict(n_v=8, n_t=32, n_p=32))
    assert pieces.layout == "pieces" and not pieces.fallback
    rng = np.random.default_rng(3)
    n = 3000
    xi = rng.uniform(0.001, 0.999, size=(n, 2))
    wo = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)

    def renderer(cdf):
        # the hidden materials of lab.testing.common_kernel: the render kernel is the common
        # test kernel of other files
        spec = T.lambert(albedo=(0.8, 0.6, 0.4), sampler="mis-rational")
        spec.cdf = cdf
        r = Renderer(T.common_kernel(T.plane_scene(spec, [T.constant_env(1.0)], resolution=4, spp=1)))
        assert r.material_data.strategies[r.material_index("m")] == "mis-rational"
        return r

    first = renderer(global_fits[0])
    first.compile()
    first.sample_material("m", wo, xi)
    with _compiles_in_this_process() as log:
        for cdf in (*global_fits, pieces):
            r = renderer(cdf)
            assert _hashes(r) == _hashes(first)
            r.compile()
            wi, w = r.sample_material("m", wo, xi)
            ref_wi, ref_w = technique.numpy_sample(cdf, wo, xi)
            np.testing.assert_allclose(wi, ref_wi, atol=2e-4)
            np.testing.assert_allclose(w, ref_w, rtol=2e-3, atol=1e-5)
    assert not log.compiled(), log.compiled()


@wp.kernel
def _global_kernel(gi: wp.array(dtype=int), gf: wp.array(dtype=wp.float64), gq: wp.array(dtype=wp.vec2d), g: int,
                   q: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = technique.global_sample(gf, gi, gq, g, q[i][0], q[i][1], q[i][2])


def test_global_sampler_equals_numpy_closely(global_fits):
    """The global layout in float64 from data: theta_l, phi_l and alpha against
    :meth:`CDFFit.sample` at the same float32 inputs, far tighter than the contract's bounds."""
    packed = cdf_data.pack(list(global_fits))
    gi = wp.array(packed["cdf_gi"], dtype=int, device="cpu")
    gf = wp.array(packed["cdf_gf"], dtype=wp.float64, device="cpu")
    gq = wp.array(packed["cdf_gq"], dtype=wp.vec2d, device="cpu")
    rng = np.random.default_rng(8)
    n = 4000
    q = (rng.random((n, 3)) * [np.pi / 2, 1, 1]).astype(np.float32)
    for m, cdf in enumerate(global_fits):
        out = wp.zeros(n, dtype=wp.vec3, device="cpu")
        wp.launch(_global_kernel, dim=n, device="cpu",
                  inputs=[gi, gf, gq, int(packed["cdf_info"][m, CDF_MAPS]), wp.array(q, dtype=wp.vec3, device="cpu")],
                  outputs=[out])
        got = out.numpy().astype(float)
        qq = q.astype(float)
        tl, pl, alpha = cdf.sample(qq[:, 0], qq[:, 1], qq[:, 2])
        np.testing.assert_allclose(got[:, 0], tl, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(got[:, 1], pl, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(got[:, 2], alpha, rtol=1e-5, atol=1e-6)


def test_degree_beyond_the_limit_is_a_one_line_error():
    from warp_rbrdf.errors import SceneError
    from warp_rbrdf.scene import MaterialSpec

    e = basis.tensor_exponents((chebyshev.MAX_DEGREE + 1, 1))
    with pytest.raises(ValueError, match="exceeds the renderer's limit"):
        chebyshev.pack_polynomials([(e, np.ones(len(e)))], 2)
    m = _model()
    for f in m.functions:
        f.num_exponents, f.num_coef = e, np.full(len(e), 0.01)
    with pytest.raises(SceneError) as err:
        rational.load(MaterialSpec(name="m", type="rational", data=m))
    assert "\n" not in str(err.value) and "materials.file" in str(err.value) and "limit 15" in str(err.value)
