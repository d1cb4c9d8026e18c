"""The inverse CDFs of a rational BRDF fit made from the fit itself (2-D and 3-D): what the
renderer shows of the fit (:func:`vouched_evaluate`), tabulated and turned into the pieces (or
the paper's global) layout by :func:`fit.sampling.cdf_file.fit_cdf` (:func:`fit_model_sampler`),
and stored with the fit (:func:`embed_sampler`, :mod:`fit.sampling.embedded`).

The tabulation evaluates the fit, never the measurement: a 2-D fit through
:mod:`fit.rational.vouched` (its measured domain, the fallback table embedded in the file where
a piece is flagged), a 3-D fit of (θh, θd, |φd|) by its recipe with the light's and the view's
roles kept (:func:`fit.rational.variables3d.evaluate_directions`: ``wi`` the light, ``wo`` the
view, as the renderer's ``rational_eval``). The table is a function of the view's polar angle
θv and of the light's (θl, φl) with φl measured from the view's azimuth, symmetric in φl: both
hold for a 3-D fit too, whose |φd| makes ρ even in φl for a fixed view (isotropic and mirror
symmetric), and which is not reciprocal: the table samples the light given the view, the role
the renderer's BSDF sample has. Everything is deterministic (fixed grids, the variance gate's
fixed seed): the same fit gives the same sampler, and its table is bit for bit the table the
renderer tabulates from the same fit at load (``tests/test_fit_sampler.py``).
"""
from __future__ import annotations

from functools import partial

from ..progress import Deadline
from ..rational.domain import measured_domain
from ..rational.fallback import table_from_record
from ..rational.flagged import describe_regions, flagged_regions
from ..rational.variables3d import evaluate_directions, is_3d
from ..rational.vouched import evaluate_at_angles
from .cdf_file import TIME_LIMIT_S, fit_cdf
from .cdf_fit import CDFFit
from .embedded import attach


def vouched_evaluate(model):
    """``evaluate(wi, wo) -> (..., 3)``: ρ (1/sr) of the fit ``model`` as the renderer shows it
    (``wi`` the light, ``wo`` the view; 0 below the horizon). ValueError when the fit is flagged
    where nothing vouched stands in: a flagged 3-D fit, or a flagged 2-D fit whose file carries
    no fallback table."""
    regions = flagged_regions(model)
    if is_3d(model):
        if regions:
            raise ValueError(f"the 3-D fit is not within its bound for {describe_regions(model, regions)}: "
                             "nothing vouched to sample there")
        return partial(evaluate_directions, model)
    cut = measured_domain(model)
    if not regions:
        return model.evaluate if cut is None else evaluate_at_angles(model, None, cut)
    if getattr(model, "fallback", None) is None:
        raise ValueError(f"the fit is not within its bound for {describe_regions(model, regions)} and carries "
                         "no fallback table to use there")
    return evaluate_at_angles(model, table_from_record(model.fallback, model), cut)


def fit_model_sampler(model, layout: str = "pieces", time_limit_s: float | None = TIME_LIMIT_S,
                      deadline: Deadline | None = None, progress=None, log=None,
                      pieces_kw: dict | None = None) -> CDFFit:
    """The inverse CDFs of ρ·cos θl of the fit ``model`` (:func:`vouched_evaluate`):
    :func:`fit.sampling.cdf_file.fit_cdf` with the default table (32 view rows x 64 x 64 cells,
    the table the renderer tabulates) and ``layout`` (``"pieces"``, default, or ``"global"``).
    ``time_limit_s`` / ``deadline``, ``progress(stage, done, total)`` (:mod:`fit.progress`) and
    ``log`` as there: the table is always completed, and what is not verified by the deadline is
    sampled with the table; ``pieces_kw`` tunes the pieces layout
    (:func:`fit.sampling.variance_gate.fit_pieces`)."""
    return fit_cdf(vouched_evaluate(model), name=model.name, layout=layout, time_limit_s=time_limit_s,
                   deadline=deadline, progress=progress, log=log, source={"file": "", "sha256": ""},
                   pieces_kw=pieces_kw)


def embed_sampler(model, **kw) -> CDFFit:
    """:func:`fit_model_sampler` of ``model`` (keywords as there), stored as ``model.sampler``
    (:func:`fit.sampling.embedded.attach`): saving the model writes it into the file. Returns
    the :class:`CDFFit`."""
    cdf = fit_model_sampler(model, **kw)
    attach(model, cdf)
    return cdf
