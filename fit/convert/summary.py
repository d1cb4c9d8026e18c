"""What a conversion lost: the converted file, read back, against its source at random
direction pairs (:func:`compare`), and the summary a conversion returns and prints
(:class:`ConversionSummary`).

The comparison draws ``n_pairs`` (light, view) pairs, each direction uniform in solid angle
over the cap ``theta <= max_theta_deg`` (default 80 deg: the grazing band where every format
extrapolates is left out), seeded, and compares the luminance (Rec.709) of rho, in 1/sr:
``rel = |Y_out - Y_src| / max(Y_src, floor)`` with ``floor`` = 1 % of the source's 99th
percentile over the pairs (so that near-zero values do not dominate). It reports the max,
99th percentile, RMS and median of ``rel``, and the ratio of the means (energy bias).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import display_path
from ..formats.colour import LUMINANCE

DEFAULT_PAIRS = 20000
DEFAULT_MAX_THETA_DEG = 80.0


@dataclass
class Difference:
    """Relative differences of the luminance over ``n`` pairs (fractions, not percent)."""

    n: int
    rel_max: float
    rel_p99: float
    rel_rms: float
    rel_median: float
    mean_ratio: float
    max_theta_deg: float

    def describe(self) -> str:
        return (f"result vs source at {self.n} random direction pairs (theta <= {self.max_theta_deg:g} deg), "
                f"luminance relative difference: max {100 * self.rel_max:.1f} %, p99 "
                f"{100 * self.rel_p99:.1f} %, RMS {100 * self.rel_rms:.1f} %, median "
                f"{100 * self.rel_median:.2f} %; mean ratio {self.mean_ratio:.4f}")

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def random_pairs(n: int, seed: int = 0, max_theta_deg: float = DEFAULT_MAX_THETA_DEG):
    """``(wi, wo)``: two ``(n, 3)`` arrays of unit directions, uniform in solid angle over
    ``theta <= max_theta_deg``, independent."""
    rng = np.random.default_rng(seed)
    lo = np.cos(np.radians(max_theta_deg))

    def draw():
        ct = rng.uniform(lo, 1.0, n)
        ph = rng.uniform(0.0, 2.0 * np.pi, n)
        st = np.sqrt(np.maximum(1.0 - ct * ct, 0.0))
        return np.stack([st * np.cos(ph), st * np.sin(ph), ct], axis=-1)

    return draw(), draw()


def compare(evaluate_out, evaluate_src, n_pairs: int = DEFAULT_PAIRS, seed: int = 0,
            max_theta_deg: float = DEFAULT_MAX_THETA_DEG) -> Difference | None:
    """:class:`Difference` of ``evaluate_out(wi, wo)`` against ``evaluate_src(wi, wo)`` (rho,
    (n, 3), 1/sr) at :func:`random_pairs`; None when ``n_pairs`` is 0."""
    if n_pairs <= 0:
        return None
    wi, wo = random_pairs(n_pairs, seed, max_theta_deg)
    ys = np.asarray(evaluate_src(wi, wo)) @ LUMINANCE
    yo = np.asarray(evaluate_out(wi, wo)) @ LUMINANCE
    floor = max(0.01 * float(np.percentile(ys, 99)), 1e-12)
    rel = np.abs(yo - ys) / np.maximum(ys, floor)
    return Difference(n_pairs, float(rel.max()), float(np.percentile(rel, 99)),
                      float(np.sqrt(np.mean(rel ** 2))), float(np.median(rel)),
                      float(np.mean(yo) / max(np.mean(ys), 1e-300)), float(max_theta_deg))


@dataclass
class ConversionSummary:
    """What :func:`fit.convert.convert` did: the files, the formats, the source's notes, the
    phi_d fold (MERL outputs), the parameterization (RGL outputs) and the measured difference
    of the written file against the source (None when not measured)."""

    source: str
    output: str
    source_format: str
    output_format: str
    name: str
    notes: list = field(default_factory=list)
    fold: object = None
    build: object = None
    difference: Difference | None = None
    seconds: float = 0.0

    def lines(self) -> list:
        out = [(f"converted {display_path(self.source)} ({self.source_format}) -> "
               f"{display_path(self.output)} ({self.output_format}) in {self.seconds:.1f} s")]
        out += [f"  {n}" for n in self.notes]
        if self.fold is not None:
            out.append(f"  {self.fold.describe()}")
        if self.build is not None:
            out.append(f"  {self.build.describe()}")
        if self.difference is not None:
            out.append(f"  {self.difference.describe()}")
        return out

    def __str__(self) -> str:
        return "\n".join(self.lines())
