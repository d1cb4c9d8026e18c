"""3-D fits are identical under load (:mod:`fit.rational.ceiling`, docs/fitting.md "Budgets"):

* the safety net of a fit is measured in the process's CPU seconds, not on the wall clock: a
  small fit whose process sees the wall clock run 50 times fast (a machine loaded so that the fit
  takes 50 times longer) gives the same coefficients, bit for bit, as an ordinary run, with the
  default settings (the wall-clock net of 120 s stopped this fit after a 72 s wall-clock share);
* the CPU-time net still ends a runaway, and a wall-clock limit applies only when one is given
  (``wall_limit``; ``rbrdf-fit brdf --time-limit``), each recorded as ``stopped_by``;
* ``rbrdf-fit brdf --model 3d`` gives the fit no wall-clock limit unless ``--time-limit`` asks for one.
"""
from __future__ import annotations

import functools
import time as _time

import numpy as np
import pytest

from fit.rational import ceiling as ceiling_module
from fit.rational.ceiling import DEFAULT_TIME_LIMIT, Ceiling
from fit.rational.settings import Fit3DSettings
from lab.analytic import RGLLike, phi_d_lobe
from test_fit3d_budget import normal_selection
from test_fit3d_budget import select as budget_select

FAST = 50.0       # the wall clock runs this many times fast


#: a diffuse base and a glossy lobe in theta_h that depends on phi_d (1/sr, RGB)
lobe_brdf = phi_d_lobe(3.0, 0.13, 4, base=(0.1, 0.14, 0.2))


#: an RGL-like object of :func:`lobe_brdf` (the last incidence 80 deg)
Lobe = functools.partial(RGLLike, lobe_brdf, "lobe")


def select(**kw):
    """The selection of tests/test_fit3d_budget.py (two small layouts, a verification with refits
    and the albedo policy: every step that checks the safety net runs)."""
    return budget_select(**kw)


def coefficients(res) -> np.ndarray:
    pieces = list(res.model.pieces) if hasattr(res.model, "pieces") else [res.model]
    return np.concatenate([np.concatenate([f.num_coef, f.den_coef]) for p in pieces for f in p.functions])


def fast_wall_clock(monkeypatch, factor=FAST):
    """``time.perf_counter`` (and ``time.time``, ``time.monotonic``) of this process run ``factor``
    times fast from now: every module that reads the wall clock sees a machine ``factor`` times
    slower. Returns the real seconds elapsed."""
    real = {name: getattr(_time, name) for name in ("perf_counter", "time", "monotonic")}
    starts = {name: f() for name, f in real.items()}
    for name, f in real.items():
        monkeypatch.setattr(_time, name, lambda f=f, s=starts[name]: s + factor * (f() - s))
    return lambda: real["perf_counter"]() - starts["perf_counter"]


@pytest.fixture(scope="module")
def ordinary():
    """The ordinary run: the one tests/test_fit3d_budget.py makes (once per test session)."""
    return normal_selection()


def test_a_fit_on_a_loaded_machine_gives_the_same_coefficients(ordinary, monkeypatch):
    elapsed = fast_wall_clock(monkeypatch)
    t0 = _time.perf_counter()
    loaded = select()
    seen = _time.perf_counter() - t0
    real = elapsed()
    assert seen > 0.6 * 120.0, "the fit is too short to have reached the old wall-clock net: the test proves nothing"
    assert seen > 0.5 * FAST * real        # the fit saw the fast clock
    assert loaded.model.fit_info["time_limit"] == DEFAULT_TIME_LIMIT and loaded.model.fit_info["wall_limit"] is None
    assert loaded.model.fit_info["stopped"] is None and ordinary.model.fit_info["stopped"] is None
    assert np.array_equal(coefficients(loaded), coefficients(ordinary))
    assert [v.get("skipped") for v in loaded.info["variants"]] == [v.get("skipped") for v in ordinary.info["variants"]]
    assert loaded.info["verify_max_ratio"] == ordinary.info["verify_max_ratio"]
    assert loaded.info["albedo"]["refitted"] == ordinary.info["albedo"]["refitted"]
    # every step that checks the net ran: a second layout, a refit and an albedo correction
    assert all("skipped" not in v for v in ordinary.info["variants"])
    assert ordinary.model.fit_info["verify_points_added"] > 0
    assert ordinary.info["albedo"]["refitted"], "the albedo policy corrected nothing: the test does not reach it"


def test_the_cpu_net_ends_a_runaway_and_says_so():
    res = select(time_limit=1e-3)
    fi = res.model.fit_info
    assert fi["stopped"] == "time" and fi["stopped_by"] == ["cpu"] and fi["time_limit"] == 1e-3
    assert "selection" in fi["stopped_at"] and [v.get("skipped") for v in res.info["variants"]] == [None, "time"]
    assert fi["verify_points_added"] == 0 and res.info["albedo"]["rounds"] == 0


def test_the_ceiling_reads_cpu_seconds_and_a_chosen_wall_limit(monkeypatch):
    cpu = [0.0]
    wall = [0.0]
    monkeypatch.setattr(ceiling_module.time, "process_time", lambda: cpu[0])
    monkeypatch.setattr(ceiling_module.time, "perf_counter", lambda: wall[0])
    net = Ceiling()
    chosen = Ceiling(wall_limit=30.0)
    wall[0] = 1e6                       # a loaded machine: the wall clock runs, the CPU time does not
    assert not net.out("a") and net.hits == []
    assert chosen.out("b") and chosen.by == ["wall"]
    cpu[0] = 0.6 * DEFAULT_TIME_LIMIT + 1.0
    assert net.out("selection", 0.6) and not Ceiling(None).out("c")
    info = {}
    net.record(info)
    assert info == {"time_limit": DEFAULT_TIME_LIMIT, "wall_limit": None, "stopped": "time",
                    "stopped_at": ["selection"], "stopped_by": ["cpu"]}
    s = Fit3DSettings(wall_limit=5.0, time_limit=None)
    assert (Ceiling.of(s).time_limit, Ceiling.of(s).wall_limit) == (None, 5.0)
    with pytest.raises(ValueError, match="wall_limit"):
        Fit3DSettings(wall_limit=0.0)


@pytest.mark.parametrize("flags, wall", [([], None), (["--time-limit", "0"], None), (["--time-limit", "300"], 300.0)])
def test_the_command_gives_a_wall_clock_limit_only_when_asked(flags, wall, monkeypatch, tmp_path):
    """``rbrdf-fit brdf --model 3d``: the settings the fit is given (the fit itself replaced by a
    recorder, the file by the synthetic lobe): the CPU-time net always, a wall-clock limit only
    from ``--time-limit``."""
    import fit.formats.rgl as rgl
    from fit.cli import brdf3d, main

    seen = []

    def record(brdf, layouts, *, settings, progress=None):
        seen.append(settings)
        raise RuntimeError("recorded")

    monkeypatch.setattr(rgl, "read_rgl", lambda path: Lobe())
    monkeypatch.setattr(brdf3d, "fit_rgl_select", record)
    src = tmp_path / "lobe.bsdf"
    src.write_bytes(b"")
    rc = main(["brdf", str(src), "--model", "3d", "--out", str(tmp_path / "f.json"), "--no-progress", *flags])
    assert rc == 1 and len(seen) == 1
    s = seen[0]
    assert s.time_limit == DEFAULT_TIME_LIMIT
    if wall is None:
        assert s.wall_limit is None
    else:
        assert 0.9 * wall < s.wall_limit <= wall
