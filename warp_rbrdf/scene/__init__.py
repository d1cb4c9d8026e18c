"""Scenes: description types (:mod:`.specs`), TOML files (:mod:`.parse`, :mod:`.toml_table`) and
the scene-file reference (:mod:`.format_doc`). Errors raise
:class:`~warp_rbrdf.errors.SceneError` naming the file, the key and what was expected."""
from .format_doc import FORMAT_DOC
from .parse import load_scene, parse_scene, scene_from_dict
from .specs import (
                    ENV_TYPES,
                    LIGHT_TYPES,
                    MATERIAL_TYPES,
                    PATTERNS,
                    SAMPLERS,
                    SHAPE_TYPES,
                    CameraSpec,
                    IntegratorSpec,
                    LightSpec,
                    MaterialSpec,
                    Scene,
                    ShapeSpec,
)

__all__ = [
                    "ENV_TYPES",
                    "FORMAT_DOC",
                    "LIGHT_TYPES",
                    "MATERIAL_TYPES",
                    "PATTERNS",
                    "SAMPLERS",
                    "SHAPE_TYPES",
                    "CameraSpec",
                    "IntegratorSpec",
                    "LightSpec",
                    "MaterialSpec",
                    "Scene",
                    "ShapeSpec",
                    "load_scene",
                    "parse_scene",
                    "scene_from_dict",
]
