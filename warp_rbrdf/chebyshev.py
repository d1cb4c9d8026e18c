"""Tensor Chebyshev polynomials as data: the packed form the kernels read and the Warp functions
that evaluate it (the rational BRDF fits of :mod:`.materials.rational` and the global-layout
inverse CDFs of :mod:`.techniques.rational`).

A group of ``W`` polynomials ``P_w = sum_j c_wj prod_v T_{E_w[j, v]}(t_v)`` of the same 1 to 3
variables (the basis of :mod:`fit.rational.basis`; ``t_v`` in [-1, 1], the caller maps the
inputs) is stored in two flat arrays, so that every fit shares one compiled function and a new
fit costs no compile:

* the variables are padded in front to three, ``(a, b, c)``: a 2-variable polynomial in
  ``(x0, x1)`` has ``a`` of degree 0, ``b = x0``, ``c = x1``;
* ints: the number of slots ``n``, the highest exponent of ``a``, ``b`` and ``c`` (at most
  :data:`MAX_DEGREE`), then one code ``a << 16 | b << 8 | c`` per slot: the union of the
  group's exponent rows with a nonzero coefficient, in increasing order;
* float64 coefficients: ``W`` per slot, 0 where a polynomial lacks the term; duplicate rows are
  summed.

Evaluation fills the 1-D tables ``T_k(t)`` of the three variables once (``T_{k+1} = 2 t T_k -
T_{k-1}``, up to the group's highest exponents), then makes one pass over the slots: ``W``
multiply-adds with the slot's product ``T_a T_b T_c`` (no unrolling: one compiled function for
every fit; a flat loop over slots with tables was measured 2.7x faster than nested loops with
the recurrence inside). Sums run in float64 (Chebyshev sums can cancel). Two groups are used:

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
MAX_DEGREE = 31     # highest exponent per variable (the fitter's default limit is 12)
HEAD = 4            # ints before the slot codes: n, and the highest exponent of a, b, c

vec6d = wp.types.vector(length=6, dtype=wp.float64)
vec8d = wp.types.vector(length=8, dtype=wp.float64)
vec_table = wp.types.vector(length=MAX_DEGREE + 1, dtype=wp.float64)


def pack_polynomials(polys, n_vars: int) -> tuple:
    """``(ints int32, floats float64)`` of the packed form of a group of polynomials, each
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
    kmax = np.max(np.array(keys, np.int64).reshape(-1, N_PACKED_VARS), axis=0) if keys else np.zeros(3, np.int64)
    ints = [len(keys), *(int(k) for k in kmax)] + [a << 16 | b << 8 | c for a, b, c in keys]
    floats = np.array([terms[k] for k in keys], np.float64).reshape(-1)
    return np.asarray(ints, np.int32), floats


def evaluate_packed(ints, floats, t, width: int) -> np.ndarray:
    """NumPy reference of the packed form: the group's ``width`` polynomials at ``t``
    ``(..., n_vars)`` (mapped inputs, the polynomials' own variables; padded in front like the
    packing); shape ``(..., width)``."""
    from fit.rational.basis import chebyshev_table

    t = np.asarray(t, np.float64)
    t = np.concatenate([np.zeros(t.shape[:-1] + (N_PACKED_VARS - t.shape[-1],)), t], axis=-1)
    n = int(ints[0])
    tabs = [chebyshev_table(t[..., v], int(ints[1 + v])) for v in range(N_PACKED_VARS)]
    code = np.asarray(ints[HEAD:HEAD + n], np.int64)
    prod = tabs[0][..., code >> 16] * tabs[1][..., (code >> 8) & 255] * tabs[2][..., code & 255]
    return prod @ np.asarray(floats, np.float64).reshape(n, width)


class FlatData:
    """Growing int and float64 lists that records append to; offsets are positions in them
    (the kernels add the owner's start)."""

    def __init__(self):
        self.ints: list = []
        self.floats: list = []

    def add_ints(self, values) -> int:
        off = len(self.ints)
        self.ints.extend(int(v) for v in values)
        return off

    def add_floats(self, values) -> int:
        off = len(self.floats)
        self.floats.extend(float(v) for v in values)
        return off

    def add_polynomials(self, polys, n_vars: int) -> tuple:
        """``(int offset, float offset)`` of a packed group (:func:`pack_polynomials`)."""
        i, f = pack_polynomials(polys, n_vars)
        return self.add_ints(i), self.add_floats(f)

    def arrays(self) -> tuple:
        """``(int32 array, float64 array)``."""
        return np.asarray(self.ints, np.int32), np.asarray(self.floats, np.float64)


@wp.func
def cheb_table(t: wp.float64, kmax: int) -> vec_table:
    """``T_0(t) .. T_kmax(t)`` (entries above ``kmax`` are 0)."""
    tab = vec_table()
    prev = t                      # T_{-1} = t
    x = wp.float64(1.0)
    tab[0] = x
    for k in range(1, kmax + 1):
        nx = wp.float64(2.0) * t * x - prev
        prev = x
        x = nx
        tab[k] = x
    return tab


@wp.func
def cheb_sum6(fv: wp.array(dtype=wp.float64), iv: wp.array(dtype=int), fo: int, io: int,
              ta: wp.float64, tb: wp.float64, tc: wp.float64) -> vec6d:
    """The packed group of 6 polynomials with ints at ``iv[io:]`` and coefficients at
    ``fv[fo:]`` at the mapped inputs ``(ta, tb, tc)`` (padded variables: any value)."""
    xa = cheb_table(ta, iv[io + 1])
    xb = cheb_table(tb, iv[io + 2])
    xc = cheb_table(tc, iv[io + 3])
    s = vec6d()
    f = fo
    for j in range(iv[io]):
        e = iv[io + HEAD + j]
        w = xa[e >> 16] * xb[(e >> 8) & 255] * xc[e & 255]
        s += vec6d(fv[f], fv[f + 1], fv[f + 2], fv[f + 3], fv[f + 4], fv[f + 5]) * w
        f += 6
    return s


@wp.func
def cheb_sum2_d(fv: wp.array(dtype=wp.float64), iv: wp.array(dtype=int), fo: int, io: int,
                ta: wp.float64, tb: wp.float64, tc: wp.float64) -> vec8d:
    """The packed group of 2 polynomials ``(P, Q)`` (as :func:`cheb_sum6`) with their
    derivatives in ``t_c`` and their values at ``t_c = -1`` and ``+1``: ``(P, Q, dP/dt_c,
    dQ/dt_c, P_lo, Q_lo, P_hi, Q_hi)``, one pass; ``dT_{k+1} = 2 T_k + 2 t dT_k - dT_{k-1}``
    from ``dT_{-1} = 1``, ``T_k(-1) = (-1)^k``, ``T_k(1) = 1``."""
    xa = cheb_table(ta, iv[io + 1])
    xb = cheb_table(tb, iv[io + 2])
    kc = iv[io + 3]
    xc = cheb_table(tc, kc)
    dc = vec_table()
    prev = wp.float64(1.0)        # dT_{-1}
    d = wp.float64(0.0)           # dT_0
    for k in range(1, kc + 1):
        nd = wp.float64(2.0) * xc[k - 1] + wp.float64(2.0) * tc * d - prev
        prev = d
        d = nd
        dc[k] = d
    s = vec8d()
    f = fo
    for j in range(iv[io]):
        e = iv[io + HEAD + j]
        c = e & 255
        w = xa[e >> 16] * xb[(e >> 8) & 255]
        p = fv[f] * w
        q = fv[f + 1] * w
        sign = wp.float64(1.0)
        if (c & 1) == 1:
            sign = wp.float64(-1.0)
        s += vec8d(p * xc[c], q * xc[c], p * dc[c], q * dc[c], p * sign, q * sign, p, q)
        f += 2
    return s
