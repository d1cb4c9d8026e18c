"""Python API: build a scene for Warp and render it.

>>> from warp_rbrdf import load_scene, render
>>> img = render(load_scene("scenes/sphere.toml"), spp=16, seed=1)   # (H, W, 3) float32, linear

:class:`Renderer` keeps the built scene (BVH, tables, compiled kernels) for repeated renders and
reports setup, compile and render times separately.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np

from fit.progress import one_step

from . import camera, geometry, integrator, registry, sample_patterns
from .defaults import default_scene
from .errors import RenderError, SceneError
from .limits import check_render_size
from .lights.directional import make_directional_struct
from .lights.env_distribution import build_env_distribution, compensated_distribution
from .lights.env_file import environment_image
from .lights.env_map import make_env_struct
from .materials.build import build_material_data
from .materials.data import make_materials_struct
from .runtime import get_device, init_warp
from .scene import Scene, load_scene
from .shipped_kernels import load_module as load_render_module


@dataclass
class RenderStats:
    width: int
    height: int
    spp: int
    threads: int
    device: str
    setup_seconds: float      # loading files, building tables and the BVH
    compile_seconds: float    # code generation + Warp compile (or kernel-cache load)
    render_seconds: float     # the render itself (wall clock, all tiles)
    tiles: int

    @property
    def samples(self) -> int:
        return self.width * self.height * self.spp

    @property
    def samples_per_second(self) -> float:
        return self.samples / self.render_seconds if self.render_seconds > 0 else float("inf")


class Renderer:
    """A scene built for one Warp device. ``render()`` can be called many times.

    ``device``: ``"cpu"``, ``"cuda"`` or ``"cuda:N"``; None: ``$RBRDF_DEVICE``, else ``"cpu"``.

    ``analytic_spheres``: intersect ``sphere`` shapes analytically where their transform keeps
    them spheres (default); False tessellates every sphere into its icosphere of
    ``subdivisions`` (for comparisons; :mod:`warp_rbrdf.geometry`).

    ``progress(stage, done, total)`` (:mod:`fit.progress`; None: silent) is told the setup's
    stages: ``"loading materials"`` (materials), the inverse-CDF tabulation and fits a material
    needs (rows), ``"building the geometry"`` and ``"environment map"`` (one step each), and
    :meth:`compile`'s ``"loading the render kernel"``."""

    def __init__(self, scene: Scene, device: str | None = None, analytic_spheres: bool = True, progress=None):
        wp = init_warp()
        self.wp = wp
        self.scene = scene
        self.analytic_spheres = bool(analytic_spheres)
        self.device = get_device(device)
        t0 = time.perf_counter()
        self.progress = progress
        self._build()
        self.setup_seconds = time.perf_counter() - t0
        self.compile_seconds = None
        self.kernel_source = None   # "shipped", "cache" or "compiled" (shipped_kernels.load_module)
        self._kernels = self._all_kernels = None

    @property
    def mis_compensated(self) -> bool:
        """Whether the environment is sampled with its MIS-compensated distribution
        (:func:`~warp_rbrdf.lights.env_distribution.compensated_distribution`, the fraction
        ``integrator.mis_compensation``): when that is > 0 and every material that samples the
        environment combines the sample with a BSDF sample by MIS. One material with the
        ``light`` sampler (the environment sample alone) keeps the full distribution for the
        whole scene: the kernel holds one."""
        combine = np.asarray(self.material_data.combine)
        return (self.scene.integrator.mis_compensation > 0 and bool(np.any(combine == registry.COMBINE_MIS))
                and not np.any(combine == registry.COMBINE_LIGHT))

    # ------------------------------------------------------------------------------------------
    def _build(self):
        dev, sc = self.device, self.scene
        used = []
        for sh in sc.shapes:
            if sh.material not in used:
                used.append(sh.material)
        self.material_data = build_material_data(sc, used, progress=self.progress)
        index = {n: i for i, n in enumerate(used)}
        with one_step(self.progress, "building the geometry"):
            geom = geometry.build_geometry(sc, index, analytic_spheres=self.analytic_spheres)
            self.geometry = geom
            self.mesh = geometry.make_warp_mesh(geom, dev)   # None: no triangle, no BVH
        self.scene_geometry = geometry.make_geometry_struct(geom, self.mesh, dev)
        eps = sc.integrator.ray_epsilon
        if eps <= 0:
            extent = 1.0 if geom.empty else max(geom.diagonal, 1e-3)
            eps = 1e-5 * extent
        self.ray_epsilon = float(eps)

        self.camera = camera.make_camera_struct(sc.camera)
        env_spec = sc.environment
        self.env_data = None
        self.env_sampling = None
        if env_spec is not None:
            with one_step(self.progress, "environment map"):
                img = environment_image(env_spec, sc.path, f"lights[{sc.lights.index(env_spec)}]")
                self.env_data = build_env_distribution(img, env_spec.rotation)
                self.env_sampling = self.env_data
                if self.mis_compensated:
                    self.env_sampling = compensated_distribution(self.env_data, sc.integrator.mis_compensation)
        self.env = make_env_struct(self.env_sampling, dev)
        dirs, irr = [], []
        o = np.asarray(sc.camera.origin, float)
        t = np.asarray(sc.camera.target, float)
        for l in sc.directional_lights:
            to_light = (o - t) if l.colinear_with_view else -np.asarray(l.direction, float)
            dirs.append(to_light / np.linalg.norm(to_light))
            irr.append(l.irradiance)
        self.directional = make_directional_struct(np.array(dirs, np.float32).reshape(-1, 3),
                                                   np.array(irr, np.float32).reshape(-1, 3), dev)
        self.materials = make_materials_struct(self.material_data, dev)

    def _make_kernels(self, all_techniques: bool = False):
        """The integrator's kernels for the scene's material kinds and techniques (``all_techniques``:
        every registered technique, for sampling a material with another technique than its own)."""
        md = self.material_data
        kinds = [(c, registry.material_by_code(c).impl().kernel_eval(md.loaded_of_kind(c)))
                 for c in md.kinds_used()]
        codes = [t.code for t in registry.TECHNIQUES] if all_techniques else md.techniques_used()
        techniques = []
        for c in codes:
            t = registry.technique_by_code(c)
            fits = md.global_fits if t.needs_fit else ()
            sample, pdf = t.impl().kernel_functions(fits)
            fused = getattr(t.impl(), "kernel_fused", None)   # optional: sample + f, f + pdf
            sample_f, eval_pdf = fused(fits) if fused is not None else (None, None)
            lanes = getattr(t.impl(), "kernel_lanes", None)   # optional: sample + f over K lanes
            techniques.append((c, sample, pdf, t.pdf_exact, sample_f, eval_pdf,
                               None if lanes is None else (lambda K, lanes=lanes, fits=fits: lanes(K, fits))))
        g = self.geometry
        # the lanes are a CPU form (one thread, K samples); a GPU thread takes one sample
        return integrator.make_kernels(kinds, techniques, has_mesh=g.num_triangles > 0,
                                       has_spheres=g.num_spheres > 0, lanes=None if self.device.is_cpu else 0)

    @property
    def kernels(self):
        """The scene's kernels (:class:`warp_rbrdf.integrator.Kernels`); each is its own Warp
        module, compiled (or loaded from the kernel cache) on its first launch."""
        if self._kernels is None:
            self._kernels = self._make_kernels()
        return self._kernels

    def compile(self):
        """Load the scene's render kernel from the shipped ahead-of-time set when it holds it
        (:mod:`warp_rbrdf.shipped_kernels`), else from the kernel cache, else generate and
        compile it; ``self.kernel_source`` says which."""
        if self.compile_seconds is not None:
            return self.compile_seconds
        t0 = time.perf_counter()
        with one_step(self.progress, "loading the render kernel"):
            self.kernel_source = load_render_module(self.kernels.render_tile.module, self.device)
        self.compile_seconds = time.perf_counter() - t0
        return self.compile_seconds

    # ------------------------------------------------------------------------------------------
    def render(self, spp: int | None = None, seed: int | None = None, threads: int | None = None,
               progress: bool = False, return_variance: bool = False):
        """Render; returns the (H, W, 3) float32 linear image (the mean of ``spp`` samples).

        With ``return_variance=True`` also returns the per-pixel sample variance (H, W, 3)
        (divide by spp for the variance of the pixel mean). ``self.stats`` holds the timings.
        """
        wp = self.wp
        self.compile()
        it = self.scene.integrator
        spp = int(it.spp if spp is None else spp)
        seed = int(it.seed if seed is None else seed)
        if (problem := check_render_size(*self.scene.camera.resolution, spp)) is not None:
            raise RenderError(problem)   # bounds: warp_rbrdf.limits
        if not 0 <= seed < 2**32:
            raise RenderError(f"seed must be in [0, 2^32), got {seed}")
        threads = int(threads or os.cpu_count() or 1)
        W, H = self.scene.camera.resolution
        dev = self.device
        mean = wp.zeros(W * H, dtype=wp.vec3, device=dev)
        sq = wp.zeros(W * H, dtype=wp.vec3, device=dev)
        tile = it.tile_size if dev.is_cpu else max(W, H)
        tl = integrator.tiles(W, H, tile)
        k = self.kernels.render_tile
        fixed = [self.scene_geometry, self.camera, self.env, self.directional, self.materials,
                 spp, seed, sample_patterns.kernel_pattern(it.pattern, self.material_data), it.max_depth,
                 1 if it.hide_environment else 0, self.ray_epsilon]

        def one(t):
            x0, y0, tw, th = t
            wp.launch(k, dim=tw * th, inputs=fixed + [x0, y0, tw], outputs=[mean, sq], device=dev)
            if not dev.is_cpu:
                wp.synchronize_device(dev)

        bar = None
        if progress:     # a bar on a terminal, else one line with an estimate (fit.progress)
            from fit.progress import CLIProgress, StageBar

            bar = StageBar(CLIProgress("rbrdf render"), f"render ({len(tl)} tiles)", len(tl))
        t0 = time.perf_counter()
        try:
            integrator.launch_tiles(one, tl, threads if dev.is_cpu else 1, bar)
            wp.synchronize_device(dev)
        finally:
            if bar is not None:
                bar.close()
        dt = time.perf_counter() - t0
        self.stats = RenderStats(W, H, spp, threads if dev.is_cpu else 1, str(dev), self.setup_seconds,
                                 self.compile_seconds, dt, len(tl))
        img = mean.numpy().reshape(H, W, 3)
        if return_variance:
            var = np.maximum(sq.numpy().reshape(H, W, 3) - img.astype(np.float64) ** 2, 0.0)
            var *= spp / max(spp - 1, 1)
            return img, var.astype(np.float32)
        return img

    def material_index(self, name: str) -> int:
        """Index ``m`` of material ``name`` in the kernels' arrays."""
        if name not in self.material_data.names:
            raise RenderError(f"material {name!r} is not used by any shape of the scene")
        return self.material_data.names.index(name)

    def technique_code(self, name: str, sampler: str | None = None) -> int:
        """Technique code of ``sampler`` (a strategy name; default: the material's own strategy
        after any fallback); clear error when it needs an inverse-CDF table the material lacks
        (the rational technique samples the table where the material has no verified maps)."""
        m = self.material_index(name)
        strat = registry.strategy(sampler or self.material_data.strategies[m])
        tech = registry.technique(strat.technique)
        cdf = self.material_data.cdf[m]
        if tech.needs_table and cdf is None:
            raise RenderError(f"material {name!r}: sampler {strat.name!r} needs data the material's "
                              f"sampler {self.material_data.strategies[m]!r} did not build")
        return tech.code

    def kernels_for(self, t: int):
        """Kernels (:class:`warp_rbrdf.integrator.Kernels`) that can sample technique
        ``t``: the scene's, or, for a technique the scene does not use, kernels with every
        technique (for :meth:`sample_material`, :meth:`pdf_material` and the benchmarks)."""
        if t in self.material_data.techniques_used():
            return self.kernels
        if self._all_kernels is None:
            self._all_kernels = self._make_kernels(all_techniques=True)
        return self._all_kernels

    def _array(self, a, n, dtype):
        return self.wp.array(np.ascontiguousarray(a, np.float32).reshape(-1, n), dtype=dtype, device=self.device)

    def eval_material(self, name: str, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Evaluate material ``name`` with the Warp code at local direction pairs (N, 3)."""
        wp = self.wp
        m = self.material_index(name)
        wi, wo = self._array(wi, 3, wp.vec3), self._array(wo, 3, wp.vec3)
        out = wp.zeros(len(wi), dtype=wp.vec3, device=self.device)
        wp.launch(self.kernels.eval_bsdf, dim=len(wi), inputs=[self.materials, m, wi, wo], outputs=[out],
                  device=self.device)
        return out.numpy()

    def sample_material(self, name: str, wo: np.ndarray, xi: np.ndarray, sampler: str | None = None):
        """The Warp BSDF sample of material ``name`` with the technique of ``sampler`` (default:
        its scene sampler, after any fallback) at local views ``wo`` (N, 3) and uniforms ``xi``
        (N, 2): returns ``(wi (N, 3), weight (N,))`` with weight = 1/pdf or alpha (0: no sample)."""
        wp = self.wp
        m, t = self.material_index(name), self.technique_code(name, sampler)
        k = self.kernels_for(t)
        wo, xi = self._array(wo, 3, wp.vec3), self._array(xi, 2, wp.vec2)
        out = wp.zeros(len(wo), dtype=wp.vec4, device=self.device)
        wp.launch(k.sample_bsdf, dim=len(wo), inputs=[self.materials, m, t, wo, xi], outputs=[out],
                  device=self.device)
        o = out.numpy()
        return o[:, :3], o[:, 3]

    def pdf_material(self, name: str, wi: np.ndarray, wo: np.ndarray, sampler: str | None = None):
        """The density (1/sr) the MIS weights use for the BSDF sample of material ``name`` with
        the technique of ``sampler`` at local direction pairs (N, 3): exact for techniques with
        ``pdf_exact``, the table's for the rational maps."""
        wp = self.wp
        m, t = self.material_index(name), self.technique_code(name, sampler)
        k = self.kernels_for(t)
        wi, wo = self._array(wi, 3, wp.vec3), self._array(wo, 3, wp.vec3)
        out = wp.zeros(len(wi), dtype=float, device=self.device)
        wp.launch(k.pdf_bsdf, dim=len(wi), inputs=[self.materials, m, t, wi, wo], outputs=[out],
                  device=self.device)
        return out.numpy()


def render(scene, spp: int | None = None, seed: int | None = None, device: str | None = None,
           threads: int | None = None, progress: bool = False) -> np.ndarray:
    """Render ``scene`` (a :class:`~warp_rbrdf.scene.Scene`, a TOML path, or None for the
    embedded default) and return the linear (H, W, 3) float32 image."""
    if scene is None:
        scene = default_scene()
    elif not isinstance(scene, Scene):
        scene = load_scene(scene)
    return Renderer(scene, device=device).render(spp=spp, seed=seed, threads=threads, progress=progress)


__all__ = ["Renderer", "RenderStats", "render", "RenderError", "SceneError"]
