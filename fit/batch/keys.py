"""What a batch output is keyed by: the content hash of its input file and the options that
made it (:func:`output_key`), and the options themselves, normalized (:class:`BatchOptions`).

Two runs with the same input bytes and the same options produce an output of the same key, so
a re-run finds it (its manifest, :mod:`fit.batch.tasks`) and skips the work; changing a byte
of the input or any option that changes the result gives a new key, and the old output stays
untouched next to the new one. Options that do not change a result (workers, scheduler,
progress bar) are not part of any key.

Key: the first 16 hex digits (64 bits) of the sha256 of the canonical JSON (sorted keys, no
whitespace) of ``{"key_version", "kind", "input_sha256", "options"}``; ``kind`` is ``"brdf"``
(options: ``get_params()`` of the fit's :class:`fit.rational.settings.BRDFFitSettings`, every
setting of the 2-D fit) or ``"cdf"`` (options: the :func:`fit.fit_cdf` table and layout
arguments); a BRDF output that stores the fit's sampler adds its options
(:class:`SamplerOptions`) under ``"sampler"``. :data:`KEY_VERSION` is raised when the
meaning of an option changes. The fitter's own code version is *not* part of the key: after
an update that changes results, re-run into a new folder (or delete the old outputs).
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field

from ..rational.settings import BRDFFitSettings

KEY_VERSION = 2
KEY_HEX_DIGITS = 16


#: The options of one BRDF output (one tolerance): the 2-D fit's settings, whose defaults are
#: those of ``rbrdf-fit brdf`` (:mod:`fit.cli.brdf`).
BrdfOptions = BRDFFitSettings


@dataclass(frozen=True)
class CdfOptions:
    """Arguments of :func:`fit.sampling.cdf_file.fit_cdf`, with the defaults of ``rbrdf-fit cdf``
    (:mod:`fit.cli.cdf`): table size ``n_v`` x ``n_t`` x ``n_p``, cosine mixture ``eps``,
    ``incident`` (roles of an RGL file's directions), ``layout``, ``refinements`` and
    ``time_limit_s`` (global layout; None: no limit)."""

    n_v: int = 32
    n_t: int = 64
    n_p: int = 64
    eps: float = 0.02
    incident: str = "view"
    layout: str = "pieces"
    refinements: int = 1
    time_limit_s: float | None = 180.0


@dataclass(frozen=True)
class SamplerOptions:
    """The fit's own inverse CDFs stored in each BRDF output, as ``rbrdf-fit brdf`` stores them
    (:func:`fit.sampling.model_sampler.embed_sampler`, the defaults of ``--sampler-time-limit``):
    ``time_limit_s`` bounds making them (None: no limit; the table is always completed, rows
    not verified by then are sampled with the table)."""

    time_limit_s: float | None = None


@dataclass(frozen=True)
class BatchOptions:
    """Everything that decides a batch's outputs: the tolerances (one BRDF fit per material and
    tolerance), the other BRDF options, the CDF options (None: no CDF, ``--no-cdf``) and the
    sampler stored in each BRDF output (None: none, ``--no-sampler``)."""

    tols: tuple = (0.05,)
    brdf: dict = field(default_factory=dict)      # BRDFFitSettings names other than tol
    cdf: CdfOptions | None = field(default_factory=CdfOptions)
    sampler: SamplerOptions | None = field(default_factory=SamplerOptions)

    def brdf_options(self) -> list:
        """One :class:`fit.rational.settings.BRDFFitSettings` per tolerance, in the order given."""
        return [BRDFFitSettings(tol=float(t), **self.brdf) for t in self.tols]


def _canonical(value):
    """JSON-ready value with floats that hash the same however they were written (0.05 and
    5e-2 are one float; integers stay integers)."""
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"option value {value!r} is not finite")
        return float(repr(value))
    return value


def output_key(kind: str, input_sha256: str, options: dict) -> str:
    """The key of one output: 16 hex digits of the sha256 of the canonical JSON of the key
    version, ``kind`` (``"brdf"`` or ``"cdf"``), the input's sha256 (hex) and ``options``
    (a JSON-able dict)."""
    if kind not in ("brdf", "cdf"):
        raise ValueError(f"kind must be 'brdf' or 'cdf', not {kind!r}")
    doc = {"key_version": KEY_VERSION, "kind": kind, "input_sha256": input_sha256,
           "options": _canonical(options)}
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:KEY_HEX_DIGITS]


def brdf_key(input_sha256: str, settings: BRDFFitSettings, sampler: SamplerOptions | None = None) -> str:
    """The key of a BRDF output: from every setting of the fit (``settings.get_params()``) and,
    when the output stores the fit's sampler, its options (``"sampler"``; an output without
    one keeps the key it has always had)."""
    options = settings.get_params()
    if sampler is not None:
        options = {**options, "sampler": asdict(sampler)}
    return output_key("brdf", input_sha256, options)


def cdf_key(input_sha256: str, options: CdfOptions) -> str:
    return output_key("cdf", input_sha256, asdict(options))
