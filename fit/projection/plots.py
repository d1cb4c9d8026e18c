"""PNG plots of a projected BRDF (matplotlib, non-interactive Agg backend).

* ``<name>_mean.png`` / ``<name>_variance.png``: per-cluster mean and normalized variance
  (variance / mean^2) over (theta_h, theta_d) in degrees, per channel, log colour scale.
* ``<name>_isolines.png``: the isolines theta_h = 0 (value vs theta_d) and theta_d = 0
  (value vs theta_h) for R, G, B, with the grazing region theta_d >= 80 deg shaded.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .projected import ProjectedBRDF
from ..outputs import save_figure

GRAZING_DEG = 80.0
_CHANNEL_COLOURS = ("tab:red", "tab:green", "tab:blue")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _map_figure(plt, data: np.ndarray, p: ProjectedBRDF, title: str, label: str):
    from matplotlib.colors import LogNorm

    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8), constrained_layout=True)
    th = np.degrees(p.theta_h)
    td = np.degrees(p.theta_d)
    finite = data[np.isfinite(data) & (data > 0)]
    norm = None
    if finite.size:
        lo, hi = np.percentile(finite, [1, 100])
        norm = LogNorm(vmin=max(lo, hi * 1e-8), vmax=hi)
    for c, ax in enumerate(axes):
        img = np.where(np.isfinite(data[..., c]) & (data[..., c] > 0), data[..., c], np.nan)
        m = ax.pcolormesh(td, th, img, norm=norm, shading="nearest", cmap="viridis")
        ax.set_xlabel("θd (deg)")
        ax.set_ylabel("θh (deg)")
        ax.set_title(f"{title}: {'RGB'[c]}")
        ax.axvline(GRAZING_DEG, color="w", lw=0.8, ls="--")
    fig.colorbar(m, ax=axes, label=label, shrink=0.9)
    return fig


def plot_projection(p: ProjectedBRDF, out_dir, outputs=None) -> list[Path]:
    """Write the three PNG files for ``p`` into ``out_dir``; returns their paths. ``outputs``:
    an :class:`fit.outputs.OutputSet` to stage them in (the caller commits), else each is
    written atomically at once."""
    plt = _pyplot()
    out = Path(out_dir)
    files = []

    fig = _map_figure(plt, p.mean, p, f"{p.name} cluster mean", "mean ρ (1/sr)")
    files.append(out / f"{p.name}_mean.png")
    save_figure(fig, files[-1], outputs)

    fig = _map_figure(plt, p.normalized_variance, p, f"{p.name} variance/mean²", "normalized variance")
    files.append(out / f"{p.name}_variance.png")
    save_figure(fig, files[-1], outputs)

    fig, (a0, a1) = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    td = np.degrees(p.theta_d)
    th = np.degrees(p.theta_h)
    for c in range(3):
        a0.semilogy(td, p.value[0, :, c], color=_CHANNEL_COLOURS[c], label="RGB"[c])
        a1.semilogy(th, p.value[:, 0, c], color=_CHANNEL_COLOURS[c], label="RGB"[c])
    a0.set_xlabel("θd (deg)")
    a0.set_title(f"{p.name}: θh = 0 (first θh bin)")
    a1.set_xlabel("θh (deg)")
    a1.set_title(f"{p.name}: θd = 0 (first θd bin)")
    for a in (a0, a1):
        a.set_ylabel(f"{p.statistic} ρ (1/sr)")
        a.legend()
        a.grid(True, which="both", alpha=0.3)
    a0.axvspan(GRAZING_DEG, 90, color="0.85", label="θd ≥ 80° (grazing)")
    a0.text(GRAZING_DEG + 1, a0.get_ylim()[1], "grazing", va="top", fontsize=8)
    files.append(out / f"{p.name}_isolines.png")
    save_figure(fig, files[-1], outputs)
    return files
