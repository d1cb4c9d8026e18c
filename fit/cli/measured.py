"""``rbrdf-fit info``, ``rbrdf-fit project`` and ``rbrdf-fit plot``: what a measured BRDF file
holds, its (theta_h, theta_d) projection saved as ``.npz``, and PNG plots of the projection.

Angles are printed in degrees, BRDF values in 1/sr. Outputs are checked before the input is
read and renamed into place only when the run succeeds (:class:`fit.outputs.OutputSet`).
"""
from __future__ import annotations

from ..errors import BRDFFileError, FlagError, display_path, display_text
from ..formats import load_measured
from ..outputs import OutputSet, check_output_dir, check_output_file
from ..projection.albedo import directional_albedo
from ..projection.plots import plot_projection
from ..projection.project import project
from ..projection.projected import GRAZING_ANGLES, STATISTICS
from ..progress import one_step
from .flags import add_run_flags, number


def _cmd_info(args) -> int:
    with one_step(getattr(args, "progress", None), "reading the file"):
        b = load_measured(args.file)
    print(f"file            {display_path(b.source)}")
    print(f"material        {display_text(b.name)}")
    if b.metadata.get("description"):
        print(f"description     {display_text(b.metadata['description'])}")
    print(f"grid            theta_h x theta_d x phi_d = {b.values.shape[0]} x {b.values.shape[1]} x "
          f"{b.values.shape[2]}, channels RGB")
    print(f"valid fraction  {b.valid_fraction:.4f}")
    for c, ch in enumerate("RGB"):
        v = b.values[..., c][b.valid[..., c]]
        lo, hi = float(v.min()), float(v.max())   # the reader guarantees a valid sample per channel
        print(f"range {ch}         [{lo:.4g}, {hi:.4g}] 1/sr  ({v.size} valid samples)")
    a = directional_albedo(b.evaluate, 0.0)
    print(f"albedo (theta_i = 0)  R {a[0]:.4f}  G {a[1]:.4f}  B {a[2]:.4f}")
    return 0


def _add_projection_args(p) -> None:
    p.add_argument("--statistic", choices=STATISTICS, default="median",
                   help="cluster statistic stored as the projected value (default: median)")
    p.add_argument("--grazing-cutoff", type=number(0.0, 90.0, lo_open=True), default=None, metavar="DEG",
                   help="drop samples beyond this angle in degrees, in (0, 90], before the statistics (e.g. 80)")
    p.add_argument("--grazing-angle", choices=GRAZING_ANGLES, default="theta_io",
                   help="angle the cut-off applies to: max(theta_i, theta_o) (default) or theta_d")
    add_run_flags(p)


def _project_from_args(args):
    progress = getattr(args, "progress", None)
    with one_step(progress, "reading the file"):
        b = load_measured(args.file)
    with one_step(progress, "projecting"):
        p = project(b, statistic=args.statistic, grazing_cutoff_deg=args.grazing_cutoff,
                    grazing_angle=args.grazing_angle)
    for c, ch in enumerate("RGB"):
        if not (p.count[..., c] > 0).any():
            if args.grazing_cutoff is not None:
                raise FlagError("--grazing-cutoff", f"{args.grazing_cutoff:g} deg ({args.grazing_angle}) "
                                                    f"keeps no sample of channel {ch} of {display_path(args.file)}")
            raise BRDFFileError(args.file, f"no valid sample in channel {ch}")
    return p


def _cmd_project(args) -> int:
    out = check_output_file(args.out, "--out", (".npz",))
    p = _project_from_args(args)
    with OutputSet() as outputs:
        p.save(outputs.stage(out))
        outputs.commit()
    empty = int((p.count[..., 0] == 0).sum())
    print(f"projected {display_text(p.name)} onto (theta_h, theta_d) with the {p.statistic}: 90 x 90 "
          f"clusters, {empty} empty; wrote {display_path(out)}")
    return 0


def _cmd_plot(args) -> int:
    out = check_output_dir(args.out, "--out")
    p = _project_from_args(args)
    with OutputSet() as outputs:
        plot_projection(p, out, outputs=outputs)
        files = outputs.commit()
    for f in files:
        print(f"wrote {display_path(f)}")
    return 0


def register(sub) -> None:
    """Add ``info``, ``project`` and ``plot`` to the sub-parsers ``sub``."""
    p = sub.add_parser("info", help="dimensions, valid fraction, value range and normal-incidence albedo",
                       description="Print what a measured BRDF file holds.")
    p.add_argument("file", help="MERL .binary or RGL .bsdf file")
    add_run_flags(p)
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser("project", help="project onto (theta_h, theta_d) and save an .npz",
                       description="Project the 3-D (theta_h, theta_d, phi_d) data onto the 90x90 "
                                   "(theta_h, theta_d) clusters (median by default).")
    p.add_argument("file", help="MERL .binary or RGL .bsdf file")
    p.add_argument("--out", required=True, help="output .npz file (replaced only if the run succeeds)")
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
