"""What the conversions of ``rbrdf-fit convert`` lose, measured (the numbers of docs/interop.md).

    python -m benchmarks.bench_convert [--materials NAME ...] [--pairs 20000] [--mitsuba-pairs 2000]
                                       [--json FILE]

For every RGL-EPFL material (default: the six of the test suite, from $RBRDF_DATA/rgl):

* RGL -> MERL: the phi_d fold (reciprocity difference of the file), the MERL table against
  the file;
* MERL -> RGL (the default sizes): against the MERL table, and the round trip RGL -> MERL ->
  RGL against the original file;
* RGL -> RGL (re-parameterized at the default sizes) against the original file;

for analytic lobes written as exact-layout MERL files (Lambert, Blinn-Phong exponents 80 and
400): MERL -> RGL, evaluated by **Mitsuba 3's** ``measured`` plugin (when the ``reference``
extra is installed) against the analytic function, and Mitsuba against our reader; and for
the rational fits shipped in warp_rbrdf/data: fit -> MERL and fit -> RGL against the fit.

Every difference is the luminance relative difference at random direction pairs, both
directions within 80 deg of the normal (and, for the RGL outputs, within 70 deg) (:func:`fit.convert.summary.compare`: max, p99, RMS,
median, ratio of the means). Wall times are printed too (2 cores shared; not a target).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data"))
MATERIALS = ("cc_ibiza_sunset_rgb", "cc_iris_purple_gem_rgb", "colodur_napoli_4f_rgb", "paper_white_rgb",
             "satin_rosaline_rgb", "vch_golden_yellow_rgb")
#: The second comparison cap (degrees): the grazing band 70-80 deg left out.
CORE_DEG = 70.0
LOBES = {"lambert": ("lambert", {}), "blinn80": ("glossy_lobe", {"exponent": 80.0}),
         "blinn400": ("glossy_lobe", {"exponent": 400.0, "kd": (0.02, 0.02, 0.02)})}


def _fmt(d) -> str:
    if d is None:
        return "-"
    if d.rel_max < 1e-3:        # float32 agreement: significant digits, not 0.0 %
        return f"max {d.rel_max:.2g}, p99 {d.rel_p99:.2g}, RMS {d.rel_rms:.2g} (relative)"
    return (f"max {100 * d.rel_max:.1f} %, p99 {100 * d.rel_p99:.1f} %, RMS {100 * d.rel_rms:.1f} %, "
            f"median {100 * d.rel_median:.2f} %, mean ratio {d.mean_ratio:.3f}")


def _mitsuba_vs(path, func, n, seed=7):
    """(Mitsuba vs func, Mitsuba vs our reader) as Differences of f cos, or None without Mitsuba."""
    from fit.convert.summary import compare
    from fit.formats.rgl import read_rgl
    from lab import mitsuba_reference as MR

    if not MR.available():
        return None, None
    ours = read_rgl(path)

    def mitsuba(wi, wo):          # Mitsuba's roles: si.wi = the view, wo = the light
        return MR.eval(path, wo, wi) / wi[:, 2:3]

    return (compare(mitsuba, func, n, seed), compare(mitsuba, ours.evaluate, n, seed))


def run(materials, pairs: int, mitsuba_pairs: int, work: Path) -> dict:
    from lab import analytic
    from fit.convert import convert
    from fit.convert.sources import load_source
    from fit.convert.summary import compare
    from fit.formats.measured import MeasuredBRDF
    from fit.formats.merl import write_merl

    res = {"pairs": pairs, "materials": {}, "lobes": {}, "fits": {}}
    for name in materials:
        src = DATA / "rgl" / f"{name}.bsdf"
        merl, back, direct = work / f"{name}.binary", work / f"{name}.rt.bsdf", work / f"{name}.re.bsdf"
        t = time.perf_counter()
        s1 = convert(src, merl, n_pairs=pairs)
        t1 = time.perf_counter() - t
        t = time.perf_counter()
        s2 = convert(merl, back, n_pairs=pairs)
        t2 = time.perf_counter() - t
        s3 = convert(src, direct, n_pairs=pairs)
        from fit.formats.rgl import read_rgl

        orig = load_source(src).evaluate
        rt = compare(read_rgl(back).evaluate, orig, pairs)
        rt70 = compare(read_rgl(back).evaluate, orig, pairs, 0, CORE_DEG)
        re70 = compare(read_rgl(direct).evaluate, orig, pairs, 0, CORE_DEG)
        res["materials"][name] = {"to_merl": s1.difference.as_dict(), "fold": dict(s1.fold.__dict__),
                                  "merl_to_rgl": s2.difference.as_dict(), "round_trip": rt.as_dict(),
                                  "rgl_to_rgl": s3.difference.as_dict(), "round_trip_70": rt70.as_dict(),
                                  "rgl_to_rgl_70": re70.as_dict(), "seconds_to_merl": t1,
                                  "seconds_to_rgl": t2}
        print(f"{name}: RGL->MERL ({t1:.1f} s) {_fmt(s1.difference)}\n  {s1.fold.describe()}\n"
              f"  MERL->RGL ({t2:.1f} s) {_fmt(s2.difference)}\n  round trip RGL->MERL->RGL {_fmt(rt)}\n"
              f"  RGL->RGL {_fmt(s3.difference)}\n  within {CORE_DEG:g} deg: round trip {_fmt(rt70)}; "
              f"RGL->RGL {_fmt(re70)}", flush=True)
    for label, (factory, kw) in LOBES.items():
        f = getattr(analytic, factory)(**kw)
        path, out = work / f"{label}.binary", work / f"{label}.bsdf"
        write_merl(MeasuredBRDF.from_function(f, name=label), path)
        s = convert(path, out, n_pairs=pairs)
        ana = compare(load_source(out).evaluate, f, pairs)
        mit_ana, mit_ours = _mitsuba_vs(out, f, mitsuba_pairs) if mitsuba_pairs else (None, None)
        res["lobes"][label] = {"merl_vs_analytic": compare(load_source(path).evaluate, f, pairs).as_dict(),
                               "rgl_vs_merl": s.difference.as_dict(), "rgl_vs_analytic": ana.as_dict(),
                               "mitsuba_vs_analytic": mit_ana.as_dict() if mit_ana else None,
                               "mitsuba_vs_ours": mit_ours.as_dict() if mit_ours else None}
        print(f"{label}: MERL table vs analytic {_fmt(compare(load_source(path).evaluate, f, pairs))}\n"
              f"  RGL vs analytic {_fmt(ana)}\n  Mitsuba vs analytic {_fmt(mit_ana)}\n"
              f"  Mitsuba vs our reader {_fmt(mit_ours)}", flush=True)
    for fit_file in sorted((ROOT / "warp_rbrdf" / "data").glob("*.json")):
        a = convert(fit_file, work / f"{fit_file.stem}.fit.binary", n_pairs=pairs)
        b = convert(fit_file, work / f"{fit_file.stem}.fit.bsdf", n_pairs=pairs)
        fit = load_source(fit_file).evaluate
        m70 = compare(load_source(work / f"{fit_file.stem}.fit.binary").evaluate, fit, pairs, 0, CORE_DEG)
        r70 = compare(load_source(work / f"{fit_file.stem}.fit.bsdf").evaluate, fit, pairs, 0, CORE_DEG)
        res["fits"][fit_file.stem] = {"to_merl": a.difference.as_dict(), "to_rgl": b.difference.as_dict(),
                                      "to_merl_70": m70.as_dict(), "to_rgl_70": r70.as_dict()}
        print(f"fit {fit_file.stem}: ->MERL {_fmt(a.difference)}\n  ->RGL {_fmt(b.difference)}\n"
              f"  within {CORE_DEG:g} deg: ->MERL {_fmt(m70)}; ->RGL {_fmt(r70)}", flush=True)
    return res


def _cell(d) -> str:
    if d is None:
        return "-"
    if d["rel_max"] < 1e-3:
        return f"{d['rel_rms']:.1e} / {d['rel_max']:.1e}"
    return f"{100 * d['rel_rms']:.1f} / {100 * d['rel_p99']:.1f} / {100 * d['rel_max']:.0f}"


def markdown(res: dict) -> str:
    """The tables of docs/interop.md: RMS / p99 / max in percent."""
    out = [("| RGL-EPFL file | φd fold RMS / p99 (≤ 80°) | RGL → MERL | MERL → RGL | round trip RGL → MERL → RGL "
           "| round trip ≤ 70° | RGL → RGL | RGL → RGL ≤ 70° |"), "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, r in res["materials"].items():
        f = r["fold"]
        out.append(f"| {name} | {100 * f['core_rms']:.1f} / {100 * f['core_p99']:.1f} | {_cell(r['to_merl'])} | "
                   f"{_cell(r['merl_to_rgl'])} | {_cell(r['round_trip'])} | {_cell(r['round_trip_70'])} | "
                   f"{_cell(r['rgl_to_rgl'])} | {_cell(r['rgl_to_rgl_70'])} |")
    out += ["", ("| analytic lobe (exact-layout MERL file) | MERL table vs lobe | RGL (from the MERL file) vs lobe "
            "| Mitsuba `measured` vs lobe | Mitsuba vs our reader (RMS / max) |"), "| --- | --- | --- | --- | --- |"]
    for name, r in res["lobes"].items():
        out.append(f"| {name} | {_cell(r['merl_vs_analytic'])} | {_cell(r['rgl_vs_analytic'])} | "
                   f"{_cell(r['mitsuba_vs_analytic'])} | {_cell(r['mitsuba_vs_ours'])} |")
    out += ["", "| rational fit | → MERL | → MERL ≤ 70° | → RGL | → RGL ≤ 70° |", "| --- | --- | --- | --- | --- |"]
    for name, r in res["fits"].items():
        out.append(f"| {name}.json | {_cell(r['to_merl'])} | {_cell(r['to_merl_70'])} | {_cell(r['to_rgl'])} | "
                   f"{_cell(r['to_rgl_70'])} |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_convert", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="*", default=list(MATERIALS))
    ap.add_argument("--pairs", type=int, default=20000)
    ap.add_argument("--mitsuba-pairs", type=int, default=2000, help="0: no Mitsuba evaluation")
    ap.add_argument("--json", metavar="FILE", help="write the numbers as JSON")
    ap.add_argument("--from-json", metavar="FILE", help="print the tables of a previous --json run")
    args = ap.parse_args(argv)
    if args.from_json:
        print(markdown(json.loads(Path(args.from_json).read_text())))
        return 0
    with tempfile.TemporaryDirectory(prefix="bench_convert.") as d:
        res = run(args.materials, args.pairs, args.mitsuba_pairs, Path(d))
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))
    print(markdown(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
