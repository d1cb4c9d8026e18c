"""Steps 5-7 of the rational recipe for a leaf's three channels at once, as native code
(:func:`make_channels`): P/Q, the value transform (linear / log, with ``log(max + offset)`` as the
ceiling before ``exp``), ``max(y, min)``, ``min(y, max)``, the fallback table in flagged
channels, the step-7 range; the result rounded to float32. It computes what
:func:`.rational_kernel._channel` computes per channel (float64 throughout, Warp's ``min`` /
``max`` / ``clamp``: C ``fmin`` / ``fmax``), with the three channels as lanes of one Clang
vector (``ext_vector_type``) and ``exp`` inline on the vector (:data:`EXP_SOURCE`): Cody-Waite
reduction by ln 2, the Taylor polynomial of degree 13 on ``|r| <= ln(2) / 2`` (truncation below
5e-18 relative) by Estrin's scheme, and the scale 2^k as one exact factor built from k's bits in
the rounding sum with an integer add and a shift (x86-64-v3 has no four-lane double-to-integer
conversion). The input is clamped to [-708, 709.4], where k stays in [-1021, 1023] and every
result is a normal double within 2 ulps of ``exp`` (``tests/test_rational_classes.py`` measures
it against NumPy's); beyond the clamp the result is the clamp's value, which the float32 result
rounds as it rounds ``exp`` (0 below, inf above). A second scale factor, for the subnormals and
the top of the double range, would cost 3-4 ns of a 2-D fit's evaluation, and the float32 result
never shows them (``docs/bench_eval.md``). Three libm ``exp`` calls and the scalar code around
them cost a third of a 2-D fit's evaluation (``benchmarks/bench_eval.py``). A CUDA build
compiles the same steps per channel with ``exp``.
"""
from __future__ import annotations

import functools
import math

import warp as wp

from ..chebyshev import vec6d
from ..chebyshev_dense import Native
from .rational_records import (
    CH_RANGE,
    CH_TABLE,
    FH_LOGMAX,
    FH_MAX,
    FH_MIN,
    FH_OFFSET,
    FH_RANGES,
    LEAF_LOG,
    LEAF_MAX,
    LEAF_MIN,
)

#: 1 / k! for k = 0 .. 13, as C++ literals
_C = [repr(1.0 / math.factorial(k)) for k in range(14)]

#: ``rbrdf_exp(x)``: exp of the four lanes of ``x`` (a C++ lambda; NaN lanes give NaN; the input
#: clamped to [-708, 709.4], module docstring). The
#: polynomial by Estrin's scheme (depth four multiply-adds instead of Horner's thirteen)
EXP_SOURCE = f"""auto rbrdf_exp = [](rbrdf_v4d x) -> rbrdf_v4d {{
    const rbrdf_v4d lo = -708.0, hi = 709.4;
    rbrdf_v4d c = x > lo ? x : lo;                          /* one select each way (a NaN lane: lo) */
    c = c < hi ? c : hi;
    const rbrdf_v4d shifter = 6755399441055744.0;          /* 1.5 * 2^52: rounds to an integer */
    rbrdf_v4d ks = c * 1.4426950408889634 + shifter;        /* k's bits: those of the shifter + k */
    rbrdf_v4d k = ks - shifter;
    rbrdf_v4d r = c - k * 6.93147180369123816490e-01;       /* ln 2, high part: k * it is exact */
    r = r - k * 1.90821492927058770002e-10;                 /* ln 2, low part */
    rbrdf_v4d r2 = r * r;
    rbrdf_v4d r4 = r2 * r2;
    rbrdf_v4d r8 = r4 * r4;
    rbrdf_v4d q0 = ({_C[0]} + {_C[1]} * r) + ({_C[2]} + {_C[3]} * r) * r2;
    rbrdf_v4d q1 = ({_C[4]} + {_C[5]} * r) + ({_C[6]} + {_C[7]} * r) * r2;
    rbrdf_v4d q2 = ({_C[8]} + {_C[9]} * r) + ({_C[10]} + {_C[11]} * r) * r2;
    rbrdf_v4d q3 = {_C[12]} + {_C[13]} * r;
    rbrdf_v4d e = (q0 + q1 * r4) + (q2 + q3 * r4) * r8;
    rbrdf_v4l ki = (rbrdf_v4l)ks - (rbrdf_v4l)shifter;     /* k as an integer, no conversion */
    e = e * (rbrdf_v4d)((ki + 1023) << 52);
    rbrdf_v4l nan = (rbrdf_v4l)(x != x);
    return (rbrdf_v4d)(((rbrdf_v4l)e & ~nan) | ((rbrdf_v4l)x & nan));
}};
"""

#: C++ statements: ``rb_min``, ``rb_max``, ``rb_clamp`` of two (three) numbers of one type, one
#: select each, as :func:`warp_rbrdf.fastmath.fmin` / ``fmax`` / ``clamp`` (Warp's ``wp::min`` /
#: ``wp::max`` / ``wp::clamp`` of floats take two compares and two selects: fmin's NaN rule)
MINMAX_SOURCE = """auto rb_min = [](auto a, auto b) { return a < b ? a : b; };
auto rb_max = [](auto a, auto b) { return a > b ? a : b; };
auto rb_clamp = [](auto x, auto lo, auto hi) { const auto y = x > lo ? x : lo; return y < hi ? y : hi; };
"""

#: the vector steps on ``p``, ``q`` (``rbrdf_v4d``: P and Q of R, G, B and a fourth lane), ``hd``
#: (the leaf header), ``flags``, ``m0``, ``m1``, ``m2`` and ``tab`` (the table's value) into
#: ``wp::vec_t<3, float> out`` (needs the typedefs and ``rbrdf_exp`` of :data:`VECTOR_PRELUDE`
#: and ``rb_clamp`` of :data:`MINMAX_SOURCE`)
VECTOR_STEPS = f"""rbrdf_v4d y = p / q;
if (flags & {LEAF_LOG}) {{
    if (flags & {LEAF_MAX}) {{ const rbrdf_v4d b = hd[{FH_LOGMAX}]; y = y < b ? y : b; }}
    y = rbrdf_exp(y) - hd[{FH_OFFSET}];
}}
if (flags & {LEAF_MIN}) {{ const rbrdf_v4d b = hd[{FH_MIN}]; y = y > b ? y : b; }}
if (flags & {LEAF_MAX}) {{ const rbrdf_v4d b = hd[{FH_MAX}]; y = y < b ? y : b; }}
const int modes[3] = {{m0, m1, m2}};
wp::vec_t<3, float> out;
for (int c = 0; c < 3; ++c) {{
    double v = (modes[c] & {CH_TABLE}) ? (double)tab.c[c] : y[c];
    if (modes[c] & {CH_RANGE}) v = rb_clamp(v, hd[{FH_RANGES} + 2 * c], hd[{FH_RANGES} + 2 * c + 1]);
    out.c[c] = (float)v;
}}
"""

#: the vector types of :data:`EXP_SOURCE` and :data:`VECTOR_STEPS`
VECTOR_TYPES = """typedef double rbrdf_v4d __attribute__((ext_vector_type(4)));
typedef long long rbrdf_v4l __attribute__((ext_vector_type(4)));
"""

#: the vector types and the inline ``exp`` the steps use
VECTOR_PRELUDE = VECTOR_TYPES + EXP_SOURCE

_VECTOR = (VECTOR_PRELUDE + MINMAX_SOURCE + """const double* hd = (const double*)head;
rbrdf_v4d p = {pq.c[0], pq.c[1], pq.c[2], 0.0};
rbrdf_v4d q = {pq.c[3], pq.c[4], pq.c[5], 1.0};
""" + VECTOR_STEPS + "return out;\n")

#: the scalar steps on ``pq`` (``wp::vec_t<6, double>``: P of R, G, B, then Q), ``hd`` (the leaf
#: header), ``flags``, ``m0``, ``m1``, ``m2`` and ``tab`` into ``wp::vec_t<3, float> out``: the
#: CUDA build's form of :data:`VECTOR_STEPS` (the same operations per channel, ``wp::exp``)
SCALAR_STEPS = f"""const int modes[3] = {{m0, m1, m2}};
wp::vec_t<3, float> out;
for (int c = 0; c < 3; ++c) {{
    double v = pq.c[c] / pq.c[3 + c];
    if (flags & {LEAF_LOG}) {{
        if (flags & {LEAF_MAX}) v = wp::min(v, hd[{FH_LOGMAX}]);
        v = wp::exp(v) - hd[{FH_OFFSET}];
    }}
    if (flags & {LEAF_MIN}) v = wp::max(v, hd[{FH_MIN}]);
    if (flags & {LEAF_MAX}) v = wp::min(v, hd[{FH_MAX}]);
    if (modes[c] & {CH_TABLE}) v = (double)tab.c[c];
    if (modes[c] & {CH_RANGE}) v = wp::clamp(v, hd[{FH_RANGES} + 2 * c], hd[{FH_RANGES} + 2 * c + 1]);
    out.c[c] = (float)v;
}}
"""

_SCALAR = "const double* hd = (const double*)head;\n" + SCALAR_STEPS + "return out;\n"


def channels_source(scalar: bool = False) -> str:
    """The C++ body of :func:`make_channels`' function: the vector form on the CPU and the
    scalar one in a CUDA build (``scalar``: the scalar form everywhere, for tests)."""
    if scalar:
        return _SCALAR
    return "#if defined(__CUDA_ARCH__)\n" + _SCALAR + "#else\n" + _VECTOR + "#endif\n"


@functools.lru_cache(maxsize=None)
def make_channels(scalar: bool = False):
    """``channels(pq, head, flags, m0, m1, m2, tab) -> vec3``: rho of the three channels (before
    ``Materials.scale``) of a leaf with flags ``flags``, channel modes ``m0, m1, m2`` and header
    at address ``head`` (``wp.address_of`` of its first float), from ``pq`` = (P_R, P_G, P_B, Q_R,
    Q_G, Q_B) and the fallback table's value ``tab`` (:func:`channels_source`)."""

    @Native.func_native(channels_source(scalar), "rational_channels" + ("_scalar" if scalar else ""))
    def channels(pq: vec6d, head: wp.uint64, flags: int, m0: int, m1: int, m2: int, tab: wp.vec3) -> wp.vec3:
        ...

    return channels


#: the function the renderer uses (:func:`make_channels`)
channels = make_channels()
