"""Log-value intervals and the secant weights of the 3-D fits' second stage.

The 3-D fits (:mod:`fit.rational.fit3d`) and their albedo policy (:mod:`fit.rational.albedo3d`)
fit ``log(rho + offset)``: a bound ``rho +- tol * scale`` on the value is an interval of the log
value (:func:`log_intervals`), and the squared error of the value is the squared log residual
times the secant slope of ``exp`` squared (:func:`secant_slope`, :func:`secant_weights`), the
weights of :func:`fit.rational.refine.refine`'s Sanathanan-Koerner iteration.
"""
from __future__ import annotations

import numpy as np


def log_intervals(y, scale, offset: float, tol: float) -> tuple:
    """``(lower, upper)`` of ``log(value + offset)`` for values ``y`` (1/sr, ``(N,)``) within
    ``y +- tol * scale`` (``scale`` the per-point error unit, 1/sr), the lower value clamped at 0:
    ``[log(max(y - tol s, 0) + offset), log(y + tol s + offset)]``."""
    e = tol * scale
    return np.log(np.maximum(y - e, 0.0) + offset), np.log(y + e + offset)


def secant_slope(R, t):
    """The secant slope ``(exp(R) - exp(t)) / (R - t)`` of ``exp`` (``exp(t)`` where ``R`` is
    within 1e-6 of ``t``): the value's error per unit of log error."""
    d = R - t
    small = np.abs(d) < 1e-6
    return np.where(small, np.exp(t), (np.exp(np.clip(R, None, 50.0)) - np.exp(t)) / np.where(small, 1.0, d))


def secant_weights(base):
    """``reweight(R, t)`` for :func:`fit.rational.refine.refine` on log values: the squared
    error of the value ``exp(R) - offset`` is ``((exp(R) - exp(t)) / (R - t))^2 (R - t)^2``, so
    the weight of the squared log residual is ``base`` times that secant slope squared (the value
    squared where ``R`` is within 1e-6 of ``t``)."""
    def reweight(R, t):
        return base * secant_slope(R, t) ** 2
    return reweight
