"""Warp initialisation: kernel cache folder, quiet logging, no adjoint code, device selection."""
from __future__ import annotations

import os
import threading

from .errors import RenderError
from .paths import PROJECT_ROOT, in_checkout

_lock = threading.Lock()
_initialised = False


def init_warp():
    """Initialise Warp once. Kernel cache: ``$WARP_CACHE_PATH``; else ``<checkout>/.warp_cache``
    when running from a source checkout; else Warp's own per-user default."""
    global _initialised
    import warp as wp

    with _lock:
        if not _initialised:
            cache = os.environ.get("WARP_CACHE_PATH")
            if cache is None and in_checkout():
                cache = str(PROJECT_ROOT / ".warp_cache")
            if cache is not None:
                wp.config.kernel_cache_dir = cache
            wp.config.log_level = wp.LOG_WARNING
            wp.config.quiet = True
            # nothing is differentiated: without adjoints a kernel compiles in about half the
            # time (benchmarks/bench_startup.py)
            wp.config.enable_backward = False
            wp.init()
            _initialised = True
    return wp


def get_device(name: str | None = None):
    """The Warp device for ``name`` (``"cpu"``, ``"cuda"``, ``"cuda:N"``); ``None``: the
    environment variable ``RBRDF_DEVICE``, else ``"cpu"``. Clear error (naming the variable when
    the name came from it) if the name is unknown or the device absent."""
    wp = init_warp()
    source = ""
    if name is None:
        name = os.environ.get("RBRDF_DEVICE", "")
        source = "RBRDF_DEVICE: " if name.strip() else ""
    name = (name or "").strip().lower() or "cpu"
    if name.startswith("cuda"):
        if not wp.is_cuda_available():
            raise RenderError(f"{source}device {name!r} requested but CUDA is not available on this "
                              "machine (no CUDA driver/GPU found); use --device cpu")
        try:
            return wp.get_device(name)
        except Exception as e:  # noqa: BLE001 - Warp raises plain exceptions for bad ordinals
            raise RenderError(f"{source}device {name!r}: {e}") from None
    if name != "cpu":
        raise RenderError(f"{source}unknown device {name[:40]!r}; expected 'cpu', 'cuda' or 'cuda:N'")
    return wp.get_device("cpu")
