"""Deterministic work budgets of the 3-D fits (:mod:`fit.rational.fit3d`,
:mod:`fit.rational.albedo3d`, :mod:`fit.rational.refine`): no rule reads the wall clock.

* the same selection (two layouts, verification with refits, the albedo policy) run twice gives
  the same coefficients, bit for bit, the second time with a wall clock that jumps 10 s at
  every reading (below the safety ceiling's trigger): time is not a stopping rule;
* the wall-clock safety ceiling, when it is passed, is recorded (``stopped = "time"``, where) and
  stops the selection, the verification and the albedo policy.
"""
from __future__ import annotations

import time as _time
from pathlib import Path

import numpy as np
import pytest
from conftest import session_cached

from fit.rational import albedo3d, ceiling, fit3d, ladder3d, rgl3d, select3d, verify3d
from fit.rational.fit3d import fit_rgl_select
from test_albedo3d import Synthetic, small_policy  # the synthetic glossy lobe as an RGL-like object


#: every module of the 3-D fits that reads the clock
CLOCKED = (ladder3d, verify3d, rgl3d, select3d, albedo3d, ceiling)
#: two small layouts, a verification with refits and the albedo policy at a tight tolerance (it
#: corrects on this lobe): every loop that used to stop on time runs
VARIANTS = ({"theta_h_edges": [0.15], "degrees": (4, 2)}, {"theta_h_edges": [], "degrees": (4, 2)})
FIT = {"grid": (8, 7, 5), "n_random": 200, "n_objective": 800, "tol": 0.01, "verify": 2000,
       "verify_rounds": 2, "albedo_tol": 0.01,
       "select_by": "validation"}   # the budgets, not what compares layouts (tests/test_image_check.py: the image)


def select(**kw):
    """The selection, its albedo policy at the default run's sizes of tests/test_albedo3d.py (the
    budgets are counts, whatever the sizes; the policy at its own sizes: that file's ``extended``
    tests)."""
    with small_policy():
        return fit_rgl_select(Synthetic(), variants=VARIANTS, **dict(FIT, **kw))


def coefficients(res) -> np.ndarray:
    pieces = list(res.model.pieces) if hasattr(res.model, "pieces") else [res.model]
    return np.concatenate([np.concatenate([f.num_coef, f.den_coef]) for p in pieces for f in p.functions])


class JumpingClock:
    """A ``time`` module whose ``perf_counter`` advances ``step`` seconds more at every reading."""

    def __init__(self, step):
        self.step, self.n = float(step), 0

    def perf_counter(self):
        self.n += 1
        return _time.perf_counter() + self.n * self.step

    process_time = perf_counter          # the safety net's clock (CPU seconds) jumps as well

    def __getattr__(self, name):
        return getattr(_time, name)


def normal_selection():
    """:func:`select`, made once per test session for every worker (:func:`conftest.session_cached`;
    tests/test_fit_determinism.py runs it again under a fast wall clock): callers must not
    modify it."""
    return session_cached(Path(__file__), "normal-selection", select)


@pytest.fixture(scope="module")
def normal():
    return normal_selection()


@pytest.fixture(scope="module")
def slow_run():
    """``(clock, fit)``: the same selection run a second time, every clock it reads jumping 10 s
    at each reading (one run for the two tests below: a second run that differs from the first
    fails both, whether the clock or anything else made it differ)."""
    clock = JumpingClock(10.0)
    with pytest.MonkeyPatch.context() as mp:
        for module in CLOCKED:
            mp.setattr(module, "time", clock)
        slow = select(time_limit=1e7)   # the ceiling far beyond the clock's jumps: only the budgets stop
    return clock, slow


def test_same_inputs_give_identical_coefficients(normal, slow_run):
    _, again = slow_run
    assert np.array_equal(coefficients(again), coefficients(normal))
    for res in (normal, again):
        assert res.model.fit_info["verify_points_added"] > 0, "no verification refit: the test does not reach it"
        assert res.valid and res.model.fit_info["valid"]      # kept functions are within the bound they met
        assert res.model.fit_info["stopped"] is None
        assert res.info["albedo"]["refitted"], "the albedo policy corrected nothing: the test does not reach it"


def test_a_slow_clock_changes_nothing(normal, slow_run):
    clock, slow = slow_run
    assert clock.n > 10                  # the clock was read, and ran ahead by minutes
    assert np.array_equal(coefficients(slow), coefficients(normal))
    assert slow.info["verify_max_ratio"] == normal.info["verify_max_ratio"]
    assert slow.info["variants"] == [dict(v, time_s=w["time_s"]) if "time_s" in v else v
                                     for v, w in zip(normal.info["variants"], slow.info["variants"])]
    assert slow.model.fit_info["stopped"] is None


def test_the_safety_ceiling_is_recorded(monkeypatch):
    clock = JumpingClock(1.0)
    for module in CLOCKED:
        monkeypatch.setattr(module, "time", clock)
    res = select(time_limit=2.0)
    fi = res.model.fit_info
    assert fi["stopped"] == "time" and fi["time_limit"] == 2.0
    assert "tolerance ladder" in fi["stopped_at"] and "selection" in fi["stopped_at"]
    assert [v.get("skipped") for v in res.info["variants"]] == [None, "time"]
    assert fi["verify_points_added"] == 0           # no refit started past the ceiling
    assert res.info["albedo"]["stopped"] == "time" and res.info["albedo"]["rounds"] == 0


def test_the_file_says_what_is_guaranteed_on_the_whole_domain_and_why_not_more(normal):
    """``fit_info["domain"]`` (issue 25: the guarantee on the whole measured domain "or the reason it
    cannot be, per material, in the file"): proved at the data points, with the fit's own
    fresh-point ratio in the reason, and between the grid nodes by the proof the fit records per
    piece and channel; written to the coefficient file and read back (the module's selection,
    the one the tests above repeat). Without a proof's records it says the bound is proved at
    the data points only."""
    import json

    from fit.rational.coefficient_file import load, save

    res = normal
    fi = res.model.fit_info
    d = fi["domain"]
    assert d["proved_at"] == "grid cells" and "Between the nodes of the measurement's grid" in d["reason"]
    assert d["proved"] == all(b["proved"] <= b["tolerance"] for b in fi["bound"])
    assert len(fi["bound"]) == 3 * (len(res.edges) - 1)
    bare = fit3d.domain_record({"n_points": 10, "theta_max_deg": 89.0, "verify_points": 40, "verify_max_ratio": 2.0})
    assert bare["proved"] is False and bare["proved_at"] == "data points"
    assert d["n_points"] == fi["n_points"] and d["fresh_points"] == fi["verify_points"] > 0
    assert d["fresh_max_ratio"] == fi["verify_max_ratio"]
    assert f"{fi['verify_max_ratio']:.3g} x the bound" in d["reason"]
    assert f"{fi['n_points']} data points" in d["reason"]
    assert ("not within it between them" in d["reason"]) == (fi["verify_max_ratio"] > 1.0)
    assert fit3d.domain_record({"n_points": 10, "theta_max_deg": 89.0, "verify_points": 40,
                                "verify_max_ratio": 0.5})["reason"].count("verified, not proved") == 1
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as t:
        save(res.model, Path(t) / "f.json")
        assert json.loads((Path(t) / "f.json").read_text())["fit"]["domain"] == json.loads(json.dumps(d))
        assert load(Path(t) / "f.json").fit_info["domain"]["reason"] == d["reason"]
