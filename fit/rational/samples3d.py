"""The data of a 3-D fit (:mod:`fit.rational.fit3d`): where a measured BRDF is sampled, the
second stage's objective points, the per-channel noise levels and the grazing weight of the
error unit. Angles in radians, rows ``(theta_h, theta_d, |phi_d|)``; values rho in 1/sr.
"""
from __future__ import annotations

import itertools

import numpy as np

from ..formats.angles import cos_theta_i_o, cosine_directions, half_diff_to_directions
from .variables3d import half_diff_3d

DEFAULT_GRID = (28, 22, 13)          # theta_h, theta_d, phi_d samples of the data grid
DEFAULT_NOISE_FRAC = 0.01            # noise level: this fraction of a channel's median
DEFAULT_THETA_FIT_DEG = 89.0         # data up to here: the file's own extrapolation beyond its last incidence
DEFAULT_RANDOM = 8000                # random points of each of the two kinds


def sample_grid(theta_max: float, grid=DEFAULT_GRID, n_random: int = DEFAULT_RANDOM, seed: int = 7) -> np.ndarray:
    """``(N, 3)`` physical ``(theta_h, theta_d, |phi_d|)`` (radians) of the data points (module
    docstring of :mod:`fit.rational.fit3d`): the grid, ``n_random`` points uniform in ``(sqrt(theta_h), theta_d, phi_d)`` and
    ``n_random`` pairs of cosine-distributed directions (seeded), all those whose light and view
    directions are both above the horizon and within ``theta_max`` of the normal."""
    nh, nd, npd = (int(g) for g in grid)
    th = theta_max * np.linspace(0.0, 1.0, nh) ** 2
    td = np.linspace(0.0, theta_max, nd)
    pd = np.linspace(0.0, np.pi, npd)
    parts = [np.stack(np.meshgrid(th, td, pd, indexing="ij"), axis=-1).reshape(-1, 3)]
    rng = np.random.default_rng(seed)
    if n_random:
        u = rng.random((n_random, 3))
        parts.append(np.stack([theta_max * u[:, 0] ** 2, theta_max * u[:, 1], np.pi * u[:, 2]], axis=1))
        parts.append(half_diff_3d(cosine_directions(rng, n_random), cosine_directions(rng, n_random)))
    X = np.concatenate(parts)
    wi, wo = half_diff_to_directions(X[:, 0], 0.0, X[:, 1], X[:, 2])
    cmin = np.cos(theta_max) - 1e-9
    keep = (wi[:, 2] >= cmin) & (wo[:, 2] >= cmin) & (wi[:, 2] > 0) & (wo[:, 2] > 0)
    keep &= (X[:, 0] <= theta_max) & (X[:, 1] <= theta_max)
    return X[keep]


#: The second stage's objectives (``Fit3DSettings.objective``): ``"relative"``, the squared
#: relative error of rho (rho floored at the error unit's floor) over pairs of cosine-distributed
#: directions; ``"rho_cos_cos"``, the squared error of ``rho cos theta_i cos theta_o`` (1/sr) over
#: the same pairs (the benchmark's relative RMSE, dominated by the peak).
OBJECTIVES = ("relative", "rho_cos_cos", "blend")


def objective_points(theta_max: float, edges, n_per_piece: int = 4000, seed: int = 21, objective: str = "rho_cos_cos"):
    """``(X (M, 3), w (M,))``: the points and weights of the second stage's objective
    (:data:`OBJECTIVES`) as an importance-weighted sum over pairs of independent
    cosine-distributed directions. Per theta_h piece
    ``[edges[k], edges[k+1]]`` (radians), ``n_per_piece`` points uniform in ``(sqrt(theta_h),
    theta_d, |phi_d|)`` on the piece's box (``theta_d <= theta_max``), weighted by the density of
    cosine-distributed pairs there over the uniform one,

        p(theta_h, theta_d, phi_d) ~ cos theta_i cos theta_o cos theta_d sin theta_d sin theta_h
        (Rusinkiewicz Jacobian 4 cos theta_d sin theta_d sin theta_h, phi_h integrated out),

    times ``(cos theta_i cos theta_o)^2`` for ``"rho_cos_cos"`` (the metric weighs ``rho cos
    cos``); for ``"relative"`` the density alone (the caller divides by the squared floored value
    per channel, :func:`relative_weights`); ``w = 0`` where a direction is below the horizon or
    beyond ``theta_max``. Many points near the peak, where the values are large and cosine pairs
    rare (the peak piece theta_h <= 0.05 holds a few per thousand of them)."""
    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
    rng = np.random.default_rng(seed)
    parts, weights = [], []
    for a, b in itertools.pairwise(edges):
        u = rng.random((int(n_per_piece), 3))
        s0, s1 = np.sqrt(a), np.sqrt(b)
        sq = s0 + (s1 - s0) * u[:, 0]
        X = np.stack([sq ** 2, theta_max * u[:, 1], np.pi * u[:, 2]], axis=1)
        ci, co = cos_theta_i_o(X[:, 0], X[:, 1], X[:, 2])
        cmin = np.cos(theta_max) - 1e-9
        ok = (ci > 0) & (co > 0) & (ci >= cmin) & (co >= cmin)
        vol = (s1 - s0) * theta_max * np.pi
        dens = ci * co * np.cos(X[:, 1]) * np.sin(X[:, 1]) * np.sin(X[:, 0]) * 2.0 * sq * vol
        parts.append(X[ok])
        weights.append((dens * (ci * co) ** 2 if objective == "rho_cos_cos" else dens)[ok])
    return np.concatenate(parts), np.concatenate(weights)


def relative_weights(w, rho, floor, channel_floor: float) -> np.ndarray:
    """``(M, 3)`` weights of the ``"relative"`` objective: the density weights ``w`` ``(M,)`` of
    :func:`objective_points` over the squared floored value ``max(rho_c, floor_c, channel_floor *
    max_c rho)^2`` (``rho`` ``(M, 3)`` and ``floor`` ``(3,)`` in 1/sr): the squared error of rho
    in units of the value, where a value below the floor counts by the floor (a dark channel next
    to a bright one by a share of the bright one, as a colour difference does)."""
    rho = np.maximum(np.asarray(rho, np.float64), 0.0)
    unit = np.maximum(np.maximum(rho, np.asarray(floor, np.float64)[None, :]),
                      channel_floor * rho.max(axis=1, keepdims=True))
    return np.asarray(w, np.float64)[:, None] / np.maximum(unit, 1e-300) ** 2


def objective_weights(objective: str, X, w, rho, floor, channel_floor: float, fw=None) -> np.ndarray:
    """``(M, 3)`` per-channel weights of the squared error of the fitted value at objective points
    ``X`` ``(M, 3)`` with the weights ``w`` of :func:`objective_points` for ``objective`` and values
    ``rho`` ``(M, 3)``: ``"rho_cos_cos"`` ``w`` itself; ``"relative"``
    :func:`relative_weights`; ``"blend"`` the sum of the relative weights and those of ``rho cos
    cos``, each normalised to a unit sum per channel (half the objective each). ``fw`` ``(M,)``
    (default 1): the functions give ``rho / fw`` (:func:`fit.rational.model.value_factor_weights`)
    and ``rho`` holds those values; an error of ``rho cos cos`` is then ``fw`` times theirs, so
    its weights are multiplied by ``fw^2`` (the relative weights are those of the values given,
    floors in their unit)."""
    f2 = 1.0 if fw is None else np.asarray(fw, np.float64) ** 2
    if objective == "rho_cos_cos":
        return np.repeat((np.asarray(w, np.float64) * f2)[:, None], 3, axis=1)
    rel = relative_weights(w, rho, floor, channel_floor)
    if objective == "relative":
        return rel
    ci, co = cos_theta_i_o(X[:, 0], X[:, 1], X[:, 2])
    ab = np.repeat((np.asarray(w, np.float64) * (ci * co) ** 2 * f2)[:, None], 3, axis=1)
    return rel / np.maximum(rel.sum(axis=0), 1e-300) + ab / np.maximum(ab.sum(axis=0), 1e-300)


def noise_levels(rho, noise_frac: float = DEFAULT_NOISE_FRAC) -> np.ndarray:
    """Per channel the noise level ``n_c`` (1/sr) of data ``rho`` ``(N, 3)``: the larger of
    ``noise_frac * median(rho_c)`` and, where a fraction ``z`` of the values are 0 (negative
    measurements clamped: values within the noise of 0), the ``min(2 z, 0.5)`` quantile of the
    channel (vch_golden_yellow's blue: 8.5 % zeros next to a peak of 364 /sr; with the 1 % floor
    alone its fit went to 0 over the dark region and its bound was 100 % everywhere)."""
    rho = np.asarray(rho, np.float64)
    noise = noise_frac * np.median(rho, axis=0)
    z = np.mean(rho <= 0.0, axis=0)
    for c in range(rho.shape[1]):
        if z[c] > 0:
            noise[c] = max(noise[c], float(np.quantile(rho[:, c], min(2.0 * z[c], 0.5))))
    return np.maximum(noise, 1e-12)


def grazing_weight(X, grazing_cos: float) -> np.ndarray:
    """``g = max(1, grazing_cos / (cos theta_i cos theta_o))`` of rows ``(theta_h, theta_d,
    |phi_d|)`` ``(N, 3)``: 1 (a relative bound on rho) where the product of the cosines is at least
    ``grazing_cos``, beyond it a bound on ``rho cos theta_i cos theta_o`` (:mod:`fit.rational.fit3d`);
    ``grazing_cos = 0``: 1 everywhere."""
    ci, co = cos_theta_i_o(X[:, 0], X[:, 1], X[:, 2])
    return np.maximum(1.0, grazing_cos / np.maximum(ci * co, 1e-6))


def sample_rgl(brdf, grid=DEFAULT_GRID, n_random: int = DEFAULT_RANDOM, theta_fit_deg: float = DEFAULT_THETA_FIT_DEG):
    """``(X (N, 3), rho (N, 3), theta_fit)``: the data of a 3-D fit of an
    :class:`fit.formats.rgl.RGLBRDF` (its reference evaluation, light = ``wi``, negatives 0) up
    to ``theta_fit`` = the larger of ``theta_fit_deg`` and its last measured incidence
    (:mod:`fit.rational.fit3d`)."""
    theta_max = max(float(brdf.theta_i_max), float(np.radians(theta_fit_deg)))
    X = sample_grid(theta_max, grid, n_random)
    wi, wo = half_diff_to_directions(X[:, 0], 0.0, X[:, 1], X[:, 2])
    rho = np.maximum(np.asarray(brdf.evaluate(wi, wo), np.float64), 0.0)
    return X, rho, theta_max
