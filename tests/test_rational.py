"""RationalFunction: evaluation, analytic derivatives, certificates, JSON coefficient files."""
import json

import numpy as np
import pytest

from fit.errors import BRDFFileError
from fit.rational.basis import chebyshev_basis, chebyshev_series, tensor_exponents, total_degree_exponents
from fit.rational.bernstein import bernstein_coefficients
from fit.rational.coefficient_file import load, save
from fit.rational.function import RationalFunction, RationalRGB
from fit.rational.model import RationalModel, Variable


def _random_rf(n_vars, m, n, seed=0):
    rng = np.random.default_rng(seed)
    Ep, Eq = total_degree_exponents(n_vars, m), total_degree_exponents(n_vars, n)
    q = 0.1 * rng.standard_normal(len(Eq))
    q[0] = 1.0
    dom = np.array([[0.0, 1.0], [-2.0, 3.0], [0.5, 1.5]][:n_vars])
    return RationalFunction(dom, Ep, rng.standard_normal(len(Ep)), Eq, q)


def test_exponent_lists():
    assert total_degree_exponents(2, 2).tolist() == [[0, 0], [1, 0], [0, 1], [2, 0], [1, 1], [0, 2]]
    assert len(total_degree_exponents(3, 4)) == 35
    assert len(tensor_exponents([2, 3])) == 12
    # total-degree lists are prefixes of each other (the fitter relies on it)
    assert (total_degree_exponents(2, 5)[:21] == total_degree_exponents(2, 5)).all()
    assert (total_degree_exponents(2, 7)[:21] == total_degree_exponents(2, 5)).all()


def test_chebyshev_basis_matches_numpy():
    x = np.linspace(-3, 5, 11)
    B = chebyshev_basis(x, [[k] for k in range(6)], [[-3, 5]])
    t = (2 * x - 2) / 8
    ref = np.polynomial.chebyshev.chebvander(t, 5)
    assert np.allclose(B, ref)


@pytest.mark.parametrize("n_vars, degree", [(1, 9), (2, 14), (3, 6)])
def test_chebyshev_series_equals_the_basis_matrix_product(n_vars, degree):
    """The series without the basis matrix (what P and Q evaluate with) against the basis
    matrix times the coefficients: total-degree and tensor exponent lists, in any order, inside
    and outside the domain, at any leading shape; no exponent: zero."""
    rng = np.random.default_rng(n_vars)
    dom = np.array([[0.0, 1.0], [-2.0, 3.0], [0.5, 1.5]][:n_vars])
    x = dom[:, 0] - 0.5 + rng.random((3, 50, n_vars)) * (dom[:, 1] - dom[:, 0] + 1.0)
    for E in (total_degree_exponents(n_vars, degree), tensor_exponents([3, 1, 2][:n_vars]),
              rng.permutation(total_degree_exponents(n_vars, degree))[: max(3, degree)]):
        c = rng.standard_normal(len(E))
        ref = chebyshev_basis(x, E, dom) @ c
        got = chebyshev_series(x, E, dom, c)
        assert got.shape == (3, 50)
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    assert np.array_equal(chebyshev_series(x, np.zeros((0, n_vars), int), dom, []), np.zeros((3, 50)))
    if n_vars == 1:
        assert np.shape(chebyshev_series(0.3, [[0], [2]], dom, [1.0, 1.0])) == ()


@pytest.mark.parametrize("n_vars", [1, 2, 3])
def test_derivatives_equal_finite_differences(n_vars):
    f = _random_rf(n_vars, 3, 2, seed=n_vars)
    rng = np.random.default_rng(1)
    x = f.domain[:, 0] + rng.random((20, n_vars)) * (f.domain[:, 1] - f.domain[:, 0])
    for v in range(n_vars):
        h = 1e-6 * (f.domain[v, 1] - f.domain[v, 0])
        dx = np.zeros(n_vars)
        dx[v] = h
        fd = (f(x + dx) - f(x - dx)) / (2 * h)
        assert np.allclose(f.derivative(x, v), fd, rtol=1e-5, atol=1e-6)
    assert f.gradient(x).shape == (20, n_vars)


def test_vectorised_shapes_and_scalar_1d():
    f = _random_rf(1, 2, 1)
    assert np.shape(f(0.3)) == ()
    assert f(np.zeros((4, 5))).shape == (4, 5)
    g = _random_rf(2, 2, 1)
    assert g(np.zeros((4, 5, 2))).shape == (4, 5)
    rgb = RationalRGB([g, g.scaled(2.0), g.scaled(3.0)])
    out = rgb(np.full((7, 2), 0.5))
    assert out.shape == (7, 3) and np.allclose(out[:, 1], 2 * out[:, 0])


def test_bernstein_exact_and_certificates():
    # 2 t^2 - 0.8 = T_2 + 0.2: negative at t = 0 -> not certified
    bad = RationalFunction([[-1, 1]], [[0]], [1.0], [[0], [2]], [0.2, 1.0])
    assert not bad.certify_denominator().certified
    good = RationalFunction([[-1, 1]], [[0]], [1.0], [[0], [2]], [1.02, 1.0])   # 2 t^2 + 0.02
    cert = good.certify_denominator()
    assert cert.certified and 0 < cert.lower_bound <= 0.02
    b = bernstein_coefficients([[0], [2]], [1.02, 1.0])
    assert [float(v) for v in b] == pytest.approx([2.02, -1.98, 2.02])   # exact rationals
    f = _random_rf(2, 3, 3)
    assert f.certify_denominator().certified
    assert f.denominator(f.grid(50)).min() > 0


def _model():
    f = _random_rf(2, 3, 2)
    f = RationalFunction([[0, np.sqrt(np.pi / 2)], [0, 1.3]], f.num_exponents, np.abs(f.num_coef),
                         f.den_exponents, f.den_coef)
    return RationalModel("test", [Variable("theta_h", "rad", "sqrt", (0, np.pi / 2)),
                                  Variable("theta_d", "rad", "identity", (0, 1.3))],
                         [f, f.scaled(0.5), f.scaled(0.25)], value_transform="log", value_offset=1e-3)


def test_json_round_trip(tmp_path):
    m = _model()
    path = tmp_path / "m.json"
    save(m, path)
    m2 = load(path)
    th = np.linspace(0, 1.6, 7)
    td = np.linspace(0, 1.5, 7)   # partly outside: clamped
    assert np.array_equal(m.evaluate_brdf(th, td), m2.evaluate_brdf(th, td))
    assert np.allclose(m2.evaluate_brdf(0.1, 1.5), m2.evaluate_brdf(0.1, 1.3))
    d = json.loads(path.read_text())
    assert d["format"] == "rbrdf-rational" and d["version"] == 1
    assert d["variables"][0]["transform"] == "sqrt"


def test_save_writes_only_what_the_reader_reads(tmp_path):
    """A model the reader refuses (here a function vouched up to 2e8 1/sr, above
    fit.limits.MAX_BRDF_VALUE) is not written: the reader's one-line error, the file at the
    path untouched. The fitters' vouched envelope is capped at that limit."""
    from fit.limits import MAX_BRDF_VALUE
    from fit.rational.model import vouched_envelope

    path = tmp_path / "m.json"
    path.write_text("the user's file")
    m = _model()
    m.function_info = [{"vouched_range": [0.0, 2e8]}, {}, {}]
    with pytest.raises(BRDFFileError, match=r"functions\[0\]\.vouched_range: \[0, 2e\+08\] 1/sr is not inside"):
        save(m, path)
    assert path.read_text() == "the user's file" and sorted(p.name for p in tmp_path.iterdir()) == ["m.json"]
    y = np.array([3.0, 5e4])
    assert vouched_envelope(y - 2000 * y, y + 2000 * y) == [0.0, MAX_BRDF_VALUE]
    assert vouched_envelope(y * 0.9, y * 1.1) == pytest.approx([2.7, 5.5e4], rel=1e-15)
    m.function_info = [{"vouched_range": vouched_envelope(y - 2000 * y, y + 2000 * y)}, {}, {}]
    save(m, path)
    assert load(path).function_info[0]["vouched_range"] == [0.0, MAX_BRDF_VALUE]


def test_json_errors(tmp_path):
    m = _model()
    path = tmp_path / "m.json"
    save(m, path)
    d = json.loads(path.read_text())
    d["version"] = 99
    (tmp_path / "v.json").write_text(json.dumps(d))
    with pytest.raises(BRDFFileError, match="unsupported rbrdf-rational version 99"):
        load(tmp_path / "v.json")
    (tmp_path / "c.json").write_text(path.read_text()[:200])
    with pytest.raises(BRDFFileError, match="corrupt"):
        load(tmp_path / "c.json")
    d["version"] = 1
    del d["functions"][0]["numerator"]
    (tmp_path / "k.json").write_text(json.dumps(d))
    with pytest.raises(BRDFFileError, match="invalid"):
        load(tmp_path / "k.json")
    (tmp_path / "o.json").write_text('{"format": "other"}')
    with pytest.raises(BRDFFileError, match="not an rbrdf-rational"):
        load(tmp_path / "o.json")
    with pytest.raises(BRDFFileError, match="file not found"):
        load(tmp_path / "missing.json")


def _piecewise():
    from fit.rational.model import PiecewiseRationalModel

    edges = [0.0, 0.6, 1.3]
    pieces = []
    for k in range(2):
        f = _random_rf(2, 3, 2)
        f = RationalFunction([[0, np.sqrt(np.pi / 2)], edges[k:k + 2]], f.num_exponents,
                             np.abs(f.num_coef) + k, f.den_exponents, f.den_coef)
        pieces.append(RationalModel("p", [Variable("theta_h", "rad", "sqrt", (0, np.pi / 2)),
                                          Variable("theta_d", "rad", "identity", edges[k:k + 2])],
                                    [f, f.scaled(0.5), f.scaled(0.25)], value_transform="log",
                                    value_offset=1e-3, value_max=1e3))
    return PiecewiseRationalModel("pw", [Variable("theta_h", "rad", "sqrt", (0, np.pi / 2)),
                                         Variable("theta_d", "rad", "identity", (0.0, 1.3))],
                                  "theta_d", edges, pieces,
                                  piece_info=[{"guaranteed": True}, {"guaranteed": False}])


def test_piecewise_evaluation_and_round_trip(tmp_path):
    m = _piecewise()
    th = np.linspace(0, 1.5, 11)
    for td, k in ((0.2, 0), (0.6, 0), (0.61, 1), (1.2, 1), (1.5, 1)):   # edge -> lower piece
        got = m.evaluate_brdf(th, td)
        assert np.array_equal(got, m.pieces[k].evaluate_brdf(th, min(td, 1.3)))
    assert not np.allclose(m.evaluate_brdf(th, 0.6), m.evaluate_brdf(th, 0.6 + 1e-9))  # a real jump
    save(m, tmp_path / "pw.json")
    d = json.loads((tmp_path / "pw.json").read_text())
    assert d["version"] == 2 and d["split"]["variable"] == "theta_d" and len(d["pieces"]) == 2
    assert "functions" not in d and d["pieces"][1]["info"]["guaranteed"] is False
    m2 = load(tmp_path / "pw.json")
    x = np.random.default_rng(1).uniform([0, 0], [1.6, 1.5], size=(200, 2))
    assert np.array_equal(m2(x), m(x)) and m2.n_coefficients == m.n_coefficients
    assert m2.piece_info[1]["guaranteed"] is False
    # corrupt version-2 files: edges that do not match the pieces
    d["split"]["edges"] = [0.0, 0.7, 1.3]
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(BRDFFileError, match="version-2.*piece 0"):
        load(tmp_path / "bad.json")
    del d["split"]
    (tmp_path / "nosplit.json").write_text(json.dumps(d))
    with pytest.raises(BRDFFileError, match="version-2"):
        load(tmp_path / "nosplit.json")
