"""What a 3-D fit is made of and what it records: :class:`Fit3D` (the result, everything a fit
finds in its attributes), :class:`FitData3D` (what a refit of it needs), :data:`INTERVALS` (the
interval policy, written into every record), :func:`file_value_range` (the value range a coefficient
file holds, given to the model the proof reads) and :func:`domain_record` (the coefficient file's
statement of what is proved on the whole measured domain). The method is in
docs/fitting.md ("The 3-D method").
"""
from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from .settings import Fit3DSettings

#: The interval of every data point of a 3-D fit (the error unit ``s`` of docs/fitting.md,
#: "Intervals and the bound"), as the records state it.
INTERVALS = ("rho_c +- tolerance * max(rho_c, noise_c, channel_floor * max(rho_R, rho_G, rho_B)) "
             "* max(1, grazing_cos / (cos theta_i cos theta_o))")


@dataclass
class FitData3D:
    """What a refit of a fit made by :func:`fit.rational.rgl3d.fit_rgl` needs
    (:func:`fit.rational.verify3d.verify_and_refit`, the albedo policy of
    :mod:`fit.rational.albedo3d`): the data ``X`` ``(N, 3)`` (theta_h, theta_d, |phi_d|,
    radians) and ``rho`` ``(N, 3)`` (1/sr), ``theta_max`` (radians), the ``source`` record, the
    second stage's ``objective`` (``(Xo (M, 3), rho_o (M, 3), w (M,))`` or None), the model's
    ``name`` and the ``progress`` callback."""

    X: np.ndarray
    rho: np.ndarray
    theta_max: float
    source: dict
    objective: tuple | None = None
    name: str = "brdf3d"
    progress: object = None


@dataclass
class Fit3D:
    """A 3-D fit.

    What it is: ``model`` (evaluate with :func:`fit.rational.variables3d.evaluate_directions`),
    ``records`` (per piece and channel: degrees, stated tolerance, LP rounds, seconds; the same
    dicts as the model's function records), ``tolerance`` (the largest stated tolerance: every
    data point is within it), ``valid``, ``time_s`` (s), ``n_points``, ``noise`` (per channel,
    1/sr), ``edges`` (the theta_h piece edges, radians, from 0 to ``theta_max``).

    What made it and what a refit needs: ``settings``
    (:class:`fit.rational.settings.Fit3DSettings`), ``data`` (:class:`FitData3D`; None after
    :func:`fit.rational.select3d.fit_rgl_select`), ``verify_points`` (``(X, rho)`` of the last
    verification's fresh points).

    What the steps after the fit found (None where the step did not run): the verification
    (:mod:`fit.rational.verify3d`): ``verify_round`` (the last round), ``verify_max_ratio``
    (largest error over the stated bound at its fresh points), ``verified`` (<= 1),
    ``verify_points_added``, ``verify_s`` (s); the albedo policy (:mod:`fit.rational.albedo3d`):
    ``albedo`` (its record, also ``model.fit_info["albedo"]``), ``model_before_albedo`` (a copy
    of the model it started from); the layout selection (:mod:`fit.rational.select3d`):
    ``validation_rmse``, ``validation_score`` (the held-out criterion of its ``objective``),
    ``variant`` (the index of the layout chosen), ``variants`` (what each layout achieved); the
    proof between the grid nodes (setting ``prove_bound``, :mod:`fit.rational.proved_bound`):
    ``bounds``."""

    model: object
    records: list
    tolerance: float
    valid: bool
    time_s: float
    n_points: int
    noise: tuple
    edges: list = field(default_factory=list)
    settings: Fit3DSettings | None = None          # the settings that made it
    data: FitData3D | None = None                  # what a refit needs (fit_rgl); None after fit_rgl_select
    verify_points: tuple | None = None             # (X, rho) of the last verification's fresh points
    verify_round: int | None = None
    verify_max_ratio: float | None = None
    verified: bool | None = None
    verify_points_added: int | None = None
    verify_s: float | None = None
    albedo: dict | None = None
    model_before_albedo: object = None
    validation_rmse: float | None = None
    validation_score: float | None = None
    variant: int | None = None
    variants: list | None = None
    bounds: list | None = None                     # fit.rational.proved_bound.ProvedBound per piece, channel

    #: the attributes :attr:`info` lists (those not None)
    _FOUND = ("edges", "verify_round", "verify_max_ratio", "verified", "verify_points_added", "verify_s",
              "albedo", "model_before_albedo", "validation_rmse", "validation_score", "variant",
              "variants")

    @property
    def info(self) -> MappingProxyType:
        """What the fit found, for reports and benchmarks: a read-only mapping of the attributes
        named in ``_FOUND`` that are not None (the attributes are the state; a step sets them)."""
        return MappingProxyType({k: getattr(self, k) for k in self._FOUND if getattr(self, k) is not None})

    @property
    def n_coefficients(self) -> int:
        return int(self.model.n_coefficients)

    def summary(self) -> str:
        return (f"3-D fit {self.model.name}: {self.n_coefficients} coefficients, bound "
                f"{100 * self.tolerance:.3g} % of max(rho, noise) at {self.n_points} points, "
                f"{'valid' if self.valid else 'NOT valid'}, {self.time_s:.1f} s")


def file_value_range(model) -> None:
    """Give every piece of a piecewise 3-D ``model`` the value range its coefficient file holds,
    in place: a file has one ``value`` record for the whole model (the first piece's ``min`` and
    ``max``, :mod:`fit.rational.coefficient_writer`), which every piece reads back.
    :func:`fit.rational.ladder3d.fit_samples` makes its pieces with that one range already; the
    proof (:class:`fit.rational.proved_bound.Fit3DProof`) applies it to the copy it proves, so
    that a model whose pieces were given ranges of their own is proved as its file would hold
    it. A one-piece model is left as it is (the offset and the transform are the same in every
    piece by construction)."""
    pieces = getattr(model, "pieces", None)
    if not pieces:
        return
    lo, hi = model.value_min, model.value_max          # the first piece's: what the file writes
    stack = list(pieces)
    while stack:
        p = stack.pop()
        if getattr(p, "pieces", None):
            stack.extend(p.pieces)
        else:
            p.value_min, p.value_max = lo, hi


def domain_record(fit_info: dict) -> dict:
    """``fit_info["domain"]``: what is proved on the whole measured domain (theta_i, theta_o <=
    ``theta_max_deg``), and why not more, from the fit's own record, per material, in the file
    and the report.

    The bound is *proved* at every data point (an LP certificate of each point, exactly
    re-measured in float64) and Q > 0 on every piece's box (exact Bernstein coefficients); the
    fit is bounded by its ``vouched_range`` everywhere. Between the data points: at
    ``verify_points`` fresh points, the largest error over the bound is ``verify_max_ratio``
    (verified, not proved); where ``fit_info["bound"]`` holds the records of
    :func:`fit.rational.proved_bound.prove_fit3d`, the error against the measurement trilinear
    between the nodes of a grid (:data:`fit.rational.proved_bound.UNIT_3D`) is proved on every
    cell of it: ``proved`` is True when every piece's and channel's proved bound is within its
    stated tolerance, ``proved_bound`` the largest (None: Q inconclusive somewhere),
    ``proved_over_stated`` the largest ratio of a proved bound to its stated tolerance,
    ``proved_fraction`` the smallest fraction of a piece's domain within its tolerance. Without
    those records ``proved`` is False (not proved between the data points)."""
    n = fit_info.get("n_points")
    tm = fit_info.get("theta_max_deg")
    ratio = fit_info.get("verify_max_ratio")
    m = fit_info.get("verify_points")
    if ratio is None:
        checked = "not verified between the data points (no verification)"
    elif ratio <= 1.0:
        checked = (f"verified, not proved, between them: within the bound at all {m} fresh points "
                   f"(largest error {ratio:.3g} x the bound)")
    else:
        checked = (f"not within it between them: at {m} fresh points the largest error is "
                   f"{ratio:.3g} x the bound")
    bounds = fit_info.get("bound") or []
    proved_vals = [b["proved"] for b in bounds]
    proved_max = None if any(p is None for p in proved_vals) else max(proved_vals, default=None)
    over = (max(b["proved"] / max(b["tolerance"], 1e-300) for b in bounds)
            if bounds and proved_max is not None else None)
    proved = bool(bounds) and proved_max is not None and all(b["proved"] <= b["tolerance"] for b in bounds)
    if not bounds:
        between = "No proof between the data points (prove_bound off)"
    elif proved_max is None:
        between = "Between the grid nodes: not proved (Q's Bernstein coefficients inconclusive on a cell)"
    else:
        frac = min(b["proved_fraction"] for b in bounds)
        between = (f"Between the nodes of the measurement's grid (trilinear): error proved <= {proved_max:.3g} "
                   f"(unit of the bound records), {'within' if proved else 'NOT within'} the stated tolerance "
                   f"everywhere (at most {over:.3g} x it); within it on at least {100 * frac:.3g} % of each piece")
    rec = {"proved": proved, "proved_at": "grid cells" if bounds else "data points", "n_points": n,
           "theta_max_deg": tm, "fresh_points": m, "fresh_max_ratio": ratio,
           "proved_bound": proved_max if bounds else None,
           "proved_fraction": min((b["proved_fraction"] for b in bounds), default=None),
           "proved_over_stated": over,
           "reason": (f"bound proved at the {n} data points (theta_i, theta_o <= {tm:.4g} deg) and Q > 0 "
                      f"on every piece; {checked}. {between}")}
    fit_info["domain"] = rec
    return rec
