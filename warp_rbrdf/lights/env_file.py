"""Environment images: lat-long ``.exr`` / ``.hdr`` files read and checked, the constant
environment, and :func:`environment_image`, the (H, W, 3) float32 radiance of a light spec.

Every problem is a one-line :class:`~warp_rbrdf.errors.SceneError` naming the scene key; texels
are checked, never clamped or zeroed (robustness.md)."""
from __future__ import annotations

import os

import numpy as np

from fit.errors import BRDFFileError, display_path
from fit.inputs import open_regular

from .. import limits
from ..errors import SceneError
from ..image_io import oiio_filename
from .sky import sky_image

#: First bytes of the environment-map formats (OpenEXR magic number; Radiance "#?").
_MAGIC = {".exr": b"\x76\x2f\x31\x01", ".hdr": b"#?"}


def read_latlong(path, file="<scene>", key="file") -> np.ndarray:
    """(H, W, 3) float32 linear RGB of an HDR/EXR lat-long map (OpenImageIO), validated by
    :func:`check_texels`.

    Before reading: a regular file (a named pipe or folder is refused, never opened) of at
    most :data:`~warp_rbrdf.limits.MAX_ENV_BYTES`, and the size its header states within
    :func:`warp_rbrdf.limits.check_env_size` (a compressed EXR of a few kB can state
    10^5 x 10^5 texels). Each problem is a one-line :class:`SceneError` naming the key."""
    import OpenImageIO as oiio

    shown = display_path(path)
    try:
        with open_regular(path, limits.MAX_ENV_BYTES, "environment map") as f:
            magic = f.read(4)
    except BRDFFileError as e:
        raise SceneError(file, key, f"environment map {shown}: {e.problem}") from None
    except OSError as e:
        raise SceneError(file, key, f"environment map {shown}: cannot read ({e.strerror or e})") from None
    # the format must match the suffix: OpenImageIO would otherwise try every reader it has on
    # the bytes (libpng then prints to stderr)
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    want = _MAGIC.get(suffix)
    if want is not None and not magic.startswith(want):
        raise SceneError(file, key, f"environment map {shown}: not a{'n OpenEXR' if suffix == '.exr' else ' Radiance HDR'} "
                                    f"file (it starts with {magic!r})")
    with oiio_filename(path) as name:   # OpenImageIO takes only UTF-8 names
        inp = oiio.ImageInput.open(name)
    if inp is None:
        err = " ".join(oiio.geterror().split())[:160]
        raise SceneError(file, key, f"cannot open environment map {shown} ({err})")
    try:
        spec = inp.spec()
        W, H, C = int(spec.width), int(spec.height), int(spec.nchannels)
        problem = limits.check_env_size(W, H)
        if problem:
            raise SceneError(file, key, f"environment map {shown}: {problem}")
        if not 1 <= C <= 64 or spec.depth > 1:
            raise SceneError(file, key, f"environment map {shown}: expected a 2-D image with 1 to 64 channels, "
                                        f"got {C} channels, depth {spec.depth}")
        px = inp.read_image(0, 0, 0, min(C, 3), oiio.FLOAT)
        if px is None:
            err = " ".join(inp.geterror().split())[:160]
            raise SceneError(file, key, f"cannot read environment map {shown} ({err})")
    finally:
        inp.close()
    px = np.asarray(px, np.float32)
    if px.size != H * W * min(C, 3):
        raise SceneError(file, key, f"cannot read environment map {shown} (got {px.size} values for "
                                    f"{W} x {H} x {min(C, 3)})")
    px = px.reshape(H, W, -1)
    if px.shape[2] < 3:
        px = np.repeat(px[:, :, :1], 3, axis=2)
    px = np.ascontiguousarray(px[:, :, :3])
    check_texels(px, file, key, shown)
    return px


def check_texels(img: np.ndarray, file="<scene>", key="file", what="environment map") -> None:
    """Policy for texels: every texel of an environment image must be finite, >= 0 and at most
    :data:`~warp_rbrdf.limits.MAX_ENV_TEXEL`; otherwise a one-line :class:`SceneError` with
    the count and the first bad texel (row, column). Nothing is clamped or zeroed silently."""
    bad = ~np.isfinite(img) | (img < 0) | (img > limits.MAX_ENV_TEXEL)
    if bad.any():
        flat = bad.reshape(-1, img.shape[-1]).any(axis=1)
        n = int(flat.sum())
        j, i = divmod(int(np.flatnonzero(flat)[0]), img.shape[1])
        v = img[j, i]
        kind = "NaN" if np.isnan(v).any() else "infinite" if np.isinf(v).any() else \
            "negative" if (v < 0).any() else f"above {limits.MAX_ENV_TEXEL:g}"
        raise SceneError(file, key, f"{what}: {n} of {img.shape[0] * img.shape[1]} texels are NaN, infinite, "
                                    f"negative or above {limits.MAX_ENV_TEXEL:g} (first: row {j}, column {i}, "
                                    f"{kind}); texels are refused, never clamped")


def constant_image(radiance) -> np.ndarray:
    """A (4, 8, 3) float32 map of one radiance (the constant environment; its lookup is
    exactly that radiance everywhere)."""
    return np.tile(np.asarray(radiance, np.float32), (4, 8, 1))


def environment_image(light, file="<scene>", key="lights") -> np.ndarray:
    """(H, W, 3) float32 radiance of an environment light (its texels times its ``scale``);
    texels are checked (:func:`check_texels`): a map with NaN, infinite or negative texels is
    refused, not repaired."""
    if light.image is not None:
        img = np.asarray(light.image, np.float32)
        if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 2:
            raise SceneError(file, key, f"in-memory environment image: expected (H >= 2, W, 3), got {img.shape}")
        check_texels(img, file, key, "in-memory environment image")
    elif light.type == "envmap":
        img = read_latlong(light.file, file, f"{key}.file")
    elif light.type == "constant":
        img = constant_image(light.radiance)
    else:
        img = sky_image(light.resolution[0], light.resolution[1], light.sun_elevation, light.sun_azimuth)
    scale = float(light.scale) if light.type != "constant" else 1.0
    if not (np.isfinite(scale) and 0.0 <= scale <= limits.MAX_ENV_SCALE):
        raise SceneError(file, f"{key}.scale", f"expected a number in [0, {limits.MAX_ENV_SCALE:g}], got {scale!r}")
    return (img * np.float32(scale)).astype(np.float32)
