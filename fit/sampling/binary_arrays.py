"""Float arrays of a JSON file as base64 text: a table of 10⁵ float64 values in about 1.4 MB of
one JSON string instead of nested lists (2.7 MB, 2 000 containers, slow to parse). Used by the
sampler record a coefficient file carries (:mod:`fit.sampling.embedded`) for the CDFs of its
table; an ``rbrdf-cdf`` file may hold either form (:mod:`fit.sampling.cdf_reader`).

An encoded array is the object ``{"encoding": "base64", "dtype": "<f8", "shape": [n0, n1, ...],
"data": "..."}``: ``data`` the base64 text of the array's little-endian float64 bytes in C
order. :func:`decode` checks everything before it allocates: the keys, the dtype, the shape
(integers, the caller's expected sizes, at most ``max_size`` entries), the text's length against
the shape, the alphabet (strict base64), and that every value is finite. Errors are
:class:`fit.jsonfields.Invalid` naming the key.
"""
from __future__ import annotations

import base64
import binascii

import numpy as np

from .. import jsonfields as F

ENCODING = "base64"
DTYPE = "<f8"


def is_encoded(v) -> bool:
    """True when ``v`` is an encoded array object (a dict with ``encoding``), not a JSON list."""
    return isinstance(v, dict) and "encoding" in v


def encode(a) -> dict:
    """The encoded-array object of ``a`` (as float64, little-endian, C order)."""
    a = np.ascontiguousarray(a, dtype=DTYPE)
    return {"encoding": ENCODING, "dtype": DTYPE, "shape": list(a.shape),
            "data": base64.b64encode(a.tobytes()).decode("ascii")}


def encoded_shape(v, key: str) -> tuple:
    """The ``shape`` of an encoded array object: a list of at most 8 integers in [0, 2^31)."""
    F.obj(v, key)
    raw = F.get(v, "shape", key)
    if not isinstance(raw, list) or not 1 <= len(raw) <= 8:
        raise F.Invalid(F.sub(key, "shape"), "expected a list of 1 to 8 sizes")
    return tuple(F.integer(n, f"{F.sub(key, 'shape')}[{i}]", lo=0, hi=2**31 - 1) for i, n in enumerate(raw))


def decode(v, key: str, shape: tuple, max_size: int) -> np.ndarray:
    """The float64 array of the encoded object ``v``, of ``shape`` (``None`` entries: any size)
    and at most ``max_size`` entries, every value finite; :class:`fit.jsonfields.Invalid`
    naming the key otherwise."""
    F.obj(v, key)
    F.string(F.get(v, "encoding", key), F.sub(key, "encoding"), choices=(ENCODING,))
    F.string(F.get(v, "dtype", key), F.sub(key, "dtype"), choices=(DTYPE,))
    got = encoded_shape(v, key)
    if len(got) != len(shape) or any(w is not None and w != g for w, g in zip(shape, got)):
        raise F.Invalid(F.sub(key, "shape"), f"{list(got)}, expected {[('any' if w is None else w) for w in shape]}")
    size = int(np.prod(got, dtype=np.int64))
    if size > max_size:
        raise F.Invalid(F.sub(key, "shape"), f"{size} entries, above the limit {max_size}")
    data = F.get(v, "data", key)
    if not isinstance(data, str):
        raise F.Invalid(F.sub(key, "data"), "expected a base64 string")
    n_bytes = 8 * size
    if len(data) != 4 * ((n_bytes + 2) // 3):
        raise F.Invalid(F.sub(key, "data"), f"{len(data)} characters, but {size} float64 values take "
                                            f"{4 * ((n_bytes + 2) // 3)} (truncated or padded)")
    try:
        raw = base64.b64decode(data.encode("ascii"), validate=True)
    except (binascii.Error, UnicodeEncodeError, ValueError):
        raise F.Invalid(F.sub(key, "data"), "not base64 text") from None
    if len(raw) != n_bytes:
        raise F.Invalid(F.sub(key, "data"), f"{len(raw)} bytes, expected {n_bytes}")
    a = np.frombuffer(raw, dtype=DTYPE).astype(np.float64).reshape(got)
    if not np.all(np.isfinite(a)):
        raise F.Invalid(F.sub(key, "data"), "holds a value that is not finite")
    return a
