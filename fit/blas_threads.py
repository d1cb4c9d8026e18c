"""One BLAS thread while a fit runs (:func:`one_blas_thread`).

A fit's least-squares solves and matrix products go through the BLAS NumPy and SciPy load
(OpenBLAS in their wheels). With more than one BLAS thread, OpenBLAS splits some reductions
between the threads, so the rounding of a sum depends on the thread count: the same fit made with
one and with two BLAS threads differed in the functions of one channel of cm_toxic_green
(docs/fitting.md, "One BLAS thread"). The fitter's outcome must depend on its input and its
settings only, so every fit entry point (``fit_brdf``, ``fit_rgl``, ``fit_rgl_select``,
``fit_cdf`` and the ``rbrdf-fit`` command) runs its BLAS calls on one thread, whatever
``OMP_NUM_THREADS`` / ``OPENBLAS_NUM_THREADS`` say. The fits' matrices are small (at most a few
thousand rows by a few hundred columns), so a second BLAS thread buys little; on a busy machine
its spinning costs CPU time (docs/fitting.md). Parallel work belongs one level up: ``rbrdf-fit
batch`` fits files in parallel processes.

The limit is :func:`threadpoolctl.threadpool_limits` (``user_api="blas"``), restored on return,
so calling code keeps its own setting; nested entry points are fine.
"""
from __future__ import annotations

import functools

from threadpoolctl import threadpool_limits


def one_blas_thread(func):
    """``func`` with the process's BLAS libraries limited to one thread while it runs (the
    earlier limits restored when it returns or raises)."""
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return func(*args, **kwargs)
    return wrapper
