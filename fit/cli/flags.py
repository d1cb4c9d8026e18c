"""Command-line values of ``rbrdf-fit`` (and ``rbrdf``): a parser whose errors are one line,
typed, bounded flag values, and the flags every long-running command shares.

:class:`OneLineParser` prints ``rbrdf-fit brdf: error: argument --tol: ...`` and exits with
status 2 -- one line, no usage block. An unknown flag is reported by the sub-command that got
it, with the closest flag it knows: ``rbrdf-fit brdf: error: unrecognized argument --tolerance
(did you mean --tol?); see 'rbrdf-fit brdf --help'``. :func:`add_run_flags` adds
``--no-progress`` and ``--verbose``. The converters (:func:`number`, :func:`integer`,
:func:`core_angle`, :func:`file_prefix`) refuse NaN, infinities and values outside the ranges
of :mod:`fit.limits` with a message that argparse prefixes with the flag's name.
"""
from __future__ import annotations

import argparse
import difflib
import math
import os
import sys

from ..errors import display_text


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` (sub-parsers too) whose errors are one line on stderr, exit 2."""

    def error(self, message):
        if getattr(self, "_argv", None) is not None:
            # an unknown flag is what the user got wrong first (a mistyped --out makes --out
            # "required"): name it rather than the consequence
            chosen, tokens = self._chosen_from_argv(self._argv)
            unknown = [t for t in tokens if chosen._unknown_flag(t)]
            if unknown:
                chosen.unrecognized(unknown)
        self.exit(2, f"{self.prog}: error: {display_text(message)} (see {self.prog} --help)\n")

    def parse_args(self, args=None, namespace=None):
        """As ``ArgumentParser.parse_args``, but arguments nobody recognised are reported by
        the innermost sub-command that was chosen (:meth:`unrecognized`), also when they
        caused another error (a mistyped required flag)."""
        import sys
        argv = list(sys.argv[1:] if args is None else args)
        parsers = self._all_parsers()
        for q in parsers:
            q._argv = argv
        try:
            ns, extras = self.parse_known_args(argv, namespace)
        finally:
            for q in parsers:
                q._argv = None
        if extras:
            self._chosen(ns).unrecognized(extras)
        return ns

    def _all_parsers(self) -> list:
        """This parser and every sub-parser below it."""
        out = [self]
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in set(action.choices.values()):
                    if isinstance(sub, OneLineParser):
                        out += sub._all_parsers()
        return out

    def _chosen_from_argv(self, argv) -> tuple:
        """``(innermost sub-parser named in argv, the tokens after its name)``."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                for i, tok in enumerate(argv):
                    sub = action.choices.get(tok)
                    if isinstance(sub, OneLineParser):
                        return sub._chosen_from_argv(argv[i + 1:])
        return self, list(argv)

    def _unknown_flag(self, token: str) -> bool:
        """``token`` looks like a flag (``-x``, ``--name[=v]``, not a negative number) that is
        neither a flag of this parser nor an unambiguous abbreviation of one."""
        if not token.startswith("-") or token == "-" or token == "--" or self._negative_number_matcher.match(token):
            return False
        word = token.split("=", 1)[0]
        flags = {o for a in self._actions for o in a.option_strings}
        if word in flags:
            return False
        if word.startswith("--") and self.allow_abbrev:
            return sum(f.startswith(word) for f in flags) != 1
        return not (len(word) > 2 and word[:2] in flags)      # -n5 style

    def _chosen(self, ns) -> "OneLineParser":
        """The innermost sub-parser that ``ns`` went through (``self`` when none)."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                sub = action.choices.get(getattr(ns, action.dest, None) or "")
                if isinstance(sub, OneLineParser):
                    return sub._chosen(ns)
        return self

    def unrecognized(self, extras) -> None:
        """Exit 2 with one line naming the first unknown argument of ``extras``, the closest
        flag of this parser (difflib, or the flag that begins the same way) and its help."""
        flags = sorted({o for a in self._actions for o in a.option_strings})
        words = [e for e in extras if e.startswith("-")] or list(extras)
        word = words[0].split("=", 1)[0]
        close = [f for f in flags if f.startswith("--") and len(word) > 3 and
                 (f.startswith(word) or word.startswith(f))]
        close = close or difflib.get_close_matches(word, flags, n=1, cutoff=0.7)
        hint = f" (did you mean {close[0]}?)" if close else ""
        what = "argument" if len(extras) == 1 or len(words) == 1 else "arguments"
        shown = word if what == "argument" else " ".join(w.split("=", 1)[0] for w in words)
        self.exit(2, f"{self.prog}: error: unrecognized {what} {display_text(shown)[:80]}{hint}; "
                     f"see '{self.prog} --help'\n")


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


def add_run_flags(p) -> None:
    """``--no-progress`` (no progress bar or progress lines on stderr) and ``--verbose`` (HiGHS's
    banner and solver log on stdout) on the sub-parser ``p`` of a command that may run long."""
    p.add_argument("--no-progress", dest="no_progress", action="store_true",
                   help="no progress on stderr (default: a bar on a terminal, otherwise one line per "
                        "stage with an estimate of the time left)")
    p.add_argument("--verbose", action="store_true", help="show the LP solver's (HiGHS) banner and log")


def quiet_stdout() -> None:
    """Point stdout at /dev/null, so that the interpreter's final flush of a stdout whose reader
    has gone (``rbrdf-fit info FILE | head -1``) does not print a second ``BrokenPipeError``;
    both command lines call it before they exit with status 141."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass
