"""The fit settings objects (:mod:`fit.rational.settings`), scikit-learn style:

* the contract of every settings class: ``get_params()`` is a plain dict that round-trips
  through the constructor, ``set_params`` / ``clone`` change what they are told after checking
  the whole combination, an unknown name is a ``TypeError`` and an invalid value a
  ``ValueError``, both one line naming the setting, and a failed ``set_params`` changes nothing;
  the same construction gives the same object;
* the fit entry points take ``settings=`` and keep their keyword arguments as overrides: a small
  deterministic 3-D fit gives the same coefficients, bit for bit, either way (old-style keyword
  arguments against a settings object, in the same run);
* what a 3-D fit made travels in the result's attributes, never in private dictionary keys, and
  ``albedo3d`` no longer imports ``fit3d`` (the secant and interval helpers are public in
  :mod:`fit.rational.secant`);
* ``rbrdf-fit brdf``'s defaults and the studies' fit settings are the settings object's.
"""
from __future__ import annotations

import ast
import inspect
from pathlib import Path

import numpy as np
import pytest

from fit.rational.settings import BRDFFitSettings, Fit3DSettings

ROOT = Path(__file__).resolve().parents[1]

INVALID = {
    BRDFFitSettings: [("tol", 0.0), ("tol", float("nan")), ("max_degree", 2.5), ("max_degree", -1),
                      ("max_den_degree", 99), ("intervals", "spread"), ("band_intervals", None),
                      ("core_theta_d_deg", 1.0), ("core_theta_d_deg", "all"), ("band_partial", (2.0, 1.0)),
                      ("peak_split_deg", 95.0), ("max_theta_h_pieces", 1), ("max_theta_h_pieces", 2.5), ("theta_h_transform", "cube"),
                      ("value_transform", "exp"),
                      ("floor_frac", -1.0), ("spread_k", float("inf"))],
    Fit3DSettings: [("tol", -1.0), ("degrees", (7,)), ("degrees", (7, "3")), ("theta_h_edges", [-0.1]),
                    ("piece_degrees", [(4, 2)] * 3), ("noise_frac", 0.0), ("grazing_cos", 2.0),
                    ("relax", float("nan")), ("ladder_steps", 0), ("time_limit", 0.0), ("grid", (0, 1, 1)),
                    ("n_random", -5), ("theta_fit_deg", 90.0), ("verify", 1.5), ("albedo", "yes"),
                    ("albedo_tol", 0.0), ("albedo_refits", -1), ("select_share", 0.0), ("max_variants", -1),
                    ("objective", "log"), ("relative_floor", -0.5)],
}
CHANGES = {BRDFFitSettings: {"tol": 0.1, "max_degree": 8, "core_theta_d_deg": 60.0, "band_partial": None},
           Fit3DSettings: {"tol": 0.01, "theta_h_edges": [0.15], "piece_degrees": [(4, 2), (5, 2)],
                           "albedo": False, "time_limit": None}}


@pytest.mark.parametrize("cls", [BRDFFitSettings, Fit3DSettings])
def test_get_params_round_trips_and_is_deterministic(cls):
    s = cls(**CHANGES[cls])
    p = s.get_params()
    assert type(p) is dict and list(p) == [f for f in cls.__dataclass_fields__]
    assert cls(**p) == s and cls(**p).get_params() == p
    assert s.changed_params() == CHANGES[cls]
    assert cls() == cls() and repr(cls()) == repr(cls()) and cls().changed_params() == {}
    c = s.clone(tol=0.2)
    assert c.tol == 0.2 and s.tol == CHANGES[cls]["tol"] and c.get_params() == dict(p, tol=0.2)
    assert s.set_params(tol=0.2) is s and s == c


@pytest.mark.parametrize("cls", [BRDFFitSettings, Fit3DSettings])
def test_unknown_names_are_one_line_type_errors(cls):
    s = cls()
    for call in (lambda: s.set_params(tolerance=0.1), lambda: s.clone(tolerance=0.1),
                 lambda: cls.resolve(None, tolerance=0.1)):
        with pytest.raises(TypeError) as e:
            call()
        assert "tolerance" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(TypeError):
        cls(tolerance=0.1)
    with pytest.raises(TypeError, match="settings must be"):
        cls.resolve({"tol": 0.1})
    assert s == cls()


@pytest.mark.parametrize("cls", [BRDFFitSettings, Fit3DSettings])
def test_invalid_values_are_one_line_value_errors_and_change_nothing(cls):
    for name, value in INVALID[cls]:
        with pytest.raises(ValueError) as e:
            cls(**{name: value})
        msg = str(e.value)
        assert msg.startswith(f"{name} must be ") and "\n" not in msg, msg
        s = cls()
        with pytest.raises(ValueError):
            s.set_params(**{name: value})
        assert s == cls(), name                      # a failed set_params leaves it as it was
        setattr(s, name, value)                      # a direct assignment is caught at the fit
        with pytest.raises(ValueError):
            cls.resolve(s)


def test_entry_points_take_settings_and_reject_unknown_keywords():
    from fit.rational.brdf_fit import fit_brdf
    from fit.rational.fit3d import fit_rgl, fit_rgl_select, fit_samples

    for f in (fit_brdf, fit_samples, fit_rgl, fit_rgl_select):
        assert "settings" in inspect.signature(f).parameters, f.__name__
    X = np.zeros((4, 3))
    with pytest.raises(TypeError, match="tolerance"):
        fit_samples(X, X, tolerance=0.1)
    with pytest.raises(TypeError, match="tolerance"):
        fit_brdf(None, tolerance=0.1)                # checked before the BRDF is touched
    with pytest.raises(ValueError, match="^tol must be"):
        fit_brdf(None, BRDFFitSettings(), tol=5.0)


def _coefficients(model):
    pieces = list(model.pieces) if hasattr(model, "pieces") else [model]
    return np.concatenate([np.concatenate([f.num_coef, f.den_coef]) for p in pieces for f in p.functions])


def test_settings_object_and_keywords_give_the_same_3d_fit_bit_for_bit():
    """A small two-stage fit (two pieces, objective points), once with the keyword arguments the
    3-D API always took and once with a settings object: the same coefficients, records and
    stated bound; the result carries its settings."""
    from fit.rational.fit3d import fit_samples, objective_points, sample_grid
    from test_fit3d import lobe

    tm = np.radians(80.0)
    X = sample_grid(tm, grid=(7, 6, 5), n_random=120, seed=3)
    Xo, wo = objective_points(tm, [0.0, 0.2, tm], 300)
    obj = (Xo, lobe(Xo), wo)
    kw = dict(degrees=(3, 1), theta_h_edges=[0.2], tol=0.02, time_limit=None, grazing_cos=0.1)
    old = fit_samples(X, lobe(X), name="lobe3d", theta_max=tm, objective=obj, **kw)
    s = Fit3DSettings(**kw)
    new = fit_samples(X, lobe(X), settings=s, name="lobe3d", theta_max=tm, objective=obj)
    assert np.array_equal(_coefficients(old.model), _coefficients(new.model))
    assert old.tolerance == new.tolerance and [r["stage"]["kind"] for r in new.records] == ["two-stage"] * 6
    assert new.settings == s == old.settings and s.get_params() == Fit3DSettings(**kw).get_params()
    # an override on top of a settings object wins, and the object itself is not changed
    other = fit_samples(X, lobe(X), settings=s, name="lobe3d", theta_max=tm, objective=obj, degrees=(2, 1))
    assert other.settings.degrees == (2, 1) and s.degrees == (3, 1)
    assert other.model.n_coefficients < new.model.n_coefficients


def test_fit_state_is_in_attributes_not_private_keys():
    """fit_rgl's data, objective and last fresh points are attributes of the result (what the
    verification and the albedo policy read), and no ``info`` key is private."""
    from fit.rational.fit3d import FitData3D, fit_rgl
    from test_albedo3d import Synthetic

    s = Fit3DSettings(grid=(6, 5, 4), n_random=80, n_objective=300, verify=200, verify_rounds=1,
                      degrees=(3, 1), theta_h_edges=[0.15], tol=0.02, albedo=False, time_limit=None)
    res = fit_rgl(Synthetic(), settings=s)
    assert not [k for k in res.info if k.startswith("_")], list(res.info)
    assert isinstance(res.data, FitData3D) and len(res.data.X) == len(res.data.rho) >= res.n_points
    assert res.data.objective is not None and res.data.name == "glossy_lobe_3d"
    Xv, rv = res.verify_points
    assert len(Xv) == len(rv) > 0 and res.model.fit_info["verify_points"] == 200
    assert res.settings.get_params() == s.get_params()


def test_albedo3d_does_not_import_fit3d():
    """The import circle is gone: albedo3d imports neither fit3d nor any private name."""
    tree = ast.parse((ROOT / "fit/rational/albedo3d.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            assert node.module != "fit3d" and not (node.module or "").endswith(".fit3d"), node.module
            assert not [a.name for a in node.names if a.name.startswith("_")], node.module
    from fit.rational import secant

    assert {"log_intervals", "secant_slope", "secant_weights"} <= set(dir(secant))
    lo, hi = secant.log_intervals(np.array([1.0, 0.01]), np.array([1.0, 1.0]), 0.5, 0.1)
    assert np.allclose(np.exp(lo) - 0.5, [0.9, 0.0]) and np.allclose(np.exp(hi) - 0.5, [1.1, 0.11])


def test_cli_and_studies_use_the_settings_object(monkeypatch):
    """``rbrdf-fit brdf`` without flags builds the default settings; the studies fit with the
    same object (their fit_material hands fit_brdf a BRDFFitSettings with the study's tolerance)."""
    from fit.cli import build_parser
    from fit.cli.brdf import settings_from_args
    from studies import fits as F

    a = build_parser().parse_args(["brdf", "x.binary", "--out", "x.json"])
    assert settings_from_args(a) == BRDFFitSettings()
    a = build_parser().parse_args(["brdf", "x.binary", "--out", "x.json", "--tol", "0.1", "--max-degree", "8"])
    assert settings_from_args(a) == BRDFFitSettings(tol=0.1, max_degree=8)
    assert F.FIT_SETTINGS == BRDFFitSettings()
    seen = []
    monkeypatch.setattr("fit.rational.brdf_fit.fit_brdf", lambda b, settings=None, **kw: seen.append(settings))
    monkeypatch.setattr("fit.formats.load_measured", lambda path: path)
    F.fit_material(str(ROOT / "x.binary"), 0.1, band_intervals="tol+spread")
    assert seen == [BRDFFitSettings(tol=0.1, band_intervals="tol+spread")]


def test_3d_objective_flag_sets_the_objective_and_refuses_others(capsys):
    """``rbrdf-fit brdf FILE --objective relative`` fits the relative objective (the setting of
    :class:`Fit3DSettings`); without it the default; an unknown objective is refused by the
    parser (exit 2, the flag named) before any file is read (tests/test_cli_fit.py: refused with a
    MERL file, whose fit is 2-D)."""
    from fit.cli import build_parser
    from fit.cli.brdf3d import given, settings_from_args

    p = build_parser()
    a = p.parse_args(["brdf", "x.bsdf", "--out", "x.json"])
    assert settings_from_args(a)[0].objective == Fit3DSettings().objective == "rho_cos_cos"
    a = p.parse_args(["brdf", "x.bsdf", "--out", "x.json", "--objective", "relative"])
    s, layouts = settings_from_args(a)
    assert s.objective == "relative" and s.clone(objective="rho_cos_cos") == settings_from_args(
        p.parse_args(["brdf", "x.bsdf", "--out", "x.json"]))[0]
    assert "--objective" in given(a)
    with pytest.raises(SystemExit) as e:
        p.parse_args(["brdf", "x.bsdf", "--out", "x.json", "--objective", "rmse"])
    assert e.value.code == 2 and "--objective" in capsys.readouterr().err


def test_3d_select_by_flag_sets_what_the_selection_compares(capsys):
    """``rbrdf-fit brdf FILE --select-by image`` selects the layout by the image check (the setting
    ``select_by``); without it the default; an unknown value is refused by the parser (exit 2)."""
    from fit.cli import build_parser
    from fit.cli.brdf3d import given, settings_from_args

    p = build_parser()
    a = p.parse_args(["brdf", "x.bsdf", "--out", "x.json"])
    assert settings_from_args(a)[0].select_by == Fit3DSettings().select_by
    a = p.parse_args(["brdf", "x.bsdf", "--out", "x.json", "--select-by", "image"])
    assert settings_from_args(a)[0].select_by == "image" and "--select-by" in given(a)
    a = p.parse_args(["brdf", "x.bsdf", "--out", "x.json", "--select-by", "validation"])
    assert settings_from_args(a)[0].select_by == "validation"
    with pytest.raises(SystemExit) as e:
        p.parse_args(["brdf", "x.bsdf", "--out", "x.json", "--select-by", "rmse"])
    assert e.value.code == 2 and "--select-by" in capsys.readouterr().err
