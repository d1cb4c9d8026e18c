"""Opening input files defensively: every reader of :mod:`fit` goes through here.

* :func:`check_regular_file`: the path names an existing regular file no larger than a limit
  -- checked with ``stat`` *before* ``open``, so a named pipe, a device or a directory is refused
  at once instead of blocking or being read forever;
* :func:`read_bytes`: the whole file, at most a limit (the size is checked again while reading:
  a file that grows under us is refused, not read without bound);
* :func:`read_json`: a UTF-8 JSON document with no ``NaN`` / ``Infinity`` literals, no number
  that overflows float64, no integer longer than 30 digits, nested at most
  :data:`fit.limits.MAX_JSON_DEPTH` deep.

Each problem is a one-line :class:`fit.errors.BRDFFileError` naming the file.
"""
from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path

from .errors import BRDFFileError
from .limits import MAX_JSON_BYTES, MAX_JSON_CONTAINERS, MAX_JSON_DEPTH


def check_regular_file(path, max_bytes: int | None = None, what: str = "file") -> int:
    """Size in bytes of the regular file ``path``; :class:`BRDFFileError` if it is missing,
    unreadable, not a regular file (directory, named pipe, device, socket) or larger than
    ``max_bytes``."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise BRDFFileError(path, "file not found (cannot read: no such file)") from None
    except NotADirectoryError:
        raise BRDFFileError(path, "file not found (cannot read: a parent of it is not a folder)") from None
    except (OSError, ValueError) as e:   # ValueError: embedded NUL byte
        raise BRDFFileError(path, f"cannot read file ({getattr(e, 'strerror', None) or e})") from None
    mode = st.st_mode
    if stat.S_ISDIR(mode):
        raise BRDFFileError(path, f"is a directory, not a {what}")
    if not stat.S_ISREG(mode):
        kind = ("named pipe" if stat.S_ISFIFO(mode) else "device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
                else "socket" if stat.S_ISSOCK(mode) else "special file")
        raise BRDFFileError(path, f"is a {kind}, not a regular {what}")
    if max_bytes is not None and st.st_size > max_bytes:
        raise BRDFFileError(path, f"{what} is {st.st_size} bytes, above the limit of {max_bytes} bytes")
    return int(st.st_size)


def open_regular(path, max_bytes: int | None = None, what: str = "file"):
    """Open the regular file ``path`` for reading in binary mode (:func:`check_regular_file`
    first). The file is opened non-blocking and checked again with ``fstat``, so a path that
    became a named pipe in between is refused too, never waited on."""
    check_regular_file(path, max_bytes, what)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise BRDFFileError(path, f"cannot read file ({e.strerror or e})") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise BRDFFileError(path, f"is not a regular {what}")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes(path, max_bytes: int, what: str = "file") -> bytes:
    """The bytes of the regular file ``path`` (at most ``max_bytes``; see
    :func:`open_regular`)."""
    f = open_regular(path, max_bytes, what)
    try:
        with f:
            data = f.read(max_bytes + 1)
    except OSError as e:
        raise BRDFFileError(path, f"cannot read file ({e.strerror or e})") from None
    if len(data) > max_bytes:
        raise BRDFFileError(path, f"{what} grew above the limit of {max_bytes} bytes while being read")
    return data


def _finite_float(s: str) -> float:
    v = float(s)
    if not math.isfinite(v):
        raise ValueError(f"number {s[:40]} overflows float64")
    return v


def _bounded_int(s: str) -> int:
    if len(s.lstrip("-")) > 30:
        raise ValueError(f"integer with {len(s)} digits")
    return int(s)


def _no_constant(s: str):
    raise ValueError(f"{s} is not allowed (JSON has no NaN or infinity)")


def nesting_depth(obj, limit: int) -> int:
    """Nesting depth of a parsed JSON (or TOML) value: dicts and lists, iteratively (no recursion); stops past ``limit``."""
    deepest = 0
    stack = [(obj, 1)]
    while stack:
        o, d = stack.pop()
        if d > deepest:
            deepest = d
            if deepest > limit:
                return deepest
        if isinstance(o, dict):
            stack.extend((v, d + 1) for v in o.values() if isinstance(v, (dict, list)))
        elif isinstance(o, list):
            stack.extend((v, d + 1) for v in o if isinstance(v, (dict, list)))
    return deepest


def parse_json(text, path=None, what: str = "JSON file"):
    """Parse JSON ``text`` (str or UTF-8 bytes) with the rules of :func:`read_json`."""
    if isinstance(text, (bytes, bytearray)):
        try:
            text = bytes(text).decode("utf-8")
        except UnicodeDecodeError as e:
            raise BRDFFileError(path, f"{what} is not UTF-8 text (byte {e.start})") from None
    containers = text.count("[") + text.count("{")
    if containers > MAX_JSON_CONTAINERS:
        raise BRDFFileError(path, f"{what} holds {containers} arrays/objects, above the limit "
                                  f"{MAX_JSON_CONTAINERS} (fit.limits.MAX_JSON_CONTAINERS)")
    try:
        obj = json.loads(text, parse_float=_finite_float, parse_int=_bounded_int,
                         parse_constant=_no_constant)
    except json.JSONDecodeError as e:
        raise BRDFFileError(path, f"corrupt {what}: not valid JSON ({e.msg} at line {e.lineno} "
                                  f"column {e.colno})") from None
    except RecursionError:
        raise BRDFFileError(path, f"corrupt {what}: nested too deeply") from None
    except ValueError as e:
        raise BRDFFileError(path, f"corrupt {what}: {e}") from None
    if nesting_depth(obj, MAX_JSON_DEPTH) > MAX_JSON_DEPTH:
        raise BRDFFileError(path, f"corrupt {what}: nested more than {MAX_JSON_DEPTH} levels deep "
                                  "(fit.limits.MAX_JSON_DEPTH)")
    return obj


def read_json(path, what: str = "JSON file", max_bytes: int = MAX_JSON_BYTES):
    """Parse the JSON file ``path``: a regular file of at most ``max_bytes``
    (:data:`fit.limits.MAX_JSON_BYTES`), UTF-8, without NaN/Infinity literals or numbers that
    overflow, nested at most :data:`fit.limits.MAX_JSON_DEPTH` deep."""
    return parse_json(read_bytes(Path(path), max_bytes, what), path, what)


def sha256_regular(path, max_bytes: int, what: str = "file") -> str:
    """Hex sha256 of the bytes of the regular file ``path``, at most ``max_bytes`` (checked
    with ``stat`` before the first byte is read, :func:`open_regular`; a file that grows past
    the limit while it is hashed is refused)."""
    import hashlib

    h = hashlib.sha256()
    n = 0
    f = open_regular(path, max_bytes, what)
    try:
        with f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                n += len(chunk)
                if n > max_bytes:
                    raise BRDFFileError(path, f"{what} grew above the limit of {max_bytes} bytes while being read")
                h.update(chunk)
    except OSError as e:
        raise BRDFFileError(path, f"cannot read file ({e.strerror or e})") from None
    return h.hexdigest()


def walk_files(root, max_entries: int):
    """Every entry under the folder ``root`` that is not a folder, as ``(path, parts)`` (parts:
    the names below ``root``), depth first in sorted order. Links to folders are neither
    followed nor returned (no loop, no walk out of ``root``); links to files are returned.
    At most ``max_entries`` entries (files and folders) are looked at: a larger tree is a
    :class:`BRDFFileError` naming ``root`` (an unbounded walk, e.g. of ``/``, is refused, not
    waited on), and so is a folder that cannot be listed."""
    root = Path(root)
    stack = [(root, ())]
    seen = 0
    while stack:
        folder, parts = stack.pop()
        try:
            with os.scandir(folder) as it:
                entries = sorted(it, key=lambda e: e.name)
        except OSError as e:
            raise BRDFFileError(folder, f"cannot list folder ({e.strerror or e})") from None
        seen += len(entries)
        if seen > max_entries:
            raise BRDFFileError(root, f"folder tree holds more than {max_entries} entries "
                                      "(fit.limits.MAX_WALK_ENTRIES); name a smaller folder or a pattern")
        subfolders = []
        for e in entries:
            try:
                if e.is_dir(follow_symlinks=False):
                    subfolders.append((Path(e.path), parts + (e.name,)))
                    continue
                if e.is_symlink() and e.is_dir():
                    continue
            except OSError:
                pass
            yield Path(e.path), parts + (e.name,)
        stack.extend(reversed(subfolders))
