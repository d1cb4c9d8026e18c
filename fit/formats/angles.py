"""Direction <-> Rusinkiewicz half/difference angle conversions (vectorized NumPy).

Conventions (``../shared/design/conventions.md``): local shading frame with z = normal,
x = tangent, y = bitangent; directions are unit vectors pointing *away* from the surface
(``wi`` towards the light, ``wo`` towards the viewer). All angles are in radians.

* ``h = normalize(wi + wo)``, ``theta_h = acos(h.z)``, ``phi_h = atan2(h.y, h.x)``.
* ``d`` = ``wi`` rotated by ``-phi_h`` about z, then by ``-theta_h`` about y;
  ``theta_d = acos(d.z)``, ``phi_d = atan2(d.y, d.x)``.

Degenerate cases: when ``theta_h ~ 0`` the half vector is the normal and ``phi_h`` is
arbitrary (0 is returned; the result for ``d`` is still exact because the rotation about z
and the rotation about y by 0 commute with the choice). When ``theta_d ~ 0`` (wi == wo),
``phi_d`` is arbitrary (``atan2(0, 0) = 0``). When ``wi ~ -wo`` the half vector is
undefined; the normal is used in its place and ``theta_d = pi/2`` results.

Arrays: directions have shape ``(..., 3)``; angle arrays have shape ``(...)``.
"""
from __future__ import annotations

import numpy as np

#: pi / 2 in radians: the largest polar angle of the upper hemisphere. The one definition of
#: this constant in the fit package; every module takes it from here.
HALF_PI = 0.5 * np.pi
_EPS = 1e-12


def cosine_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    """``(n, 3)`` unit directions distributed as cos(theta) over the upper hemisphere (z = normal,
    float64), from two draws of ``rng``: ``u`` then ``v``, ``r = sqrt(u)``, ``phi = 2 pi v``."""
    u, v = rng.random(n), rng.random(n)
    r, p = np.sqrt(u), 2 * np.pi * v
    return np.stack([r * np.cos(p), r * np.sin(p), np.sqrt(np.maximum(1 - u, 0))], -1)


def _normalize(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, _EPS)


def spherical_to_direction(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit vector(s) ``(sin t cos p, sin t sin p, cos t)``; shape ``broadcast(theta, phi) + (3,)``."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def direction_to_spherical(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(theta, phi)`` of unit vector(s) ``v`` (shape ``(..., 3)``); phi in (-pi, pi]."""
    v = np.asarray(v, float)
    # atan2 keeps full precision near the poles, where acos loses half the digits.
    theta = np.arctan2(np.hypot(v[..., 0], v[..., 1]), v[..., 2])
    phi = np.arctan2(v[..., 1], v[..., 0])
    return theta, phi


def _rotate_z(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x - s * y, s * x + c * y, z], axis=-1)


def _rotate_y(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x + s * z, y, -s * x + c * z], axis=-1)


def directions_to_half_diff(wi: np.ndarray, wo: np.ndarray):
    """Convert direction pairs to Rusinkiewicz angles.

    Parameters
    ----------
    wi, wo : arrays of shape ``(..., 3)``, unit vectors (light, view), broadcastable.

    Returns
    -------
    theta_h, phi_h, theta_d, phi_d : arrays of shape ``(...)`` in radians;
    ``theta_h`` in [0, pi], ``theta_d`` in [0, pi/2] for upper-hemisphere pairs,
    ``phi_h`` and ``phi_d`` in (-pi, pi].
    """
    wi = np.asarray(wi, float)
    wo = np.asarray(wo, float)
    wi, wo = np.broadcast_arrays(wi, wo)
    s = wi + wo
    norm = np.linalg.norm(s, axis=-1, keepdims=True)
    normal = np.zeros_like(s)
    normal[..., 2] = 1.0
    h = np.where(norm > 1e-9, s / np.maximum(norm, _EPS), normal)
    theta_h, phi_h = direction_to_spherical(h)
    # For theta_h ~ 0 the azimuth of h is meaningless: fix it to 0 so that d stays continuous.
    phi_h = np.where(np.hypot(h[..., 0], h[..., 1]) < 1e-12, 0.0, phi_h)
    d = _rotate_y(_rotate_z(wi, -phi_h), -theta_h)
    theta_d, phi_d = direction_to_spherical(_normalize(d))
    phi_d = np.where(np.hypot(d[..., 0], d[..., 1]) < 1e-12, 0.0, phi_d)
    return theta_h, phi_h, theta_d, phi_d


def half_diff_to_directions(theta_h, phi_h, theta_d, phi_d):
    """Inverse of :func:`directions_to_half_diff`.

    Returns ``(wi, wo)``, unit vectors of shape ``broadcast(...) + (3,)``.
    ``wo`` is the mirror of ``wi`` about the half vector: ``wo = 2 (wi.h) h - wi``.
    """
    d = spherical_to_direction(theta_d, phi_d)
    th, ph = np.broadcast_arrays(np.asarray(theta_h, float), np.asarray(phi_h, float))
    shape = np.broadcast_shapes(th.shape, d.shape[:-1])
    d = np.broadcast_to(d, shape + (3,))
    th = np.broadcast_to(th, shape)
    ph = np.broadcast_to(ph, shape)
    wi = _rotate_z(_rotate_y(d, th), ph)
    h = spherical_to_direction(th, ph)
    wo = 2.0 * np.sum(wi * h, axis=-1, keepdims=True) * h - wi
    return wi, wo


def above_horizon(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """True where both directions are strictly above the tangent plane (z > 0); directions
    ``(..., 3)``, result ``(...)`` bool."""
    return (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)


def cos_theta_i_o(theta_h, theta_d, phi_d):
    """Closed-form ``(cos theta_i, cos theta_o)`` for given half/difference angles.

    ``cos theta_i = cos th cos td - sin th sin td cos pd`` and
    ``cos theta_o = cos th cos td + sin th sin td cos pd``. Independent of ``phi_h``
    (isotropy); used to decide which (theta_h, theta_d, phi_d) triplets put the light or
    the view below the tangent plane.
    """
    th, td, pd = (np.asarray(a, float) for a in (theta_h, theta_d, phi_d))
    a = np.cos(th) * np.cos(td)
    b = np.sin(th) * np.sin(td) * np.cos(pd)
    return a - b, a + b
