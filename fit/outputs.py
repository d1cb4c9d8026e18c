"""Writing outputs so that a failing run loses nothing (issue 22).

Every file the fitter writes is first written to a hidden temporary file in the folder of its
final name and renamed onto that name (``os.replace``, atomic on one file system) only when it
is complete: an existing file is either left as it was or replaced by a whole new one, never
truncated or half-written.

* :func:`atomic_write` / :func:`atomic_path`: one file (the ``save`` functions of the library);
* :class:`OutputSet`: every output of one command-line run, staged as temporary files and
  renamed into place together by :meth:`OutputSet.commit` only when the whole run has
  succeeded; :meth:`OutputSet.abort` (any error, a non-zero exit, Ctrl-C) removes the
  temporary files and the folders the run created;
* :func:`check_output_file` / :func:`check_output_dir`: the checks a run makes on its output
  paths *before* it reads or computes anything (a folder that is a file, a target that is a
  folder or a named pipe, a read-only place, a wrong suffix): one-line
  :class:`fit.errors.OutputError`.

Renamed files get the permissions of the file they replace, or ``0666`` less the umask.
"""
from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from pathlib import Path

from .errors import OutputError, display_path

_NAME_MAX = 255


def _umask_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _kind(mode: int) -> str:
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
        raise OutputError(path, f"{display_path(q)} is a {'file' if stat.S_ISREG(st.st_mode) else _kind(st.st_mode)}, "
                                "not a folder", flag)
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
            raise OutputError(path, f"is a {_kind(st.st_mode)}; refusing to replace it", flag)
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
            kind = "file" if stat.S_ISREG(st.st_mode) else _kind(st.st_mode)
            raise OutputError(path, f"is a {kind}, not a folder", flag)
        if not os.access(path, os.W_OK | os.X_OK):
            raise OutputError(path, "folder is not writable", flag)
        return path
    _existing_ancestor(path, flag)
    return path


def _make_dirs(folder: Path, created: list, flag=None) -> None:
    """Create ``folder`` and its missing parents, recording the ones created (outermost first)."""
    missing = []
    q = folder
    while not q.exists():
        missing.append(q)
        if q.parent == q:
            break
        q = q.parent
    for d in reversed(missing):
        try:
            os.mkdir(d)
        except FileExistsError:
            if not d.is_dir():
                raise OutputError(d, "is a file, not a folder", flag) from None
            continue
        except OSError as e:
            raise OutputError(d, f"cannot create folder ({e.strerror or e})", flag) from None
        created.append(d)


def _temp_in(folder: Path, final: Path, flag=None) -> Path:
    """A new empty hidden file in ``folder`` that keeps ``final``'s suffix (savefig and
    savez choose the format from it)."""
    try:
        fd, name = tempfile.mkstemp(dir=folder, prefix=f".{final.name[:80]}.", suffix=f".part{final.suffix}")
    except OSError as e:
        raise OutputError(final, f"cannot write in {display_path(folder)} ({e.strerror or e})", flag) from None
    os.close(fd)
    return Path(name)


def _replace(tmp: Path, final: Path, flag=None) -> None:
    try:
        try:
            mode = stat.S_IMODE(os.stat(final).st_mode)
        except OSError:
            mode = _umask_mode()
        os.chmod(tmp, mode)
        os.replace(tmp, final)
    except OSError as e:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise OutputError(final, f"cannot write ({e.strerror or e})", flag) from None


def _remove_created(created: list) -> None:
    for d in reversed(created):
        with contextlib.suppress(OSError):
            os.rmdir(d)      # only if empty
    created.clear()


@contextlib.contextmanager
def atomic_path(path, flag: str | None = None):
    """Yield a temporary path next to ``path`` (same suffix) to write the file to; on success
    it is renamed onto ``path`` (parent folders created), on an exception it is removed and
    ``path`` is left as it was."""
    final = Path(path)
    if final.is_symlink():
        final = Path(os.path.realpath(final))
    created: list = []
    _make_dirs(final.parent, created, flag)
    tmp = _temp_in(final.parent, final, flag)
    try:
        yield tmp
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        _remove_created(created)
        raise
    try:
        _replace(tmp, final, flag)
    except OutputError:
        _remove_created(created)
        raise


@contextlib.contextmanager
def atomic_write(path, mode: str = "w", flag: str | None = None):
    """Open a temporary file next to ``path`` for writing (``"w"``: UTF-8 text, ``"wb"``:
    bytes); renamed onto ``path`` when the block ends without an exception."""
    with atomic_path(path, flag) as tmp:
        kw = {} if "b" in mode else {"encoding": "utf-8", "newline": "\n"}
        try:
            with open(tmp, "wb" if "b" in mode else "w", **kw) as f:
                yield f
        except OSError as e:
            raise OutputError(path, f"cannot write ({e.strerror or e})", flag) from None


def save_figure(fig, path, outputs=None, dpi: int = 90) -> None:
    """Save the matplotlib figure ``fig`` as the PNG ``path`` and close it: staged in
    ``outputs`` (an :class:`OutputSet`, renamed into place by its commit) when given, else
    through a temporary file renamed onto ``path`` (:func:`atomic_path`)."""
    import matplotlib.pyplot as plt

    try:
        if outputs is not None:
            fig.savefig(outputs.stage(path), dpi=dpi, format="png")
        else:
            with atomic_path(path) as tmp:
                fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        plt.close(fig)


class OutputSet:
    """All outputs of one run: staged as temporary files (:meth:`stage`), renamed into place by
    :meth:`commit` when the run has succeeded, removed by :meth:`abort` otherwise. Use as a
    context manager: leaving the block without :meth:`commit` aborts."""

    def __init__(self, flag: str | None = "--out"):
        self.flag = flag
        self._staged: list = []     # (tmp, final)
        self._created: list = []
        self.committed: list = []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self._staged or self._created:
            self.abort()
        return False

    def stage(self, final) -> Path:
        """A temporary path for the output ``final`` (its folders are created, and removed
        again on abort); the caller writes the whole file there."""
        final = Path(final)
        if final.is_symlink():
            final = Path(os.path.realpath(final))
        try:
            st = os.stat(final)
        except (FileNotFoundError, NotADirectoryError):
            st = None
        except OSError as e:
            raise OutputError(final, f"cannot use it ({e.strerror or e})", self.flag) from None
        if st is not None and not stat.S_ISREG(st.st_mode):
            raise OutputError(final, f"is a {_kind(st.st_mode)}; refusing to replace it", self.flag)
        _make_dirs(final.parent, self._created, self.flag)
        tmp = _temp_in(final.parent, final, self.flag)
        self._staged.append((tmp, final))
        return tmp

    def commit(self) -> list:
        """Rename every staged file onto its final name; returns the final paths."""
        staged, self._staged = self._staged, []
        try:
            for k, (tmp, final) in enumerate(staged):
                _replace(tmp, final, self.flag)
                self.committed.append(final)
        except OutputError:
            for tmp, _ in staged[k + 1:]:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
            raise
        self._created.clear()
        return list(self.committed)

    def abort(self) -> None:
        """Remove the staged files and the folders this run created."""
        for tmp, _ in self._staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        self._staged.clear()
        _remove_created(self._created)
