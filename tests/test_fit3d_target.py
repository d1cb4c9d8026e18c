"""The coefficient count as the dial (``Fit3DSettings.target_rmse``, ``rbrdf-fit brdf --target-rmse``):
layouts tried cheapest first, the first within the target kept, the later ones skipped; none
within it: the lowest validation RMSE kept and the file says the target was not met."""
from __future__ import annotations

import pytest
from test_fit_determinism import Lobe

from fit.rational.fit3d import TARGET_LADDER, VARIANTS, fit_rgl_select
from fit.rational.settings import Fit3DSettings

#: three one-piece layouts, cheapest first (small data: the rule, not the accuracy, is tested)
LADDER = tuple({"theta_h_edges": [], "degrees": d} for d in ((2, 1), (3, 1), (4, 2)))
FIT = {"grid": (9, 8, 6), "n_random": 300, "n_objective": 800, "tol": 0.01, "verify": 0, "albedo": False,
       "time_limit": None}


@pytest.fixture(scope="module")
def untargeted():
    """Every layout fitted (a target nothing meets): their validation RMSEs and coefficients."""
    res = fit_rgl_select(Lobe(), variants=LADDER, target_rmse=1e-9, **FIT)
    return res


def test_nothing_within_the_target_keeps_the_lowest(untargeted):
    log = untargeted.variants
    assert [v.get("skipped") for v in log] == [None, None, None]
    rmse = [v["validation_rmse"] for v in log]
    assert untargeted.variant == min(range(3), key=rmse.__getitem__)
    t = untargeted.model.fit_info["target"]
    assert t == {"rmse": 1e-9, "met": False, "coefficients": untargeted.n_coefficients}


def test_the_first_layout_within_the_target_is_kept_and_the_rest_skipped(untargeted):
    rmse = [v["validation_rmse"] for v in untargeted.variants]
    coefs = [v["coefficients"] for v in untargeted.variants]
    assert coefs == sorted(coefs) and rmse[1] < rmse[0], rmse     # the ladder buys accuracy
    target = (rmse[0] + rmse[1]) / 2           # the second layout meets it, the first does not
    res = fit_rgl_select(Lobe(), variants=LADDER, target_rmse=target, **FIT)
    assert res.variant == 1 and res.n_coefficients == coefs[1]
    assert res.validation_rmse == pytest.approx(rmse[1], rel=1e-12)      # the same fit: deterministic
    assert res.variants[2]["skipped"] == f"target RMSE {target:g} met"
    assert res.model.fit_info["target"] == {"rmse": target, "met": True, "coefficients": coefs[1]}
    first = fit_rgl_select(Lobe(), variants=LADDER, target_rmse=10.0, **FIT)   # any fit meets it
    assert first.variant == 0 and [v.get("skipped") for v in first.variants][1:] == ["target RMSE 10 met"] * 2


def test_the_file_records_its_grid_after_a_refit():
    """A selected fit whose verification refits it (a new model) still records the data grid its
    proof was made on: a proof read back from the file uses it (without it, the default grid)."""
    res = fit_rgl_select(Lobe(), variants=LADDER[:1], **dict(FIT, verify=4000))
    assert res.model.fit_info["verify_refitted"]            # the case: the model was replaced
    assert res.model.fit_info["grid"] == list(FIT["grid"])


def test_default_ladder_and_settings():
    assert [len(v["theta_h_edges"]) for v in TARGET_LADDER] == [0, 0, 0, 0, 0, 6]
    assert TARGET_LADDER[-1] == VARIANTS[0]
    assert Fit3DSettings().target_rmse is None
    for bad in (0.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="target_rmse"):
            Fit3DSettings(target_rmse=bad)


def test_cli_refuses_a_target_with_a_fixed_layout(tmp_path, capsys):
    from fit.cli import main

    out = tmp_path / "x.json"
    code = main(["brdf", str(tmp_path / "missing.bsdf"), "--model", "3d", "--layout", "pieces",
                 "--target-rmse", "0.05", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--target-rmse" in err[0], err
    assert not out.exists()
