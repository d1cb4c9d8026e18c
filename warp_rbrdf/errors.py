"""Exceptions of the renderer.

Every error is one line: the command line prints ``str(err)`` and exits non-zero without a
traceback. Scene errors name the file, the key and what was expected.
"""
from __future__ import annotations


class RenderError(Exception):
    """Base class of the renderer's one-line errors (bad device, unreadable asset, ...)."""


class SceneError(RenderError, ValueError):
    """A scene description cannot be used.

    ``str(err)`` is ``"<file>: <key>: <problem>"``, e.g.
    ``"scenes/bunny.toml: camera.fov: expected a number in (0, 180), got 'wide'"``.
    """

    def __init__(self, file, key: str | None, problem: str):
        self.file = str(file) if file is not None else "<scene>"
        self.key = key
        self.problem = problem
        where = f"{self.file}: {key}: " if key else f"{self.file}: "
        super().__init__(where + problem)
