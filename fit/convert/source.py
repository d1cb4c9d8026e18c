"""The evaluable BRDF a conversion starts from: :class:`Source`.

Every source evaluates ``rho(wi_light, wo_view)`` in 1/sr, RGB, *without* the cosine, for
local unit directions of shape ``(..., 3)`` (z = normal), 0 where either direction is at or
below the tangent plane (conventions.md). The readers that make one are
:func:`fit.convert.sources.load_source` (any file by its extension) and
:func:`fit.convert.dense.rational_source` (a rational fit).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass
class Source:
    """A BRDF to convert.

    Attributes
    ----------
    kind : str  ``"merl"``, ``"rgl"`` or ``"rational"``
    name, path, description : str
    evaluate : callable ``(wi, wo) -> (..., 3)``  rho in 1/sr (light ``wi``, view ``wo``)
    reciprocal : bool  ``evaluate(wi, wo) == evaluate(wo, wi)`` by construction
    obj : the object read (``MeasuredBRDF``, ``RGLBRDF`` or a rational model)
    notes : list of str  what the reader did to the data (clamps, domain), for the summary
    evaluate_angles : callable ``(theta_h, theta_d) -> (..., 3)`` or None  for a source that
        is a function of the Rusinkiewicz angles (radians) alone (a rational fit): the same
        rho above the horizon, so that a table is tabulated on 90 x 90 angles, not 1.5 M pairs
    """

    kind: str
    name: str
    path: str
    evaluate: Callable
    reciprocal: bool
    obj: object = None
    description: str = ""
    notes: list = field(default_factory=list)
    evaluate_angles: Callable | None = None
