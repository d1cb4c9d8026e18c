"""The (theta_h, theta_d) projection of a measured BRDF and what is computed from it.

* :mod:`fit.projection.projected`: :class:`~fit.projection.projected.ProjectedBRDF`, the projection
  as data, and its ``.npz`` file;
* :mod:`fit.projection.project`: the per-cluster statistics (median by default) over phi_d;
* :mod:`fit.projection.albedo`: directional albedo by quadrature;
* :mod:`fit.projection.plots`: PNG maps and isolines of a projection (matplotlib).
"""
