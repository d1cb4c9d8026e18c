"""Generated Warp code, used only where coefficients are baked into the code (rational BRDF
fits, the paper's global-layout inverse CDFs): literal helpers and the loader.

A generated module is written to ``<Warp kernel cache>/rbrdf_generated/<prefix>_<hash>.py``
(named by the hash of its source) and imported from that file with :mod:`importlib.util`
(nothing is put on ``sys.path``). Warp hashes the functions' source, so its kernel cache serves
the same coefficients again without a compile.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import threading
from pathlib import Path

from .runtime import init_warp

_lock = threading.Lock()


def lit(x: float) -> str:
    """A float64 literal of Warp code (exact: ``repr`` round-trips)."""
    return f"wp.float64({float(x)!r})"


def tree_sum(terms) -> str:
    """A balanced sum of expression strings: independent partial sums instead of one serial chain
    (the compiler may not reassociate floating-point adds, and a 45-term chain is a 45-add
    latency chain)."""
    terms = list(terms)
    if not terms:
        return "wp.float64(0.0)"
    while len(terms) > 1:
        terms = [f"({terms[i]} + {terms[i + 1]})" if i + 1 < len(terms) else terms[i]
                 for i in range(0, len(terms), 2)]
    return terms[0]


def generated_dir() -> Path:
    """Folder of the generated modules: inside Warp's kernel cache (see :func:`runtime.init_warp`)."""
    return Path(init_warp().config.kernel_cache_dir) / "rbrdf_generated"


def load_generated(source: str, prefix: str):
    """Write ``source`` to the generated-code folder (named by its hash) and import it as module
    ``<prefix>_<hash>`` (once per process)."""
    name = f"{prefix}_{hashlib.sha1(source.encode()).hexdigest()[:16]}"
    with _lock:
        if name in sys.modules:
            return sys.modules[name]
        d = generated_dir()
        d.mkdir(parents=True, exist_ok=True)
        path = d / f"{name}.py"
        if not path.exists() or path.read_text() != source:
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_text(source)
            os.replace(tmp, path)
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        return module
