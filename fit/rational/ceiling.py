"""The last-resort wall-clock safety net of a 3-D fit (:class:`Ceiling`).

No rule of a fit reads the clock otherwise: every loop of :mod:`fit.rational.fit3d` and
:mod:`fit.rational.albedo3d` stops on a count (docs/fitting.md, "Budgets").
"""
from __future__ import annotations

import time

DEFAULT_TIME_LIMIT = 120.0        # wall-clock safety net of a whole fit (s): never reached in normal runs


class Ceiling:
    """The last-resort wall-clock safety net of a fit (``time_limit`` seconds from its creation;
    None: none). :meth:`out` answers whether the ceiling is passed and, when it is, remembers
    where it was noticed (``hits``; the fit records ``stopped = "time"`` and ``stopped_at``)."""

    def __init__(self, time_limit=DEFAULT_TIME_LIMIT):
        self.time_limit = None if time_limit is None else float(time_limit)
        self.t0 = time.perf_counter()
        self.hits: list = []

    def out(self, where: str, share: float = 1.0) -> bool:
        """Whether more than ``share`` of the time limit has passed; ``where`` is remembered
        when it has."""
        if self.time_limit is None or time.perf_counter() - self.t0 <= share * self.time_limit:
            return False
        if where not in self.hits:
            self.hits.append(where)
        return True

    def record(self, fit_info: dict) -> None:
        """Write ``time_limit``, ``stopped`` (``"time"`` or None) and ``stopped_at`` into ``fit_info``."""
        fit_info["time_limit"] = self.time_limit
        fit_info["stopped"] = "time" if self.hits else None
        if self.hits:
            fit_info["stopped_at"] = list(self.hits)
