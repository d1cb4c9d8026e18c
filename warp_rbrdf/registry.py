"""The renderer's closed lists: material kinds (BSDFs), BSDF sampling techniques and the
per-material sampling strategies a scene can name. Single source of truth for scene parsing,
``rbrdf scene-format``, the CLI help, the kernels and the studies.

Pure Python (no Warp import): the implementation of an entry lives in the module it names and
is imported only when a scene uses it (:meth:`MaterialKind.impl`, :meth:`Technique.impl`).

* A **material kind** (scene ``type``) is one module under :mod:`warp_rbrdf.materials` with
  ``load(spec, scene_file, key) -> LoadedMaterial`` (files -> NumPy data and a NumPy
  ``evaluate``) and ``kernel_eval(loaded) -> wp.func (mats, m, wi, wo) -> vec3``: rho in 1/sr
  without the cosine, local shading frame (z = normal), 0 at or below the horizon.
* A **technique** is one way of drawing the BSDF sample: one module under
  :mod:`warp_rbrdf.techniques` (a material kind's own sampling: that kind's module, ``rgl``) with ``sample (mats, m, wo, xi) -> vec4(wi, weight)`` (weight =
  1/pdf, or alpha for the derivative estimator; <= 0: no sample), ``pdf (mats, m, wi, wo) ->
  float`` (1/sr) and their NumPy references. ``pdf_exact`` False says that ``pdf`` is only an
  approximation of the density ``sample`` draws from (the rational inverse CDFs: their weight is
  exact, their pdf for MIS is the table's) -- pbrt-v4's ``pdfIsProportional``.
* A **strategy** (scene ``sampler``) says which estimators a material's shading point uses:
  one environment sample (``light``), one BSDF sample with a technique (``technique``), both
  combined by the power heuristic when both are drawn, and which strategy replaces it when a
  rational inverse CDF fails its verification (``fallback``).
* A material kind's **default strategy** (:func:`default_strategy`: used when neither the
  material nor ``[integrator]`` names a sampler) is its own importance sampling combined with
  one environment sample by the power heuristic -- never the cosine sample for a measured
  material: ``lambert`` ``mis`` (the cosine density is Lambert's own, exact), ``rgl``
  ``mis-rgl`` (the format's own warps), ``measured`` and ``projected`` ``mis-tabulated`` (their
  own table, built at load or read from ``cdf``), ``rational`` ``mis-rational`` with a ``cdf``
  file (its verified rational inverse CDFs) and ``mis-tabulated`` without one (fitting rational
  inverse CDFs at load takes minutes; tabulating takes seconds).

Adding a material: one module with ``load`` and ``kernel_eval`` plus one :data:`MATERIALS`
entry. Adding a technique: one module plus one :data:`TECHNIQUES` entry (and strategies that
name it).
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass


@dataclass(frozen=True)
class MaterialKind:
    """A BSDF a scene can name with ``[materials.NAME] type = ...``."""

    name: str
    code: int                 # value of ``Materials.kind`` in the kernels
    summary: str
    suffixes: tuple = ()      # file types its ``file`` key accepts (empty: no file)
    module: str = ""          # implementation module
    keys: tuple = ()          # scene keys it reads besides type / sampler / cdf, among
                              # albedo, file, scale, statistic, incident, interpolation (see scene-format)
    default_sampler: str = "mis"            # strategy when neither material nor integrator names one
    default_sampler_cdf: str | None = None  # the same when the material has a ``cdf`` (None: as without)

    def impl(self):
        return importlib.import_module(self.module)


@dataclass(frozen=True)
class Technique:
    """A way of drawing the BSDF sample (sample, pdf and their NumPy references)."""

    name: str
    code: int                 # value of ``Materials.technique`` in the kernels
    summary: str
    pdf_exact: bool           # False: ``pdf`` approximates the sampled density (MIS weights only)
    needs_table: bool = False  # needs the material's tabulated inverse CDFs
    needs_fit: bool = False    # needs verified rational inverse CDFs (else its strategy falls back)
    module: str = ""
    material: str | None = None  # only for materials of this kind (its own data drive it)

    def impl(self):
        return importlib.import_module(self.module)


@dataclass(frozen=True)
class Strategy:
    """A per-material sampling strategy (scene ``sampler``)."""

    name: str
    summary: str
    light_sample: bool        # one environment sample per vertex
    technique: str            # the technique of the BSDF sample
    bsdf_sample: bool = True  # False: no BSDF sample at the last vertex (the technique only
                              # continues the path when max_depth > 1)
    estimator: str = "pdf"    # "pdf": f cos / pdf; "derivative": f cos * alpha (alpha = 1/pdf)
    fallback: str | None = None  # strategy used when the rational inverse CDFs fail verification

    @property
    def mis(self) -> bool:
        """Both samples drawn and combined with the power heuristic."""
        return self.light_sample and self.bsdf_sample

    @property
    def pdf_exact(self) -> bool:
        return technique(self.technique).pdf_exact


# How the integrator combines a vertex's samples (``Materials.combine``).
COMBINE_BSDF = 0     # BSDF sample only
COMBINE_LIGHT = 1    # environment sample only (the technique continues longer paths)
COMBINE_MIS = 2      # both, power heuristic

MATERIALS = (
    MaterialKind("lambert", 0, "albedo / pi", (), "warp_rbrdf.materials.lambert", ("albedo",),
                 default_sampler="mis"),
    MaterialKind("measured", 1, "3-D (theta_h, theta_d, phi_d) MERL-grid table, trilinear between "
                 "bin centres (MERL .binary, or RGL .bsdf resampled)", (".binary", ".bsdf"),
                 "warp_rbrdf.materials.measured", ("file", "scale", "incident", "interpolation"),
                 default_sampler="mis-tabulated"),
    MaterialKind("projected", 2, "2-D (theta_h, theta_d) median projection, nearest cluster "
                 "(.binary/.bsdf projected at load, or an .npz from `rbrdf-fit project`)",
                 (".binary", ".bsdf", ".npz"), "warp_rbrdf.materials.projected",
                 ("file", "scale", "statistic", "incident"), default_sampler="mis-tabulated"),
    MaterialKind("rational", 3, "rational fit P/Q from `rbrdf-fit brdf` (coefficient .json)",
                 (".json",), "warp_rbrdf.materials.rational", ("file", "scale", "unvouched"),
                 default_sampler="mis-tabulated", default_sampler_cdf="mis-rational"),
    MaterialKind("rgl", 4, "RGL-EPFL .bsdf evaluated exactly with the format's own "
                 "interpolation (inverse VNDF warp, bilinear rgb, linear in theta_i); the "
                 "reference representation", (".bsdf",), "warp_rbrdf.materials.rgl",
                 ("file", "scale", "incident"), default_sampler="mis-rgl"),
)

TECHNIQUES = (
    Technique("cosine", 0, "cosine-weighted hemisphere", True,
              module="warp_rbrdf.techniques.cosine"),
    Technique("uniform", 1, "uniform hemisphere", True, module="warp_rbrdf.techniques.uniform"),
    Technique("tabulated", 2, "tabulated inverse CDFs of rho cos (binary search)", True,
              needs_table=True, module="warp_rbrdf.techniques.tabulated"),
    Technique("rational", 3, "rational inverse CDFs (pieces or global layout); weight alpha "
              "exact, pdf = the table's (approximate)", False, needs_table=True, needs_fit=True,
              module="warp_rbrdf.techniques.rational"),
    Technique("rgl", 4, "the RGL format's own importance sampling: luminance warp, then VNDF "
              "warp, exact pdf (rgl materials only)", True, module="warp_rbrdf.materials.rgl",
              material="rgl"),
)

STRATEGIES = (
    Strategy("mis", "environment sample + cosine BSDF sample, power heuristic", True, "cosine"),
    Strategy("light", "environment sample only", True, "cosine", bsdf_sample=False),
    Strategy("cosine", "cosine BSDF sample only", False, "cosine"),
    Strategy("uniform", "uniform BSDF sample only", False, "uniform"),
    Strategy("tabulated", "tabulated inverse-CDF BSDF sample only", False, "tabulated"),
    Strategy("rational", "rational inverse-CDF BSDF sample only, f cos / pdf (pdf = 1/alpha)",
             False, "rational", fallback="tabulated"),
    Strategy("rational-derivative", "rational inverse-CDF BSDF sample only, derivative "
             "estimator f cos alpha", False, "rational", estimator="derivative",
             fallback="tabulated"),
    Strategy("mis-tabulated", "environment sample + tabulated BSDF sample, power heuristic",
             True, "tabulated"),
    Strategy("mis-rational", "environment sample + rational BSDF sample; MIS weights use the "
             "table's pdf (approximate, still unbiased)", True, "rational", fallback="mis-tabulated"),
    Strategy("rgl", "the RGL format's own BSDF sample only (rgl materials)", False, "rgl"),
    Strategy("mis-rgl", "environment sample + the RGL format's own BSDF sample, power "
             "heuristic (rgl materials; Mitsuba 3's estimator)", True, "rgl"),
)

MATERIAL_NAMES = tuple(m.name for m in MATERIALS)
STRATEGY_NAMES = tuple(s.name for s in STRATEGIES)
TECHNIQUE_NAMES = tuple(t.name for t in TECHNIQUES)


def _find(entries, what: str, **key):
    (field_, value), = key.items()
    for e in entries:
        if getattr(e, field_) == value:
            return e
    raise KeyError(f"unknown {what} {value!r}; expected one of "
                   f"{', '.join(str(getattr(e, field_)) for e in entries)}")


def material(name: str) -> MaterialKind:
    return _find(MATERIALS, "material type", name=name)


def technique(name: str) -> Technique:
    return _find(TECHNIQUES, "sampling technique", name=name)


def strategy(name: str) -> Strategy:
    return _find(STRATEGIES, "sampler", name=name)


def default_strategy(kind: str, cdf: bool = False) -> str:
    """Name of the strategy a material of kind ``kind`` uses when neither its table nor
    ``[integrator]`` names a ``sampler``; ``cdf``: the material has an inverse-CDF file (or an
    in-memory fit). See the module docstring for the choice."""
    k = material(kind)
    return (k.default_sampler_cdf or k.default_sampler) if cdf else k.default_sampler


def combine_code(s: Strategy) -> int:
    """The integrator's ``combine`` code of strategy ``s``."""
    if s.mis:
        return COMBINE_MIS
    return COMBINE_LIGHT if s.light_sample else COMBINE_BSDF


def strategies_using(*techniques: str) -> tuple:
    """Names of the strategies whose BSDF sample uses one of ``techniques``."""
    return tuple(s.name for s in STRATEGIES if s.technique in techniques)


#: Strategies that need no inverse-CDF data and work with every material (the studies' base
#: samplers).
BASE_STRATEGIES = tuple(s.name for s in STRATEGIES if not technique(s.technique).needs_table
                        and technique(s.technique).material is None)
#: Strategies whose BSDF sample needs the material's inverse-CDF table (and maybe a fit).
TABLE_STRATEGIES = strategies_using(*(t.name for t in TECHNIQUES if t.needs_table))
#: Strategies that need verified rational inverse CDFs (they have a ``fallback``).
RATIONAL_STRATEGIES = strategies_using(*(t.name for t in TECHNIQUES if t.needs_fit))


def material_by_code(code: int) -> MaterialKind:
    return _find(MATERIALS, "material code", code=int(code))


def technique_by_code(code: int) -> Technique:
    return _find(TECHNIQUES, "technique code", code=int(code))
