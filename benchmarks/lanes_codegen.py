"""What the compiler made of a variant of the K-lane prototype (:mod:`benchmarks.lanes_prototype`):
instruction counts of its CPU object and LLVM's loop-vectorizer remarks.

* :func:`instruction_counts` / :func:`count_instructions`: ``objdump -d`` of the object Warp
  wrote in its kernel cache: all instructions, those on ymm registers, packed single-precision
  arithmetic (xmm or ymm), gathers, scalar single-precision arithmetic;
* :func:`vectorizer_remarks`: the remarks Clang prints for every loop of a module compiled
  with ``-Rpass=loop-vectorize`` and its ``-missed`` / ``-analysis`` forms, each attributed to
  the Warp source line it comes from (Warp writes ``<L n>`` comments above each generated
  statement); remarks located in Warp's own headers keep the header's name.
"""
import collections
import os
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

#: Clang flags that print the loop vectorizer's decisions
REMARK_FLAGS = " -Rpass=loop-vectorize -Rpass-missed=loop-vectorize -Rpass-analysis=loop-vectorize"
REMARK = re.compile(r"^(\S+?):(\d+):\d+: remark: (.*?) \[-Rpass")


def object_file(kernel) -> Path | None:
    """The CPU object of ``kernel``'s module in Warp's kernel cache (None before a load)."""
    import warp as wp

    folder = Path(wp.config.kernel_cache_dir) / kernel.module.get_module_identifier()
    objs = sorted(folder.glob("*.o"))
    return objs[0] if objs else None


#: instruction classes counted in the disassembly
PACKED = re.compile(r"^v(?:add|sub|mul|div|fmadd\w*|fmsub\w*|fnmadd\w*|fnmsub\w*|min|max|sqrt|rcp|rsqrt|cmp\w*|blendv|round)ps$")
SCALAR = re.compile(r"^v(?:add|sub|mul|div|fmadd\w*|fmsub\w*|fnmadd\w*|fnmsub\w*|min|max|sqrt|cmp\w*|round)ss$")


def instruction_counts(path: Path | None) -> dict:
    """Counts in ``objdump -d`` of the object: all instructions, those on ymm and on zmm registers,
    packed single-precision arithmetic (xmm, ymm or zmm; and of it on ymm, on zmm), gathers, scalar
    single-precision arithmetic."""
    if path is None or shutil.which("objdump") is None:
        return {}
    text = subprocess.run(["objdump", "-d", "--no-show-raw-insn", str(path)], capture_output=True, text=True,
                          check=True).stdout
    return count_instructions(text)


def count_instructions(text: str) -> dict:
    """:func:`instruction_counts` of ``objdump -d --no-show-raw-insn`` output."""
    counts = {"instructions": 0, "ymm": 0, "zmm": 0, "packed_ps": 0, "packed_ps_ymm": 0, "packed_ps_zmm": 0,
              "gathers": 0, "scalar_ss": 0}
    for line in text.splitlines():
        parts = line.split("\t")
        if len(parts) < 2 or not re.match(r"^\s*[0-9a-f]+:$", parts[0]):
            continue
        ins = parts[1].strip()
        op = ins.split(" ", 1)[0]
        counts["instructions"] += 1
        ymm, zmm = "%ymm" in ins, "%zmm" in ins
        counts["ymm"] += ymm
        counts["zmm"] += zmm
        if PACKED.match(op):
            counts["packed_ps"] += 1
            counts["packed_ps_ymm"] += ymm
            counts["packed_ps_zmm"] += zmm
        counts["gathers"] += "gather" in op
        counts["scalar_ss"] += bool(SCALAR.match(op))
    return counts


def vectorizer_remarks(build, render) -> collections.Counter:
    """``Counter`` of ``(where, remark)`` for a kernel compiled now: ``build(extra_flags)``
    returns it (a flag that makes its module new, so that it compiles), ``render(kernel)``
    loads it. ``where`` is ``Python line <n>: <statement>`` or a Warp header's name."""
    tag = f" -DLANES_REMARKS_{os.getpid()}_{time.monotonic_ns()}"
    kernel = build(REMARK_FLAGS + tag)
    with tempfile.TemporaryFile("w+") as log:
        saved = os.dup(2)
        os.dup2(log.fileno(), 2)          # Clang writes to the process's stderr
        try:
            render(kernel)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        log.seek(0)
        text = log.read()
    obj = object_file(kernel)
    cpp = sorted(obj.parent.glob("*.cpp"))[0].read_text().splitlines() if obj else []
    out = collections.Counter()
    for line in text.splitlines():
        m = REMARK.match(line)
        if not m:
            continue
        path, n, msg = m.group(1), int(m.group(2)), m.group(3)
        where = Path(path).name
        if path.endswith(".cpp") and cpp:
            src = next((c for c in reversed(cpp[:n]) if "<L " in c), "")
            where = " ".join(src.strip().lstrip("/").split())
        out[where, msg] += 1
    return out
