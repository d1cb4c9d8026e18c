"""Image metrics of the studies: RMSE on an object mask, and CIE ΔE2000 of linear Rec.709 images
at a stated exposure (linear RGB -> XYZ -> CIE Lab with colour-science, the ``studies`` extra)."""
from __future__ import annotations

import numpy as np


def rmse(img, ref, mask) -> float:
    d = (np.asarray(img, np.float64) - np.asarray(ref, np.float64))[mask]
    return float(np.sqrt(np.mean(d * d))) if d.size else float("nan")


def exposure_for(ref, mask, percentile: float = 99.0) -> float:
    """Scale that maps the ``percentile`` of the reference's luminance on ``mask`` to Y = 1
    (the Lab white), so ΔE is measured at a fixed, stated exposure per scene."""
    Y = np.asarray(ref, np.float64)[mask] @ np.array([0.2126, 0.7152, 0.0722])
    v = np.percentile(Y, percentile) if Y.size else 1.0
    return float(1.0 / v) if v > 0 else 1.0


def rgb_to_lab(img, exposure: float = 1.0) -> np.ndarray:
    import colour

    cs = colour.RGB_COLOURSPACES["ITU-R BT.709"]
    rgb = np.asarray(img, np.float64) * exposure
    xyz = colour.RGB_to_XYZ(rgb, cs, illuminant=cs.whitepoint, chromatic_adaptation_transform=None,
                            apply_cctf_decoding=False)
    return colour.XYZ_to_Lab(xyz, cs.whitepoint)


def delta_e2000(img, ref, exposure: float = 1.0) -> np.ndarray:
    """Per-pixel CIE ΔE2000 between two linear Rec.709 images at the same exposure."""
    import colour

    return colour.delta_E(rgb_to_lab(img, exposure), rgb_to_lab(ref, exposure), method="CIE 2000")


def de_stats(de, mask) -> dict:
    v = np.asarray(de)[mask]
    return {"mean": float(v.mean()), "p99": float(np.percentile(v, 99)), "max": float(v.max())} if v.size \
        else {"mean": float("nan"), "p99": float("nan"), "max": float("nan")}
