"""Exceptions of the renderer.

Every error is one line: the command line prints ``str(err)`` and exits with status 2 without a
traceback. Scene errors name the file, the key and what was expected.

:class:`RenderError` is a :class:`fit.errors.RbrdfError`, so one ``except`` in ``rbrdf`` catches
the renderer's errors and those of the fitter's readers (a bad ``cdf =`` or rational ``file =``
of a scene raises :class:`fit.errors.BRDFFileError`). File names and keys that are not UTF-8
or hold control characters print escaped (:func:`fit.errors.display_text`).
"""
from __future__ import annotations

from fit.errors import RbrdfError, display_path, display_text

#: Longest scene key shown in a message (characters).
_MAX_KEY_CHARS = 120


class RenderError(RbrdfError):
    """Base class of the renderer's one-line errors (bad device, unreadable asset, ...)."""

    def __init__(self, message="", *args):
        super().__init__(display_text(message), *args)


class SceneError(RenderError, ValueError):
    """A scene description cannot be used.

    ``str(err)`` is ``"<file>: <key>: <problem>"``, e.g.
    ``"scenes/bunny.toml: camera.fov: expected a number in (0, 180), got 'wide'"``.
    """

    def __init__(self, file, key: str | None, problem: str):
        self.file = display_path(file) if file is not None else "<scene>"
        self.key = key
        self.problem = problem
        shown = display_text(key) if key else ""
        if len(shown) > _MAX_KEY_CHARS:   # a TOML key can be any string: keep the line readable
            shown = shown[:_MAX_KEY_CHARS - 3] + "..."
        where = f"{self.file}: {shown}: " if key else f"{self.file}: "
        super().__init__(where + display_text(problem))
