"""Image output with OpenImageIO: linear float EXR and tone-mapped sRGB PNG.

The PNG is ``clip(linear * 2**exposure)`` encoded with the sRGB transfer curve; the exposure
(in stops) is written into the PNG metadata (``rbrdf:exposure_ev`` and the ``Comment``) and,
by :func:`png_path_for`, into the file name (``name_ev+0.0.png``).

:func:`write_exr` and :func:`write_png` write to a temporary file next to the target and rename
it into place when it is complete (:func:`fit.outputs.atomic_path`); ``rbrdf render`` instead
stages both in one :class:`fit.outputs.OutputSet` and renames them together. OpenImageIO can
report success for a file it could not write (on a full disk it leaves an empty file and every
call returns true), so every written image is read back (:func:`check_image_file`: the header's
size and channels and every pixel equal to what was written) before it is renamed; a failure is
an ``OSError`` that the caller names with the final output path.
:func:`nonfinite_pixels` is the check every rendered image passes before it is written.
"""
from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from fit.errors import display_path
from fit.outputs import atomic_path, no_space_left

from .errors import RenderError

#: Rows tone-mapped at a time (bounds the float temporaries of :func:`tonemap`).
_TONEMAP_ROWS = 256


def srgb_encode(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def tonemap(img: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """uint8 sRGB image (H, W, C) of linear ``img`` (H, W, C) after ``exposure`` stops,
    computed in blocks of rows (temporaries of a few MB whatever the image size)."""
    img = np.asarray(img)
    out = np.empty(img.shape, np.uint8)
    gain = np.float32(2.0 ** exposure)
    for r in range(0, img.shape[0], _TONEMAP_ROWS):
        blk = np.nan_to_num(img[r:r + _TONEMAP_ROWS].astype(np.float32), nan=0.0, posinf=1.0) * gain
        out[r:r + _TONEMAP_ROWS] = np.clip(np.round(srgb_encode(blk) * 255.0), 0, 255).astype(np.uint8)
    return out


def nonfinite_pixels(img: np.ndarray) -> tuple:
    """``(count, (row, column) of the first)`` of the pixels of ``img`` (H, W, C) with a NaN or
    infinite channel; ``(0, None)`` when every pixel is finite."""
    bad = ~np.isfinite(img).all(axis=-1)
    n = int(bad.sum())
    if n == 0:
        return 0, None
    j, i = divmod(int(np.argmax(bad.ravel())), img.shape[1])
    return n, (j, i)


def _utf8(path) -> bool:
    try:
        os.fspath(path).encode("utf-8")
    except UnicodeEncodeError:     # surrogate escapes of bytes that are not UTF-8
        return False
    return True


@contextlib.contextmanager
def oiio_filename(path, write: bool = False):
    """A ``str`` file name OpenImageIO accepts for ``path``. Its Python binding takes only valid
    UTF-8 names (a name with other bytes raised ``TypeError``); for such a path this yields a
    name in a fresh temporary folder: a symbolic link to ``path`` (reading), or a file that is
    moved onto ``path`` when the block ends without an exception (``write``)."""
    if _utf8(path):
        yield str(path)
        return
    tmpdir = tempfile.mkdtemp(prefix="rbrdf-oiio-")
    try:
        name = os.path.join(tmpdir, "image" + Path(path).suffix.encode("ascii", "replace").decode())
        if not write:
            os.symlink(os.path.abspath(path), name)
        yield name
        if write:
            shutil.move(name, os.fspath(path))
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


#: Rows read back at a time by :func:`check_image_file` (bounds its memory whatever the size).
_CHECK_ROWS = 256


def _write(path: Path, pixels: np.ndarray, fmt, attrs: dict, atomic: bool = True):
    """Write ``pixels`` (H, W, C) to ``path`` and read it back (:func:`check_image_file`);
    ``atomic``: through a temporary file next to it, renamed onto ``path`` when complete (an
    existing file is never left half-written; a failure is a one-line
    :class:`fit.errors.OutputError` naming ``path``). Without ``atomic`` a failure is an
    ``OSError``."""
    if atomic:
        with atomic_path(path) as tmp:
            _write(tmp, pixels, fmt, attrs, atomic=False)
        return
    if not _utf8(path):
        with oiio_filename(path, write=True) as name:
            _write(Path(name), pixels, fmt, attrs, atomic=False)
        return
    import OpenImageIO as oiio

    path.parent.mkdir(parents=True, exist_ok=True)
    H, W, C = pixels.shape
    spec = oiio.ImageSpec(W, H, C, fmt)
    for k, v in attrs.items():
        spec.attribute(k, v)
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise OSError(errno.EIO, f"cannot create an image writer ({_oneline(oiio.geterror())})")
    try:
        if not out.open(str(path), spec):
            raise OSError(errno.EIO, f"cannot open it for writing ({_oneline(out.geterror())})")
        if not out.write_image(np.ascontiguousarray(pixels)):
            raise OSError(errno.EIO, f"cannot write the image ({_oneline(out.geterror())})")
    finally:
        closed = out.close()
    if not closed:
        raise OSError(errno.EIO, f"cannot finish the image ({_oneline(out.geterror())})")
    check_image_file(path, pixels)


def check_image_file(path, pixels: np.ndarray) -> None:
    """Raise ``OSError`` unless the image file ``path`` reads back as ``pixels`` (H, W, C; float32
    or uint8, compared exactly, NaN equal to NaN), read in blocks of :data:`_CHECK_ROWS` rows:
    the check OpenImageIO's own return values cannot give (it reports success for an empty or
    truncated file on a full disk). ``errno.ENOSPC`` when the file system is full, else
    ``errno.EIO``."""
    path = Path(path)
    try:
        _compare(path, pixels)
    except OSError as e:
        if no_space_left(path.parent):
            raise OSError(errno.ENOSPC, f"No space left on device ({e.strerror})") from None
        raise


def _compare(path: Path, pixels: np.ndarray) -> None:
    import OpenImageIO as oiio

    if os.path.getsize(path) == 0:
        raise OSError(errno.EIO, "the image writer left an empty file")
    H, W, C = pixels.shape
    fmt = oiio.UINT8 if pixels.dtype == np.uint8 else oiio.FLOAT
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(errno.EIO, f"the written image cannot be read back ({_oneline(oiio.geterror())})")
    try:
        spec = inp.spec()
        if (spec.width, spec.height, spec.nchannels) != (W, H, C):
            raise OSError(errno.EIO, f"the written image reads back as {spec.width}x{spec.height}x"
                                     f"{spec.nchannels}, not {W}x{H}x{C}")
        for r in range(0, H, _CHECK_ROWS):
            e = min(H, r + _CHECK_ROWS)
            px = inp.read_scanlines(0, 0, r, e, 0, 0, C, fmt)
            if px is None:
                raise OSError(errno.EIO, f"the written image cannot be read back ({_oneline(inp.geterror())})")
            px = np.asarray(px).reshape(e - r, W, C)
            if not np.array_equal(px, pixels[r:e], equal_nan=fmt != oiio.UINT8):
                raise OSError(errno.EIO, f"the written image reads back different (rows {r}-{e - 1})")
    finally:
        inp.close()


def _oneline(text) -> str:
    return " ".join(str(text).split())[:200]


def write_exr(path, img: np.ndarray, attrs: dict | None = None, atomic: bool = True):
    """Linear, unclamped float32 RGB EXR of ``img`` (H, W, 3); ``atomic``: see :func:`_write`
    (False when ``path`` is already a staged temporary file)."""
    import OpenImageIO as oiio

    path = Path(path)
    a = {"compression": "zip"}
    a.update(attrs or {})
    _write(path, np.asarray(img, np.float32), oiio.FLOAT, a, atomic)


def write_png(path, img: np.ndarray, exposure: float = 0.0, attrs: dict | None = None, atomic: bool = True):
    """sRGB PNG of linear ``img`` (H, W, 3) after ``exposure`` stops (stated in the metadata)."""
    import OpenImageIO as oiio

    path = Path(path)
    a = {"rbrdf:exposure_ev": f"{exposure:+.2f}",
         "Comment": f"linear render * 2^({exposure:+.2f}), clipped, sRGB transfer curve",
         "oiio:ColorSpace": "sRGB"}
    a.update(attrs or {})
    _write(path, tonemap(img, exposure), oiio.UINT8, a, atomic)


def png_path_for(exr_path, exposure: float) -> Path:
    p = Path(exr_path)
    return p.with_name(f"{p.stem}_ev{exposure:+.1f}.png")


def read_image(path) -> np.ndarray:
    """(H, W, C) float32 pixels of any image OpenImageIO reads."""
    import OpenImageIO as oiio

    with oiio_filename(path) as name:
        inp = oiio.ImageInput.open(name)
        if inp is None:
            raise RenderError(f"{display_path(path)}: cannot open image ({_oneline(oiio.geterror())})")
        try:
            spec = inp.spec()
            px = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
        finally:
            inp.close()
    return np.asarray(px, np.float32).reshape(spec.height, spec.width, spec.nchannels)
