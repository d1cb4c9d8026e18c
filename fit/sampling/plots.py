"""Plots of the sampling densities and inverse CDFs (``rbrdf-fit plot-cdf``), as in the
supplementary figures 6-9: PDF_v(theta_l) and CDF^-1_v(mu) for theta_v = 0, 45, 85 deg, and slices
of PDF_v(phi_l | theta_l) and CDF^-1_v(tau | theta_l) for several theta_v (tabulated: solid;
rational maps, when verified: dashed; in the pieces layout only view rows with rational maps
show a dashed curve, the others are sampled with the table)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..outputs import save_figure
from .table import inverse_cdf_phi, inverse_cdf_theta, pdf_phi, pdf_theta


def plot_cdf(fit, out_dir, prefix: str = "cdf", outputs=None) -> list:
    """Write ``<prefix>_theta.png`` and ``<prefix>_phi.png`` into ``out_dir``; returns their
    paths. ``outputs``: an :class:`fit.outputs.OutputSet` to stage them in (the caller
    commits), else each is written atomically at once."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    t = fit.table
    rational = not fit.fallback
    files = []
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    mu = np.linspace(0, 1, 401)
    for tv_deg, c in ((0, "r"), (45, "g"), (85, "b")):
        tv = np.radians(tv_deg)
        e, p = pdf_theta(t, tv)
        ax[0].stairs(p, np.degrees(e), color=c, label=f"theta_v = {tv_deg} deg")
        ax[1].plot(mu, np.degrees(inverse_cdf_theta(t, [tv], mu)[0]), c, label=f"table, {tv_deg} deg")
        if rational:
            th = fit.inverse_theta(tv, mu)
            if np.isfinite(th).any():
                ax[1].plot(mu, np.degrees(th), "k--", lw=0.9, label=f"rational, {tv_deg} deg")
    ax[0].set(xlabel="theta_l (deg)", ylabel="PDF_v(theta_l) (1/rad)", title=f"{fit.name}: PDF_v(theta_l)")
    ax[1].set(xlabel="mu", ylabel="theta_l (deg)", title="CDF^-1_v(mu)")
    ax[0].legend(); ax[1].legend(fontsize=7)
    f1 = out / f"{prefix}_theta.png"
    fig.tight_layout()
    save_figure(fig, f1, outputs, dpi=100)
    files.append(f1)

    tvs = (0, 20, 45, 85)
    fig, ax = plt.subplots(2, len(tvs), figsize=(4 * len(tvs), 7))
    tau = np.linspace(0, 1, 401)
    for k, tv_deg in enumerate(tvs):
        tv = np.radians(tv_deg)
        for tl_deg, c in ((10, "r"), (tv_deg if tv_deg else 5, "g"), (70, "b")):
            tl = np.radians(tl_deg)
            e, p = pdf_phi(t, tv, tl)
            ax[0, k].stairs(p, np.degrees(e), color=c, label=f"theta_l = {tl_deg}")
            u = np.abs(2 * tau - 1)
            ph = np.sign(tau - 0.5) * inverse_cdf_phi(t, [tv], [tl], u)[0, 0]
            ax[1, k].plot(tau, np.degrees(ph), c, label=f"table, theta_l = {tl_deg}")
            if rational:
                g = fit.inverse_phi(tv, tl, u)
                if np.isfinite(g).any():
                    ax[1, k].plot(tau, np.degrees(np.sign(tau - 0.5) * g), "k--", lw=0.9,
                                  label=f"rational, theta_l = {tl_deg}")
        ax[0, k].set(title=f"PDF_v(phi_l | theta_l), theta_v = {tv_deg} deg", xlabel="phi_l (deg)")
        ax[1, k].set(title=f"CDF^-1_v(tau | theta_l), theta_v = {tv_deg} deg", xlabel="tau", ylabel="phi_l (deg)")
        ax[0, k].legend(fontsize=7); ax[1, k].legend(fontsize=7)
    f2 = out / f"{prefix}_phi.png"
    fig.tight_layout()
    save_figure(fig, f2, outputs, dpi=90)
    files.append(f2)
    return files
