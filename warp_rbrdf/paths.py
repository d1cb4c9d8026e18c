"""Where data files are found.

* ``${RBRDF_DATA}/x`` and ``data:x`` resolve against the environment variable ``RBRDF_DATA``
  (default ``../shared/data`` relative to the project root).
* ``pkg:x`` resolves against the package data folder ``warp_rbrdf/data/``.
* Any other relative path resolves against the folder of the scene file (or the current
  directory for scenes built in memory). ``~`` and other ``${VAR}`` are expanded.
"""
from __future__ import annotations

import os
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
PROJECT_ROOT = PACKAGE_DIR.parent
PACKAGE_DATA = PACKAGE_DIR / "data"


def data_root() -> Path:
    """The shared data folder: ``$RBRDF_DATA`` or ``<project>/../shared/data``."""
    env = os.environ.get("RBRDF_DATA")
    return Path(env) if env else PROJECT_ROOT.parent / "shared" / "data"


def resolve_path(text: str, base_dir: Path | None = None) -> Path:
    """Resolve a path as written in a scene file (see the module docstring)."""
    s = str(text)
    if s.startswith("data:"):
        return data_root() / s[5:].lstrip("/")
    if s.startswith("pkg:"):
        return PACKAGE_DATA / s[4:].lstrip("/")
    root = str(data_root())
    s = s.replace("${RBRDF_DATA}", root).replace("$RBRDF_DATA", root)
    s = os.path.expanduser(os.path.expandvars(s))
    p = Path(s)
    if not p.is_absolute():
        p = (base_dir or Path.cwd()) / p
    return p
