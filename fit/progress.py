"""Progress of long fitter work: the callback protocol of the Python API, the command line's
reporter, and the deadline that a ``--time-limit`` shares between the stages of one command.

Callback protocol: ``progress(stage: str, done: int, total: int)``, called by the long entry
points (:func:`fit.sampling.cdf_file.fit_cdf`, :func:`fit.rational.brdf_fit.fit_brdf`,
:func:`fit.rational.fit3d.fit_samples` / :func:`~fit.rational.fit3d.fit_rgl`) with ``done``
counting up from 0 to ``total`` within one stage (``stage`` a short human phrase such as
``"tabulating the CDFs"``); a stage may end early (a time limit) without reaching ``total``.
``None`` reports nothing. The callback runs in the caller's thread; an exception it raises
propagates.

:class:`CLIProgress` is the command line's callback: a tqdm bar per stage on a terminal, and
otherwise one line per stage on stderr (``rbrdf-fit cdf: variance gate (16 phi pieces): 2/32
after 6.1 s, about 91 s left``), for the stages expected to take at least
:data:`MIN_SECONDS` -- results stay on stdout.
"""
from __future__ import annotations

import sys
import time
from contextlib import contextmanager

MIN_SECONDS = 2.0   # a stage reported by CLIProgress takes at least this long (estimated)


def report(progress, stage: str, done: int, total: int) -> None:
    """Call ``progress(stage, done, total)`` unless ``progress`` is None."""
    if progress is not None:
        progress(stage, int(done), int(total))


class Deadline:
    """An absolute wall-clock end (``time.perf_counter()`` seconds) shared by the stages of one
    run; ``seconds`` None: no limit. :meth:`left` is the time left (None: unlimited, else
    >= 0), :meth:`passed` whether it ran out."""

    def __init__(self, seconds: float | None, start: float | None = None):
        self.seconds = None if seconds is None else float(seconds)
        t0 = time.perf_counter() if start is None else float(start)
        self.end = None if self.seconds is None else t0 + self.seconds

    def left(self) -> float | None:
        return None if self.end is None else max(self.end - time.perf_counter(), 0.0)

    def passed(self) -> bool:
        return self.end is not None and time.perf_counter() >= self.end


class CLIProgress:
    """``progress(stage, done, total)`` of a command: on a terminal (``stream.isatty()``) one
    tqdm bar per stage (shown after ``min_seconds``, default :data:`MIN_SECONDS`, removed when the stage ends); otherwise
    one line per stage on ``stream`` (default stderr), at the first step after at least
    ``min_seconds / 2`` of the stage at which its estimated length (elapsed / done x total)
    reaches ``min_seconds``: ``PROG: STAGE:
    done/total after T s, about E s left`` (or ``PROG: STAGE: done in T s`` when that step
    ends it). A stage estimated shorter prints nothing. ``enabled`` False: silent.
    :meth:`close` ends the current bar."""

    def __init__(self, prog: str, enabled: bool = True, stream=None, min_seconds: float | None = None):
        self.prog = prog
        self.enabled = enabled
        self.min_seconds = float(MIN_SECONDS if min_seconds is None else min_seconds)
        self.stream = stream if stream is not None else sys.stderr
        try:
            self.tty = bool(self.stream.isatty())
        except (AttributeError, ValueError):
            self.tty = False
        self._stage = None
        self._t0 = 0.0
        self._said = False
        self._bar = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        if stage != self._stage:
            self.close()
            self._stage, self._t0, self._said = stage, time.perf_counter(), False
            if self.tty:
                from tqdm import tqdm

                self._bar = tqdm(total=max(int(total), 1), desc=stage, leave=False, file=self.stream,
                                 delay=self.min_seconds)
        if self._bar is not None:
            self._bar.total = max(int(total), 1)
            self._bar.n = min(int(done), self._bar.total)
            self._bar.refresh()
            return
        if self._said or done <= 0:
            return
        dt = time.perf_counter() - self._t0
        if dt < 0.5 * self.min_seconds or dt / done * max(total, done) < self.min_seconds:
            return          # too early for an estimate, or a short stage
        self._said = True
        if done >= total:
            line = f"{self.prog}: {stage}: done in {dt:.1f} s"
        else:
            rest = dt / done * (total - done)
            line = f"{self.prog}: {stage}: {done}/{total} after {dt:.1f} s, about {rest:.0f} s left"
        print(line, file=self.stream, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


@contextmanager
def one_step(progress, stage: str):
    """A stage of one step around a ``with`` block: ``progress(stage, 0, 1)`` before it and
    ``progress(stage, 1, 1)`` after it (not when it raises)."""
    report(progress, stage, 0, 1)
    yield
    report(progress, stage, 1, 1)


class StageBar:
    """A tqdm-like counter (``update(n)``, ``close()``) that reports one stage of ``total`` steps
    to ``progress(stage, done, total)``: for loops written against a tqdm bar (the renderer's
    tiles)."""

    def __init__(self, progress, stage: str, total: int):
        self.progress, self.stage, self.total, self.n = progress, stage, int(total), 0
        report(progress, stage, 0, self.total)

    def update(self, n: int = 1) -> None:
        self.n = min(self.n + int(n), self.total)
        report(self.progress, self.stage, self.n, self.total)

    def close(self) -> None:
        close = getattr(self.progress, "close", None)
        if close is not None:
            close()
