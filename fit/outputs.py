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

Before a temporary file is renamed it is checked (:func:`_finish`): flushed to the disk
(``os.fsync``, which reports the write errors a file system delays), its size on disk equal to
the bytes the writer handed over (:func:`atomic_write`, :meth:`OutputSet.write_bytes`) or at
least non-empty (writers that write by path, such as OpenImageIO or matplotlib, which may fail
silently on a full disk), and read back by a ``verify`` function when one is given. A failure
(``ENOSPC``, ``EIO``, a short file) is one :class:`fit.errors.OutputError` naming the final
path, e.g. ``--out x.exr: no space left on device; nothing written, x.exr unchanged``; the
temporary files are removed and every existing output is left as it was.

Renamed files get the permissions of the file they replace, or ``0666`` less the umask.
"""
from __future__ import annotations

import contextlib
import errno
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


#: Words for an ``OSError`` of a write that carries no strerror of its own.
_PROBLEMS = {errno.ENOSPC: "No space left on device", errno.EDQUOT: "Disk quota exceeded",
             errno.EFBIG: "File too large for its file system", errno.EIO: "Input/output error",
             errno.EROFS: "Read-only file system"}

#: Errors that an ``OutputSet`` block turns into an :class:`OutputError` naming its last staged
#: output (a writer that raises them while writing a staged file: matplotlib, NumPy, pandas).
_WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS})

#: Staged temporary file (its ``os.fspath``) -> (final path, flag) while an OutputSet holds it:
#: a ``save`` function writing a staged file atomically names the final output in its errors.
_STAGED: dict = {}


def _named(path, flag):
    """``(path, flag)`` to name in an error about writing ``path``: the final output and its
    flag when ``path`` is a file staged by an :class:`OutputSet`."""
    final, staged_flag = _STAGED.get(os.fspath(path), (path, None))
    return final, (flag if flag is not None else staged_flag)


def _problem(e) -> str:
    """The words for ``e`` (an ``OSError`` or a text)."""
    if isinstance(e, OSError):
        return e.strerror or _PROBLEMS.get(e.errno) or str(e)
    return str(e)


def write_failed(path, e, flag: str | None = None) -> OutputError:
    """The one-line error for an output ``path`` that could not be written (``e``: the
    ``OSError`` or the problem in words): says that nothing was written and whether an earlier
    file of that name is there, unchanged."""
    final, flag = _named(path, flag)
    try:
        kept = os.path.lexists(final)
    except (OSError, ValueError):
        kept = False
    tail = f"; nothing written, {display_path(final)} unchanged" if kept else "; nothing written"
    return OutputError(final, _problem(e) + tail, flag)


def no_space_left(folder) -> bool:
    """True when the file system of ``folder`` has no free block left for this user."""
    try:
        return os.statvfs(folder).f_bavail == 0
    except (OSError, ValueError):
        return False


def _finish(tmp: Path, expected: int | None = None, verify=None) -> None:
    """Make the temporary file ``tmp`` durable and check it: ``os.fsync``; its size equal to
    ``expected`` bytes when given, else non-zero; ``verify(tmp)`` (raises ``OSError`` when the
    file does not hold what was meant) when given. Raises ``OSError``."""
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
        size = os.fstat(fd).st_size
    finally:
        os.close(fd)
    complete = size == expected if expected is not None else size > 0
    if not complete:
        if no_space_left(tmp.parent):
            raise OSError(errno.ENOSPC, f"No space left on device (the file has {size} bytes"
                                        + (f" of {expected})" if expected is not None else ")"))
        raise OSError(errno.EIO, f"Short write ({size} of {expected} bytes on disk)" if expected is not None
                      else "The writer left an empty file")
    if verify is not None:
        verify(tmp)


def _fsync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable (best effort: the file is already in place)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _temp_in(folder: Path, final: Path, flag=None) -> Path:
    """A new empty hidden file in ``folder`` that keeps ``final``'s suffix (savefig and
    savez choose the format from it)."""
    try:
        fd, name = tempfile.mkstemp(dir=folder, prefix=f".{final.name[:80]}.", suffix=f".part{final.suffix}")
    except OSError as e:
        raise write_failed(final, f"cannot write in {display_path(folder)} ({_problem(e)})", flag) from None
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
        raise write_failed(final, e, flag) from None


def _remove_created(created: list) -> None:
    for d in reversed(created):
        with contextlib.suppress(OSError):
            os.rmdir(d)      # only if empty
    created.clear()


class _Temp:
    """One temporary file being written: ``tmp`` (renamed onto ``final``), the bytes the writer
    handed over when known (``expected``) and an optional read-back check (``verify``)."""

    def __init__(self, tmp: Path, final: Path, expected=None, verify=None):
        self.tmp, self.final, self.expected, self.verify = tmp, final, expected, verify


@contextlib.contextmanager
def _atomic(path, flag, verify=None):
    """Yield a :class:`_Temp` next to ``path``; when the block ends without an exception the
    file is checked (:func:`_finish`) and renamed onto ``path``; otherwise, or when the check
    fails, it is removed (with the folders created for it) and ``path`` is left as it was.
    ``OSError`` in the block or the check is an :class:`OutputError` naming ``path``."""
    final = Path(path)
    if final.is_symlink():
        final = Path(os.path.realpath(final))
    created: list = []
    _make_dirs(final.parent, created, flag)
    t = _Temp(_temp_in(final.parent, final, flag), final, verify=verify)
    try:
        try:
            yield t
            _finish(t.tmp, t.expected, t.verify)
        except OSError as e:
            raise write_failed(final, e, flag) from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(t.tmp)
        _remove_created(created)
        raise
    try:
        _replace(t.tmp, final, flag)
    except OutputError:
        _remove_created(created)
        raise
    _fsync_dir(final.parent)


@contextlib.contextmanager
def atomic_path(path, flag: str | None = None, verify=None):
    """Yield a temporary path next to ``path`` (same suffix) to write the file to; on success
    it is flushed, checked non-empty (and by ``verify(tmp)``, which raises ``OSError`` when the
    file is not what was meant) and renamed onto ``path`` (parent folders created); on an
    exception or a failed check it is removed and ``path`` is left as it was."""
    with _atomic(path, flag, verify) as t:
        yield t.tmp


class _Tracked:
    """The writer's view of a temporary file opened by :func:`_open_counting`: ``write`` takes
    ``str`` (``text``: UTF-8, no newline translation) or bytes-like data and counts what it was
    handed; ``end`` is the furthest position written, the size the writer means the file to
    have (``seek`` and ``tell`` are followed, so a zip writer that rewrites its headers counts
    once). Everything else is the binary file's."""

    def __init__(self, raw, text: bool):
        self._raw, self._text = raw, text
        self._pos = self.end = 0

    def write(self, data) -> int:
        b = data.encode("utf-8") if self._text else data
        self._raw.write(b)
        n = memoryview(b).nbytes
        self._pos += n
        self.end = max(self.end, self._pos)
        return len(data) if self._text else n

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        self._pos = self._raw.seek(offset, whence)
        return self._pos

    def tell(self) -> int:
        return self._pos

    def __getattr__(self, name):          # flush, fileno, seekable, ... of the binary file
        return getattr(self._raw, name)


@contextlib.contextmanager
def _open_counting(t: _Temp, mode: str):
    """Open ``t.tmp`` for writing (``"w"`` UTF-8 text, ``"wb"`` bytes) as a :class:`_Tracked`
    file; when the block ends the file is flushed, fsynced and closed, and ``t.expected`` is the
    size the writer meant it to have."""
    with open(t.tmp, "wb") as raw:
        f = _Tracked(raw, "b" not in mode)
        yield f
        raw.flush()
        os.fsync(raw.fileno())
        t.expected = f.end


@contextlib.contextmanager
def atomic_write(path, mode: str = "w", flag: str | None = None):
    """Open a temporary file next to ``path`` for writing (``"w"``: UTF-8 text, ``"wb"``:
    bytes); renamed onto ``path`` when the block ends without an exception and the file on disk
    has every byte written (a short or failed write is a one-line :class:`OutputError`)."""
    with _atomic(path, flag) as t, _open_counting(t, mode) as f:
        yield f


#: The last 12 bytes of every complete PNG file (an empty IEND chunk and its CRC).
_PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"


def png_complete(path) -> None:
    """Raise ``OSError`` unless the file ``path`` starts with the PNG signature and ends with
    the IEND chunk (a PNG cut short by a full disk does not)."""
    with open(path, "rb") as f:
        head = f.read(8)
        size = f.seek(0, os.SEEK_END)
        f.seek(max(size - len(_PNG_END), 0))
        tail = f.read()
    if head != b"\x89PNG\r\n\x1a\n" or tail != _PNG_END:
        raise OSError(errno.EIO, f"the PNG written is incomplete ({size} bytes, no IEND chunk at its end)")


def save_figure(fig, path, outputs=None, dpi: int = 90) -> None:
    """Save the matplotlib figure ``fig`` as the PNG ``path`` and close it: staged in
    ``outputs`` (an :class:`OutputSet`, renamed into place by its commit) when given, else
    through a temporary file renamed onto ``path`` (:func:`atomic_path`); either way checked
    whole (:func:`png_complete`) before the rename."""
    import matplotlib.pyplot as plt

    try:
        if outputs is not None:
            with outputs.writing(path, verify=png_complete) as tmp:
                fig.savefig(tmp, dpi=dpi, format="png")
        else:
            with atomic_path(path, verify=png_complete) as tmp:
                fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        plt.close(fig)


class OutputSet:
    """All outputs of one run: staged as temporary files (:meth:`stage`, :meth:`writing`,
    :meth:`write_bytes`, :meth:`write_text`), checked and renamed into place by :meth:`commit`
    when the run has succeeded, removed by :meth:`abort` otherwise. Use as a context manager:
    leaving the block without :meth:`commit` aborts, and a write error (``ENOSPC``, ``EIO``,
    ...) raised in the block is an :class:`OutputError` naming the output last staged."""

    def __init__(self, flag: str | None = "--out"):
        self.flag = flag
        self._staged: list = []     # _Temp
        self._created: list = []
        self.committed: list = []

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        last = self._staged[-1].final if self._staged else None
        if self._staged or self._created:
            self.abort()
        if isinstance(exc, OSError) and exc.errno in _WRITE_ERRNOS and last is not None:
            raise write_failed(last, exc, self.flag) from None
        return False

    def stage(self, final, verify=None) -> Path:
        """A temporary path for the output ``final`` (its folders are created, and removed
        again on abort); the caller writes the whole file there. ``verify(tmp)``, when given,
        is called by :meth:`commit` before any rename and raises ``OSError`` when the file does
        not hold what was meant."""
        return self._stage(final, verify).tmp

    def _stage(self, final, verify=None) -> _Temp:
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
        t = _Temp(_temp_in(final.parent, final, self.flag), final, verify=verify)
        self._staged.append(t)
        _STAGED[os.fspath(t.tmp)] = (final, self.flag)
        return t

    @contextlib.contextmanager
    def writing(self, final, verify=None):
        """Stage ``final`` and yield its temporary path to a writer that writes by name (an
        ``OSError`` it raises is an :class:`OutputError` naming ``final``)."""
        tmp = self.stage(final)
        self._staged[-1].verify = verify
        try:
            yield tmp
        except OSError as e:
            raise write_failed(final, e, self.flag) from None

    def write_bytes(self, final, data: bytes) -> Path:
        """Stage ``final`` holding ``data``; :meth:`commit` checks every byte is on disk."""
        self.stage(final)
        t = self._staged[-1]
        try:
            with _open_counting(t, "wb") as f:
                f.write(data)
        except OSError as e:
            raise write_failed(final, e, self.flag) from None
        return t.tmp

    def write_text(self, final, text: str) -> Path:
        """Stage ``final`` holding ``text`` (UTF-8, ``\n`` line ends)."""
        return self.write_bytes(final, text.encode("utf-8"))

    def commit(self) -> list:
        """Check every staged file (:func:`_finish`: fsync, size, ``verify``), then, only when
        all are complete, rename each onto its final name; returns the final paths. A failed
        check removes every staged file and leaves every final path as it was."""
        for t in self._staged:
            try:
                _finish(t.tmp, t.expected, t.verify)
            except OSError as e:
                self.abort()
                raise write_failed(t.final, e, self.flag) from None
        staged, self._staged = self._staged, []
        for t in staged:
            _STAGED.pop(os.fspath(t.tmp), None)
        try:
            for k, t in enumerate(staged):
                _replace(t.tmp, t.final, self.flag)
                self.committed.append(t.final)
        except OutputError:
            for u in staged[k + 1:]:
                with contextlib.suppress(OSError):
                    os.unlink(u.tmp)
            raise
        for folder in {t.final.parent for t in staged}:
            _fsync_dir(folder)
        self._created.clear()
        return list(self.committed)

    def abort(self) -> None:
        """Remove the staged files and the folders this run created."""
        for t in self._staged:
            _STAGED.pop(os.fspath(t.tmp), None)
            with contextlib.suppress(OSError):
                os.unlink(t.tmp)
        self._staged.clear()
        _remove_created(self._created)
