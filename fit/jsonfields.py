"""Typed, bounded access to the values of a parsed JSON file.

``np.asarray(["1", "2"], float)`` quietly turns strings into numbers and ``float(True)`` is 1:
the readers of :mod:`fit` never convert a file's values that way. They ask this module for a
number, an integer, a string, a flag or an array of a stated shape; every mismatch raises
:class:`Invalid` with the key's path (``functions[0].numerator.coefficients[3]``), which the
reader turns into one :class:`fit.errors.BRDFFileError` line naming the file and the key.
"""
from __future__ import annotations

import math
import re

import numpy as np


class Invalid(ValueError):
    """A value of a JSON file is missing or of the wrong type, shape or range; ``str`` names
    its key."""

    def __init__(self, key: str, problem: str):
        self.key = key
        super().__init__(f"key {key}: {problem}" if key else problem)


def _kind(v) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true/false"
    if isinstance(v, (int, float)):
        return "a number"
    if isinstance(v, str):
        return f"a string ({v[:20]!r})"
    if isinstance(v, list):
        return "a list"
    if isinstance(v, dict):
        return "an object"
    return type(v).__name__


def is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def obj(v, key: str) -> dict:
    """``v`` if it is a JSON object."""
    if not isinstance(v, dict):
        raise Invalid(key, f"expected an object, got {_kind(v)}")
    return v


def get(d: dict, name: str, key: str = ""):
    """``d[name]``; :class:`Invalid` naming ``key.name`` when it is missing."""
    if not isinstance(d, dict):
        raise Invalid(key, f"expected an object, got {_kind(d)}")
    if name not in d:
        raise Invalid(f"{key}.{name}" if key else name, "missing")
    return d[name]


def sub(key: str, name) -> str:
    """The key path of a member (``name`` a str) or an element (an int) of ``key``."""
    if isinstance(name, int):
        return f"{key}[{name}]"
    return f"{key}.{name}" if key else str(name)


def number(v, key: str, lo: float | None = None, hi: float | None = None, optional: bool = False):
    """A finite JSON number in [lo, hi] as float (``None`` allowed when ``optional``)."""
    if v is None and optional:
        return None
    if not is_number(v):
        raise Invalid(key, f"expected a number, got {_kind(v)}")
    f = float(v)
    if not math.isfinite(f):
        raise Invalid(key, "not a finite number")
    if (lo is not None and f < lo) or (hi is not None and f > hi):
        raise Invalid(key, f"{f:g} is outside [{lo if lo is not None else '-inf'}, "
                           f"{hi if hi is not None else 'inf'}]")
    return f


def integer(v, key: str, lo: int | None = None, hi: int | None = None) -> int:
    """A JSON integer in [lo, hi]: written without a fraction or exponent (``3``, never ``3.0``
    or ``3e0``, which JSON parsers return as floats: an integer field is never converted)."""
    if isinstance(v, float):
        raise Invalid(key, f"expected an integer, got the number {v!r} (integers are written without "
                           "a decimal point or exponent)")
    if not isinstance(v, int) or isinstance(v, bool):
        raise Invalid(key, f"expected an integer, got {_kind(v)}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise Invalid(key, f"{v} is outside [{lo if lo is not None else '-inf'}, "
                           f"{hi if hi is not None else 'inf'}]")
    return int(v)


def string(v, key: str, choices=None, optional: bool = False, max_len: int = 10000):
    """A JSON string (one of ``choices`` when given)."""
    if v is None and optional:
        return None
    if not isinstance(v, str):
        raise Invalid(key, f"expected a string, got {_kind(v)}")
    if len(v) > max_len:
        raise Invalid(key, f"string of {len(v)} characters (at most {max_len})")
    if choices is not None and v not in choices:
        raise Invalid(key, f"{v[:40]!r} is not one of {', '.join(map(repr, choices))}")
    return v


#: Longest name (a model, material, output, variable or unit name, a source file name) a file
#: may hold, in characters; the project's names are below 64.
MAX_NAME_CHARS = 256
#: Characters a name may not hold: C0 and C1 controls (NUL, escape, newline, tab, DEL...), the
#: Unicode line and paragraph separators and the bidirectional embedding, override and isolate
#: controls (text that would print on several lines or reorder what a reader sees).
_NAME_FORBIDDEN = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069]")


def name(v, key: str, optional: bool = False, max_len: int = MAX_NAME_CHARS):
    """A JSON string used as a name: at most ``max_len`` characters, none of them a control
    character, a line separator or a bidirectional control (:data:`_NAME_FORBIDDEN`). Names
    are data: writers that put them into code or markup escape them as well."""
    s = string(v, key, optional=optional, max_len=max_len)
    if s is not None:
        bad = _NAME_FORBIDDEN.search(s)
        if bad:
            raise Invalid(key, f"a name may not hold control characters (U+{ord(bad.group()):04X} at "
                               f"character {bad.start()})")
    return s


def source_record(v, key: str) -> dict:
    """The ``source`` record of a coefficient or CDF file (informative: where the fit came
    from) as a dict: its ``file`` a :func:`name` and its ``sha256`` a hexadecimal digest (at
    most 128 digits) when given; other members are kept for the caller to check."""
    src = dict(obj(v, key))
    if src.get("file") is not None:
        name(src["file"], sub(key, "file"))
    sha = src.get("sha256")
    if sha is not None and (not isinstance(sha, str) or len(sha) > 128
                            or any(ch not in "0123456789abcdefABCDEF" for ch in sha)):
        raise Invalid(sub(key, "sha256"), "expected a hexadecimal digest")
    return src


def flag(v, key: str) -> bool:
    """A JSON ``true`` / ``false``."""
    if not isinstance(v, bool):
        raise Invalid(key, f"expected true or false, got {_kind(v)}")
    return v


def array(v, key: str, shape: tuple, kind: str = "number", max_size: int | None = None) -> np.ndarray:
    """A nested JSON list of ``shape`` (``None`` entries: any length) holding only numbers
    (``kind="number"``: finite, float64), integers (``"int"``: int64) or true/false
    (``"bool"``); :class:`Invalid` naming the first offending element otherwise."""
    ndim = len(shape)
    dims = []
    # the shape, read down the first elements, then checked on every list
    probe = v
    for level in range(ndim):
        k = key if level == 0 else f"{key}{'[0]' * level}"
        if not isinstance(probe, list):
            raise Invalid(k, f"expected a list ({ndim}-D array), got {_kind(probe)}")
        n = len(probe)
        want = shape[level]
        if want is not None and n != want:
            raise Invalid(k, f"has {n} entries, expected {want}")
        dims.append(n)
        probe = probe[0] if n else None
        if n == 0:
            dims.extend([0] * (ndim - level - 1))
            break
    size = int(np.prod(dims)) if dims else 0
    if max_size is not None and size > max_size:
        raise Invalid(key, f"array of {size} entries, above the limit {max_size}")
    if kind == "number":
        ok = is_number
    elif kind == "int":
        def ok(x):
            return isinstance(x, int) and not isinstance(x, bool) and -2**62 < x < 2**62
    elif kind == "bool":
        def ok(x):
            return isinstance(x, bool)
    else:
        raise ValueError(kind)
    flat = []

    def walk(node, level, path):
        if level == ndim:
            if not ok(node):
                want = {"int": "an integer", "bool": "true/false"}.get(kind, "a number")
                raise Invalid(path, f"expected {want}, got {_kind(node)}")
            flat.append(node)
            return
        if not isinstance(node, list):
            raise Invalid(path, f"expected a list, got {_kind(node)}")
        if len(node) != dims[level]:
            raise Invalid(path, f"has {len(node)} entries, expected {dims[level]} (ragged array)")
        if level == ndim - 1:
            # fast path: the innermost lists
            bad = [i for i, x in enumerate(node) if not ok(x)]
            if bad:
                walk(node[bad[0]], ndim, f"{path}[{bad[0]}]")
            flat.extend(node)
            return
        for i, x in enumerate(node):
            walk(x, level + 1, f"{path}[{i}]")

    walk(v, 0, key)
    dtype = {"number": np.float64, "int": np.int64, "bool": bool}[kind]
    out = np.array(flat, dtype=dtype).reshape(dims)
    if kind == "number" and not np.all(np.isfinite(out)):
        raise Invalid(key, "contains a non-finite number")
    return out
