"""Material kinds (BSDFs) of the renderer, one module each, listed in
:data:`warp_rbrdf.registry.MATERIALS`.

Every kind module has:

* ``load(spec, scene_file, key) -> LoadedMaterial``: read the material's file(s) into NumPy
  data, a NumPy ``evaluate(wi, wo) -> (..., 3)`` (rho in 1/sr, ``scale`` applied), the RGB
  multiplier the kernel applies and the table it needs (:class:`.data.LoadedMaterial`);
  errors are one-line :class:`~warp_rbrdf.errors.SceneError` naming the scene file and key;
* ``kernel_eval(loaded_list) -> wp.func (mats: Materials, m: int, wi: vec3, wo: vec3) -> vec3``:
  the Warp evaluation for the scene's materials of that kind (``loaded_list`` in the order of
  their ``Materials.offset`` where that is an index; most kinds return one fixed function).

Conventions (``../shared/design/conventions.md``): local shading frame z = normal, directions
point away from the surface (``wi`` to the light, ``wo`` to the viewer), rho without the cosine,
0 when either direction is at or below the horizon. :mod:`.data` holds the per-scene Warp
struct, :mod:`.build` fills it from a scene.
"""
