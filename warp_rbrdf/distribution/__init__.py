"""Sampling distributions of the renderer, in one place: 1-D and 2-D, piecewise constant and
piecewise linear, each with its sample, density and inverse (after Mitsuba 3's ``distr_1d.h`` /
``distr_2d.h`` and pbrt-v4's ``PiecewiseConstant1D/2D``).

* :mod:`.reference`: NumPy (float64) builds and references: :func:`~.reference.find_interval`,
  :class:`~.reference.PiecewiseConstant1D`, :class:`~.reference.PiecewiseLinear1D`,
  :class:`~.reference.PiecewiseConstant2D`, :class:`~.reference.Marginal2D`;
* :mod:`.warp_1d`: the Warp interval search and the 1-D samplers over flat arrays;
* :mod:`.warp_2d`: the Warp 2-D samplers (piecewise constant; the RGL-EPFL format's bilinear
  ``Marginal2D`` warp).

Conventions. Distributions live on [0, 1] or the unit square; a caller maps points onto its
domain and divides densities by the domain's size. A sampler turns uniforms into a point
continuously: the uniform's remainder inside the chosen interval places the point inside its
cell, so that the map is monotone and :func:`~.warp_1d.pc1d_invert` (and the other inverses)
undo it. Interval searches return the last interval whose lower CDF value is ``<= u`` (the
``Marginal2D`` warp: ``< u``, as Mitsuba's), clamped to the array's intervals. The Warp
functions read one distribution as consecutive entries of a flat array from an offset, so that
many share one array (tables of rows). Tested once in ``tests/test_distribution.py``:
Warp = NumPy, sample then invert = identity, and a chi-square test of each sampler against its
density.
"""
from __future__ import annotations

from .warp_1d import (
    find_interval,
    find_interval_row,
    linear_fraction,
    pc1d_cell,
    pc1d_in_cell,
    pc1d_invert,
    pc1d_mass,
    pc1d_pdf,
    pc1d_sample,
    pl1d_invert,
    pl1d_pdf,
    pl1d_sample,
)
from .warp_2d import (
    bilinear_lerp,
    format_fraction,
    marginal2d_invert,
    marginal2d_pdf,
    marginal2d_sample,
    pc2d_invert,
    pc2d_pdf,
    pc2d_sample,
)

__all__ = [
    "bilinear_lerp",
    "find_interval",
    "find_interval_row",
    "format_fraction",
    "linear_fraction",
    "marginal2d_invert",
    "marginal2d_pdf",
    "marginal2d_sample",
    "pc1d_cell",
    "pc1d_in_cell",
    "pc1d_invert",
    "pc1d_mass",
    "pc1d_pdf",
    "pc1d_sample",
    "pc2d_invert",
    "pc2d_pdf",
    "pc2d_sample",
    "pl1d_invert",
    "pl1d_pdf",
    "pl1d_sample",
]
