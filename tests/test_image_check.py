"""The fitter's image check (:mod:`fit.rational.image_check`): its CIEDE2000 against published
test pairs and colour-science, the sphere image's geometry under a uniform sky, and that the
ΔE grows with a fit's error."""
from __future__ import annotations

import numpy as np
import pytest

from fit.rational import image_check as IC

#: Sharma, Wu and Dalal (2005), Table 1: (Lab1, Lab2, ΔE00).
SHARMA = [
    ((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
    ((50.0, 3.1571, -77.2803), (50.0, 0.0, -82.7485), 2.8615),
    ((50.0, 2.8361, -74.0200), (50.0, 0.0, -82.7485), 3.4412),
    ((50.0, -1.3802, -84.2814), (50.0, 0.0, -82.7485), 1.0000),
    ((50.0, 2.5, 0.0), (73.0, 25.0, -18.0), 27.1492),
]


@pytest.mark.parametrize("lab1, lab2, expected", SHARMA)
def test_delta_e2000_matches_the_published_pairs(lab1, lab2, expected):
    assert IC.delta_e2000(np.array(lab1), np.array(lab2)) == pytest.approx(expected, abs=1e-4)
    assert IC.delta_e2000(np.array(lab2), np.array(lab1)) == pytest.approx(expected, abs=1e-4)


def test_lab_and_delta_e_match_colour_science():
    colour = pytest.importorskip("colour")
    rng = np.random.default_rng(0)
    a = rng.random((2000, 3)) * 2
    b = np.maximum(a * (1 + 0.2 * rng.standard_normal((2000, 3))), 0)
    cs = colour.RGB_COLOURSPACES["ITU-R BT.709"]

    def lab(x):
        xyz = colour.RGB_to_XYZ(x * 0.7, cs, illuminant=cs.whitepoint, chromatic_adaptation_transform=None,
                                apply_cctf_decoding=False)
        return colour.XYZ_to_Lab(xyz, cs.whitepoint)

    assert np.abs(IC.rgb_to_lab(a, 0.7) - lab(a)).max() < 1e-9
    ref = colour.delta_E(lab(a), lab(b), method="CIE 2000")
    assert np.abs(IC.delta_e2000(IC.rgb_to_lab(a, 0.7), IC.rgb_to_lab(b, 0.7)) - ref).max() < 1e-9


def test_a_lambertian_sphere_under_a_uniform_sky_shows_its_albedo():
    """Radiance 1 from every light direction: each pixel of a Lambertian a / pi is a (the
    cosine-weighted hemisphere is pi), within the light quadrature's error; the frames and the
    horizon test are right or this fails (a wrong normal gives a cosine-dependent image)."""
    views = IC.sphere_views(24)
    dirs, _ = IC.generic_lights(1, 4096)
    L = np.full((len(dirs), 3), 4 * np.pi / len(dirs))
    a = np.array([0.2, 0.5, 0.8])
    img = IC.sphere_image(lambda wi, wo: np.tile(a / np.pi, (len(wi), 1)), dirs, L, views)
    assert np.allclose(img, a[None, :], rtol=0.02)
    assert np.all(views[1][:, 2] > 0)                     # every view above its pixel's horizon


def test_delta_e_is_zero_for_the_truth_and_grows_with_the_error():
    def glossy(wi, wo):
        h = wi + wo
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        return np.array([0.3, 0.5, 0.2])[None, :] / np.pi + 2.0 * h[:, 2:3] ** 40

    assert IC.image_delta_e(glossy, glossy, n=16, k=64)["mean"] == 0.0
    means = [IC.image_delta_e(glossy, lambda wi, wo, s=s: glossy(wi, wo) * s, n=16, k=64)["mean"]
             for s in (1.02, 1.05, 1.2)]
    assert 0 < means[0] < means[1] < means[2]


def test_the_selection_records_the_image_check_of_the_fit_it_keeps():
    """``fit_rgl_select`` stores the kept fit's image check in ``fit_info["image_check"]`` (the
    same numbers as checking that model again), and nothing with ``image_check=False``."""
    from test_fit_determinism import Lobe
    from test_fit3d_target import FIT, LADDER

    from fit.rational.fit3d import fit_rgl_select

    res = fit_rgl_select(Lobe(), variants=LADDER[:1], **FIT)
    rec = res.model.fit_info["image_check"]
    assert rec == IC.image_check(Lobe(), res.model) and rec["mean"] > 0 and rec["p99"] >= rec["mean"]
    off = fit_rgl_select(Lobe(), variants=LADDER[:1], image_check=False, **FIT)
    assert "image_check" not in off.model.fit_info


def test_the_selection_by_image_keeps_the_layout_the_image_check_prefers():
    """``select_by="image"``: every layout's fit is checked (its check in its log entry), the one
    with the lowest ``mean + p99 / 3`` is kept (a later one only when 5 % lower), and a layout may
    fit its own objective; ``"validation"`` logs no checks."""
    from test_fit_determinism import Lobe
    from test_fit3d_target import FIT, LADDER

    from fit.rational.fit3d import fit_rgl_select
    from fit.rational.select3d import SELECT_MARGIN, image_score

    variants = (LADDER[0], dict(LADDER[2], objective="relative"), LADDER[2])
    res = fit_rgl_select(Lobe(), variants=variants, image_check=False, **FIT)        # select_by: image, the default
    log = res.model.fit_info["variants"]
    assert [e["options"].get("objective") for e in log] == [None, "relative", None]
    scores = [image_score(e["image_check"]) for e in log]
    assert [e["validation_score"] for e in log] == scores
    kept = 0
    for k in (1, 2):
        if scores[k] < (1 - SELECT_MARGIN) * scores[kept]:
            kept = k
    assert res.variant == kept and res.model.fit_info["select_by"] == "image"
    assert scores[2] < scores[0]          # the degree-(4, 2) fit looks better than the (2, 1) one
    plain = fit_rgl_select(Lobe(), variants=variants[:1], image_check=False, select_by="validation", **FIT)
    assert "image_check" not in plain.model.fit_info["variants"][0]
    assert plain.model.fit_info["select_by"] == "validation"


def test_the_sun_shows_a_fit_that_misses_the_grazing_light():
    """The RGL data grow as 1 / cos(theta_i) beyond about 80 deg (rho cos theta_i constant); a fit
    without that growth renders the terminator too dark. The check's sun carries most of its light
    (``DEFAULT_SUN``) so that the terminator weighs in its p99 as under the chart's maps: with a
    sky-dominated set (a sun of 40) the same miss looks 2.5 times smaller or less."""
    c80 = np.cos(np.radians(80.0))

    def truth(wi, wo):
        ci = np.clip(wi[:, 2], 1e-4, 1.0)
        return np.repeat((0.3 / np.pi * np.where(ci > c80, 1.0, c80 / ci))[:, None], 3, axis=1)

    def fit(wi, wo):
        return np.full((len(wi), 3), 0.3 / np.pi)

    d, L = IC.generic_lights(1)
    y = L @ np.array([0.2126, 0.7152, 0.0722])
    assert y.max() > 0.75 * y.sum()                  # the sun: most of the light
    assert IC.image_delta_e(truth, truth)["p99"] == 0.0
    sun = IC.image_delta_e(truth, fit)
    sky = IC.image_delta_e(truth, fit, sun=40.0)
    assert sun["sun"] == IC.DEFAULT_SUN and sun["p99"] > 2.5 * sky["p99"] and sun["p99"] > 10.0
