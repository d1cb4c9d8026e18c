"""The last-resort safety net of a 3-D fit (:class:`Ceiling`), in the process's CPU seconds, and
the wall-clock limit a user chose (``rbrdf-fit brdf --time-limit``).

No rule of a fit reads a clock otherwise: every loop of :mod:`fit.rational.fit3d` and
:mod:`fit.rational.albedo3d` stops on a count (docs/fitting.md, "Budgets"). The safety net must
not change a result a normal run produces on any load, and a runaway must still end, so it is

* measured in CPU seconds of the process (``time.process_time()``: the work done, not the time
  other processes took from it; a loaded machine slows the wall clock, not this one), and
* set far beyond a normal fit: :data:`DEFAULT_TIME_LIMIT` is about ten times the largest CPU time
  of a default fit measured on one core (docs/fitting.md, "Budgets", has the numbers).

CPU seconds still grow somewhat under load (shared caches, a BLAS thread that spins while it
waits counts), which the margin absorbs. A wall-clock limit (``wall_limit``) is only ever the
user's explicit choice: a fit it stops depends on the load, and the file records that it was
stopped.
"""
from __future__ import annotations

import time

#: The CPU-time safety net of a whole fit (s of ``time.process_time()``): about 10x the largest
#: default fit measured on one core; never reached in normal runs.
DEFAULT_TIME_LIMIT = 600.0


class Ceiling:
    """The last-resort safety net of a fit: ``time_limit`` CPU seconds of the process from its
    creation (None: none) and, when a user chose one, ``wall_limit`` wall-clock seconds (None:
    none). :meth:`out` answers whether either is passed and, when one is, remembers where it was
    noticed (``hits``; the fit records ``stopped = "time"``, ``stopped_at`` and ``stopped_by``)."""

    def __init__(self, time_limit=DEFAULT_TIME_LIMIT, wall_limit=None):
        self.time_limit = None if time_limit is None else float(time_limit)
        self.wall_limit = None if wall_limit is None else float(wall_limit)
        self.c0 = time.process_time()
        self.t0 = time.perf_counter()
        self.hits: list = []
        self.by: list = []

    @classmethod
    def of(cls, settings) -> "Ceiling":
        """The ceiling of a :class:`fit.rational.settings.Fit3DSettings` (``time_limit``,
        ``wall_limit``)."""
        return cls(settings.time_limit, settings.wall_limit)

    def _passed(self, share: float) -> str | None:
        if self.time_limit is not None and time.process_time() - self.c0 > share * self.time_limit:
            return "cpu"
        if self.wall_limit is not None and time.perf_counter() - self.t0 > share * self.wall_limit:
            return "wall"
        return None

    def out(self, where: str, share: float = 1.0) -> bool:
        """Whether more than ``share`` of a limit has passed; ``where`` (and which limit) is
        remembered when it has."""
        by = self._passed(share)
        if by is None:
            return False
        if where not in self.hits:
            self.hits.append(where)
        if by not in self.by:
            self.by.append(by)
        return True

    def record(self, fit_info: dict) -> None:
        """Write ``time_limit`` (CPU s), ``wall_limit`` (s), ``stopped`` (``"time"`` or None) and,
        when stopped, ``stopped_at`` (where) and ``stopped_by`` (``"cpu"``, ``"wall"``) into
        ``fit_info``."""
        fit_info["time_limit"] = self.time_limit
        fit_info["wall_limit"] = self.wall_limit
        fit_info["stopped"] = "time" if self.hits else None
        if self.hits:
            fit_info["stopped_at"] = list(self.hits)
            fit_info["stopped_by"] = list(self.by)
