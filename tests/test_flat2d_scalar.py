"""The scalar form of the flat records' functions (``rational_flat2d.flat_source``: the CUDA
build's, one sum per channel) computes what the vector form (the CPU build's, Clang vectors)
computes: both compiled for the CPU and fed the same record pointers and angles, for the
package's 2-D fits and synthetic flat records of both split variables (log values with an upper
clamp, vouched ranges, flagged channels read from the fallback table), and 3-D flat records
(theta_h pieces, a single box, with and without the value factor), over random direction pairs
including grazing ones (the measured-domain move)."""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from test_rational_classes import _flat_theta_h_model, _pairs, model_3d, single_3d
from test_warp_rational import random_model

from lab import testing as T
from warp_rbrdf.materials import rational_flat2d as RF
from warp_rbrdf.materials import rational_flat3d as RF3
from warp_rbrdf.materials import rational_records as R
from warp_rbrdf.materials.data import Materials
from warp_rbrdf.materials.rational_kernel import DOMAIN_MARGIN
from warp_rbrdf.paths import PACKAGE_DATA
from warp_rbrdf.renderer import Renderer
from warp_rbrdf.scene import MaterialSpec

_KERNELS: dict = {}


def _kernel(keys: tuple, n_vars: int):
    """Per pair: the vector and the scalar form's ``(R, G, B, 1)`` of material ``m``'s flat record
    of ``n_vars`` variables (3: ``rational_flat3d``, its angles and step 8's wi.z)."""
    if (keys, n_vars) not in _KERNELS:
        make = RF.make_flat2d if n_vars == 2 else RF3.make_flat3d
        vec, sca = make(keys, DOMAIN_MARGIN), make(keys, DOMAIN_MARGIN, scalar=True)

        @wp.kernel(module="unique", enable_backward=False)
        def k(mats: Materials, m: int, wi: wp.array(dtype=wp.vec3), wo: wp.array(dtype=wp.vec3),
              out_v: wp.array(dtype=wp.vec4), out_s: wp.array(dtype=wp.vec4)):
            i = wp.tid()
            ib = mats.coef_i[3 * m]
            fb = mats.coef_i[3 * m + 1]
            nf = ib
            if mats.coef_i[nf] == wp.static(R.NODE_DOMAIN):
                nf = ib + mats.coef_i[nf + wp.static(R.DOMAIN_CHILD)]
            fp = wp.address_of(mats.coef_f[fb + mats.coef_i[nf + wp.static(R.FLAT_FLOATS)]])
            ip = wp.address_of(mats.coef_i[nf + wp.static(R.FLAT_PIECES)])
            dp = wp.address_of(mats.coef_f[fb])
            tp = wp.address_of(mats.tables[mats.param[m]])
            var = mats.coef_i[nf + wp.static(R.FLAT_VAR)]
            if wp.static(n_vars == 2):
                ang = RF.angles_2d(wi[i], wo[i])
                out_v[i] = vec(fp, ip, dp, tp, var, ang)
                out_s[i] = sca(fp, ip, dp, tp, var, ang)
            else:
                ang3 = RF3.angles_3d(wi[i], wo[i])
                out_v[i] = vec(fp, ip, dp, tp, var, ang3, wi[i][2])
                out_s[i] = sca(fp, ip, dp, tp, var, ang3, wi[i][2])

        _KERNELS[keys, n_vars] = k
    return _KERNELS[keys, n_vars]


def _flat_theta_d_model():
    """Two theta_d pieces of linear fits (a flat record split in theta_d)."""
    import fit.rational.model as M

    e = [0.0, np.radians(40.0), np.radians(80.0)]
    pieces = [random_model("linear", 40 + k, theta_d_range=(e[k], e[k + 1])) for k in range(2)]
    return M.PiecewiseRationalModel(
        name="flat_d", variables=[M.Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2)),
                                  M.Variable("theta_d", "rad", "identity", (0.0, e[-1]))],
        split_variable="theta_d", edges=e, pieces=pieces)


@pytest.fixture(scope="module")
def scene():
    from test_rational_classes import _fallback_record

    spec = lambda name, **kw: MaterialSpec(name=name, type="rational", sampler="mis", **kw)  # noqa: E731 - no CDF
    specs = {p.stem: spec(p.stem, file=p) for p in sorted(PACKAGE_DATA.glob("*.json"))}
    flat_h = _flat_theta_h_model()
    flat_h.fallback = _fallback_record(flat_h)
    specs["flat_h"] = spec("flat_h", data=flat_h)
    specs["flat_d"] = spec("flat_d", data=_flat_theta_d_model())
    specs["flat3d_h"] = spec("flat3d_h", data=model_3d(phi_split=False, value_factor="1/cos_theta_i"))
    specs["single3d"] = spec("single3d", data=single_3d(value_factor="none"))
    sc = T.spheres_scene(specs)
    return Renderer(sc, device="cpu"), list(specs)


def test_scalar_form_equals_the_vector_form(scene):
    from warp_rbrdf.materials import rational

    r, names = scene
    md = r.material_data
    keys = set()
    for lm in md.loaded:
        keys |= rational.packed_classes(lm.coefficients[0])
    keys = tuple(sorted(k for k in keys if k))
    wi, wo = _pairs(40_000)
    a = lambda x: wp.array(np.asarray(x, np.float32), dtype=wp.vec3, device="cpu")  # noqa: E731
    flat = {R.NODE_FLAT2D: 0, R.NODE_FLAT3D: 0}
    for name in names:
        m = r.material_index(name)
        ints = md.loaded[m].coefficients[0]
        n = int(ints[R.DOMAIN_CHILD]) if ints[0] == R.NODE_DOMAIN else 0
        kind = int(ints[n])
        if kind not in flat:
            continue
        flat[kind] += 1
        kernel = _kernel(keys, 2 if kind == R.NODE_FLAT2D else 3)
        out_v, out_s = (wp.zeros(len(wi), dtype=wp.vec4, device="cpu") for _ in range(2))
        wp.launch(kernel, dim=len(wi), inputs=[r.materials, m, a(wi), a(wo)], outputs=[out_v, out_s],
                  device="cpu")
        v, s = out_v.numpy(), out_s.numpy()
        above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        assert np.all(v[above, 3] == 1.0) and np.all(s[above, 3] == 1.0), name
        assert np.all(np.isfinite(v[above])) and v[above, :3].std() > 0, name
        # the same operations in another order (per-channel sums instead of lanes; wp::exp
        # instead of the inline exp: within one float32 ulp)
        np.testing.assert_allclose(s[above], v[above], rtol=4e-7, atol=1e-30, err_msg=name)
    assert flat[R.NODE_FLAT2D] >= 3, "the scene must hold 2-D flat records of both split variables"
    assert flat[R.NODE_FLAT3D] == 2
