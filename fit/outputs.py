"""Writing outputs so that a failing run loses nothing: :class:`OutputSet`, every output of one
command-line run, staged as temporary files and renamed into place together by
:meth:`OutputSet.commit` only when the whole run has succeeded; :meth:`OutputSet.abort` (any
error, a non-zero exit, Ctrl-C) removes the temporary files and the folders the run created.

The public face of the fitter's outputs, from three modules:

* :mod:`fit.output_paths`: :func:`check_output_file` / :func:`check_output_dir`, the checks a
  run makes on its output paths *before* it reads or computes anything;
* :mod:`fit.atomic_files`: one file written atomically (:func:`atomic_write`,
  :func:`atomic_path`, :func:`save_figure`), the checks before a rename (fsync, size, a
  ``verify`` function, :func:`png_complete`) and the one-line errors (:func:`write_failed`);
* this module: :class:`OutputSet`.
"""
from __future__ import annotations

import contextlib
import os
import stat
from pathlib import Path

from .atomic_files import (
    WRITE_ERRNOS,
    TempFile,
    atomic_path,
    atomic_write,
    finish,
    fsync_dir,
    make_dirs,
    no_space_left,
    open_counting,
    png_complete,
    remove_created,
    replace_onto,
    save_figure,
    stage_name,
    temp_in,
    unstage_name,
    write_failed,
)
from .errors import OutputError
from .output_paths import check_output_dir, check_output_file, file_kind

__all__ = ["OutputError", "OutputSet", "atomic_path", "atomic_write", "check_output_dir", "check_output_file",
           "no_space_left", "png_complete", "save_figure", "write_failed"]


class OutputSet:
    """All outputs of one run: staged as temporary files (:meth:`stage`, :meth:`writing`,
    :meth:`write_bytes`, :meth:`write_text`), checked and renamed into place by :meth:`commit`
    when the run has succeeded, removed by :meth:`abort` otherwise. Use as a context manager:
    leaving the block without :meth:`commit` aborts, and a write error (``ENOSPC``, ``EIO``,
    ...) raised in the block is an :class:`OutputError` naming the output last staged."""

    def __init__(self, flag: str | None = "--out"):
        self.flag = flag
        self._staged: list = []     # TempFile
        self._created: list = []
        self.committed: list = []

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        last = self._staged[-1].final if self._staged else None
        if self._staged or self._created:
            self.abort()
        if isinstance(exc, OSError) and exc.errno in WRITE_ERRNOS and last is not None:
            raise write_failed(last, exc, self.flag) from None
        return False

    def stage(self, final, verify=None) -> Path:
        """A temporary path for the output ``final`` (its folders are created, and removed
        again on abort); the caller writes the whole file there. ``verify(tmp)``, when given,
        is called by :meth:`commit` before any rename and raises ``OSError`` when the file does
        not hold what was meant."""
        return self._stage(final, verify).tmp

    def _stage(self, final, verify=None) -> TempFile:
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
            raise OutputError(final, f"is a {file_kind(st.st_mode)}; refusing to replace it", self.flag)
        make_dirs(final.parent, self._created, self.flag)
        t = TempFile(temp_in(final.parent, final, self.flag), final, verify=verify)
        self._staged.append(t)
        stage_name(t.tmp, final, self.flag)
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
            with open_counting(t, "wb") as f:
                f.write(data)
        except OSError as e:
            raise write_failed(final, e, self.flag) from None
        return t.tmp

    def write_text(self, final, text: str) -> Path:
        """Stage ``final`` holding ``text`` (UTF-8, ``\n`` line ends)."""
        return self.write_bytes(final, text.encode("utf-8"))

    def commit(self) -> list:
        """Check every staged file (:func:`finish`: fsync, size, ``verify``), then, only when
        all are complete, rename each onto its final name; returns the final paths. A failed
        check removes every staged file and leaves every final path as it was."""
        for t in self._staged:
            try:
                finish(t.tmp, t.expected, t.verify)
            except OSError as e:
                self.abort()
                raise write_failed(t.final, e, self.flag) from None
        staged, self._staged = self._staged, []
        for t in staged:
            unstage_name(t.tmp)
        try:
            for k, t in enumerate(staged):
                replace_onto(t.tmp, t.final, self.flag)
                self.committed.append(t.final)
        except OutputError:
            for u in staged[k + 1:]:
                with contextlib.suppress(OSError):
                    os.unlink(u.tmp)
            raise
        for folder in {t.final.parent for t in staged}:
            fsync_dir(folder)
        self._created.clear()
        return list(self.committed)

    def abort(self) -> None:
        """Remove the staged files and the folders this run created."""
        for t in self._staged:
            unstage_name(t.tmp)
            with contextlib.suppress(OSError):
                os.unlink(t.tmp)
        self._staged.clear()
        remove_created(self._created)
