"""Tensor Chebyshev polynomials as data: the packed form the kernels read and the Warp functions
that evaluate it (the rational BRDF fits of :mod:`.materials.rational` and the global-layout
inverse CDFs of :mod:`.techniques.rational`).

A group of ``W`` polynomials ``P_w = sum_j c_wj prod_v T_{E_w[j, v]}(t_v)`` of the same 1 to 3
variables (the basis of :mod:`fit.rational.basis`; ``t_v`` in [-1, 1], the caller maps the
inputs) is stored in flat arrays, so that every fit shares one compiled function and a new fit
costs no compile:

* the variables are padded in front to three, ``(a, b, c)``: a 2-variable polynomial in
  ``(x0, x1)`` has ``a`` of degree 0, ``b = x0``, ``c = x1``;
* ints: the number of slots ``n``, then one code ``a << 16 | b << 8 | c`` per slot: the union
  of the group's exponent rows with a nonzero coefficient, in increasing order (exponents at
  most :data:`MAX_DEGREE`);
* coefficient rows: one float64 vector of length ``W`` per slot (an array of ``vec6d`` or
  ``vec2d``: one contiguous load per slot), 0 where a polynomial lacks the term; duplicate
  exponent rows are summed.

Evaluation fills the 1-D tables ``T_0 .. T_15`` of the three variables once (``T_{k+1} = 2 t
T_k - T_{k-1}``, a loop of constant length that Warp unrolls), then makes one pass over the
slots: ``W`` multiply-adds with the slot's product ``T_a T_b T_c``, two slots per step into two
partial sums (one compiled function for every fit). Each choice here was the faster one in
development timings of a six-polynomial group: rows read as one vector instead of ``W`` scalar
loads, tables of constant length instead of filled to the group's degree by a loop of variable
length, and one flat pass over slots instead of nested loops with the recurrence inside them;
``benchmarks/bench_startup.py`` gives the resulting cost per evaluation against generated code.
Sums run in float64 (Chebyshev sums can cancel). Two groups are used:

* :func:`cheb_sum6`: the numerators and denominators of a BRDF piece's three channels,
  ``(P_R, P_G, P_B, Q_R, Q_G, Q_B)``;
* :func:`cheb_sum2_d`: ``(P, Q)`` of an inverse-CDF map with, in the same pass, their
  derivatives in the last variable and their values at its ends ``t_c = -1, +1`` (the
  endpoint-normalised maps of :mod:`fit.sampling.maps`).

:func:`evaluate_packed` is the NumPy reference of the packed form.
"""
from __future__ import annotations

import numpy as np
import warp as wp

N_PACKED_VARS = 3   # variables of the packed form (fewer are padded in front)
MAX_DEGREE = 15     # highest exponent per variable (the fitter's default limit is 12)

vec6d = wp.types.vector(length=6, dtype=wp.float64)
vec8d = wp.types.vector(length=8, dtype=wp.float64)
vec_table = wp.types.vector(length=MAX_DEGREE + 1, dtype=wp.float64)


def pack_polynomials(polys, n_vars: int) -> tuple:
    """``(ints int32, rows float64 (n_slots, W))`` of the packed form of a group of ``W`` polynomials, each
    ``(exponents (n_terms, n_vars), coefficients (n_terms,))`` or None (all coefficients 0);
    ``n_vars`` <= 3 (module docstring). ValueError beyond :data:`MAX_DEGREE`."""
    if not 1 <= n_vars <= N_PACKED_VARS:
        raise ValueError(f"packed Chebyshev polynomials have 1 to {N_PACKED_VARS} variables, got {n_vars}")
    width = len(polys)
    terms: dict = {}   # (a, b, c) -> coefficients of the group
    for w, p in enumerate(polys):
        if p is None:
            continue
        c = np.asarray(p[1], np.float64).reshape(-1)
        e = np.asarray(p[0], np.int64).reshape(len(c), -1)
        if e.shape[1] != n_vars:
            raise ValueError(f"polynomial {w} has {e.shape[1]} variables, expected {n_vars}")
        if np.any(e < 0):
            raise ValueError("negative exponent")
        if len(e) and e.max() > MAX_DEGREE:
            raise ValueError(f"degree {int(e.max())} in one variable exceeds the renderer's limit {MAX_DEGREE}")
        for row, ck in zip(e, c):
            if ck != 0.0:
                key = (0,) * (N_PACKED_VARS - n_vars) + tuple(int(k) for k in row)
                terms.setdefault(key, np.zeros(width))[w] += ck
    keys = sorted(terms)
    ints = [len(keys)] + [a << 16 | b << 8 | c for a, b, c in keys]
    rows = np.array([terms[k] for k in keys], np.float64).reshape(-1, width)
    return np.asarray(ints, np.int32), rows


def evaluate_packed(ints, rows, t) -> np.ndarray:
    """NumPy reference of the packed form: the group's ``W`` polynomials (``rows`` ``(n_slots,
    W)``) at ``t`` ``(..., n_vars)`` (mapped inputs, the polynomials' own variables; padded in
    front like the packing); shape ``(..., W)``."""
    from fit.rational.basis import chebyshev_table

    t = np.asarray(t, np.float64)
    t = np.concatenate([np.zeros(t.shape[:-1] + (N_PACKED_VARS - t.shape[-1],)), t], axis=-1)
    n = int(ints[0])
    tabs = [chebyshev_table(t[..., v], MAX_DEGREE) for v in range(N_PACKED_VARS)]
    code = np.asarray(ints[1:1 + n], np.int64)
    prod = tabs[0][..., code >> 16] * tabs[1][..., (code >> 8) & 255] * tabs[2][..., code & 255]
    return prod @ np.asarray(rows, np.float64).reshape(n, -1)


class FlatData:
    """Growing lists that records append to: ints, float64 scalars and coefficient rows of width
    ``width``; offsets are positions in them (the kernels add the owner's start)."""

    def __init__(self, width: int):
        self.width = width
        self.ints: list = []
        self.floats: list = []
        self.rows: list = []
        self.n_rows = 0

    def add_ints(self, values) -> int:
        off = len(self.ints)
        self.ints.extend(int(v) for v in values)
        return off

    def add_floats(self, values) -> int:
        off = len(self.floats)
        self.floats.extend(float(v) for v in values)
        return off

    def add_polynomials(self, polys, n_vars: int) -> tuple:
        """``(int offset, row offset)`` of a packed group of ``width`` polynomials
        (:func:`pack_polynomials`)."""
        if len(polys) != self.width:
            raise ValueError(f"a group of {len(polys)} polynomials, expected {self.width}")
        i, r = pack_polynomials(polys, n_vars)
        off = self.n_rows
        self.rows.append(r)
        self.n_rows += len(r)
        return self.add_ints(i), off

    def arrays(self) -> tuple:
        """``(ints int32, floats float64, rows float64 (n, width))``, each with at least one
        entry (Warp arrays cannot be empty)."""
        ints = np.asarray(self.ints or [0], np.int32)
        floats = np.asarray(self.floats or [0.0], np.float64)
        rows = np.concatenate(self.rows) if self.n_rows else np.zeros((1, self.width))
        return ints, floats, rows


@wp.func
def cheb_table(t: wp.float64) -> vec_table:
    """``T_0(t) .. T_MAX_DEGREE(t)``."""
    tab = vec_table()
    tab[0] = wp.float64(1.0)
    tab[1] = t
    for k in range(2, MAX_DEGREE + 1):
        tab[k] = wp.float64(2.0) * t * tab[k - 1] - tab[k - 2]
    return tab


@wp.func
def cheb_sum6(rows: wp.array(dtype=vec6d), iv: wp.array(dtype=int), ro: int, io: int,
              ta: wp.float64, tb: wp.float64, tc: wp.float64) -> vec6d:
    """The packed group of 6 polynomials with ints at ``iv[io:]`` and coefficient rows at
    ``rows[ro:]`` at the mapped inputs ``(ta, tb, tc)`` (padded variables: any value)."""
    xa = cheb_table(ta)
    xb = cheb_table(tb)
    xc = cheb_table(tc)
    s0 = vec6d()
    s1 = vec6d()              # two partial sums: two independent chains of additions
    f = ro
    j = io + 1
    end = io + 1 + iv[io]
    while j + 1 < end:
        e = iv[j]
        g = iv[j + 1]
        s0 += rows[f] * (xa[e >> 16] * xb[(e >> 8) & 255] * xc[e & 255])
        s1 += rows[f + 1] * (xa[g >> 16] * xb[(g >> 8) & 255] * xc[g & 255])
        f += 2
        j += 2
    if j < end:
        e = iv[j]
        s0 += rows[f] * (xa[e >> 16] * xb[(e >> 8) & 255] * xc[e & 255])
    return s0 + s1


@wp.func
def cheb_sum2_d(rows: wp.array(dtype=wp.vec2d), iv: wp.array(dtype=int), ro: int, io: int,
                ta: wp.float64, tb: wp.float64, tc: wp.float64) -> vec8d:
    """The packed group of 2 polynomials ``(P, Q)`` (as :func:`cheb_sum6`) with their
    derivatives in ``t_c`` and their values at ``t_c = -1`` and ``+1``: ``(P, Q, dP/dt_c,
    dQ/dt_c, P_lo, Q_lo, P_hi, Q_hi)``, one pass; ``dT_k = 2 T_{k-1} + 2 t dT_{k-1} -
    dT_{k-2}`` from ``dT_0 = 0``, ``dT_1 = 1``; ``T_k(-1) = (-1)^k``, ``T_k(1) = 1``."""
    xa = cheb_table(ta)
    xb = cheb_table(tb)
    xc = cheb_table(tc)
    dc = vec_table()
    dc[1] = wp.float64(1.0)
    for k in range(2, MAX_DEGREE + 1):
        dc[k] = wp.float64(2.0) * xc[k - 1] + wp.float64(2.0) * tc * dc[k - 1] - dc[k - 2]
    s = vec8d()
    for j in range(iv[io]):
        e = iv[io + 1 + j]
        c = e & 255
        pq = rows[ro + j] * (xa[e >> 16] * xb[(e >> 8) & 255])
        p = pq[0]
        q = pq[1]
        sign = wp.float64(1.0)
        if (c & 1) == 1:
            sign = wp.float64(-1.0)
        s += vec8d(p * xc[c], q * xc[c], p * dc[c], q * dc[c], p * sign, q * sign, p, q)
    return s
