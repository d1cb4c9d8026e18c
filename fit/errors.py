"""Exceptions of the fitter package.

Every error about a file names the file and the problem in one line, so that the command
line interfaces can print ``str(err)`` and exit non-zero without a traceback.
"""
from __future__ import annotations

import os


class RbrdfError(Exception):
    """Base class of all errors that the command line prints as one line."""


class BRDFFileError(RbrdfError, ValueError):
    """A measured-BRDF or coefficient file cannot be used.

    ``str(err)`` is ``"<path>: <problem>"``.
    """

    def __init__(self, path, problem: str):
        self.path = os.fspath(path) if path is not None else "<memory>"
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")
