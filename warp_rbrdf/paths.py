"""Where data files are found.

* ``${RBRDF_DATA}/x`` and ``data:x`` resolve against the shared data folder: the environment
  variable ``RBRDF_DATA``; when it is unset and the package runs from a source checkout, the
  folder ``shared/data`` next to the checkout (``../shared/data`` from its root). An installed
  package has no default: a path that needs the folder is then a one-line error saying to set
  ``RBRDF_DATA``.
* ``pkg:x`` resolves against the package data folder ``warp_rbrdf/data/``.
* Any other relative path resolves against the folder of the scene file (or the current
  directory for scenes built in memory). ``~`` and other ``${VAR}`` are expanded.
"""
from __future__ import annotations

import os
from pathlib import Path

from .errors import RenderError

PACKAGE_DIR = Path(__file__).resolve().parent
PROJECT_ROOT = PACKAGE_DIR.parent
PACKAGE_DATA = PACKAGE_DIR / "data"


def in_checkout() -> bool:
    """True when the package runs from a source checkout (not an installed copy)."""
    return (PROJECT_ROOT / "pyproject.toml").is_file()


def data_root() -> Path | None:
    """The shared data folder: ``$RBRDF_DATA``, else ``<checkout>/../shared/data`` in a source
    checkout, else None."""
    env = os.environ.get("RBRDF_DATA")
    if env:
        return Path(env)
    return PROJECT_ROOT.parent / "shared" / "data" if in_checkout() else None


def require_data_root(what: str = "this path") -> Path:
    """:func:`data_root`, or a one-line :class:`RenderError` when there is none."""
    root = data_root()
    if root is None:
        raise RenderError(f"{what} needs the shared data folder: set RBRDF_DATA to it "
                          "(e.g. export RBRDF_DATA=/path/to/shared/data)")
    return root


def resolve_path(text: str, base_dir: Path | None = None) -> Path:
    """Resolve a path as written in a scene file (see the module docstring)."""
    s = str(text)
    if s.startswith("data:"):
        return require_data_root(repr(s)) / s[5:].lstrip("/")
    if s.startswith("pkg:"):
        return PACKAGE_DATA / s[4:].lstrip("/")
    if "RBRDF_DATA" in s:
        root = str(require_data_root(repr(s)))
        s = s.replace("${RBRDF_DATA}", root).replace("$RBRDF_DATA", root)
    s = os.path.expanduser(os.path.expandvars(s))
    p = Path(s)
    if not p.is_absolute():
        p = (base_dir or Path.cwd()) / p
    return p
