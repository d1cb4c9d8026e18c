"""``benchmarks/bench_error_sources.py`` on cases with a known answer: an exact quadrature of the
chart's sphere, and the worst pixels' error split by the light's angle; its numbers on the RGL
fits are docs/fit_accuracy.md's."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks import bench_error_sources as B

pytestmark = pytest.mark.lab  # tests lab code only (the `lab` marker of pyproject.toml)


class Lambert:
    def __init__(self, albedo=(0.6, 0.5, 0.4)):
        self.rho = np.asarray(albedo) / np.pi

    def evaluate(self, wi, wo):
        return np.broadcast_to(self.rho, np.shape(wi)[:-1] + (3,)).copy()


def small_map(sun=True):
    """A 64 x 32 sky brighter upwards, with one bright texel (the sun) at 20 deg elevation."""
    H, W = 32, 64
    v = (np.arange(H) + 0.5) / H
    img = np.repeat((0.2 + 0.8 * np.clip(np.cos(np.pi * v), 0, 1))[:, None, None], W, axis=1) * np.ones(3)
    if sun:
        img[int(0.39 * H), int(0.45 * W)] = 2000.0
    return img


def test_block_map_keeps_power():
    img = small_map()
    for block in (1, 4):
        d, p = B.block_map(img, block)
        assert np.allclose(np.linalg.norm(d, axis=1), 1)
        # the power of a constant map is its radiance times 4 pi (midpoint rule in theta: 1e-2)
        _, pc = B.block_map(np.ones_like(img), block)
        assert abs(pc[:, 0].sum() / (4 * np.pi) - 1) < 1e-2
    _, p1 = B.block_map(img, 1)
    _, p4 = B.block_map(img, 4)
    np.testing.assert_allclose(p4.sum(0), p1.sum(0), rtol=1e-12)    # blocks keep the sin-weighted power
    with pytest.raises(ValueError):
        B.block_map(img, 5)


def test_identical_fit_has_no_error_and_a_known_lambert_image():
    dirs, power = B.block_map(small_map(sun=False), 1)
    r = B.error_sources(Lambert(), Lambert().evaluate, dirs, power, res=24)
    assert r["pixels"] > 100 and r["de_mean"] == 0 and r["de_p99"] == 0


def test_error_from_grazing_light_is_attributed_to_it():
    dirs, power = B.block_map(small_map(), 1)
    truth = Lambert()

    def fit(wi, wo):       # the truth, halved where the light is beyond 85 deg of the normal
        return truth.evaluate(wi, wo) * np.where(wi[:, 2:3] < np.cos(np.radians(85)), 0.5, 1.0)

    r = B.error_sources(truth, fit, dirs, power, res=32)
    w = r["worst"]
    assert r["de_p99"] > 0
    assert w["error_share_theta_i_gt_85"] == pytest.approx(1.0) and w["error_share_theta_i_gt_80"] == pytest.approx(1.0)
    assert w["fit_over_truth"] < 1

    def fit_front(wi, wo):  # the error only from light within 60 deg: none of it from grazing light
        return truth.evaluate(wi, wo) * np.where(wi[:, 2:3] > 0.5, 0.9, 1.0)

    w = B.error_sources(truth, fit_front, dirs, power, res=32)["worst"]
    assert w["error_share_theta_i_gt_80"] == pytest.approx(0.0) and w["error_share_theta_i_gt_85"] == pytest.approx(0.0)
