"""Where a shaded sample's time goes: a sampling profile of the render kernel, attributed to the
Warp functions it inlines.

    python -m benchmarks.profile_render [--material cc_ibiza_sunset_rgb] [--envmap rooitou_park_1k]
                                        [--spp 256] [--resolution 128] [--json FILE] [--lines]
                                        [--fit FIT.json] [--sampler NAME]

How: the reference sphere scene of :mod:`lab.mitsuba_reference` (the scene of
``benchmarks/bench_vs_mitsuba.py``), its material the ``rgl`` one of ``--material`` or the
``rational`` fit of ``--fit`` (a coefficient file, with its default sampler; ``--sampler``: another), is rendered on one
thread under Linux ``perf record``. Its
render kernel is compiled in a private Warp cache with the same flags as always plus DWARF line
tables (``-debug-info-kind=line-tables-only``: the same machine code, the object is
byte-for-byte the same ``.ltext``), so ``addr2line -i`` gives, for every sampled instruction, the
chain of Warp functions that were inlined into it (``sample_f_0`` inside
``bsdf_sample_f`` inside ``radiance_sample``...). Warp loads the object into anonymous memory
(perf shows it as ``[JIT]``); its load address is found as the offset at which every sampled
address falls on an instruction boundary of the object's disassembly (checked: the share of
samples that do is printed, and must be ~100 %).

Prints the share of the render's samples (the kernel's plus those of the libm functions it calls;
start-up and the kernel's compilation are left out) per Warp function, *inclusive* (the time
inside the function and everything inlined into it) and *exclusive* (the innermost Warp
function), the share per component (tracing, environment sampling, environment lookups, BSDF
sampling, BSDF evaluation, sample generation), and the libm functions the kernel calls
(``atan2f``, ``sincosf``, ...; not inlined, so not in the kernel's own samples). With ``--lines``
also per Warp source statement: each sample's innermost line of the generated C++, named by
the comment Warp's code generator writes above each statement (``// a = mats.rgl_f[i]  <L 87>``).

Needs ``perf`` (with access to user-space samples: ``kernel.perf_event_paranoid`` <= 2),
``objdump`` and ``addr2line`` (binutils); without them it says so in one line and exits 2.
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data"))

#: Components of a sample: (name, Warp functions whose inclusive time is the component's; the
#: render kernel's lane forms, ``warp_rbrdf.lanes``, with the one-at-a-time functions).
#: A sample counts for the first component whose function is in its inline chain.
COMPONENTS = (
    ("environment sampling", ("env_sample_uv_0", "make_env_sample_lanes__locals__env_sample_uv_lanes_0")),
    ("BSDF sampling (sample + f at the sample)", ("_sample_f_chain__locals__bsdf_sample_f_0",
                                                  "make_lanes_sampling__locals__lanes_sample_f_0")),
    ("BSDF eval + pdf at the light sample", ("_eval_pdf_chain__locals__bsdf_eval_pdf_0",
                                             "make_bsdf_eval__locals__bsdf_eval_0")),
    ("environment lookups (radiance, MIS pdf)", ("env_eval_uv_0", "env_pdf_uv_0", "env_dir_to_uv_0")),
    ("ray tracing (camera, shadow, BSDF rays)", ("make_tracer__locals__closest_hit_0",
                                                 "make_tracer__locals__any_hit_0", "camera_ray_0")),
    ("sample generation (CMJ)", ("sample_2d_0",)),
)


class ProfileError(Exception):
    """A missing tool or an unusable profile: one line, exit status 2."""


# --------------------------------------------------------------------------------------------
# Attribution (pure functions: tested on synthetic inputs)
# --------------------------------------------------------------------------------------------
def instruction_starts(disassembly: str) -> list[int]:
    """Sorted offsets of the instructions in ``objdump -d`` output."""
    out = [int(m.group(1), 16) for m in re.finditer(r"^\s*([0-9a-f]+):\s", disassembly, re.MULTILINE)]
    return sorted(set(out))


def find_load_base(addresses, starts, window: int = 1 << 20, probe: int = 3000) -> tuple[int, float]:
    """``(base, share)``: the 16-byte aligned load address at which the largest share of
    ``addresses`` (absolute sampled instruction addresses) fall on ``starts`` (offsets of the
    object's instructions), searched below the lowest address within ``window`` bytes."""
    if not addresses or not starts:
        raise ProfileError("no samples in the render kernel's code (was it running?)")
    st = set(starts)
    probe_set = list(addresses)[:probe]
    lo = min(addresses)
    span = max(starts)
    best = (-1, 0)
    first = max(((lo - min(window, lo)) // 16) * 16, ((lo - span - 16) // 16) * 16)
    for base in range(first, lo + 16, 16):
        hits = sum(1 for a in probe_set if (a - base) in st)
        if hits > best[0]:
            best = (hits, base)
    return best[1], best[0] / len(probe_set)


def _short(name: str) -> str:
    """A demangled function name without its argument list or template arguments' signature
    (``sample_2d_0(int, unsigned int)`` -> ``sample_2d_0``)."""
    name = name.strip()
    if name.startswith("void ") and "(" in name:
        name = name[5:]
    return name.split("(", 1)[0] if "(" in name else name


def parse_addr2line(text: str) -> dict[int, list[str]]:
    """``addr2line -a -f -i`` output -> {offset: [innermost, ..., outermost] function names}.
    The first name of a block is the symbol the address lies in; with line-table-only debug
    info it names that symbol, not the innermost inlined frame, so it is dropped unless it is
    the only one (code of a function that was not inlined, e.g. ``sample_2d_0``)."""
    out, cur, names = {}, None, []

    def close():
        if cur is not None:
            out[cur] = names[1:] if len(names) > 1 else names

    lines = text.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("0x"):
            close()
            cur, names = int(line, 16), []
            i += 1
            continue
        names.append(_short(line))
        i += 2          # the name's file:line
    close()
    return out


def innermost_cpp_lines(text: str) -> dict[int, int]:
    """``addr2line -a -f -i`` output -> {offset: line of the generated ``.cpp``}: the first
    ``.cpp`` file:line of each address's inline chain (the innermost line of the kernel's own
    source; Warp's headers and unknown lines ``?`` are skipped)."""
    out, cur = {}, None
    for line in text.splitlines():
        if line.startswith("0x"):
            cur = int(line, 16)
            continue
        if cur is None or cur in out:
            continue
        m = re.match(r"^(.*\.cpp):(\d+)", line.strip())
        if m:
            out[cur] = int(m.group(2))
    return out


def warp_statement(cpp: list[str], line: int, reach: int = 60) -> str:
    """The Warp source statement generated C++ line ``line`` (1-based) belongs to: the nearest
    comment at or above it that Warp's code generator writes before each statement (``// x =
    f(y)  <L 12>``), whitespace collapsed; ``"?"`` if none within ``reach`` lines."""
    for j in range(min(line, len(cpp)) - 1, max(line - 1 - reach, -1), -1):
        t = cpp[j].strip()
        if t.startswith("//") and "<L " in t:
            return " ".join(t[2:].split())
    return "?"


def attribute_lines(counts: dict[int, int], lines: dict[int, int], cpp: list[str]) -> collections.Counter:
    """Samples per Warp source statement (:func:`warp_statement` of each sample's innermost
    generated line)."""
    out = collections.Counter()
    for off, n in counts.items():
        ln = lines.get(off)
        out[warp_statement(cpp, ln) if ln else "?"] += n
    return out


def attribute(counts: dict[int, int], chains: dict[int, list[str]]):
    """``(inclusive, exclusive, components)`` Counters of samples: per Warp function name
    (inclusive: every function of a sample's inline chain; exclusive: the innermost), per
    :data:`COMPONENTS` name ("other" when none matches)."""
    inc, exc, comp = collections.Counter(), collections.Counter(), collections.Counter()
    for off, n in counts.items():
        chain = chains.get(off, [])
        for name in set(chain):
            inc[name] += n
        exc[chain[0] if chain else "?"] += n
        where = "other (integrator, frames, MIS)"
        for cname, funcs in COMPONENTS:
            if any(f in chain for f in funcs):
                where = cname
                break
        comp[where] += n
    return inc, exc, comp


# --------------------------------------------------------------------------------------------
# The profiled child: render under perf
# --------------------------------------------------------------------------------------------
def _child(a) -> None:
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    from warp_rbrdf import integrator
    from lab import mitsuba_reference as MR
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.shipped_kernels import render_module_options

    base = render_module_options()
    flags = (base.get("cpu_compiler_flags", "") + " -debug-info-kind=line-tables-only -dwarf-version=4").strip()
    integrator.render_module_options = lambda: {**base, "cpu_compiler_flags": flags}
    scene = MR.sphere_scene(DATA / "rgl" / f"{a.material}.bsdf", DATA / "envmaps" / f"{a.envmap}.hdr",
                            a.spp, a.resolution)
    if a.fit:
        from warp_rbrdf.scene import MaterialSpec

        from benchmarks.bench_eval import own_sampler

        spec = MaterialSpec(name="obj", type="rational", file=Path(a.fit))
        spec.sampler = a.sampler or own_sampler(spec)    # mis-rational where the file carries its inverse CDFs
        scene.materials["obj"] = spec
    elif a.sampler:
        scene.materials["obj"].sampler = a.sampler
    r = Renderer(scene, device="cpu")
    r.render(spp=4, threads=1)
    r.render(spp=a.spp, threads=1)


def _run(cmd, what, stdin_text=None) -> str:
    try:
        p = subprocess.run(cmd, input=stdin_text, capture_output=True, text=True, check=False)
    except OSError as e:
        raise ProfileError(f"{what}: cannot run {cmd[0]} ({e})") from None
    if p.returncode != 0:
        tail = (p.stderr or p.stdout).strip().splitlines()[-1:] or [""]
        raise ProfileError(f"{what}: {cmd[0]} exited {p.returncode} ({tail[0]})")
    return p.stdout


def profile(a) -> dict:
    for tool in ("perf", "objdump", "addr2line"):
        if shutil.which(tool) is None:
            raise ProfileError(f"{tool} not found: install linux-perf / binutils to profile")
    if not (DATA / "rgl" / f"{a.material}.bsdf").is_file():
        raise ProfileError(f"--material: {DATA / 'rgl' / (a.material + '.bsdf')} not found")
    if a.fit and not Path(a.fit).is_file():
        raise ProfileError(f"--fit: {a.fit} not found")
    with tempfile.TemporaryDirectory(prefix="rbrdf-profile-") as tmp:
        tmp = Path(tmp)
        env = dict(os.environ, WARP_CACHE_PATH=str(tmp / "cache"), PYTHONPATH=str(ROOT))
        data = tmp / "perf.data"
        cmd = ["perf", "record", "-F", str(a.frequency), "-o", str(data), "--",
               sys.executable, "-m", "benchmarks.profile_render", "--child",
               "--material", a.material, "--envmap", a.envmap, "--spp", str(a.spp),
               "--resolution", str(a.resolution)] + (["--fit", str(Path(a.fit).resolve())] if a.fit else []) \
        + (["--sampler", a.sampler] if a.sampler else [])
        p = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT, check=False)
        if p.returncode != 0:
            tail = p.stderr.strip().splitlines()[-1:] or [""]
            raise ProfileError(f"perf record exited {p.returncode} ({tail[0]})")
        objs = sorted((tmp / "cache").rglob("*render_tile*.o"))
        if not objs:
            raise ProfileError("the render kernel's object was not found in the private cache")
        obj = objs[-1]
        script = _run(["perf", "script", "-i", str(data), "-F", "ip,sym,dso"], "perf script")
        jit, libm, total = [], collections.Counter(), 0
        for line in script.splitlines():
            parts = line.split()
            if not parts:
                continue
            total += 1
            dso = parts[-1]
            if "perf-" in dso or "JIT" in dso or "unknown" in dso:
                jit.append(int(parts[0], 16))
            elif "libm" in dso and len(parts) >= 3:
                libm[re.sub(r"@.*", "", parts[1])] += 1
        starts = instruction_starts(_run(["objdump", "-d", "--no-show-raw-insn", str(obj)], "objdump"))
        base, share = find_load_base(jit, starts)
        counts = collections.Counter(x - base for x in jit)
        inside = {o: n for o, n in counts.items() if 0 <= o <= starts[-1]}
        a2l = _run(["addr2line", "-a", "-f", "-i", "-C", "-j", ".ltext", "-e", str(obj)], "addr2line",
                   stdin_text="\n".join(hex(o) for o in inside))
        chains = parse_addr2line(a2l)
        inc, exc, comp = attribute(inside, chains)
        by_line = collections.Counter()
        if getattr(a, "lines", False):
            cpps = sorted((tmp / "cache").rglob("*render_tile*.cpp"))
            if cpps:
                by_line = attribute_lines(inside, innermost_cpp_lines(a2l), cpps[-1].read_text().splitlines())
    return {"material": Path(a.fit).name if a.fit else a.material, "sampler": a.sampler, "envmap": a.envmap, "spp": a.spp, "resolution": a.resolution,
                "samples": total, "kernel_samples": sum(inside.values()), "aligned_share": share,
                "libm_samples": sum(libm.values()), "libm": dict(libm.most_common()),
                "inclusive": dict(inc.most_common()), "exclusive": dict(exc.most_common()),
                "components": dict(comp.most_common()), "lines": dict(by_line.most_common())}


def report(res: dict, top: int = 25) -> str:
    """The tables of :func:`profile`, as shares of the render's samples (the kernel's plus the
    libm functions it calls; start-up and compilation are left out)."""
    tot = res["kernel_samples"] + res["libm_samples"]
    pct = lambda n: f"{100.0 * n / max(tot, 1):5.1f} %"
    out = [(f"{res['material']}{' (' + res['sampler'] + ')' if res.get('sampler') else ''} under {res['envmap']}, {res['resolution']} px, {res['spp']} spp, 1 thread: "
           f"{tot} samples in the render kernel and the libm functions it calls (of {res['samples']} in "
           f"the process: start-up and compilation are the rest); load address found for "
           f"{100 * res['aligned_share']:.1f} % of the kernel's samples"), "",
           "component (share of the render's samples)"]
    out += [f"  {pct(n)}  {name}" for name, n in res["components"].items()]
    out += [f"  {pct(res['libm_samples'])}  libm (trig called from the kernel)", "",
            "Warp function, inclusive"]
    out += [f"  {pct(n)}  {name}" for name, n in list(res["inclusive"].items())[:top]]
    out += ["", "Warp function, exclusive (innermost)"]
    out += [f"  {pct(n)}  {name}" for name, n in list(res["exclusive"].items())[:top]]
    out += ["", "libm"]
    out += [f"  {pct(n)}  {name}" for name, n in list(res["libm"].items())[:10]]
    if res.get("lines"):
        out += ["", ("Warp source statement (of each sample's innermost generated line; a load's wait shows "
                     "on the statement that uses it)")]
        out += [f"  {pct(n)}  {name}" for name, n in list(res["lines"].items())[:top]]
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.profile_render", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--material", default="cc_ibiza_sunset_rgb", help="RGL file name under $RBRDF_DATA/rgl")
    ap.add_argument("--envmap", default="rooitou_park_1k", help="map name under $RBRDF_DATA/envmaps")
    ap.add_argument("--fit", default=None, help="a rational coefficient file: profile it instead of --material")
    ap.add_argument("--sampler", default=None,
                    help="the sampler (strategy) to render with (default: the material's own: mis-rgl for --material, "
                         "mis-rational for a --fit that carries its inverse CDFs)")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--frequency", type=int, default=4000, help="perf sampling frequency (Hz)")
    ap.add_argument("--json", default=None, help="also write the numbers to this file")
    ap.add_argument("--lines", action="store_true",
                    help="also attribute the samples to Warp source statements (the generated C++ line's comment)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.spp < 1 or a.resolution < 8:
        ap.error("--spp must be >= 1 and --resolution >= 8")
    if a.child:
        _child(a)
        return 0
    try:
        res = profile(a)
    except ProfileError as e:
        print(f"profile_render: {e}", file=sys.stderr)
        return 2
    print(report(res))
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
