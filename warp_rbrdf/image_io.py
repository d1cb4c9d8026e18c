"""Image output with OpenImageIO: linear float EXR and tone-mapped sRGB PNG.

The PNG is ``clip(linear * 2**exposure)`` encoded with the sRGB transfer curve; the exposure
(in stops) is written into the PNG metadata (``rbrdf:exposure_ev`` and the ``Comment``) and,
by :func:`png_path_for`, into the file name (``name_ev+0.0.png``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import RenderError


def srgb_encode(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def tonemap(img: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """uint8 sRGB image of linear ``img`` after ``exposure`` stops."""
    y = srgb_encode(np.nan_to_num(img, nan=0.0, posinf=1.0) * 2.0 ** exposure)
    return np.clip(np.round(y * 255.0), 0, 255).astype(np.uint8)


def _write(path: Path, pixels: np.ndarray, fmt, attrs: dict):
    import OpenImageIO as oiio

    path.parent.mkdir(parents=True, exist_ok=True)
    H, W, C = pixels.shape
    spec = oiio.ImageSpec(W, H, C, fmt)
    for k, v in attrs.items():
        spec.attribute(k, v)
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise RenderError(f"{path}: cannot create image writer ({oiio.geterror()})")
    try:
        if not out.open(str(path), spec):
            raise RenderError(f"{path}: cannot open for writing ({out.geterror()})")
        if not out.write_image(np.ascontiguousarray(pixels)):
            raise RenderError(f"{path}: cannot write image ({out.geterror()})")
    finally:
        out.close()


def write_exr(path, img: np.ndarray, attrs: dict | None = None):
    """Linear, unclamped float32 RGB EXR."""
    import OpenImageIO as oiio

    path = Path(path)
    a = {"compression": "zip"}
    a.update(attrs or {})
    _write(path, np.asarray(img, np.float32), oiio.FLOAT, a)


def write_png(path, img: np.ndarray, exposure: float = 0.0, attrs: dict | None = None):
    """sRGB PNG of linear ``img`` after ``exposure`` stops (stated in the metadata)."""
    import OpenImageIO as oiio

    path = Path(path)
    a = {"rbrdf:exposure_ev": f"{exposure:+.2f}",
         "Comment": f"linear render * 2^({exposure:+.2f}), clipped, sRGB transfer curve",
         "oiio:ColorSpace": "sRGB"}
    a.update(attrs or {})
    _write(path, tonemap(img, exposure), oiio.UINT8, a)


def png_path_for(exr_path, exposure: float) -> Path:
    p = Path(exr_path)
    return p.with_name(f"{p.stem}_ev{exposure:+.1f}.png")


def read_image(path) -> np.ndarray:
    """(H, W, C) float32 pixels of any image OpenImageIO reads."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise RenderError(f"{path}: cannot open image ({oiio.geterror()})")
    try:
        spec = inp.spec()
        px = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    finally:
        inp.close()
    return np.asarray(px, np.float32).reshape(spec.height, spec.width, spec.nchannels)
