"""Lights: directional lights and one environment (lat-long map, constant, or procedural sky).

One concept per module; import from the module that holds a name:

* :mod:`.latlong`: the lat-long conventions (direction <-> map coordinates, bilinear lookup,
  luminance), NumPy;
* :mod:`.env_file`: environment images: reading and checking ``.exr`` / ``.hdr`` maps, the
  constant environment, :func:`~.env_file.environment_image` of a light spec;
* :mod:`.sky`: the procedural sky;
* :mod:`.env_distribution`: the importance-sampling distribution of a map (NumPy build,
  :class:`~.env_distribution.EnvData`, its MIS-compensated form, float64 reference pdf and
  sampler);
* :mod:`.env_map`: the Warp ``EnvMap`` struct, its construction, lookup, radiance and pdf;
* :mod:`.env_sampling`: the Warp environment sample (hierarchical warp, patch inversion);
* :mod:`.directional`: the Warp ``Directional`` struct of the directional lights.
"""
