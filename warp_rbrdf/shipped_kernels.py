"""Ahead-of-time compiled render kernels shipped with the package: the loader (cold start).

A fresh install has an empty Warp kernel cache, and LLVM compiling the default scene's render
kernel costs about 5 s of CPU (15-25 s of wall clock on a loaded 2-core machine). For the scenes
we ship (the README main job's embedded default scene), the compiled CPU object and Warp's
metadata ship in ``warp_rbrdf/data/kernels/<warp version>/<platform>/<module identifier>/``,
with a ``manifest.json`` per platform folder recording, per module, Warp's full module hash and
the SHA-256 of every file. They are written by ``python -m tools.ship_kernels`` (a checkout
tool, not part of the package) through Warp's public ``wp.compile_aot_module``.

:func:`load_module` is the renderer's compile step. For a CPU module that the shipped set
holds, it loads the shipped object in place with Warp's public ``wp.load_aot_module`` (nothing
is copied, nothing compiled, the kernel cache is left as it is). Anything else loads from the
kernel cache or compiles, as Warp always does. Never a wrong binary:

- exactly this Warp version (the folder), platform (``linux-x86_64``) and module identifier
  (the folder; Warp's identifier contains the hash prefix), and the manifest's full module hash
  equals ``module.get_module_hash()``; the LLVM version and target triple are part of the
  object's file name as Warp names it, so another toolchain finds no object and compiles;
- the shipped files' SHA-256 match the manifest (a damaged file is not loaded);
- the CPU supports the ISA level the object was built for (its manifest entry's ``isa``: every
  flag of :data:`ISA_LEVELS` for it in ``/proc/cpuinfo``), else an illegal instruction could
  kill the process;
- if Warp fails to load the shipped object, the module compiles.

The render kernels are compiled for an **ISA level** chosen at run time (:func:`isa_level`): the
best of :data:`ISA_LEVELS` whose every feature the CPU has, ``x86-64-v4`` (AVX-512) or
``x86-64-v3`` (AVX2, FMA), with Warp's default flags but ``-target-cpu <level>`` for
``-march=native`` (:func:`portable_cpu_flags`), so the module hash, and thus the shipped
object, depends on the level and not on the build machine's CPU; one object per level ships.
``RBRDF_CPU_ISA`` caps the level (``x86-64-v3``: the same code, so the same images, on every
x86-64-v3 machine) or asks for ``native``. A CPU without x86-64-v3 (or a system without
``/proc/cpuinfo``) keeps Warp's ``-march=native`` (and compiles). What the level buys is
measured in docs/architecture.md. Their module default ``block_dim`` is 1, the variant a
CPU launch without ``block_dim`` uses (Warp's documented launch default: 1 on the CPU, 256 on
CUDA): the AOT API compiles and loads the module default variant, and CUDA launches keep 256.

``RBRDF_SHIPPED_KERNELS``: another folder to use in place of ``data/kernels`` (tests), or an
empty string to use no shipped kernels.
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import platform
import sys
from pathlib import Path

from .errors import RenderError
from .paths import PACKAGE_DATA

#: The portable ISA level: every x86-64-v3 CPU runs its code (the shipped set's floor).
ISA_LEVEL = "x86-64-v3"
#: ``/proc/cpuinfo`` flags that x86-64-v3 requires (LLVM's names: sahf = lahf_lm, sse3 = pni,
#: bmi = bmi1, lzcnt = abm).
ISA_FEATURES = frozenset({
    "cx16", "lahf_lm", "popcnt", "pni", "sse4_1", "sse4_2", "ssse3",                  # v2
    "avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe", "xsave",            # v3
})
#: The ISA levels of the render kernels' code, best first, with the ``/proc/cpuinfo`` flags
#: each requires: x86-64-v4 adds AVX-512 F, BW, CD, DQ and VL to x86-64-v3.
ISA_LEVELS = {
    "x86-64-v4": ISA_FEATURES | {"avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl"},
    ISA_LEVEL: ISA_FEATURES,
}
#: Environment variable capping the level (a name of :data:`ISA_LEVELS`, or ``native``).
ISA_ENV = "RBRDF_CPU_ISA"
#: Warp 1.19's default CPU flags (``warp.config.cpu_compiler_flags``) after ``-target-cpu
#: <level>`` in place of ``-march=native`` (the flags go to Clang's ``cc1``, which takes
#: ``-target-cpu``).
_FLAGS_TAIL = ("-mllvm=-inline-threshold=9000 -mllvm=-inline-cold-callsite-threshold=3000 "
               "-mllvm=-slp-recursion-max-depth=4 -ffp-contract=fast")


def portable_cpu_flags(level: str = ISA_LEVEL) -> str:
    """The render kernels' CPU flags for ISA ``level`` (a name of :data:`ISA_LEVELS`)."""
    return f"-target-cpu {level} {_FLAGS_TAIL}"


#: The flags of the portable level (:data:`ISA_LEVEL`).
PORTABLE_CPU_FLAGS = portable_cpu_flags(ISA_LEVEL)
#: The render kernels' module default block_dim: a CPU launch's (see the module docstring).
CPU_BLOCK_DIM = 1
#: The block_dim Warp launches with on CUDA when none is given (its documented default).
CUDA_BLOCK_DIM = 256
MANIFEST = "manifest.json"
ENV = "RBRDF_SHIPPED_KERNELS"
CPUINFO = Path("/proc/cpuinfo")


def render_module_options() -> dict:
    """Module options of every render kernel (``@wp.kernel(module_options=...)``): block_dim
    :data:`CPU_BLOCK_DIM`, and the flags of :func:`isa_level` (none where it is None: Warp's
    ``-march=native``; an x86-64-v3 object would stop such a CPU with an illegal instruction)."""
    level = isa_level()
    flags = {"cpu_compiler_flags": portable_cpu_flags(level)} if level else {}
    return {"block_dim": CPU_BLOCK_DIM, **flags}


def platform_tag() -> str:
    """``<os>-<machine>``, e.g. ``linux-x86_64``: the folder below the Warp version."""
    return f"{sys.platform}-{platform.machine().lower()}"


def shipped_root() -> Path | None:
    """The folder holding ``<warp version>/<platform>/``; ``None`` when disabled."""
    env = os.environ.get(ENV)
    if env is not None:
        return Path(env) if env else None
    return PACKAGE_DATA / "kernels"


def platform_dir(wp, root: Path | None = None) -> Path | None:
    """``<root>/<warp version>/<platform>`` (default root: :func:`shipped_root`)."""
    root = shipped_root() if root is None else root
    return None if root is None else root / wp.config.version / platform_tag()


def sha256(path: Path) -> str:
    """Hex SHA-256 of the file at ``path``."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@functools.lru_cache(maxsize=1)
def cpu_flags() -> frozenset:
    """The host CPU's feature flags from ``/proc/cpuinfo`` (empty where there is none)."""
    try:
        text = CPUINFO.read_text()
    except OSError:
        return frozenset()
    for line in text.splitlines():
        name, _, value = line.partition(":")
        if name.strip() == "flags":
            return frozenset(value.split())
    return frozenset()


def cpu_supports_isa(level: str = ISA_LEVEL) -> bool:
    """True when the host CPU has every feature of ISA ``level`` (:data:`ISA_LEVELS`)."""
    return ISA_LEVELS[level] <= cpu_flags()


def isa_level() -> str | None:
    """The ISA level of the render kernels' code on this CPU: the first of :data:`ISA_LEVELS`
    whose every feature the CPU has and that ``$RBRDF_CPU_ISA`` (:data:`ISA_ENV`) admits (a
    level: at most that one; ``native``: none); None: Warp's ``-march=native``. A value of
    ``$RBRDF_CPU_ISA`` that names no level raises :class:`~warp_rbrdf.errors.RenderError`."""
    cap = os.environ.get(ISA_ENV, "").strip()
    names = list(ISA_LEVELS)
    if cap and cap != "native" and cap not in ISA_LEVELS:
        raise RenderError(f"{ISA_ENV}: expected one of {', '.join(names)} or native, got {cap!r}")
    if cap == "native":
        return None
    for level in names[names.index(cap) if cap else 0:]:
        if cpu_supports_isa(level):
            return level
    return None


def module_hash(module) -> str:
    """Warp's full hash (hex) of the module's default variant (the one the AOT API builds)."""
    return module.get_module_hash().hex()


def find_shipped(module, device) -> tuple[Path | None, str]:
    """The verified shipped folder for ``module`` on ``device`` and a one-word reason if none."""
    import warp as wp

    if not device.is_cpu:
        return None, "not-cpu"
    pdir = platform_dir(wp)
    if pdir is None:
        return None, "disabled"
    ident = module.get_module_identifier()
    src = pdir / ident
    try:
        manifest = json.loads((pdir / MANIFEST).read_text())
    except (OSError, ValueError):
        return None, "no-manifest"
    entry = manifest.get("modules", {}).get(ident) if isinstance(manifest, dict) else None
    if not isinstance(entry, dict):
        return None, "not-shipped"
    if manifest.get("warp") != wp.config.version or manifest.get("platform") != platform_tag():
        return None, "other-version"
    if entry.get("hash") != module_hash(module):
        return None, "hash-mismatch"
    files = entry.get("files")
    if not isinstance(files, dict) or not files:
        return None, "no-files"
    for name, digest in files.items():
        try:
            if Path(name).name != name or sha256(src / name) != digest:
                return None, "checksum-mismatch"
        except OSError:
            return None, "missing-file"
    level = entry.get("isa", manifest.get("isa"))
    if level not in ISA_LEVELS or not cpu_supports_isa(level):
        return None, "cpu-lacks-isa"
    return src, "ok"


def load_module(module, device) -> str:
    """Load ``module`` on ``device`` for a launch without ``block_dim``, from the shipped set
    when it holds the module (``wp.load_aot_module``), else as Warp does. Returns where it came
    from: ``"shipped"``, ``"cache"`` or ``"compiled"`` (``"compiled (<reason>)"`` when a shipped
    binary exists but was not used or failed to load)."""
    import warp as wp

    reason = None
    cached = False
    if device.is_cpu:
        try:
            src, why = find_shipped(module, device)
        except Exception as e:  # noqa: BLE001 - an unreadable set or a Warp error: compile
            src, why = None, f"shipped lookup failed: {e}"
        if src is not None:
            try:
                wp.load_aot_module(module, device=device, module_dir=src)
                return "shipped"
            except Exception as e:  # noqa: BLE001 - Warp raises plain Exception on a bad object
                why = f"load failed: {e}"
                module.unload()
        if why not in ("not-shipped", "disabled", "no-manifest"):
            reason = why
        cached = (Path(wp.config.kernel_cache_dir) / module.get_module_identifier()).is_dir()
    wp.load_module(module, device=device, block_dim=CPU_BLOCK_DIM if device.is_cpu else CUDA_BLOCK_DIM)
    if cached:
        return "cache"
    return "compiled" if reason is None else f"compiled ({reason})"
