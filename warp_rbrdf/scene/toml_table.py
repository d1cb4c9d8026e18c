"""Typed access to one TOML table of a scene file: every value is checked, and every error is a
one-line :class:`~warp_rbrdf.errors.SceneError` naming the file, the key and what was expected."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import transforms
from ..errors import RenderError, SceneError
from ..paths import resolve_path


# --------------------------------------------------------------------------------------------
class Table:
    """Typed access to one TOML table, with errors naming the file and the key."""

    def __init__(self, data, file, prefix: str, base_dir: Path | None):
        self.file, self.prefix, self.base_dir = file, prefix, base_dir
        if not isinstance(data, dict):
            raise SceneError(file, prefix, f"expected a table, got {show(data)}")
        self.data = data
        self.used: set[str] = set()

    def key(self, k: str) -> str:
        return f"{self.prefix}.{k}" if self.prefix else k

    def error(self, k: str, problem: str):
        return SceneError(self.file, self.key(k) if k else self.prefix, problem)

    def has(self, k):
        return k in self.data

    def _get(self, k, default, required):
        self.used.add(k)
        if k not in self.data:
            if required:
                raise self.error(k, "missing required key")
            return MISSING
        return self.data[k]

    def number(self, k, default=None, lo=None, hi=None, lo_open=False, hi_open=False,
               required=False, integer=False):
        v = self._get(k, default, required)
        if v is MISSING:
            return default
        kind = "an integer" if integer else "a number"
        ok = (isinstance(v, int) if integer else isinstance(v, (int, float))) and not isinstance(v, bool)
        rng = ""
        if lo is not None or hi is not None:
            rng = " in " + ("(" if lo_open else "[") + (str(lo) if lo is not None else "-inf") + ", " \
                  + (str(hi) if hi is not None else "inf") + (")" if hi_open or hi is None else "]")
        if ok and math.isfinite(v):
            if lo is not None and (v < lo or (lo_open and v == lo)):
                ok = False
            if hi is not None and (v > hi or (hi_open and v == hi)):
                ok = False
        else:
            ok = False
        if not ok:
            raise self.error(k, f"expected {kind}{rng}, got {show(v)}")
        return int(v) if integer else float(v)

    def vector(self, k, n, default=None, required=False, allow_scalar=False, nonneg=False):
        v = self._get(k, default, required)
        if v is MISSING:
            return default
        what = f"a list of {n} numbers" + (" (or one number)" if allow_scalar else "") \
            + (" >= 0" if nonneg else "")
        if allow_scalar and isinstance(v, (int, float)) and not isinstance(v, bool):
            v = [v] * n
        if not (isinstance(v, list) and len(v) == n
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                        for x in v)):
            raise self.error(k, f"expected {what}, got {show(v)}")
        if nonneg and any(x < 0 for x in v):
            raise self.error(k, f"expected {what}, got {show(v)}")
        return tuple(float(x) for x in v)

    def string(self, k, default=None, choices=None, required=False):
        v = self._get(k, default, required)
        if v is MISSING:
            return default
        if not isinstance(v, str) or (choices and v not in choices):
            exp = "one of " + ", ".join(repr(c) for c in choices) if choices else "a string"
            raise self.error(k, f"expected {exp}, got {show(v)}")
        return v

    def boolean(self, k, default=None):
        v = self._get(k, default, False)
        if v is MISSING:
            return default
        if not isinstance(v, bool):
            raise self.error(k, f"expected true or false, got {show(v)}")
        return v

    def path(self, k, required=False, must_exist=True, what="file"):
        v = self.string(k, None, required=required)
        if v is None:
            return None
        try:
            p = resolve_path(v, self.base_dir)
        except RenderError as e:
            raise self.error(k, str(e)) from None
        if must_exist and not p.is_file():
            hint = " (set RBRDF_DATA to the shared data folder)" if ("RBRDF_DATA" in v or v.startswith("data:")) else ""
            raise self.error(k, f"{what} not found: {p}{hint}")
        return p

    def rotation(self, k):
        v = self._get(k, None, False)
        if v is MISSING:
            return np.eye(3)
        try:
            m = transforms.compose(rotate=_rotation_list(v))
        except (TypeError, ValueError, IndexError):
            raise self.error(k, f"expected [angle_deg, ax, ay, az] or a list of them, got {show(v)}") from None
        return m[:3, :3]

    def transform(self, k):
        v = self._get(k, None, False)
        if v is MISSING:
            return np.eye(4)
        t = Table(v, self.file, self.key(k), self.base_dir)
        if t.has("matrix"):
            m = t._get("matrix", None, True)
            try:
                arr = np.asarray(m, dtype=float)
                if arr.shape != (4, 4) or not np.all(np.isfinite(arr)):
                    raise ValueError
            except (TypeError, ValueError):
                raise t.error("matrix", f"expected a 4x4 list of numbers, got {show(m)}") from None
            if abs(np.linalg.det(arr[:3, :3])) < 1e-12:
                raise t.error("matrix", "matrix is singular")
            t.finish(allowed=("matrix",))
            return arr
        scale = None
        if t.has("scale"):
            scale = t.vector("scale", 3, allow_scalar=True)
            if any(s == 0 for s in scale):
                raise t.error("scale", "expected non-zero scale factors")
        rot = None
        if t.has("rotate"):
            rv = t._get("rotate", None, True)
            try:
                rot = _rotation_list(rv)
                transforms.compose(rotate=rot)
            except (TypeError, ValueError, IndexError):
                raise t.error("rotate", f"expected [angle_deg, ax, ay, az] or a list of them, got {show(rv)}") from None
        tr = t.vector("translate", 3) if t.has("translate") else None
        t.finish()
        return transforms.compose(scale=scale, rotate=rot, translate=tr)

    def finish(self, allowed=None):
        allowed = set(allowed) if allowed is not None else self.used
        extra = [k for k in self.data if k not in allowed]
        if extra:
            raise self.error(extra[0], "unknown key; expected one of "
                             + ", ".join(sorted(allowed)) if allowed else "unknown key")


MISSING = object()


def _rotation_list(v):
    if not isinstance(v, list) or not v:
        raise ValueError
    rots = v if isinstance(v[0], list) else [v]
    for r in rots:
        if not (isinstance(r, list) and len(r) == 4
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in r)):
            raise ValueError
        if all(x == 0 for x in r[1:]):
            raise ValueError
    return rots


def show(v) -> str:
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


