"""Checks of output paths, made by a run *before* it reads or computes anything
(:func:`check_output_file`, :func:`check_output_dir`): a folder that is a file, a target that is
a folder or a named pipe, a read-only place, a name too long, a wrong suffix. Each problem is one
:class:`fit.errors.OutputError` line naming the path and the flag. Writing is
:mod:`fit.atomic_files` and :mod:`fit.outputs`.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

from .errors import OutputError, display_path

_NAME_MAX = 255


def file_kind(mode: int) -> str:
    """What a path that is not a regular file is, in words (``st_mode`` of its ``stat``)."""
    return ("folder" if stat.S_ISDIR(mode) else "named pipe" if stat.S_ISFIFO(mode)
            else "device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "socket" if stat.S_ISSOCK(mode) else "special file")


def _existing_ancestor(path: Path, flag):
    """The nearest existing ancestor folder of ``path`` (exclusive): it must be a writable
    folder."""
    q = path.parent
    while True:
        try:
            st = os.stat(q)
            break
        except (FileNotFoundError, NotADirectoryError):
            if q.parent == q:
                raise OutputError(path, "no existing folder above it", flag) from None
            q = q.parent
        except (OSError, ValueError) as e:
            raise OutputError(path, f"cannot use its folder ({getattr(e, 'strerror', None) or e})", flag) from None
    if not stat.S_ISDIR(st.st_mode):
        what = "file" if stat.S_ISREG(st.st_mode) else file_kind(st.st_mode)
        raise OutputError(path, f"{display_path(q)} is a {what}, not a folder", flag)
    if not os.access(q, os.W_OK | os.X_OK):
        raise OutputError(path, f"folder {display_path(q)} is not writable", flag)
    return q


def _check_name(path: Path, flag):
    s = os.fspath(path)
    if not s or "\x00" in s:
        raise OutputError(path, "empty or invalid path", flag)
    if path.name in ("", ".", ".."):
        raise OutputError(path, "names a folder, not a file", flag)
    if len(os.fsencode(path.name)) > _NAME_MAX:
        raise OutputError(path, f"file name longer than {_NAME_MAX} bytes", flag)


def _stat_or_none(path: Path, flag):
    """``os.stat(path)``, None when the path does not exist; one-line :class:`OutputError`
    for any other failure."""
    try:
        return os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (OSError, ValueError) as e:
        raise OutputError(path, f"cannot use it ({getattr(e, 'strerror', None) or e})", flag) from None


def check_output_file(path, flag: str | None = "--out", suffixes=None) -> Path:
    """The path a file output will be renamed onto, checked before any work: not a folder or
    special file (a symbolic link is followed: its target is replaced), writable where it is,
    its nearest existing ancestor a writable folder, ending with one of ``suffixes`` (e.g.
    ``(".json",)``) when given. Returns the resolved path."""
    if isinstance(path, str) and not path:
        raise OutputError(path, "empty path", flag)
    path = Path(path)
    _check_name(path, flag)
    try:
        if path.is_symlink():
            path = Path(os.path.realpath(path))
    except (OSError, ValueError) as e:
        raise OutputError(path, f"cannot use it ({getattr(e, 'strerror', None) or e})", flag) from None
    st = _stat_or_none(path, flag)
    if st is not None:
        if not stat.S_ISREG(st.st_mode):
            raise OutputError(path, f"is a {file_kind(st.st_mode)}; refusing to replace it", flag)
        if not os.access(path, os.W_OK):
            raise OutputError(path, "existing file is not writable", flag)
    if suffixes and path.suffix.lower() not in suffixes:
        raise OutputError(path, f"expected a file name ending with {' or '.join(suffixes)}", flag)
    _existing_ancestor(path, flag)
    return path


def check_output_dir(path, flag: str | None = "--out") -> Path:
    """A folder outputs will be written into, checked before any work: an existing folder that
    is writable, or a path whose nearest existing ancestor is a writable folder."""
    if isinstance(path, str) and not path:
        raise OutputError(path, "empty path", flag)
    path = Path(path)
    if "\x00" in os.fspath(path):
        raise OutputError(path, "invalid path (NUL byte)", flag)
    st = _stat_or_none(path, flag)
    if st is not None:
        if not stat.S_ISDIR(st.st_mode):
            kind = "file" if stat.S_ISREG(st.st_mode) else file_kind(st.st_mode)
            raise OutputError(path, f"is a {kind}, not a folder", flag)
        if not os.access(path, os.W_OK | os.X_OK):
            raise OutputError(path, "folder is not writable", flag)
        return path
    _existing_ancestor(path, flag)
    return path
