"""Scene description types: what a scene file (or the Python API) states, with its defaults.
Units: angles in degrees where a key says so (``fov``), lengths in scene units, irradiance in
W/m^2, radiance in W/(m^2 sr); colours are linear Rec.709 RGB (conventions.md)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fit.formats.grid import INTERPOLATIONS as GRID_INTERPOLATIONS

from .. import registry

MATERIAL_TYPES = registry.MATERIAL_NAMES
SAMPLERS = registry.STRATEGY_NAMES
PATTERNS = ("stratified", "independent")
SHAPE_TYPES = ("mesh", "sphere", "plane")
LIGHT_TYPES = ("directional", "envmap", "constant", "sky")
ENV_TYPES = ("envmap", "constant", "sky")
STATISTICS = ("median", "mean", "geometric", "harmonic", "rms")
INCIDENT_ROLES = ("view", "light")   # which direction is an RGL file's theta_i
INTERPOLATIONS = GRID_INTERPOLATIONS   # measured: how the MERL grid is read (fit.formats.grid)
UNVOUCHED = ("projected", "refuse")   # rational: what a piece the fit does not vouch for becomes


@dataclass
class CameraSpec:
    origin: tuple = (0.0, 1.0, 4.0)
    target: tuple = (0.0, 0.5, 0.0)
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 40.0
    fov_axis: str = "x"
    resolution: tuple = (256, 256)


@dataclass
class IntegratorSpec:
    spp: int = 16
    seed: int = 0
    max_depth: int = 1
    sampler: str | None = None   # every material's default; None: each kind's own (registry.default_strategy)
    pattern: str = "stratified"
    hide_environment: bool = False
    tile_size: int = 32
    ray_epsilon: float = 0.0
    #: fraction of the environment's mean luminance taken off its sampling density where the
    #: environment sample is combined with a BSDF sample by MIS (0: off; the Renderer's
    #: ``mis_compensated``); chosen in docs/sampling.md
    mis_compensation: float = 0.25


@dataclass
class MaterialSpec:
    name: str
    type: str
    sampler: str | None = None  # None: registry.default_strategy(type, cdf given), set at construction
    albedo: tuple = (0.8, 0.8, 0.8)
    file: Path | None = None
    statistic: str = "median"
    scale: tuple = (1.0, 1.0, 1.0)
    incident: str = "view"    # RGL files: the tensors' incident direction (view | light)
    interpolation: str = "linear"  # measured: between the MERL grid's bin centres (linear | nearest)
    unvouched: str = "projected"  # rational: flagged pieces -> the projected table | "refuse"
    data: Any = None          # in-memory table / rational function (Python API only)
    cdf: Any = None           # rbrdf-cdf file path or in-memory fit.sampling.cdf_file.CDFFit

    def __post_init__(self):
        if self.sampler is None:
            self.sampler = registry.default_strategy(self.type, self.cdf is not None)


@dataclass
class ShapeSpec:
    type: str
    material: str
    transform: np.ndarray = field(default_factory=lambda: np.eye(4))
    file: Path | None = None
    smooth_normals: bool = True
    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 1.0
    subdivisions: int = 5
    size: tuple = (2.0, 2.0)


@dataclass
class LightSpec:
    type: str
    irradiance: tuple = (1.0, 1.0, 1.0)
    direction: tuple = (0.0, -1.0, 0.0)
    colinear_with_view: bool = False
    file: Path | None = None
    scale: float = 1.0
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    radiance: tuple = (1.0, 1.0, 1.0)
    sun_elevation: float = 35.0
    sun_azimuth: float = 135.0
    resolution: tuple = (512, 256)
    image: Any = None         # in-memory (H, W, 3) map (Python API only)


@dataclass
class Scene:
    camera: CameraSpec = field(default_factory=CameraSpec)
    integrator: IntegratorSpec = field(default_factory=IntegratorSpec)
    materials: dict = field(default_factory=dict)
    shapes: list = field(default_factory=list)
    lights: list = field(default_factory=list)
    path: str = "<scene>"

    @property
    def environment(self) -> LightSpec | None:
        envs = [l for l in self.lights if l.type in ENV_TYPES]
        return envs[0] if envs else None

    @property
    def directional_lights(self) -> list:
        return [l for l in self.lights if l.type == "directional"]


