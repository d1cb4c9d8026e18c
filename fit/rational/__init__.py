"""Rational functions with an error guaranteed at their data points: the basis, Q > 0
certificates, the interval fitter, the models and their coefficient files, and the fit of a
measured BRDF.

* :mod:`fit.rational.basis`: exponent lists and the tensor Chebyshev basis;
* :mod:`fit.rational.bernstein`: Bernstein forms, subdivision, Q > 0 certificates;
* :mod:`fit.rational.function`: ``RationalFunction`` (P / Q), ``RationalRGB``;
* :mod:`fit.rational.problem`, :mod:`fit.rational.lp`, :mod:`fit.rational.degree_search`,
  :mod:`fit.rational.fitter`: the interval fitter (LP with constraint generation);
* :mod:`fit.rational.model`, :mod:`fit.rational.coefficient_file`: models with transforms and
  domain policy, and the ``rbrdf-rational`` JSON files;
* :mod:`fit.rational.brdf_fit`, :mod:`fit.rational.brdf_model`: ``fit_brdf``.
"""
