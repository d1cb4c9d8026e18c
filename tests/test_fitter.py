"""Interval-constraint fitter: NIST Kirby2, exact recovery, poles, zero data, 3 variables."""
import numpy as np
import pytest
from scipy.optimize import least_squares

from conftest import data_file
from fit.rational.fitter import IntervalRationalFitter, intervals_from_tolerance

KIRBY2_CERTIFIED = [1.6745063063e+00, -1.3927397867e-01, 2.5961181191e-03,
                    -1.7241811870e-03, 2.1664802578e-05]
KIRBY2_RSS = 3.9050739624


def _to_monomial(f):
    """(b1, b2, b3, b4, b5) of a degree-(2,2) 1-D rational function, Q's constant = 1."""
    x = np.array([0.0, 1.0, 2.0])
    V = np.vander(x, 3, increasing=True)
    p = np.linalg.solve(V, f.numerator(x))
    q = np.linalg.solve(V, f.denominator(x))
    return np.concatenate([p, q[1:]]) / q[0]


def test_kirby2_interval_fit_then_least_squares():
    d = np.loadtxt(data_file("nist/Kirby2.dat"), skiprows=1)
    y, x = d[:, 0], d[:, 1]          # first column is y
    r = IntervalRationalFitter(tol=0.05, abs_floor=0.2, degrees=(2, 2)).fit(x, y)
    assert r.valid and (r.num_degree, r.den_degree) == (2, 2)
    f = r.function.normalized()
    from fit.rational.function import RationalFunction

    def make(z):
        return RationalFunction(f.domain, f.num_exponents, z[:3], f.den_exponents, np.r_[1.0, z[3:]])

    # polish in the well-conditioned Chebyshev parametrisation (q_0 = 1), then convert
    z0 = np.r_[f.num_coef, f.den_coef[1:]]
    sol = least_squares(lambda z: make(z)(x) - y, z0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    b = _to_monomial(make(sol.x))
    assert b == pytest.approx(KIRBY2_CERTIFIED, rel=1e-6)
    rss = np.sum(((b[0] + b[1] * x + b[2] * x**2) / (1 + b[3] * x + b[4] * x**2) - y) ** 2)
    assert rss == pytest.approx(KIRBY2_RSS, rel=1e-9)



def test_kirby2_degree_search_finds_small_fit():
    d = np.loadtxt(data_file("nist/Kirby2.dat"), skiprows=1)
    r = IntervalRationalFitter(tol=0.05, abs_floor=0.2, max_degree=6).fit(d[:, 1], d[:, 0])
    assert r.valid and r.n_coefficients <= 6


def test_exact_rational_recovered_with_true_degrees():
    f = lambda x: (1 + 2 * x - x**2 + 0.3 * x**3) / (1 + 0.5 * x + 0.7 * x**2)
    x = np.linspace(-1, 2, 300)
    r = IntervalRationalFitter(tol=1e-7, max_degree=6).fit(x, f(x))
    assert r.valid and (r.num_degree, r.den_degree) == (3, 2)
    assert np.allclose(r.function(x), f(x), rtol=2e-7)


def test_planted_pole_is_never_certified():
    # denominator x - 0.3 vanishes inside [0, 1]: data on both sides of the pole
    x = np.concatenate([np.linspace(0, 0.28, 60), np.linspace(0.32, 1, 140)])
    y = 1.0 / (x - 0.3)
    r = IntervalRationalFitter(tol=0.01, max_degree=5, domain=[[0, 1]]).fit(x, y)
    assert not r.valid
    assert not r.feasible or not r.certificate.certified


def test_zero_data_and_absolute_floor():
    x = np.linspace(0, 1, 50)
    y = np.where(x < 0.5, 0.0, 0.0)
    lo, hi = intervals_from_tolerance(y, 0.05, 0.0)
    assert np.all(lo == hi)                                  # no floor: zero-width intervals
    r = IntervalRationalFitter(tol=0.05, abs_floor=1e-3, max_degree=3).fit(x, y)
    assert r.valid and r.n_coefficients == 2                 # constant / constant
    assert np.all(np.abs(r.function(x)) <= 1e-3)
    # explicit lower = upper = 0 intervals still handled (widened to a tiny width)
    r = IntervalRationalFitter(max_degree=2).fit(x, lower=np.zeros(50), upper=np.zeros(50))
    assert r.feasible and np.all(np.abs(r.function(x)) < 1e-9)


def test_three_variable_smooth_table():
    g = np.linspace(0, 1, 12)
    X = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    y = np.exp(-X[:, 0]) * (1 + X[:, 1] ** 2) / (1.5 + X[:, 2])
    r = IntervalRationalFitter(tol=0.01, max_degree=5, max_den_degree=2).fit(X, y)
    assert r.valid
    assert np.max(np.abs(r.function(X) / y - 1)) <= 0.01


def test_infeasible_returns_flagged_best_fit():
    x = np.linspace(0, 1, 200)
    y = np.abs(x - 0.5) + 0.1
    r = IntervalRationalFitter(tol=1e-4, max_degree=2).fit(x, y)
    assert not r.feasible and not r.valid
    assert r.function is not None and r.max_violation > 0


def test_time_limit_and_no_best_effort_are_flagged():
    x = np.linspace(0, 1, 200)
    y = np.abs(x - 0.5) + 0.1
    # nothing feasible: without best effort the search stops at its last refuted pair (no
    # converged least-violation LP), and is flagged
    quick = IntervalRationalFitter(tol=1e-4, max_degree=4, best_effort=False).fit(x, y)
    full = IntervalRationalFitter(tol=1e-4, max_degree=4).fit(x, y)
    assert not quick.valid and not full.valid and quick.n_lp < full.n_lp
    # a time limit of zero tries no degree pair: no function, never valid, and it says why
    r = IntervalRationalFitter(tol=0.05, max_degree=6, time_limit=0.0).fit(x, y)
    assert r.function is None and not r.valid and "time limit" in r.message
    # a feasible search within its limit is unaffected
    d = np.loadtxt(data_file("nist/Kirby2.dat"), skiprows=1)
    r = IntervalRationalFitter(tol=0.05, abs_floor=0.2, max_degree=6, time_limit=600).fit(d[:, 1], d[:, 0])
    assert r.valid and "time limit" not in r.message
