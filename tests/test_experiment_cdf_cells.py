"""The issue-6 experiment with per-cell univariate inverse CDFs (benchmarks/experiment_cdf_cells.py):
its Bernstein positivity certificate, and that its sampler is unbiased and within the gate on
a material where the maps are easy (Lambert), so the numbers it prints for the RGL materials
come from a sampler that is right where it can be checked."""
from __future__ import annotations

import math
import sys

import numpy as np

from conftest import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
import experiment_cdf_cells as E  # noqa: E402


def test_positive_on_unit_certificate():
    # (x - 1/2)^2 + c: positive for c > 0, not for c < 0; a zero at an end is not positive
    for c, expect in ((1e-3, True), (1e-8, True), (-1e-6, False)):
        assert E.positive_on_unit([0.25 + c, -1.0, 1.0]) is expect
    assert E.positive_on_unit([0.0, 1.0]) is False            # x: zero at 0
    assert E.positive_on_unit([1.0, -1.0]) is False           # 1 - x: zero at 1
    assert E.positive_on_unit([2.0, -3.0, 1.2]) is True       # min 0.125 at x = 1.25: outside [0, 1]


def test_power_conversion_and_normalisation():
    from fit.rational.function import RationalFunction

    f = RationalFunction([[0.0, 1.0]], [[0], [1], [2]], [0.3, 1.0, 0.2], [[0], [1]], [2.0, 0.5])
    p, q = E.to_power(f)
    x = np.linspace(0, 1, 7)
    np.testing.assert_allclose(np.polynomial.polynomial.polyval(x, p) / np.polynomial.polynomial.polyval(x, q),
                               f(x[:, None]), rtol=1e-12)
    pn, qn = E.normalize(p, q, np.pi)
    v, d = E.eval_maps(pn[None], qn[None], np.array([0.0, 1.0]))
    np.testing.assert_allclose(v, [0.0, np.pi], atol=1e-12)


def test_cells_sampler_unbiased_on_lambert():
    _, info = E.main(["lambert", "--table", "4,8,8", "--rows", "0,3"])
    assert info["verified_rows"] == 2
    for v in (0, 3):
        vr = info["rows"][v]["variance"]
        sigma = math.sqrt((vr["variance_rational"] + vr["variance_table"]) / vr["n"])
        assert abs(vr["mean_rational"] - vr["mean_table"]) < 4.0 * sigma + 1e-12
        # luminance albedo of Lambert (0.8, 0.6, 0.4)
        assert abs(vr["mean_rational"] - (0.2126 * 0.8 + 0.7152 * 0.6 + 0.0722 * 0.4)) < 4.0 * sigma + 1e-3
        assert vr["ratio"] <= 1.2
