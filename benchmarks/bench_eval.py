"""Micro-benchmark: nanoseconds per RGB evaluation of one material in the renderer's Warp code,
one thread, for the rational fits (2-D and 3-D) against the tables and the RGL reference.

Materials (all of one RGL measurement, ``--material``, default ``satin_rosaline``):

* ``rational 2-D``: a 5 % 2-D fit (``--fit2d``; default the shipped
  ``warp_rbrdf/data/<material>_rgb.json``), as the renderer evaluates it (code specialised to
  the fit's degree classes, :mod:`warp_rbrdf.materials.rational_kernel`; a fit of at most four
  (theta_h, theta_d) boxes from its flat record, :mod:`warp_rbrdf.materials.rational_flat2d`);
* ``rational 3-D``: a 3-D fit (``--fit3d``: a coefficient file of ``fit.rational.fit3d``, e.g.
  one ``benchmarks/bench_fit_accuracy.py`` writes; without one, a stand-in of random positive
  coefficients in the layout of ``fit.rational.fit3d.VARIANTS[0]``: same pieces and
  degrees, so the same work per evaluation, said in the output);
* ``... generic``: the same two fits through the one function for every fit
  (``rational_kernel.rational_eval``: packed Chebyshev groups, libm's ``atan2``), in the same
  run: what the specialisation buys;
* ``projected``: the median (theta_h, theta_d) projection (the 2-D table, nearest cluster);
* ``measured``: the MERL-grid resampling of the file (the 3-D table, trilinear);
* ``rgl``: the ``.bsdf`` file evaluated exactly (the format's own interpolation);
* ``lambert``: the floor (dispatch, loads and stores, the horizon test).

The materials are those of one scene, so one compiled ``eval_bsdf`` kernel (the renderer's,
with its dispatch over material kinds) serves them all (the generic rows: a second renderer of
the same scene whose rational kind evaluates with the generic function). Each timing is one
``wp.launch`` over ``--pairs`` random pairs of cosine-distributed directions (upper hemisphere;
the inputs preallocated), in CPU seconds of the launching thread (the machine may be shared),
the launch overhead (a launch of one pair) subtracted; the materials are timed in turn, round
by round (``--repeats`` rounds), and each row is the median over rounds. ``--render`` also
times renders of the reference sphere scene (:func:`lab.mitsuba_reference.sphere_scene`,
``--envmap``) with each material, one thread, interleaved, in samples per CPU second: every
material with the ``mis`` sampler (environment + cosine BSDF sample, so only the material's
evaluation differs), and once more each with its own sampler (:func:`own_sampler`: ``mis-rgl``
for ``rgl``, the reference scene's; ``mis-rational`` for a fit carrying its inverse CDFs;
``mis-tabulated`` for the other fits and the tables).

``--all-2d all|a,b``: instead, every 2-D 5 % fit of the chart (the shipped file or the studies'
cache: :func:`fits_2d`) against its own material's 2-D table, each pair in one scene, with the
fit's coefficients and degree classes: where the 2-D target (at most the table's cost) holds.

    python -m benchmarks.bench_eval [--material satin_rosaline] [--fit3d FILE] [--pairs 1048576]
                                    [--repeats 7] [--render] [--json FILE] [--quick]
    python -m benchmarks.bench_eval --all-2d all [--pairs 1048576] [--repeats 7] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp_cache"))

ROWS = ("rational 2-D", "rational 3-D", "projected", "measured", "rgl", "lambert")
#: the rational rows again through the generic function (rational_kernel.rational_eval)
GENERIC = {"rational 2-D": "rational 2-D, generic", "rational 3-D": "rational 3-D, generic"}


class BenchError(Exception):
    """Bad input: one line, exit status 2."""


def data_dir() -> Path:
    from warp_rbrdf.paths import require_data_root

    return require_data_root("bench_eval's RGL file")


def synthetic_3d(seed: int = 0):
    """A 3-D model of random positive coefficients in the layout of
    ``fit.rational.fit3d.VARIANTS[0]`` (theta_h pieces, degrees per piece, the variables and
    log value transform of a 3-D fit), for timings without a fitted file."""
    import fit.rational.basis as basis
    import fit.rational.function as function
    import fit.rational.model as M
    from fit.rational.fit3d import VARIANTS

    rng = np.random.default_rng(seed)
    layout = VARIANTS[0]
    edges = [0.0] + list(layout["theta_h_edges"]) + [np.pi / 2]
    td = (0.0, np.radians(89.0))
    pd = (0.0, np.pi)
    pieces = []
    for k, (dn, dd) in enumerate(layout["piece_degrees"]):
        variables = [M.Variable("theta_h", "rad", "sqrt", (edges[k], edges[k + 1])),
                     M.Variable("theta_d", "rad", "identity", td), M.Variable("phi_d", "rad", "identity", pd)]
        dom = np.array([v.rf_domain for v in variables])
        ne, de = basis.total_degree_exponents(3, dn), basis.total_degree_exponents(3, dd)
        funcs = []
        for c in range(3):
            p = rng.normal(size=len(ne)) * 0.2
            p[0] = -1.0 + 0.3 * c
            q = rng.normal(size=len(de)) * 0.03
            q[0] = 1.0
            funcs.append(function.RationalFunction(dom, ne, p, de, q))
        pieces.append(M.RationalModel(name=f"piece{k}", variables=variables, functions=funcs,
                                      value_transform="log", value_offset=0.01, value_min=0.0, value_max=500.0))
    whole = [M.Variable("theta_h", "rad", "sqrt", (0.0, np.pi / 2)),
             M.Variable("theta_d", "rad", "identity", td), M.Variable("phi_d", "rad", "identity", pd)]
    return M.PiecewiseRationalModel(name="synthetic_3d", variables=whole, split_variable="theta_h",
                                    edges=edges, pieces=pieces)


def material_specs(material: str, fit2d, fit3d, quick: bool):
    """``({row: MaterialSpec}, notes)`` of the benchmark's materials."""
    from fit.formats import load_measured
    from fit.projection.project import project
    from warp_rbrdf.paths import PACKAGE_DATA
    from warp_rbrdf.scene import MaterialSpec

    rgl = data_dir() / "rgl" / f"{material}_rgb.bsdf"
    if not rgl.is_file():
        raise BenchError(f"no RGL file {rgl}")
    fit2d = Path(fit2d) if fit2d else PACKAGE_DATA / f"{material}_rgb.json"
    if not fit2d.is_file():
        raise BenchError(f"no 2-D fit {fit2d} (give --fit2d)")
    notes = {"rational 2-D": str(fit2d.relative_to(ROOT) if fit2d.is_relative_to(ROOT) else fit2d)}
    specs = {"rational 2-D": MaterialSpec(name="r2", type="rational", file=fit2d, sampler="mis")}
    if fit3d:
        if not Path(fit3d).is_file():
            raise BenchError(f"no 3-D fit {fit3d}")
        specs["rational 3-D"] = MaterialSpec(name="r3", type="rational", file=Path(fit3d), sampler="mis")
        notes["rational 3-D"] = str(fit3d)
    else:
        specs["rational 3-D"] = MaterialSpec(name="r3", type="rational", data=synthetic_3d(), sampler="mis")
        notes["rational 3-D"] = "stand-in: random coefficients, layout of fit3d.VARIANTS[0]"
    meas = load_measured(rgl)
    specs["projected"] = MaterialSpec(name="proj", type="projected", data=project(meas), sampler="mis")
    specs["measured"] = MaterialSpec(name="meas", type="measured", data=meas, sampler="mis")
    specs["rgl"] = MaterialSpec(name="rgl", type="rgl", file=rgl, sampler="mis")
    specs["lambert"] = MaterialSpec(name="lam", type="lambert", albedo=(0.5, 0.5, 0.5), sampler="mis")
    notes.update(projected="median projection of the RGL file's MERL-grid resampling",
                 measured="the RGL file's MERL-grid resampling (90 x 90 x 360, trilinear)", rgl=str(rgl.name))
    return specs, notes


def eval_scene(specs):
    """One scene holding every material (one small sphere each), for one compiled kernel."""
    from lab import testing as T
    from warp_rbrdf.scene import IntegratorSpec, Scene, ShapeSpec

    shapes = [ShapeSpec(type="sphere", material=s.name, center=(3.0 * k, 0.0, 0.0), radius=1.0)
              for k, s in enumerate(specs.values())]
    return Scene(camera=T.top_down_camera(4), integrator=IntegratorSpec(spp=1, max_depth=1),
                 materials={s.name: s for s in specs.values()}, shapes=shapes,
                 lights=[T.constant_env(1.0)], path="<bench_eval>")


def cosine_pairs(n: int, seed: int = 0):
    from fit.formats.angles import cosine_directions

    rng = np.random.default_rng(seed)
    return cosine_directions(rng, n).astype(np.float32), cosine_directions(rng, n).astype(np.float32)


def generic_renderer(scene):
    """A renderer of ``scene`` whose rational materials evaluate with the one generic function
    (:func:`warp_rbrdf.materials.rational_kernel.rational_eval`) instead of the code specialised
    to their degree classes."""
    from warp_rbrdf.materials import rational
    from warp_rbrdf.materials.rational_kernel import rational_eval
    from warp_rbrdf.renderer import Renderer

    specialised = rational.kernel_eval
    rational.kernel_eval = lambda loaded_list: rational_eval
    try:
        r = Renderer(scene, device="cpu")
        r.compile()
    finally:
        rational.kernel_eval = specialised
    return r


def eval_timings(runs, n_pairs: int, repeats: int, seed: int = 0) -> dict:
    """``runs``: {row: (renderer, material name)}; ``{"launch_overhead_us", "rows": {row:
    dict(ns=median ns per evaluation, all_ns=[per round])}}``."""
    r0 = next(iter(runs.values()))[0]
    wp = r0.wp
    dev = r0.device
    wi, wo = cosine_pairs(n_pairs, seed)
    a = wp.array(wi, dtype=wp.vec3, device=dev)
    b = wp.array(wo, dtype=wp.vec3, device=dev)
    o = wp.zeros(n_pairs, dtype=wp.vec3, device=dev)

    def launch(r, m, dim):
        t0 = time.thread_time()
        wp.launch(r.kernels.eval_bsdf, dim=dim, inputs=[r.materials, m, a, b], outputs=[o], device=dev)
        wp.synchronize_device(dev)
        return time.thread_time() - t0

    index = {row: (r, r.material_index(name)) for row, (r, name) in runs.items()}
    for r, m in index.values():     # warm-up
        launch(r, m, n_pairs)
    overhead = statistics.median(launch(r0, 0, 1) for _ in range(50))
    times = {row: [] for row in runs}
    for _ in range(repeats):
        for row, (r, m) in index.items():
            times[row].append((launch(r, m, n_pairs) - overhead) / n_pairs * 1e9)
    return {"launch_overhead_us": overhead * 1e6,
            "rows": {row: {"ns": statistics.median(v), "all_ns": v} for row, v in times.items()}}


def fits_2d(materials) -> dict:
    """``{material: 2-D fit file}``: the chart's 2-D 5 % fit of each shared RGL material that has
    one (:func:`benchmarks.chart_fits.fit2d` without fitting: the shipped file or the studies'
    cache; flagged fits included)."""
    from benchmarks.chart_fits import fit2d

    out = {}
    for mat in materials:
        f, _ = fit2d(data_dir() / "rgl" / f"{mat}_rgb.bsdf", allow_fit=False)
        if f is not None:
            out[mat] = f
    return out


def fit_size(path) -> tuple:
    """``(coefficients, degree classes)`` of a 2-D fit file: its coefficient count and the sorted
    (numerator, denominator) total degrees of its top-level pieces
    (:func:`warp_rbrdf.chebyshev_dense.group_degree`, the classes' degrees)."""
    from fit.rational.coefficient_file import load
    from warp_rbrdf.chebyshev_dense import group_degree

    m = load(path)
    classes = {(group_degree([(f.num_exponents, f.num_coef) for f in p.functions]),
                group_degree([(f.den_exponents, f.den_coef) for f in p.functions]))
               for p in (getattr(m, "pieces", None) or [m])}
    return m.n_coefficients, sorted(classes)


def all_2d_timings(files: dict, n_pairs: int, repeats: int) -> list:
    """Per 2-D fit (``{material: file}``): its ns per RGB evaluation against its material's
    median (theta_h, theta_d) projection, timed in one scene, interleaved (:func:`eval_timings`)."""
    from fit.formats import load_measured
    from fit.projection.project import project
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import MaterialSpec

    rows = []
    for mat, f in files.items():
        specs = {"fit": MaterialSpec(name="r2", type="rational", file=Path(f), sampler="mis"),
                 "table": MaterialSpec(name="proj", type="projected",
                                       data=project(load_measured(data_dir() / "rgl" / f"{mat}_rgb.bsdf")),
                                       sampler="mis")}
        r = Renderer(eval_scene(specs), device="cpu")
        r.compile()
        t = eval_timings({row: (r, s.name) for row, s in specs.items()}, n_pairs, repeats)["rows"]
        n, classes = fit_size(f)
        rows.append(dict(material=mat, file=str(f), coefficients=n, classes=classes, fit_ns=t["fit"]["ns"],
                         table_ns=t["table"]["ns"], ratio=t["fit"]["ns"] / t["table"]["ns"]))
        print(f"{mat}: {rows[-1]['fit_ns']:.1f} ns against the table's {rows[-1]['table_ns']:.1f} "
              f"({rows[-1]['ratio']:.2f}), {n} coefficients", flush=True)
    return rows


def markdown_2d(rows) -> str:
    out = ["| material | coefficients | (numerator, denominator) degrees | fit: ns per RGB evaluation | "
           "2-D table: ns | fit ÷ table |", "| --- | --- | --- | --- | --- | --- |"]
    for r in sorted(rows, key=lambda r: r["coefficients"]):
        cls = ", ".join(f"({a}, {b})" for a, b in r["classes"])
        out.append(f"| {r['material']} | {r['coefficients']} | {cls} | {r['fit_ns']:.1f} | {r['table_ns']:.1f} | "
                   f"{r['ratio']:.2f} |")
    met = sum(r["ratio"] <= 1.0 for r in rows)
    out.append("")
    out.append(f"At most the table's cost on {met} of {len(rows)} fits.")
    return "\n".join(out)


def own_sampler(spec) -> str:
    """The sampler a material of ``spec`` renders with when the scene names none
    (:func:`warp_rbrdf.registry.default_strategy`: a rational fit whose file carries its inverse
    CDFs samples with them, ``mis-rational``; the tables with ``mis-tabulated``)."""
    import json

    from warp_rbrdf import registry

    cdf = spec.type == "rational" and spec.file is not None and "sampler" in json.loads(Path(spec.file).read_text())
    return registry.default_strategy(spec.type, cdf=cdf)


def render_timings(specs, envmap: str, resolution: int, spp: int, repeats: int) -> dict:
    """Samples per CPU second of the reference sphere scene with each material (one thread,
    interleaved, median of ``repeats``); the rational ones also through the generic function,
    every material also with its own sampler (:func:`own_sampler`; ``rgl``: ``mis-rgl``)."""
    import dataclasses

    from lab import mitsuba_reference as MR
    from warp_rbrdf.renderer import Renderer

    env = data_dir() / "envmaps" / f"{envmap}.hdr"
    base = MR.sphere_scene(("lambert", (0.5, 0.5, 0.5)), env, spp, resolution)
    runs = {}
    for row, s in specs.items():
        variants = [(row, s, Renderer)]
        if row in GENERIC:
            variants.append((GENERIC[row], s, generic_renderer))
        if row == "rgl":
            variants.append(("rgl, mis-rgl sampler", dataclasses.replace(s, sampler="mis-rgl"), Renderer))
        own = own_sampler(s)
        if row != "rgl" and own != s.sampler:
            variants.append((f"{row}, {own} sampler", dataclasses.replace(s, sampler=own), Renderer))
        for label, spec, make in variants:
            spec = dataclasses.replace(spec, name="obj")
            sc = dataclasses.replace(base, materials={"obj": spec},
                                     integrator=dataclasses.replace(base.integrator, sampler=spec.sampler))
            r = make(sc)
            r.compile()
            r.render(spp=1, threads=1)
            runs[label] = r
    times = {k: [] for k in runs}
    for i in range(repeats):
        for k, r in runs.items():
            t0 = time.process_time()
            r.render(spp=spp, seed=i, threads=1)
            times[k].append(time.process_time() - t0)
    n = resolution * resolution * spp
    return {k: {"samples_per_s": n / statistics.median(v), "cpu_seconds": statistics.median(v), "all_s": v}
            for k, v in times.items()}


def machine() -> dict:
    cpu = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load = subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()
    except OSError:
        load = ""
    import warp as wp

    return {"cpu": cpu, "cores": os.cpu_count(), "uptime": load, "warp": wp.config.version,
            "date": time.strftime("%Y-%m-%d %H:%M %Z")}


def markdown(res) -> str:
    ev = res["eval"]["rows"]
    lines = ["| material | ns per RGB evaluation | ÷ 2-D table | ÷ 3-D table | ÷ rgl |",
             "| --- | --- | --- | --- | --- |"]
    for row in [r for r in ROWS for r in ((r, GENERIC[r]) if r in GENERIC else (r,))]:
        if row in ev:
            ns = ev[row]["ns"]
            lines.append(f"| {row} | {ns:.1f} | {ns / ev['projected']['ns']:.2f} | "
                         f"{ns / ev['measured']['ns']:.2f} | {ns / ev['rgl']['ns']:.2f} |")
    if "render" in res:
        rr = res["render"]
        ref = "rgl, mis-rgl sampler"
        own = next((k for k in rr if k.startswith("projected, ")), "projected")
        lines += ["", "| material (reference sphere scene, 1 thread) | M samples / CPU s | ÷ projected | ÷ rgl "
                      f"| ÷ rgl, mis-rgl sampler | ÷ {own} |", "| --- | --- | --- | --- | --- | --- |"]
        for k, v in rr.items():
            x = v["samples_per_s"]
            lines.append(f"| {k} | {x / 1e6:.3f} | {x / rr['projected']['samples_per_s']:.2f} | "
                         f"{x / rr['rgl']['samples_per_s']:.2f} | {x / rr[ref]['samples_per_s']:.2f} | "
                         f"{x / rr[own]['samples_per_s']:.2f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_eval", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--material", default="satin_rosaline", help="RGL file stem without _rgb (shared data rgl/)")
    ap.add_argument("--fit2d", default=None, help="2-D fit (default: the shipped <material>_rgb.json)")
    ap.add_argument("--fit3d", default=None, help="3-D fit file (default: a stand-in of the same layout)")
    ap.add_argument("--pairs", type=int, default=1 << 20, help="direction pairs per launch")
    ap.add_argument("--repeats", type=int, default=7, help="rounds (median)")
    ap.add_argument("--render", action="store_true", help="also time the reference sphere scene")
    ap.add_argument("--envmap", default="studio_small_03_1k")
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--json", default=None, help="write the results here")
    ap.add_argument("--quick", action="store_true", help="a few thousand pairs, two rounds (tests)")
    ap.add_argument("--all-2d", default=None, metavar="MATERIALS",
                    help="instead: every 2-D 5 %% fit of the chart ('all' or stems, comma-separated) "
                         "against its material's 2-D table, ns per RGB evaluation")
    a = ap.parse_args(argv)
    if a.quick:
        a.pairs, a.repeats, a.resolution, a.spp = 4096, 2, 16, 2
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.runtime import init_warp

    init_warp()
    if a.all_2d is not None:
        mats = (sorted(p.name[:-len("_rgb.bsdf")] for p in (data_dir() / "rgl").glob("*_rgb.bsdf"))
                if a.all_2d == "all" else a.all_2d.split(","))
        rows = all_2d_timings(fits_2d(mats), a.pairs, a.repeats)
        m = machine()
        print(f"{m['cpu']}, {m['date']}; {m['uptime']}")
        print(markdown_2d(rows))
        if a.json:
            Path(a.json).write_text(json.dumps(dict(machine=m, pairs=a.pairs, repeats=a.repeats, rows=rows),
                                               indent=1, default=str))
        return dict(rows=rows)
    try:
        specs, notes = material_specs(a.material, a.fit2d, a.fit3d, a.quick)
    except BenchError as e:
        print(f"bench_eval: {e}", file=sys.stderr)
        return 2
    scene = eval_scene(specs)
    r = Renderer(scene, device="cpu")
    compile_s = r.compile()
    g = generic_renderer(scene)
    runs = {row: (r, s.name) for row, s in specs.items()}
    runs.update({GENERIC[row]: (g, specs[row].name) for row in GENERIC})
    res = {"command": "python -m benchmarks.bench_eval " + " ".join(argv if argv is not None else sys.argv[1:]),
           "machine": machine(), "material": a.material, "pairs": a.pairs, "repeats": a.repeats,
           "compile_s": compile_s, "notes": notes}
    res["eval"] = eval_timings(runs, a.pairs, a.repeats)
    if a.render:
        res["render"] = render_timings(specs, a.envmap, a.resolution, a.spp, a.repeats)
    print(f"{res['machine']['cpu']}, {res['machine']['date']}; {res['machine']['uptime']}")
    print(f"{a.pairs} pairs per launch, median of {a.repeats} rounds, one thread, CPU time; launch overhead "
          f"{res['eval']['launch_overhead_us']:.1f} us subtracted")
    print(markdown(res))
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1))
    return res


if __name__ == "__main__":
    out = main()
    sys.exit(out if isinstance(out, int) else 0)
