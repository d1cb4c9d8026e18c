"""How long a default 3-D fit takes on one core, and whether it is the same fit under load.

    python -m benchmarks.bench_fit_time [--materials NAME ...] [--load] [--json FILE]

For every shared RGL material (``--materials``: names without ``_rgb.bsdf``; default all):
the 3-D fit with every default (:func:`fit.rational.fit3d.fit_rgl_select` with the command's
first tolerance, 0.01: what ``rbrdf-fit brdf FILE --model 3d`` fits), in a child process pinned
to one core (``os.sched_setaffinity``; BLAS on one thread), its CPU seconds and wall-clock
seconds, and the coefficients it writes. ``--load``: the same fit twice at once, each in its own
process on its own core (each the other's load), and whether the two write the same
coefficients (the file's pieces compared as JSON: the fit is the same to the last bit, or it is
not). Without ``--load`` the child runs alone on core 0 (whatever else runs on the machine is
its load). Needs ``$RBRDF_DATA`` (``rgl/``).
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from warp_rbrdf.paths import require_data_root

BLAS_THREADS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
TOL = 0.01          # the command's first tolerance of the 3-D ladder (fit/cli/brdf3d.py TOL_3D)


def materials() -> list:
    return sorted(p.name[:-len("_rgb.bsdf")] for p in (require_data_root("bench_fit_time") / "rgl").glob("*_rgb.bsdf"))


def fit_once(name: str, core: int, out: str) -> dict:
    """In a child process: the default 3-D fit of ``name`` on core ``core``, saved to ``out``."""
    os.sched_setaffinity(0, {core})
    from fit.formats.rgl import read_rgl
    from fit.rational.coefficient_file import save
    from fit.rational.fit3d import fit_rgl_select

    brdf = read_rgl(require_data_root("bench_fit_time") / "rgl" / f"{name}_rgb.bsdf")
    c0, t0 = time.process_time(), time.perf_counter()
    res = fit_rgl_select(brdf, tol=TOL)
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    save(res.model, out)
    return {"cpu_s": cpu, "wall_s": wall, "coefficients": int(res.n_coefficients), "variant": int(res.variant)}


def pieces_of(path: str) -> str:
    """The coefficients a file holds (its pieces and value record, without the seconds each
    function's fit took: ``time_s``), as canonical JSON."""
    def untimed(x):
        if isinstance(x, dict):
            return {k: untimed(v) for k, v in x.items() if k != "time_s"}
        if isinstance(x, list):
            return [untimed(v) for v in x]
        return x

    d = json.loads(Path(path).read_text())
    return json.dumps(untimed({k: d.get(k) for k in ("pieces", "split", "value", "outputs")}), sort_keys=True)


def run(names, load: bool) -> dict:
    rows = {}
    cores = sorted(os.sched_getaffinity(0))
    if load and len(cores) < 2:
        raise SystemExit("--load needs two cores")
    # BLAS on one thread in every child: a fresh interpreter (spawn) that reads these before it
    # imports NumPy; a forked child inherits the parent's NumPy, whose OpenBLAS already chose two
    # threads (this module's import of warp_rbrdf loads NumPy), and two BLAS threads pinned to
    # one core took 192 CPU s for a fit that takes 39 s on one thread
    for var in BLAS_THREADS:
        os.environ[var] = "1"
    with tempfile.TemporaryDirectory() as tmp, ProcessPoolExecutor(
            max_workers=2 if load else 1, mp_context=multiprocessing.get_context("spawn")) as ex:
        for name in names:
            outs = [str(Path(tmp) / f"{name}_{k}.json") for k in range(2 if load else 1)]
            futures = [ex.submit(fit_once, name, cores[k], outs[k]) for k in range(len(outs))]
            results = [f.result() for f in futures]
            row = dict(results[0], material=name)
            if load:
                row.update(cpu_s_other=results[1]["cpu_s"], wall_s_other=results[1]["wall_s"],
                           identical=pieces_of(outs[0]) == pieces_of(outs[1]))
            rows[name] = row
            print(json.dumps(row), flush=True)
    return rows


def markdown(res: dict) -> str:
    rows = list(res["rows"].values())
    load = res["load"]
    head = "| material | coefficients | CPU s | wall s |" + (" CPU s, the other copy | same coefficients |" if load else "")
    lines = [f"{res['date']}, `uptime` at the start {res['load_start']}, at the end {res['load_end']}; "
             + ("two copies of each fit at once, one per core" if load else "one fit at a time on core 0"), "",
             head, "| --- | --- | --- | --- |" + (" --- | --- |" if load else "")]
    for r in rows:
        extra = f" {r['cpu_s_other']:.1f} | {'yes' if r['identical'] else '**no**'} |" if load else ""
        lines.append(f"| {r['material']} | {r['coefficients']} | {r['cpu_s']:.1f} | {r['wall_s']:.1f} |{extra}")
    cpu = [r["cpu_s"] for r in rows] + ([r["cpu_s_other"] for r in rows] if load else [])
    lines += ["", f"CPU seconds per fit: {min(cpu):.1f}–{max(cpu):.1f}, median {statistics.median(cpu):.1f}; "
              f"over 60 s: {sum(c > 60 for c in cpu)} of {len(cpu)}"
              + (f"; the same coefficients in both copies: {sum(r['identical'] for r in rows)} of {len(rows)}" if load else "")]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_fit_time", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", default=None, help="RGL names without _rgb.bsdf (default: all shared)")
    ap.add_argument("--load", action="store_true", help="each fit twice at once, one per core, compared")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    names = args.materials or materials()
    if not names:
        raise SystemExit(f"no RGL files under {require_data_root('bench_fit_time') / 'rgl'}")
    res = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "load": args.load,
           "load_start": " ".join(f"{x:.2f}" for x in os.getloadavg())}
    res["rows"] = run(names, args.load)
    res["load_end"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(markdown(res))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
