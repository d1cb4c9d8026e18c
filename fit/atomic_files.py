"""Writing one file atomically, so that a failing write loses nothing: the file is written to a
hidden temporary file in the folder of its final name and renamed onto that name
(``os.replace``, atomic on one file system) only when it is complete; an existing file is either
left as it was or replaced by a whole new one, never truncated or half-written.

* :func:`atomic_write` (a file object) / :func:`atomic_path` (a path, for writers that write by
  name): the ``save`` functions of the library; :func:`save_figure`, :func:`png_complete`;
* the parts :class:`fit.outputs.OutputSet` stages a run's outputs with (:class:`TempFile`,
  :func:`temp_in`, :func:`make_dirs`, :func:`finish`, :func:`replace_onto`, :func:`open_counting`,
  :func:`stage_name`);
* :func:`write_failed`: the one-line :class:`fit.errors.OutputError` of a failed write.

Before a temporary file is renamed it is checked (:func:`finish`): flushed to the disk
(``os.fsync``, which reports the write errors a file system delays), its size on disk equal to
the bytes the writer handed over (:func:`atomic_write`, :meth:`fit.outputs.OutputSet.write_bytes`)
or at least non-empty (writers that write by path, such as OpenImageIO or matplotlib, which may
fail silently on a full disk), and read back by a ``verify`` function when one is given. A
failure (``ENOSPC``, ``EIO``, a short file) is one :class:`fit.errors.OutputError` naming the
final path, e.g. ``--out x.exr: no space left on device; nothing written, x.exr unchanged``;
the temporary files are removed and every existing output is left as it was.

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


def _umask_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def make_dirs(folder: Path, created: list, flag=None) -> None:
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
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS})

#: Staged temporary file (its ``os.fspath``) -> (final path, flag) while an OutputSet holds it:
#: a ``save`` function writing a staged file atomically names the final output in its errors.
_STAGED: dict = {}


def stage_name(tmp, final, flag) -> None:
    """Name ``final`` (and its ``flag``) in the errors about writing the staged file ``tmp``."""
    _STAGED[os.fspath(tmp)] = (final, flag)


def unstage_name(tmp) -> None:
    """``tmp`` is no longer staged (renamed or removed)."""
    _STAGED.pop(os.fspath(tmp), None)


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


def finish(tmp: Path, expected: int | None = None, verify=None) -> None:
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


def fsync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable (best effort: the file is already in place)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def temp_in(folder: Path, final: Path, flag=None) -> Path:
    """A new empty hidden file in ``folder`` that keeps ``final``'s suffix (savefig and
    savez choose the format from it)."""
    try:
        fd, name = tempfile.mkstemp(dir=folder, prefix=f".{final.name[:80]}.", suffix=f".part{final.suffix}")
    except OSError as e:
        raise write_failed(final, f"cannot write in {display_path(folder)} ({_problem(e)})", flag) from None
    os.close(fd)
    return Path(name)


def replace_onto(tmp: Path, final: Path, flag=None) -> None:
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


def remove_created(created: list) -> None:
    for d in reversed(created):
        with contextlib.suppress(OSError):
            os.rmdir(d)      # only if empty
    created.clear()


class TempFile:
    """One temporary file being written: ``tmp`` (renamed onto ``final``), the bytes the writer
    handed over when known (``expected``) and an optional read-back check (``verify``)."""

    def __init__(self, tmp: Path, final: Path, expected=None, verify=None):
        self.tmp, self.final, self.expected, self.verify = tmp, final, expected, verify


@contextlib.contextmanager
def _atomic(path, flag, verify=None):
    """Yield a :class:`TempFile` next to ``path``; when the block ends without an exception the
    file is checked (:func:`finish`) and renamed onto ``path``; otherwise, or when the check
    fails, it is removed (with the folders created for it) and ``path`` is left as it was.
    ``OSError`` in the block or the check is an :class:`OutputError` naming ``path``."""
    final = Path(path)
    if final.is_symlink():
        final = Path(os.path.realpath(final))
    created: list = []
    make_dirs(final.parent, created, flag)
    t = TempFile(temp_in(final.parent, final, flag), final, verify=verify)
    try:
        try:
            yield t
            finish(t.tmp, t.expected, t.verify)
        except OSError as e:
            raise write_failed(final, e, flag) from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(t.tmp)
        remove_created(created)
        raise
    try:
        replace_onto(t.tmp, final, flag)
    except OutputError:
        remove_created(created)
        raise
    fsync_dir(final.parent)


@contextlib.contextmanager
def atomic_path(path, flag: str | None = None, verify=None):
    """Yield a temporary path next to ``path`` (same suffix) to write the file to; on success
    it is flushed, checked non-empty (and by ``verify(tmp)``, which raises ``OSError`` when the
    file is not what was meant) and renamed onto ``path`` (parent folders created); on an
    exception or a failed check it is removed and ``path`` is left as it was."""
    with _atomic(path, flag, verify) as t:
        yield t.tmp


class _Tracked:
    """The writer's view of a temporary file opened by :func:`open_counting`: ``write`` takes
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
def open_counting(t: TempFile, mode: str):
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
    with _atomic(path, flag) as t, open_counting(t, mode) as f:
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
