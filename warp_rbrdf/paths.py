"""Where data files are found.

* ``${RBRDF_DATA}/x`` and ``data:x`` resolve against the shared data folder: the environment
  variable ``RBRDF_DATA``; when it is unset and the package runs from a source checkout, the
  folder ``shared/data`` next to the checkout (``../shared/data`` from its root). An installed
  package has no default: a path that needs the folder is then a one-line error saying to set
  ``RBRDF_DATA``.
* ``pkg:x`` resolves against the package data folder ``warp_rbrdf/data/``.
* Any other relative path resolves against the folder of the scene file (or the current
  directory for scenes built in memory). ``~`` and other ``${VAR}`` are expanded.
* A path taken from an environment variable (``RBRDF_DATA``, or a ``$VAR`` / ``${VAR}`` that
  starts a scene path) that is itself relative resolves against the current working directory
  at the time it is read, like any path typed in a shell (``export RBRDF_DATA=../shared/data``
  means the same folder whichever scene folder refers to it): :func:`env_path`.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

from .errors import RenderError

PACKAGE_DIR = Path(__file__).resolve().parent
PROJECT_ROOT = PACKAGE_DIR.parent
PACKAGE_DATA = PACKAGE_DIR / "data"


def in_checkout() -> bool:
    """True when the package runs from a source checkout (not an installed copy)."""
    return (PROJECT_ROOT / "pyproject.toml").is_file()


# a leading ``$NAME`` or ``${NAME}`` of a scene path
_LEADING_VAR = re.compile(r"\$(?:\{([A-Za-z_][A-Za-z0-9_]*)\}|([A-Za-z_][A-Za-z0-9_]*))")


def env_path(name: str) -> Path | None:
    """The path held by environment variable ``name``, ``~`` expanded and made absolute against
    the current working directory when it is read (``..`` kept, so the operating system's own
    meaning of it holds); None when the variable is unset or empty."""
    value = os.environ.get(name)
    if not value:
        return None
    p = Path(os.path.expanduser(value))
    return p if p.is_absolute() else Path(os.getcwd()) / p


def data_root() -> Path | None:
    """The shared data folder, an absolute path: ``$RBRDF_DATA`` (relative to the current working
    directory when relative, see :func:`env_path`), else ``<checkout>/../shared/data`` in a
    source checkout, else None."""
    env = env_path("RBRDF_DATA")
    if env is not None:
        return env
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
    m = _LEADING_VAR.match(s)
    lead = env_path(m.group(1) or m.group(2)) if m else None
    if lead is not None:                     # unset: left as written, as expandvars does
        s = str(lead) + os.path.expandvars(s[m.end():])
    else:
        s = os.path.expanduser(os.path.expandvars(s))
    p = Path(s)
    if not p.is_absolute():
        p = (base_dir or Path.cwd()) / p
    return p
