"""The Warp evaluation of rational materials against fit.rational.model's NumPy evaluation."""
from __future__ import annotations

import numpy as np
import pytest

from lab import testing as T
from warp_rbrdf.renderer import Renderer
from warp_rbrdf.scene import MaterialSpec

import fit.rational.basis as basis  # noqa: E402
import fit.rational.coefficient_file as coefficient_file  # noqa: E402
import fit.rational.function as function  # noqa: E402
import fit.rational.model as model_types  # noqa: E402


def random_model(value_transform="linear", seed=0, theta_d_range=(0.0, np.radians(80.0)), value_max=None,
                 theta_h_range=(0.0, np.pi / 2), name="random", info=None):
    """Three random but positive rational functions of (theta_h, theta_d) (numerator tensor
    degrees (5, 3), denominator total degree 2) as a :class:`RationalModel` on the given ranges
    (radians); ``info`` its ``function_info``."""
    rng = np.random.default_rng(seed)
    dom = [tuple(theta_h_range), tuple(theta_d_range)]
    variables = [model_types.Variable("theta_h", "rad", "sqrt", dom[0]),
                 model_types.Variable("theta_d", "rad", "identity", dom[1])]
    rf_dom = np.array([v.rf_domain for v in variables])
    num_e = basis.tensor_exponents((5, 3))
    den_e = basis.total_degree_exponents(2, 2)
    funcs = []
    for c in range(3):
        p = rng.normal(size=len(num_e)) * 0.3
        p[0] = 1.5 + c
        q = rng.normal(size=len(den_e)) * 0.05
        q[0] = 1.0
        funcs.append(function.RationalFunction(rf_dom, num_e, p, den_e, q))
    return model_types.RationalModel(name=name, variables=variables, functions=funcs,
                                      value_transform=value_transform, value_max=value_max,
                                      value_offset=0.01 if value_transform == "log" else 0.0,
                                      function_info=info or [])


def piecewise_model(value_transform="log"):
    """Three theta_d pieces with different coefficients (a visible jump at each edge), an upper
    clamp that is active on part of the domain, and the first piece split again in theta_h."""
    e = np.radians([0.0, 30.0, 60.0, 80.0])
    pieces = [random_model(value_transform, seed=k, theta_d_range=(e[k], e[k + 1]), value_max=8.0)
              for k in range(3)]
    h = [0.0, np.radians(5.0), np.pi / 2]
    sub = []
    for j in range(2):
        m = random_model(value_transform, seed=10 + j, theta_d_range=(e[0], e[1]), value_max=8.0)
        m.variables[0] = model_types.Variable("theta_h", "rad", "sqrt", (h[j], h[j + 1]))
        for f in m.functions:
            f.domain[0] = m.variables[0].rf_domain
        sub.append(m)
    pieces[0] = model_types.PiecewiseRationalModel(
        name="peak", variables=[model_types.Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2)),
                                model_types.Variable("theta_d", "rad", "identity", (e[0], e[1]))],
        split_variable="theta_h", edges=h, pieces=sub)
    return model_types.PiecewiseRationalModel(
        name="pieces", variables=[model_types.Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2)),
                                  model_types.Variable("theta_d", "rad", "identity", (e[0], e[-1]))],
        split_variable="theta_d", edges=list(e), pieces=pieces)


@pytest.mark.parametrize("value_transform", ["linear", "log", "piecewise"])
def test_rational_matches_numpy(value_transform):
    model = piecewise_model() if value_transform == "piecewise" else random_model(value_transform)
    # cosine MIS: no table (the default strategy tabulates the fit at load); the evaluation is the same
    spec = MaterialSpec(name="m", type="rational", data=model, sampler="mis")
    r = Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=4, spp=1))
    rng = np.random.default_rng(5)
    from fit.formats.angles import spherical_to_direction

    n = 5000
    wi = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    wo = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    got = r.eval_material("m", wi, wo)
    ref = model.evaluate(wi, wo)
    # float32 angles -> tiny input differences; the values agree to ~1e-5 relative
    np.testing.assert_allclose(got, ref, rtol=2e-4, atol=1e-6)
    wi[:, 2] *= -1
    assert np.all(r.eval_material("m", wi, wo) == 0)


def test_rational_file_round_trip(tmp_path):
    """A fit saved to a coefficient file and named by a scene: the renderer's Warp evaluation of
    the file's material is the fit's (the evaluation kernel of test_rational_matches_numpy)."""
    from fit.formats.angles import spherical_to_direction
    from warp_rbrdf.scene import parse_scene

    model = random_model()
    path = tmp_path / "m.json"
    coefficient_file.save(model, path)
    sc = parse_scene(f"""
[camera]
resolution = [8, 8]
[materials.m]
type = "rational"
file = "{path.as_posix()}"
sampler = "mis"
[[shapes]]
type = "plane"
material = "m"
[[lights]]
type = "constant"
""", path=tmp_path / "s.toml")
    rng = np.random.default_rng(6)
    wi = spherical_to_direction(np.arccos(rng.random(2000)), rng.random(2000) * 2 * np.pi)
    wo = spherical_to_direction(np.arccos(rng.random(2000)), rng.random(2000) * 2 * np.pi)
    got = Renderer(sc).eval_material("m", wi, wo)
    assert got.max() > 0
    np.testing.assert_allclose(got, model.evaluate(wi, wo), rtol=2e-4, atol=1e-6)


def test_default_scene_uses_shipped_coefficients(tmp_path, monkeypatch):
    """With a coefficient file in warp_rbrdf/data the default scene's sphere is rational, read
    from that file (a copy of the shipped default fit under another name: the render loads the
    shipped kernel and table of the default scene where they are current)."""
    import shutil

    import warp_rbrdf.defaults as defaults
    import warp_rbrdf.paths as paths

    shutil.copy(paths.PACKAGE_DATA / defaults.PREFERRED_DEFAULT, tmp_path / "shipped.json")
    monkeypatch.setattr(defaults, "PACKAGE_DATA", tmp_path)
    monkeypatch.setattr(paths, "PACKAGE_DATA", tmp_path)
    sc = defaults.default_scene()
    assert sc.materials["sphere"].type == "rational"
    assert sc.materials["sphere"].file == tmp_path / "shipped.json"
    sc.camera.resolution = (8, 8)
    img = Renderer(sc).render(spp=1)
    assert np.isfinite(img).all()


def test_nested_piecewise_file_round_trip(tmp_path):
    """A theta_d-piecewise model whose first piece is split again in theta_h (version 2, nested
    pieces) and an upper value clamp survive a JSON round trip bit for bit."""
    model = piecewise_model()
    coefficient_file.save(model, tmp_path / "nested.json")
    back = coefficient_file.load(tmp_path / "nested.json")
    assert isinstance(back.pieces[0], model_types.PiecewiseRationalModel)
    assert back.value_max == 8.0 and back.n_coefficients == model.n_coefficients
    x = np.random.default_rng(2).uniform([0, 0], [1.6, 1.5], size=(4000, 2))
    got = back(x)
    assert np.array_equal(got, model(x)) and got.max() == 8.0
