"""Importance sampling of measured BRDFs with tabulated and rational inverse CDFs.

* :mod:`fit.sampling.table`: the tabulated sampler (``CDFTable``) and its inverse CDFs;
* :mod:`fit.sampling.maps`: what the rational layouts share (normalized maps, ``sample_maps``);
* :mod:`fit.sampling.pieces`: the default "pieces" layout (``PieceMaps``);
* :mod:`fit.sampling.variance_gate`: its variance gate (build, verify, gate);
* :mod:`fit.sampling.global_layout`: the paper's "global" layout (``GlobalMaps``), repaired by
  :mod:`fit.sampling.monotone`;
* :mod:`fit.sampling.cdf_file`: ``CDFFit``, ``fit_cdf`` and the ``rbrdf-cdf`` files;
* :mod:`fit.sampling.plots`: ``rbrdf-fit plot-cdf``.
"""
