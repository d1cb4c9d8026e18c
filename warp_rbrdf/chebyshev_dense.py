"""Tensor Chebyshev polynomials of one **degree class**, stored densely and evaluated by code
generated per class: the fast form of a rational BRDF piece's numerators and denominators
(:mod:`.materials.rational_kernel`). The coefficients stay data; only the class is code.

A class ``(n_vars, num_degree, den_degree)`` (one int, :func:`class_key`) fixes the slots of a
piece's two groups: every exponent row ``(a, b, c)`` (padded in front to three variables as in
:mod:`warp_rbrdf.chebyshev`) with ``a + b + c <= degree``, in lexicographic order
(:func:`dense_slots`). Any exponent set of total degree at most ``degree`` fits its class
(absent terms are 0), so the fitter's total-degree fits share a class whatever their
per-channel degrees below it: a new fit of a class already compiled compiles nothing.

Storage (float64, :func:`pack_dense`): one row of four values per slot, ``(R, G, B, 0)``: the
numerator slots first, then the denominator slots. A channel without a function (``None``: it
reads a table) has numerator 0 and denominator 1.

Evaluation (:func:`make_dense_pq`, one function per class, cached): the 1-D tables ``T_0 ..
T_degree`` of the mapped inputs (``t`` in [-1, 1]), then per row of slots sharing ``(a, b)`` the
sum over ``c`` of ``row * T_c(t_c)``, times ``T_a(t_a) T_b(t_b)``; float64 throughout (sums of
Chebyshev terms can cancel). The rows go in turn into :data:`N_ACCUMULATORS` accumulators and a
row's terms are summed as two interleaved halves: shorter chains of dependent multiply-adds
(four accumulators against two: 2-4 % of a 2-D fit's evaluation and 5 % of a 3-D fit's, measured
side by side in one process; ``docs/bench_eval.md``). The function is a native snippet (``wp.func_native``,
:func:`dense_source`): straight-line C++ in which a row's four lanes are one Clang vector
(``ext_vector_type``), so each slot is one load and one fused multiply-add of four lanes. Warp's
own code for the same sums (unrolled with ``wp.static``) runs twice as long: LLVM's SLP
vectorizer keeps its ``vec4d`` lanes scalar when they end in scalar uses (per channel), as they
do here; a data-driven loop over the slots (or over packed slots, as
:func:`warp_rbrdf.chebyshev.cheb_sum6` does) runs 3-4 times as long again. A CUDA build compiles
the scalar form of the same sums. :func:`evaluate_dense` is the NumPy reference.
"""
from __future__ import annotations

import functools

import numpy as np
import warp as wp

from .chebyshev import MAX_DEGREE, N_PACKED_VARS, vec6d

#: the most slots (numerator + denominator) a dense class may have; larger groups stay in the
#: packed form of :mod:`warp_rbrdf.chebyshev` (a class's code grows with its slots)
MAX_DENSE_SLOTS = 256
LANES = 4          # (R, G, B, 0) per slot
#: the row sums go in turn into this many accumulators (shorter chains of dependent adds)
N_ACCUMULATORS = 4


def class_key(n_vars: int, num_degree: int, den_degree: int) -> int:
    """The class as one positive int: ``n_vars << 16 | num_degree << 8 | den_degree``."""
    return int(n_vars) << 16 | int(num_degree) << 8 | int(den_degree)


def class_of_key(key: int) -> tuple:
    """``(n_vars, num_degree, den_degree)`` of :func:`class_key`."""
    return key >> 16, (key >> 8) & 255, key & 255


def dense_slots(n_vars: int, degree: int) -> list:
    """The slots ``(a, b, c)`` of total degree <= ``degree`` of ``n_vars`` variables padded in
    front (a 2-variable slot has ``a = 0``), in lexicographic order."""
    lead = N_PACKED_VARS - n_vars
    return [(a, b, c) for a in range(degree + 1) for b in range(degree + 1 - a) for c in range(degree + 1 - a - b)
            if (lead < 1 or a == 0) and (lead < 2 or b == 0)]


def group_degree(polys) -> int:
    """The total degree of a group of polynomials ``(exponents, coefficients)`` or None: the
    largest row sum of a term with a nonzero coefficient (0 for an empty group)."""
    d = 0
    for p in polys:
        if p is None:
            continue
        e = np.asarray(p[0], np.int64).reshape(len(np.atleast_1d(p[1])), -1)
        c = np.asarray(p[1], np.float64).reshape(-1)
        if np.any(c != 0.0):
            d = max(d, int(e[c != 0.0].sum(axis=1).max()))
    return d


def dense_class(numerators, denominators, n_vars: int):
    """The class key of a piece's three numerators and three denominators (each
    ``(exponents (n_terms, n_vars), coefficients)`` or None), or None when its dense form would
    exceed :data:`MAX_DENSE_SLOTS` or a variable's degree :data:`MAX_DEGREE`."""
    dn, dd = group_degree(numerators), group_degree(denominators)
    if max(dn, dd) > MAX_DEGREE or len(dense_slots(n_vars, dn)) + len(dense_slots(n_vars, dd)) > MAX_DENSE_SLOTS:
        return None
    return class_key(n_vars, dn, dd)


def _group_rows(polys, slots, n_vars, empty_constant):
    index = {s: j for j, s in enumerate(slots)}
    rows = np.zeros((len(slots), LANES))
    for w, p in enumerate(polys):
        if p is None:
            rows[index[(0, 0, 0)], w] = empty_constant
            continue
        c = np.asarray(p[1], np.float64).reshape(-1)
        e = np.asarray(p[0], np.int64).reshape(len(c), n_vars)
        for row, ck in zip(e, c):
            if ck != 0.0:
                rows[index[(0,) * (N_PACKED_VARS - n_vars) + tuple(int(k) for k in row)], w] += ck
    return rows


def pack_dense(numerators, denominators, n_vars: int, key: int) -> np.ndarray:
    """The rows ``(n_num + n_den, 4)`` float64 of class ``key`` (:func:`dense_class`) holding
    three numerators and three denominators (module docstring; duplicate exponent rows are
    summed)."""
    nv, dn, dd = class_of_key(key)
    if nv != n_vars:
        raise ValueError(f"class of {nv} variables, got {n_vars}")
    return np.concatenate([_group_rows(numerators, dense_slots(nv, dn), nv, 0.0),
                           _group_rows(denominators, dense_slots(nv, dd), nv, 1.0)])


def evaluate_dense(key: int, rows, t) -> tuple:
    """NumPy reference: ``(P, Q)``, each ``(..., 3)``, of the dense rows of class ``key`` at the
    mapped inputs ``t`` ``(..., n_vars)``."""
    from fit.rational.basis import chebyshev_table

    nv, dn, dd = class_of_key(key)
    t = np.asarray(t, np.float64)
    t = np.concatenate([np.zeros(t.shape[:-1] + (N_PACKED_VARS - nv,)), t], axis=-1)
    tabs = [chebyshev_table(t[..., v], MAX_DEGREE) for v in range(N_PACKED_VARS)]
    rows = np.asarray(rows, np.float64)
    out = []
    start = 0
    for degree in (dn, dd):
        slots = np.array(dense_slots(nv, degree)).reshape(-1, 3)
        prod = tabs[0][..., slots[:, 0]] * tabs[1][..., slots[:, 1]] * tabs[2][..., slots[:, 2]]
        out.append(prod @ rows[start:start + len(slots), :3])
        start += len(slots)
    return out[0], out[1]


def dense_block(key: int) -> str:
    """C++ statements of the vector form of :func:`dense_source` for class ``key`` that read
    ``rows`` (``const rbrdf_v4du*``: the rows, 8-byte aligned), ``ta``, ``tb``, ``tc`` and add
    the sums to the vectors ``p`` and ``q`` (``rbrdf_v4d``, declared by the caller): one class
    of a function that holds several (:mod:`.materials.rational_flat2d`)."""
    return "\n".join(_sum_lines(key, vector=True, declare=False))


def dense_block_scalar(key: int) -> str:
    """C++ statements of the scalar form of :func:`dense_block` (one sum per lane, for a CUDA
    build): read ``rows`` (``const double*``, :data:`LANES` per row), ``ta``, ``tb``, ``tc`` and
    add the sums to the doubles ``p0, p1, p2, q0, q1, q2`` (declared by the caller)."""
    return "\n".join(_sum_lines(key, vector=False, declare=False))


def _sum_lines(key: int, vector: bool, declare: bool = True) -> list:
    nv, dn, dd = class_of_key(key)
    deg = max(dn, dd)
    names = [n for n, used in (("a", nv >= 3), ("b", nv >= 2), ("c", True)) if used]
    out = []
    for n in names:
        out.append(f"double x{n}[{deg + 1}];")
        out.append(f"x{n}[0] = 1.0;")
        if deg >= 1:
            out.append(f"x{n}[1] = t{n};")
        out += [f"x{n}[{k}] = 2.0 * t{n} * x{n}[{k - 1}] - x{n}[{k - 2}];" for k in range(2, deg + 1)]
    lanes = [None] if vector else [0, 1, 2]
    base = 0
    for group, degree in (("p", dn), ("q", dd)):
        slots = dense_slots(nv, degree)
        for lane in lanes:
            var = group if lane is None else f"{group}{lane}"
            typ = 'rbrdf_v4d' if lane is None else 'double'
            if declare:
                out.append(f"{typ} {var} = 0.0;")
            accs = [var] + [f"{var}_{i}" for i in range(1, N_ACCUMULATORS)]
            out += [f"{typ} {acc} = 0.0;" for acc in accs[1:]]
            j, r = 0, 0
            while j < len(slots):
                a, b = slots[j][:2]
                terms = []
                while j < len(slots) and slots[j][:2] == (a, b):
                    row = f"rows[{base + j}]" if lane is None else f"rows[{LANES * (base + j) + lane}]"
                    terms.append(f"{row} * xc[{slots[j][2]}]")
                    j += 1
                weight = " * ".join([f"xa[{a}]"] * (nv >= 3) + [f"xb[{b}]"] * (nv >= 2))
                out.append(f"{accs[r % N_ACCUMULATORS]} += {_pairwise(terms)}" + (f" * ({weight})" if weight else "") + ";")
                r += 1
            out.append(f"{var} += {' + '.join(accs[1:])};")
        base += len(slots)
    return out


def _pairwise(terms) -> str:
    """``terms`` summed as two interleaved halves (two shorter chains of fused multiply-adds)."""
    if len(terms) < 4:
        return f"({' + '.join(terms)})"
    return f"(({' + '.join(terms[0::2])}) + ({' + '.join(terms[1::2])}))"


def dense_source(key: int, vector: bool = True) -> str:
    """The C++ body of :func:`make_dense_pq`'s function for class ``key``: statements that read
    ``ptr`` (the rows), ``ta``, ``tb``, ``tc`` and return ``(P_R, P_G, P_B, Q_R, Q_G, Q_B)``.
    ``vector``: the four lanes of a row as one Clang vector (``ext_vector_type``: one load and one
    multiply-add per slot); else one scalar sum per lane (the CUDA build)."""
    nv = class_of_key(key)[0]
    out = []
    if vector:
        out.append("typedef double rbrdf_v4d __attribute__((ext_vector_type(4), aligned(8)));")
        out.append("const rbrdf_v4d* rows = (const rbrdf_v4d*)ptr;")
    else:
        out.append("const double* rows = (const double*)ptr;")
    out += _sum_lines(key, vector)
    out.append("wp::vec_t<6, double> r;")
    for c in range(3):
        p, q = ("p." + "xyz"[c], "q." + "xyz"[c]) if vector else (f"p{c}", f"q{c}")
        out.append(f"r.c[{c}] = {p}; r.c[{3 + c}] = {q};")
    out.append("return r;")
    return "\n".join(out)


@functools.lru_cache(maxsize=None)
def make_dense_pq(key: int, scalar: bool = False):
    """``dense_pq(ptr, ta, tb, tc) -> vec6d``: ``(P_R, P_G, P_B, Q_R, Q_G, Q_B)`` of the dense rows
    of class ``key`` at address ``ptr`` (``wp.address_of`` of their first float64) at the mapped
    inputs ``(ta, tb, tc)`` (padded in front; a padded input is not read). One native function
    per class (cached): :func:`dense_source`, the vector form on the CPU and the scalar one in a
    CUDA build (``scalar``: the scalar form everywhere, for tests); the snippet is hashed with
    its module, so Warp's kernel cache tells classes apart."""
    if scalar:
        snippet = dense_source(key, vector=False) + "\n"
    else:
        snippet = ("#if defined(__CUDA_ARCH__)\n" + dense_source(key, vector=False) + "\n#else\n"
                   + dense_source(key, vector=True) + "\n#endif\n")

    @Native.func_native(snippet, f"dense_pq_{key:06x}" + ("_scalar" if scalar else ""))
    def dense_pq(ptr: wp.uint64, ta: wp.float64, tb: wp.float64, tc: wp.float64) -> vec6d:
        ...

    return dense_pq


class Native:
    """``@Native.func_native(snippet, name)``: ``wp.func_native(snippet)`` applied to the stub
    under the unique name ``name`` (Warp keys a function by its qualified name, so stubs made
    by one factory need one each). Warp recognises a native stub by a decorator spelled
    ``<...>.func_native(...)`` in its source, hence the spelling."""

    @staticmethod
    def func_native(snippet: str, name: str):
        def decorate(f):
            f.__name__ = f.__qualname__ = name
            return wp.func_native(snippet)(f)

        return decorate
