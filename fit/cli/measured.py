"""``rbrdf-fit info``, ``rbrdf-fit project`` and ``rbrdf-fit plot``: what a measured BRDF file
holds, its (theta_h, theta_d) projection saved as ``.npz``, and PNG plots of the projection.

Angles are printed in degrees, BRDF values in 1/sr.
"""
from __future__ import annotations

from pathlib import Path

from ..formats import load_measured
from ..projection.albedo import directional_albedo
from ..projection.plots import plot_projection
from ..projection.project import GRAZING_ANGLES, STATISTICS, project


def _cmd_info(args) -> int:
    b = load_measured(args.file)
    print(f"file            {b.source}")
    print(f"material        {b.name}")
    if b.metadata.get("description"):
        print(f"description     {b.metadata['description']}")
    print(f"grid            theta_h x theta_d x phi_d = {b.values.shape[0]} x {b.values.shape[1]} x "
          f"{b.values.shape[2]}, channels RGB")
    print(f"valid fraction  {b.valid_fraction:.4f}")
    for c, ch in enumerate("RGB"):
        v = b.values[..., c][b.valid[..., c]]
        lo, hi = (float(v.min()), float(v.max())) if v.size else (float("nan"),) * 2
        print(f"range {ch}         [{lo:.4g}, {hi:.4g}] 1/sr  ({v.size} valid samples)")
    a = directional_albedo(b.evaluate, 0.0)
    print(f"albedo (theta_i = 0)  R {a[0]:.4f}  G {a[1]:.4f}  B {a[2]:.4f}")
    return 0


def _add_projection_args(p) -> None:
    p.add_argument("--statistic", choices=STATISTICS, default="median",
                   help="cluster statistic stored as the projected value (default: median)")
    p.add_argument("--grazing-cutoff", type=float, default=None, metavar="DEG",
                   help="drop samples beyond this angle in degrees before the statistics (e.g. 80)")
    p.add_argument("--grazing-angle", choices=GRAZING_ANGLES, default="theta_io",
                   help="angle the cut-off applies to: max(theta_i, theta_o) (default) or theta_d")


def _project_from_args(args):
    return project(load_measured(args.file), statistic=args.statistic,
                   grazing_cutoff_deg=args.grazing_cutoff, grazing_angle=args.grazing_angle)


def _cmd_project(args) -> int:
    p = _project_from_args(args)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    p.save(out)
    empty = int((p.count[..., 0] == 0).sum())
    print(f"projected {p.name} onto (theta_h, theta_d) with the {p.statistic}: 90 x 90 clusters, "
          f"{empty} empty; wrote {out}")
    return 0


def _cmd_plot(args) -> int:
    p = _project_from_args(args)
    files = plot_projection(p, args.out)
    for f in files:
        print(f"wrote {f}")
    return 0


def register(sub) -> None:
    """Add ``info``, ``project`` and ``plot`` to the sub-parsers ``sub``."""
    p = sub.add_parser("info", help="dimensions, valid fraction, value range and normal-incidence albedo",
                       description="Print what a measured BRDF file holds.")
    p.add_argument("file", help="MERL .binary or RGL .bsdf file")
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser("project", help="project onto (theta_h, theta_d) and save an .npz",
                       description="Project the 3-D (theta_h, theta_d, phi_d) data onto the 90x90 "
                                   "(theta_h, theta_d) clusters (median by default).")
    p.add_argument("file", help="MERL .binary or RGL .bsdf file")
    p.add_argument("--out", required=True, help="output .npz file")
    _add_projection_args(p)
    p.set_defaults(func=_cmd_project)

    p = sub.add_parser("plot", help="PNG maps of cluster mean/variance and the theta_h=0 / theta_d=0 isolines",
                       description="Plot the projection: per-cluster mean and normalized variance maps "
                                   "over (theta_h, theta_d), and the isolines theta_h = 0 and "
                                   "theta_d = 0 for R, G, B with the theta_d >= 80 deg region marked.")
    p.add_argument("file", help="MERL .binary or RGL .bsdf file")
    p.add_argument("--out", required=True, help="output folder for the PNG files")
    _add_projection_args(p)
    p.set_defaults(func=_cmd_plot)
