"""Command-line values of ``rbrdf-fit``: a parser whose errors are one line, and typed,
bounded flag values.

:class:`OneLineParser` prints ``rbrdf-fit brdf: error: argument --tol: ...`` and exits with
status 2 -- one line, no usage block. The converters (:func:`number`, :func:`integer`,
:func:`core_angle`, :func:`file_prefix`) refuse NaN, infinities and values outside the ranges
of :mod:`fit.limits` with a message that argparse prefixes with the flag's name.
"""
from __future__ import annotations

import argparse
import math

from ..errors import display_text


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` (sub-parsers too) whose errors are one line on stderr, exit 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {display_text(message)} (see {self.prog} --help)\n")


def _fmt(x) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def number(lo: float | None = None, hi: float | None = None, lo_open: bool = False, hi_open: bool = False,
           what: str = "a number"):
    """Converter of a finite float in the interval ``lo .. hi`` (open ends as stated)."""
    left = "(" if lo_open else "["
    right = ")" if hi_open else "]"
    span = f"{left}{_fmt(lo) if lo is not None else '-inf'}, {_fmt(hi) if hi is not None else 'inf'}{right}"

    def convert(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {display_text(text)[:40]!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"expected a finite number in {span}, got {text}")
        if (lo is not None and (v < lo or (lo_open and v == lo))) or \
                (hi is not None and (v > hi or (hi_open and v == hi))):
            raise argparse.ArgumentTypeError(f"{_fmt(v)} is outside {span}")
        return v

    convert.__name__ = "number"
    return convert


def integer(lo: int, hi: int):
    """Converter of an integer in ``[lo, hi]``."""
    def convert(text: str) -> int:
        try:
            v = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {display_text(text)[:40]!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{v} is outside [{lo}, {hi}]")
        return v

    convert.__name__ = "integer"
    return convert


def core_angle(lo: float, hi: float):
    """Converter of ``auto`` or an angle in degrees in ``[lo, hi]``."""
    num = number(lo, hi, what="'auto' or an angle in degrees")

    def convert(text: str):
        return "auto" if text == "auto" else num(text)

    convert.__name__ = "core angle"
    return convert


def file_prefix(text: str) -> str:
    """A file-name prefix: not empty, no folder separator, NUL or control character, at most
    100 characters (outputs stay inside the output folder)."""
    if not text or len(text) > 100 or any(c in text for c in "/\\\x00") or text in (".", "..") \
            or any(ord(c) < 32 for c in text):
        raise argparse.ArgumentTypeError(f"{display_text(text)[:40]!r} is not a plain file-name prefix "
                                         "(1-100 characters, no '/', '\\' or control characters)")
    return text
