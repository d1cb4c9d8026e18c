"""Typed access to one TOML table of a scene file: every value is checked, and every error is a
one-line :class:`~warp_rbrdf.errors.SceneError` naming the file, the key and what was expected."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from fit.errors import BRDFFileError, display_path
from fit.inputs import check_regular_file

from .. import transforms
from ..errors import RenderError, SceneError
from ..limits import MAX_ANGLE_DEG, MAX_COORDINATE, MAX_LENGTH, MIN_LENGTH
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

    def vector(self, k, n, default=None, required=False, allow_scalar=False, nonneg=False,
               max_abs=MAX_COORDINATE, hi=None, integer=False):
        """``n`` finite numbers (a tuple of floats, ints with ``integer``), each of magnitude at
        most ``max_abs`` (:data:`warp_rbrdf.limits.MAX_COORDINATE` by default), ``>= 0`` with
        ``nonneg``, ``<= hi`` when given."""
        v = self._get(k, default, required)
        if v is MISSING:
            return default
        top = hi if hi is not None else max_abs
        rng = f" in [0, {top:g}]" if nonneg else f" in [{-top:g}, {top:g}]" if hi is None else f" <= {top:g}"
        what = f"a list of {n} {'integers' if integer else 'numbers'}" \
            + (" (or one number)" if allow_scalar else "") + rng
        if allow_scalar and isinstance(v, (int, float)) and not isinstance(v, bool):
            v = [v] * n
        num = int if integer else (int, float)
        if not (isinstance(v, list) and len(v) == n
                and all(isinstance(x, num) and not isinstance(x, bool) and math.isfinite(x)
                        for x in v)):
            raise self.error(k, f"expected {what}, got {show(v)}")
        if (nonneg and any(x < 0 for x in v)) or any(abs(x) > top for x in v):
            raise self.error(k, f"expected {what}, got {show(v)}")
        return tuple(int(x) for x in v) if integer else tuple(float(x) for x in v)

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
        if must_exist:
            try:
                missing = not p.exists()
            except (OSError, ValueError):
                missing = False
            if missing:
                hint = " (set RBRDF_DATA to the shared data folder)" if ("RBRDF_DATA" in v or v.startswith("data:")) else ""
                raise self.error(k, f"{what} not found: {display_path(p)}{hint}")
            try:
                check_regular_file(p, None, what)   # a folder, named pipe or device: refused
            except BRDFFileError as e:
                raise self.error(k, f"{what} {display_path(p)}: {e.problem}") from None
        return p

    def rotation(self, k):
        v = self._get(k, None, False)
        if v is MISSING:
            return np.eye(3)
        try:
            m = transforms.compose(rotate=_rotation_list(v))
        except (TypeError, ValueError, IndexError):
            raise self.error(k, f"expected [angle_deg, ax, ay, az] (finite, |angle| <= {MAX_ANGLE_DEG:g}, a non-zero axis) or a list of them, got {show(v)}") from None
        return m[:3, :3]

    def transform(self, k):
        v = self._get(k, None, False)
        if v is MISSING:
            return np.eye(4)
        t = Table(v, self.file, self.key(k), self.base_dir)
        if t.has("matrix"):
            m = t._get("matrix", None, True)
            try:
                if not (isinstance(m, list) and len(m) == 4 and all(
                        isinstance(r, list) and len(r) == 4
                        and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in r)
                        for r in m)):
                    raise ValueError
                arr = np.asarray(m, dtype=float)
                if not np.all(np.isfinite(arr)) or np.abs(arr).max() > MAX_COORDINATE:
                    raise ValueError
            except (TypeError, ValueError, OverflowError):
                raise t.error("matrix", f"expected a 4x4 list of finite numbers of magnitude <= "
                                        f"{MAX_COORDINATE:g}, got {show(m)}") from None
            if not np.array_equal(arr[3], [0.0, 0.0, 0.0, 1.0]):
                raise t.error("matrix", f"expected an affine matrix (last row [0, 0, 0, 1]), got {show(m[3])}")
            if abs(np.linalg.det(arr[:3, :3])) < 1e-12:
                raise t.error("matrix", "matrix is singular")
            t.finish(allowed=("matrix",))
            return arr
        scale = None
        if t.has("scale"):
            scale = t.vector("scale", 3, allow_scalar=True, max_abs=MAX_LENGTH)
            if any(abs(s) < MIN_LENGTH for s in scale):
                raise t.error("scale", f"expected scale factors of magnitude in [{MIN_LENGTH:g}, "
                                       f"{MAX_LENGTH:g}], got {show(list(scale))}")
        rot = None
        if t.has("rotate"):
            rv = t._get("rotate", None, True)
            try:
                rot = _rotation_list(rv)
                transforms.compose(rotate=rot)
            except (TypeError, ValueError, IndexError):
                raise t.error("rotate", f"expected [angle_deg, ax, ay, az] (finite, |angle| <= {MAX_ANGLE_DEG:g}, a non-zero axis) or a list of them, got {show(rv)}") from None
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
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                        for x in r)):
            raise ValueError
        if abs(r[0]) > MAX_ANGLE_DEG or any(abs(x) > MAX_COORDINATE for x in r[1:]):
            raise ValueError
        if all(abs(x) < 1e-30 for x in r[1:]):
            raise ValueError
    return rots


def show(v) -> str:
    """A short one-line ``repr`` of a scene value (lists cut after a few items: a value nested
    too deeply never reaches here, see :func:`fit.inputs.nesting_depth`)."""
    if isinstance(v, list) and len(v) > 8:
        v = v[:8] + ["..."]
    try:
        s = repr(v)
    except RecursionError:
        s = "<nested too deeply>"
    return s if len(s) <= 60 else s[:57] + "..."
