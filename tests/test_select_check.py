"""The layout selection checks each layout as it will be written (fit/rational/select3d.py,
docs/fit_accuracy.md "Checking verified fits"): a layout is verified before its image check; a
``"check_unverified"`` layout is checked first and verified only when it is kept; the
proof-guided refit is the kept layout's only. Spies on the selection's steps record their order."""
from __future__ import annotations

import pytest

from conftest import data_file


@pytest.fixture(scope="module")
def paper_white():
    from fit.formats.rgl import read_rgl

    return read_rgl(data_file("rgl/paper_white_rgb.bsdf"))


def _spy_steps(monkeypatch):
    from fit.rational import select3d

    events: list = []
    for name, tag in (("fit_rgl", "fit"), ("verify_and_refit", "verify"), ("image_check", "check"),
                      ("refit_between_nodes", "proof")):
        real = getattr(select3d, name)

        def spy(*args, _real=real, _tag=tag, **kwargs):
            events.append(_tag)
            return _real(*args, **kwargs)

        monkeypatch.setattr(select3d, name, spy)
    return events


SMALL = {"theta_h_edges": [], "degrees": (3, 1)}
SMALL_PIECES = {"theta_h_edges": [0.2], "piece_degrees": [(3, 1), (3, 1)]}


def test_each_layout_is_verified_before_its_check(monkeypatch, paper_white):
    from fit.rational.select3d import fit_rgl_select

    events = _spy_steps(monkeypatch)
    res = fit_rgl_select(paper_white, variants=[SMALL, SMALL_PIECES], verify=2000, verify_rounds=1,
                         proof_rounds=1, albedo=False, prove_bound=False)
    # every layout: fit, verification, check; then the kept one's proof-guided refit and its final check
    assert events[:6] == ["fit", "verify", "check", "fit", "verify", "check"]
    assert events[6:].count("verify") == 0 and events[6] == "proof"
    log = res.model.fit_info["variants"]
    assert [v["checked"] for v in log] == ["verified", "verified"]


def test_a_check_unverified_layout_is_verified_only_when_kept(monkeypatch, paper_white):
    from fit.rational.select3d import fit_rgl_select

    events = _spy_steps(monkeypatch)
    res = fit_rgl_select(paper_white, variants=[dict(SMALL, check_unverified=True)], verify=2000,
                         verify_rounds=1, proof_rounds=0, albedo=False, prove_bound=False)
    assert events[:3] == ["fit", "check", "verify"]          # checked, kept, then verified
    assert res.model.fit_info["variants"][0]["checked"] == "before verification"
    assert "check_unverified" not in res.model.fit_info["variants"][0]["options"]


def test_the_dial_verifies_the_kept_layout_only(monkeypatch, paper_white):
    from fit.rational.select3d import fit_rgl_select

    events = _spy_steps(monkeypatch)
    fit_rgl_select(paper_white, variants=[SMALL, SMALL_PIECES], target_rmse=1.0, verify=2000, verify_rounds=1,
                   proof_rounds=0, albedo=False, prove_bound=False)
    assert events.count("verify") == 1 and events.index("verify") > events.index("fit")
