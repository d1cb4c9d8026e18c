"""Batch fitting of a whole database on dask.distributed.

* :mod:`fit.batch.inputs`: the measured files of INPUTS, each checked with ``stat`` before it is read;
* :mod:`fit.batch.scheduler`: a ``--scheduler`` address, checked and reached within seconds;
* :mod:`fit.batch.progress`: the progress events (a line per stage and per material);
* :mod:`fit.batch.keys`: what an output is keyed by (input content hash + options);
* :mod:`fit.batch.tasks`: one material as one task (BRDF fits, inverse CDFs, manifests);
* :mod:`fit.batch.report`: the database report (CSV, Markdown, chart);
* :mod:`fit.batch.runner`: :func:`fit_database`, the cluster, resume and progress.

``fit_database`` is imported on first use (dask is an optional extra, ``warp-rbrdf[batch]``).
"""
from ..lazy import lazy_attributes

__all__ = ["BatchReport", "fit_database"]

_LAZY = {"fit_database": ("fit.batch.runner", "fit_database"),
         "BatchReport": ("fit.batch.report", "BatchReport")}


__getattr__ = lazy_attributes(__name__, _LAZY, globals())
