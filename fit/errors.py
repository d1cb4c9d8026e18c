"""Exceptions of the fitter package: one hierarchy, caught by both command lines.

Every error says in one line what is wrong and where -- the file (and key), the flag, or the
output path -- so that ``rbrdf-fit`` and ``rbrdf`` print ``str(err)`` and exit with status 2
without a traceback (docs/robustness.md):

* :class:`RbrdfError`: the base class;
* :class:`BRDFFileError` (also a ``ValueError``): an input file cannot be used,
  ``"<path>: <problem>"``;
* :class:`FlagError`: a command-line value is out of range, ``"<flag>: <problem>"``;
* :class:`OutputError`: an output cannot be written, ``"<path>: <problem>"`` (no existing file
  is changed when it is raised).

Paths are shown with :func:`display_path`: file names that are not valid UTF-8 print with
their bytes escaped, never raise ``UnicodeEncodeError``, and control characters are escaped so
that a message stays on one line.
"""
from __future__ import annotations

import os


def display_text(text) -> str:
    """``text`` printable on one line under any locale: bytes that are not UTF-8 (surrogate
    escapes of file names) as ``\\xNN``, control characters (newlines, escape sequences) as
    ``\\n`` / ``\\x1b``."""
    s = str(text)
    try:
        s.encode("utf-8")
    except UnicodeEncodeError:
        s = s.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    if any(ord(c) < 32 or ord(c) == 127 for c in s):
        s = "".join(c if 32 <= ord(c) != 127 else repr(c)[1:-1] for c in s)
    return s


def display_path(path) -> str:
    """A path (str, bytes or ``os.PathLike``) as one printable line (:func:`display_text`)."""
    if path is None:
        return "<memory>"
    p = os.fspath(path)
    if isinstance(p, bytes):
        p = os.fsdecode(p)
    return display_text(p)


class RbrdfError(Exception):
    """Base class of all errors that the command line prints as one line."""


class BRDFFileError(RbrdfError, ValueError):
    """A measured-BRDF, coefficient, CDF or projection file cannot be used.

    ``str(err)`` is ``"<path>: <problem>"``.
    """

    def __init__(self, path, problem: str):
        self.path = os.fspath(path) if path is not None else "<memory>"
        self.problem = problem
        super().__init__(f"{display_path(path)}: {display_text(problem)}")


class FlagError(RbrdfError):
    """A command-line value is unusable: ``"<flag>: <problem>"``."""

    def __init__(self, flag: str, problem: str):
        self.flag = flag
        self.problem = problem
        super().__init__(f"{flag}: {display_text(problem)}")


class OutputError(RbrdfError):
    """An output file or folder cannot be written: ``"<path>: <problem>"`` (with the flag that
    named it, when known)."""

    def __init__(self, path, problem: str, flag: str | None = None):
        self.path = os.fspath(path)
        self.problem = problem
        self.flag = flag
        where = f"{flag} {display_path(path)}" if flag else display_path(path)
        super().__init__(f"{where}: {display_text(problem)}")
