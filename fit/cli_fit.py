"""``rbrdf-fit brdf FILE --tol 0.05 --out material.json``: rational fit of a measured BRDF.

Registered by :mod:`fit.cli` (it calls :func:`register` with its sub-parsers).
"""
from __future__ import annotations

from pathlib import Path

from .errors import RbrdfError


def _cmd_brdf(args) -> int:
    from tqdm import tqdm

    from .brdf_fit import INTERVALS, fit_brdf
    from .coefficients import save
    from .io import load_measured

    b = load_measured(args.file)
    bar = tqdm(desc=f"fitting {b.name}", unit="LP", leave=False)

    def progress(channel, event):
        bar.set_postfix_str(f"{channel} ({event['m']},{event['n']}) "
                            f"{'ok' if event['feasible'] else 'no'}")
        bar.update(1)

    try:
        fit = fit_brdf(b, tol=args.tol, intervals=args.intervals, theta_h_transform=args.theta_h,
                       value_transform=args.value, max_degree=args.max_degree,
                       max_den_degree=args.max_den_degree, progress=progress,
                       source_file=Path(args.file).name)
    except ValueError as e:
        raise RbrdfError(f"{args.file}: {e}") from None
    finally:
        bar.close()
    out = Path(args.out)
    save(fit.model, out)
    print(f"{b.name}: tol {args.tol:g} ({args.intervals}), theta_h {args.theta_h}, value {args.value}")
    print(f"{'channel':8s}{'degrees':>9s}{'coefs':>7s}{'max rel':>9s}{'rms rel':>9s}{'inside':>8s}"
          f"{'Q>0':>6s}{'time s':>8s}")
    for ch, r, e in zip("RGB", fit.results, fit.errors):
        print(f"{ch:8s}{f'({r.num_degree},{r.den_degree})':>9s}{r.n_coefficients:7d}"
              f"{100 * e['max_rel_error']:8.2f}%{100 * e['rms_rel_error']:8.2f}%"
              f"{100 * e['inside_fraction']:7.1f}%{'yes' if r.certificate and r.certificate.certified else 'NO':>6s}"
              f"{r.time_s:8.2f}")
    status = "guaranteed" if fit.valid else "NOT guaranteed (best fit found, flagged infeasible)"
    print(f"total {fit.n_coefficients} coefficients, {fit.time_s:.1f} s, {status}; wrote {out}")
    return 0 if fit.valid or args.allow_infeasible else 1


def register(subparsers) -> None:
    from .brdf_fit import INTERVALS

    p = subparsers.add_parser(
        "brdf", help="fit R, G, B with rational functions inside a tolerance; write JSON coefficients",
        description="Project the BRDF onto (theta_h, theta_d) (median, grazing samples beyond 79 deg "
                    "dropped), fit each channel with the rational function with the fewest "
                    "coefficients inside the intervals (LP with constraint generation), certify "
                    "Q > 0 and write an rbrdf-rational v1 JSON file (see fit.coefficients).")
    p.add_argument("file", help="MERL .binary or RGL .bsdf file")
    p.add_argument("--tol", type=float, default=0.05, help="relative tolerance (default 0.05)")
    p.add_argument("--out", required=True, help="output .json coefficient file")
    p.add_argument("--intervals", choices=INTERVALS, default="tol+spread",
                   help="interval policy: 'tol' = y +- max(tol y, floor); 'tol+spread' (default) also "
                        "widens to the cluster's phi_d standard deviation")
    p.add_argument("--theta-h", dest="theta_h", choices=("sqrt", "identity"), default="sqrt",
                   help="input transform of theta_h (default sqrt)")
    p.add_argument("--value", choices=("log", "linear"), default="log", help="value transform (default log)")
    p.add_argument("--max-degree", type=int, default=12, help="largest numerator total degree (default 12)")
    p.add_argument("--max-den-degree", type=int, default=6, help="largest denominator total degree (default 6)")
    p.add_argument("--allow-infeasible", action="store_true",
                   help="exit 0 even when no fit meets the tolerance (the file is flagged)")
    p.set_defaults(func=_cmd_brdf)
