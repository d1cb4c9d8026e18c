"""The degree search of the interval fitter (:mod:`fit.rational.fitter`): the feasible
(numerator, denominator) degree pair with the FEWEST coefficients (ties: lower denominator
degree).

The search walks the (numerator, denominator) plane: feasibility is monotone in both
degrees, so for each denominator degree n, from the largest down, a binary search finds the
smallest feasible numerator degree m; only pairs with fewer coefficients than the best found so
far are tried, and m never goes below the smallest feasible m of a higher denominator degree. An
optional ``start`` pair (e.g. the previous colour channel's degrees) is tried first: if feasible
it is the initial best, which prunes most of the walk without changing its result.
"""
from __future__ import annotations


def search_degrees(try_pair, ncoef, max_m: int, max_n: int, start=None, out_of_time=None, progress=None):
    """Fewest-coefficient feasible pair with ``0 <= m <= max_m``, ``0 <= n <= max_n``.

    ``try_pair(m, n)`` fits one pair and returns its attempt (attributes ``m``, ``n``,
    ``feasible``; certified when feasible); ``ncoef(m, n)`` is the pair's coefficient count;
    ``out_of_time()`` True stops trying new pairs (a pair not tried counts as infeasible);
    ``progress(event)`` is called after each new pair with ``{"m", "n", "feasible",
    "n_coefficients"}``. Returns ``(best attempt or None, {(m, n): attempt}, tried)`` with
    ``tried`` the list of ``(m, n, feasible, n_coefficients)`` in the order they were fitted.
    """
    out_of_time = out_of_time or (lambda: False)
    tried = []
    cache: dict = {}
    M, N = max_m, max_n

    def feas(m, n):
        if (m, n) not in cache and out_of_time():
            return False                   # not tried: the result says the limit was hit
        if (m, n) not in cache:
            att = try_pair(m, n)
            cache[(m, n)] = att
            tried.append((m, n, att.feasible, ncoef(m, n)))
            if progress is not None:
                progress({"m": m, "n": n, "feasible": att.feasible, "n_coefficients": ncoef(m, n)})
        return cache[(m, n)].feasible

    def better(m, n, ref):
        k, kr = ncoef(m, n), ncoef(ref.m, ref.n)
        return k < kr or (k == kr and n < ref.n)

    best = None
    hint = None
    if start is not None:
        hm, hn = (int(d) for d in start)
        if 0 <= hm <= M and 0 <= hn <= N:
            hint = (hm, hn)
            # A feasible hint (e.g. the previous colour channel's degrees) bounds the
            # coefficient count from the start; the walk below still visits every pair that
            # could beat it (ties: lower denominator degree), so the result is unchanged.
            if feas(hm, hn):
                best = cache[(hm, hn)]
            elif hm < M and feas(hm + 1, hn):
                # One numerator degree more usually suffices for a sibling channel: a
                # feasible pair early prunes the walk (which still finds the fewest).
                best = cache[(hm + 1, hn)]
    # Walk the denominator degree DOWN from N. The smallest feasible numerator degree
    # m_min(n) does not decrease when n decreases (monotonicity), so after n the search for
    # n - 1 starts at m_min(n): one or two pairs per lower n, most of them cheap refutations.
    # (Walking n upwards from 0 starts at m = M, the most expensive feasible LPs; measured
    # on satin_rosaline's red core: 16 pairs, 10.9 s up; 6 pairs, 3.3 s down.)
    m_lo = 0
    for n in range(N, -1, -1):
        if hint is not None and n <= hint[1] and not cache[hint].feasible:
            m_lo = max(m_lo, hint[0] + 1)        # (m <= hm, n <= hn) infeasible
        if best is None:
            lo, hi = m_lo, M + 1                 # hi = M + 1: nothing known feasible yet
        else:
            m_cap = M if n < best.n else min(M, best.m)
            while m_cap >= m_lo and not better(m_cap, n, best):
                m_cap -= 1
            if m_cap < m_lo:
                continue                         # no pair at this n beats the best
            if not feas(m_cap, n):
                m_lo = m_cap + 1                 # m_min(n) > m_cap, and m_min(n - 1) too
                continue
            lo, hi = m_lo, m_cap
        while lo < hi:                           # smallest feasible m in [lo, hi]
            mid = (lo + hi) // 2
            if feas(mid, n):
                hi = mid
            else:
                lo = mid + 1
        m_lo = lo
        if lo > M:
            continue                             # nothing feasible at this n
        cand = cache[(lo, n)]
        if best is None or better(lo, n, best):
            best = cand
    return best, cache, tried
