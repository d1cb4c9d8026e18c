"""Progress of a batch (:func:`fit.batch.fit_database`), one :class:`BatchProgress` event per
stage and per material finished, given to the ``on_progress`` callback of the Python API;
``rbrdf-fit batch`` prints each as one line (:meth:`BatchProgress.line`) on stdout, so that a
run without a terminal (a log file, a pipe, a job scheduler) shows where it is; on a terminal a
tqdm bar over the materials runs on stderr as well.

Stages, in order: ``"inputs"`` (files found and checked, before any is read), ``"hashed"``
(content hashes done: how many materials were done before, how many to fit), ``"cluster"``
(starting or reaching the workers), ``"ready"`` (workers there), ``"material"`` (one per
material finished, with its one-line result), ``"report"`` (writing the report). ``done`` /
``total`` count materials; ``elapsed_s`` is the seconds since the batch started; ``eta_s`` (on
``"material"`` events) the estimated seconds left: the mean time between the materials
finished by this run so far times the materials left (None before the first).
"""
from __future__ import annotations

import time
from dataclasses import dataclass


@dataclass(frozen=True)
class BatchProgress:
    """One progress event of a batch (see the module's docstring)."""

    stage: str
    done: int
    total: int
    elapsed_s: float
    text: str = ""
    material: str | None = None
    eta_s: float | None = None

    def line(self) -> str:
        """The event as one line: ``batch: [done/total] TEXT; elapsed 12.3 s, about 4 min left``."""
        tail = f"elapsed {_duration(self.elapsed_s)}"
        if self.eta_s is not None:
            tail += f", about {_duration(self.eta_s)} left"
        return f"batch: [{self.done}/{self.total}] {self.text}; {tail}"


def _duration(s: float) -> str:
    if s < 100:
        return f"{s:.1f} s"
    if s < 6000:
        return f"{s / 60:.1f} min"
    return f"{s / 3600:.1f} h"


class ProgressClock:
    """Makes the events of one batch: ``emit(stage, text, material=None)``; ``done`` and
    ``total`` are kept here (:meth:`start_fitting` marks when the tasks were submitted, the
    start of the time-per-material estimate)."""

    def __init__(self, callback, total: int = 0):
        self.callback = callback
        self.t0 = time.perf_counter()
        self.total = total
        self.done = 0
        self._fit_t0 = None
        self._fitted = 0

    def start_fitting(self) -> None:
        self._fit_t0 = time.perf_counter()

    def emit(self, stage: str, text: str, material: str | None = None, finished: bool = False) -> None:
        """Send one event; ``finished``: one more material is done (counted, and used for the estimate)."""
        now = time.perf_counter()
        eta = None
        if finished:
            self.done += 1
            self._fitted += 1
            if self._fit_t0 is not None:
                eta = (now - self._fit_t0) / self._fitted * max(self.total - self.done, 0)
        if self.callback is not None:
            self.callback(BatchProgress(stage, self.done, self.total, now - self.t0, text, material, eta))
