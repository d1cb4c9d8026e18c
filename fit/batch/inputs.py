"""Which measured files a batch fits: :func:`collect_inputs` turns the command line's INPUTS
(files, folders, glob patterns) into one :class:`BatchInput` per file, each checked with
``stat`` before any byte of it is read or hashed.

* A name that matches nothing, a folder without measured files, a file of another type, or a
  name given explicitly that is not a regular file or folder (a named pipe, a device, a
  socket) is a bad argument: one-line :class:`fit.errors.BRDFFileError`, nothing fitted.
* A file of the right type that cannot be fitted -- larger than its format allows
  (:func:`fit.formats.max_file_bytes`: a MERL file has one exact size, an RGL file at most
  :data:`fit.limits.MAX_RGL_FILE_BYTES`), or, found by a walk or a pattern, a named pipe,
  device or socket with a measured-file suffix -- is a :class:`BatchInput` with its one-line
  ``error``: the batch reports it as that material's failure (as a corrupt file) and fits the
  others. A 20 GB sparse ``.binary`` is refused from its size, without reading it.
* Folders are walked without following links to folders, at most
  :data:`fit.limits.MAX_WALK_ENTRIES` entries (:func:`fit.inputs.walk_files`); patterns with
  ``**`` are matched on such a walk (Python's ``glob`` follows link loops without end);
  other patterns by ``glob``, at most :data:`fit.limits.MAX_WALK_ENTRIES` matches.
"""
from __future__ import annotations

import fnmatch
import glob
import itertools
import os
from dataclasses import dataclass
from pathlib import Path

from ..errors import BRDFFileError
from ..formats import SUFFIXES, check_measured_file
from ..inputs import walk_files
from ..limits import MAX_WALK_ENTRIES

#: Most components of a ``**`` pattern below its fixed folder (the matcher recurses on them).
MAX_PATTERN_PARTS = 64


@dataclass
class BatchInput:
    """One measured file of a batch: ``path`` as found, ``size`` in bytes (0 when refused),
    ``error`` the one-line reason it is not fitted (None: it may be read)."""

    path: Path
    size: int = 0
    error: str | None = None


def _is_measured(name: str) -> bool:
    return Path(name).suffix.lower() in SUFFIXES


def _checked(p: Path) -> BatchInput:
    try:
        return BatchInput(p, check_measured_file(p))
    except BRDFFileError as e:
        return BatchInput(p, 0, str(e))


def _match_parts(pattern: tuple, parts: tuple) -> bool:
    """Whether the path components ``parts`` match the pattern components (``**``: any number
    of components; hidden names match only a component that starts with a dot, as in glob).
    Memoized on positions: linear in the pattern times the square of the depth."""
    memo = {}

    def match(i: int, j: int) -> bool:
        if (i, j) in memo:
            return memo[i, j]
        if i == len(pattern):
            r = j == len(parts)
        elif pattern[i] == "**":
            r = match(i + 1, j) or (j < len(parts) and not parts[j].startswith(".") and match(i, j + 1))
        else:
            head = pattern[i]
            r = (j < len(parts) and not (parts[j].startswith(".") and not head.startswith("."))
                 and fnmatch.fnmatchcase(parts[j], head) and match(i + 1, j + 1))
        memo[i, j] = r
        return r

    return match(0, 0)


def _walk_pattern(s: str) -> list:
    """Files matching the ``**`` pattern ``s``, from a bounded walk of its fixed leading folder."""
    parts = s.split("/")
    n = next(i for i, q in enumerate(parts) if glob.has_magic(q))
    root = "/".join(parts[:n]) or ("/" if s.startswith("/") else ".")
    pattern = tuple(q for q in parts[n:] if q)
    if len(pattern) > MAX_PATTERN_PARTS:
        raise BRDFFileError(s, f"pattern has {len(pattern)} components after its folder, at most {MAX_PATTERN_PARTS}")
    if not os.path.isdir(root):
        return []
    out = []
    for path, rel in walk_files(root, MAX_WALK_ENTRIES):
        if _is_measured(rel[-1]) and _match_parts(pattern, rel):
            out.append(Path(root, *rel) if n else Path(*rel))
    return out


def _glob_pattern(s: str) -> list:
    matches = list(itertools.islice(glob.iglob(s), MAX_WALK_ENTRIES + 1))
    if len(matches) > MAX_WALK_ENTRIES:
        raise BRDFFileError(s, f"pattern matches more than {MAX_WALK_ENTRIES} names (fit.limits.MAX_WALK_ENTRIES)")
    return [Path(q) for q in matches if _is_measured(q) and not os.path.isdir(q)]


def collect_inputs(inputs) -> list:
    """The measured files named by ``inputs`` (a path, a pattern or a list of them), as
    :class:`BatchInput` in sorted order without duplicates (same resolved path); see the
    module's docstring for what is refused and how. Reads no file."""
    out, seen = [], set()

    def add(item: BatchInput):
        key = os.path.realpath(item.path)
        if key not in seen:
            seen.add(key)
            out.append(item)

    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    for item in inputs:
        s = os.fspath(item)
        p = Path(s)
        if p.is_dir():
            found = sorted(q for q, rel in walk_files(p, MAX_WALK_ENTRIES) if _is_measured(rel[-1]))
            if not found:
                raise BRDFFileError(p, f"folder without measured-BRDF files ({', '.join(SUFFIXES)})")
            for q in found:
                add(_checked(q))
        elif p.is_file():
            if not _is_measured(p.name):
                raise BRDFFileError(p, f"unknown BRDF file type {p.suffix or '(no extension)'!r}; "
                                       f"expected one of {', '.join(SUFFIXES)}")
            add(_checked(p))
        elif glob.has_magic(s):
            found = sorted(_walk_pattern(s) if "**" in s else _glob_pattern(s))
            if not found:
                raise BRDFFileError(s, "pattern matches no measured-BRDF file")
            for q in found:
                add(_checked(q))
        elif p.exists():
            raise BRDFFileError(p, "not a regular file or folder")
        else:
            raise BRDFFileError(p, "file not found")
    return out


def expand_inputs(inputs) -> list:
    """The paths of :func:`collect_inputs` (refused files included: their ``error`` is in
    :func:`collect_inputs`'s items)."""
    return [i.path for i in collect_inputs(inputs)]
