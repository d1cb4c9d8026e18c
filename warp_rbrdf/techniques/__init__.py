"""BSDF sampling techniques, one module each, listed in :data:`warp_rbrdf.registry.TECHNIQUES`
(the ``rgl`` technique, the format's own sampling, is in its material's module
:mod:`warp_rbrdf.materials.rgl`).

Every technique module has ``kernel_functions(global_fits) -> (sample, pdf)``, the Warp
functions for a scene's materials (every technique returns two fixed module functions: its data,
global-layout fits included, are in :class:`~warp_rbrdf.materials.data.Materials`):

* ``sample(mats: Materials, m: int, wo: vec3, xi: vec2) -> vec4``: a light direction ``wi``
  (local frame, z = normal) and its estimator weight (1/pdf, or alpha for the rational maps;
  <= 0: no sample),
* ``pdf(mats, m, wi, wo) -> float``: the density in 1/sr that MIS uses (exact unless the
  registry says ``pdf_exact = False``),

and the NumPy references ``numpy_sample(cdf, wo, xi) -> (wi, weight)`` and
``numpy_pdf(cdf, wi, wo)``, where ``cdf`` is the material's inverse-CDF data (None, a
:class:`fit.sampling.table.CDFTable` or a :class:`fit.sampling.cdf_file.CDFFit`).
:mod:`.cdf_data` prepares and packs that data (:mod:`.table_cache` remembers the tables it
tabulates at load).

Optional, for speed: ``kernel_fused(global_fits) -> (sample_f, eval_pdf)``, where ``sample_f(mats,
m, wo, xi) -> (vec4, vec3 f, int)`` is ``sample`` with f_r at the sampled direction computed on
the way (last value 1; 0: the integrator evaluates the material) and ``eval_pdf(mats, m, wi, wo)
-> (vec3 f, float pdf, int)`` f_r and ``pdf`` at one pair sharing their work (last value 0: not
applicable, e.g. another material kind). The integrator uses them where present
(:func:`warp_rbrdf.integrator.make_fused`; ``rgl`` has them).
"""
