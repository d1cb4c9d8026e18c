"""The one rule for text that reaches generated code (:mod:`fit.export`): every emitter puts
text that comes from a coefficient file (its name, its source file, its tolerance record, channel
names) or from a caller through these functions only, so that such text can never become code
in a ``.c``, ``.h``, ``.glsl``, ``.hlsl``, ``.brdf`` or ``.py`` output.

* :func:`literal`: the text as a quoted, single-line, printable-ASCII form (``'...'``) that is
  inert everywhere the emitters put text: inside a C / GLSL / HLSL ``/* */`` comment, a ``#``
  comment line (Python, BRDF Explorer), and a Python (non-raw) triple-quoted docstring, where it
  reads back as the text itself. It is also a valid Python string literal of the text (cut to
  ``limit`` characters). Non-ASCII and control characters (newlines, ``\\r``, NUL, U+2028 /
  U+2029) are Python escapes (``\\n``, ``\\x00``, ``\\u2028``); the quotes and the backslash
  are escaped; and no two characters that open or close something in any of these languages
  stay next to each other: ``*/``, ``/*`` and ``//`` (C comments), ``??`` (C trigraphs, ``??/``
  is a backslash), ``::`` (BRDF Explorer's ``::begin``/``::end`` block markers) get their second
  character as a ``\\xNN`` escape. Because the form ends with a quote, no line of a comment
  ends with a backslash (a C / GLSL line continuation).
* :func:`comment_text`: short plain text (letters, digits, space and ``_.,+-=()[]``) as it is,
  anything else as :func:`literal` -- for values that are normally plain (a channel name, a
  source file name).
* :func:`python_string`: a Python string literal of any text (``ascii()``: one line, ASCII).
* :func:`identifier`: a C / GLSL / HLSL / Python identifier made of a name: letters and digits
  joined by single ``_``, not starting with a digit, at most :data:`MAX_IDENTIFIER` characters
  (so ``rbrdf_`` + it + ``_angles`` never holds ``__``, which GLSL reserves);
  :func:`is_identifier` is the ``--name`` rule (a name that :func:`identifier` keeps as it is).

No string literal of C, GLSL or HLSL is emitted from file text (those outputs carry such text
only in comments), so there is no C string function here.
"""
from __future__ import annotations

import re

#: characters of file text shown in a comment or docstring; a longer text is cut and its length
#: stated (the loader allows names of up to 1000 characters; generated code stays readable)
MAX_TEXT = 200
#: characters of an identifier made of a name (the prefix ``rbrdf_`` and suffixes not counted)
MAX_IDENTIFIER = 64

_PLAIN = re.compile(r"[A-Za-z0-9 _.,+=()\[\]-]{1,80}")
#: (previous character, character) pairs whose second character is escaped
_PAIRS = {("*", "/"), ("/", "*"), ("/", "/"), ("?", "?"), (":", ":")}
_NAMED = {"\\": "\\\\", "'": "\\'", '"': '\\"', "\n": "\\n", "\r": "\\r", "\t": "\\t"}


def _char(c: str) -> str:
    if c in _NAMED:
        return _NAMED[c]
    o = ord(c)
    if 0x20 <= o < 0x7F:
        return c
    if o < 0x100:
        return f"\\x{o:02x}"
    if o < 0x10000:
        return f"\\u{o:04x}"
    return f"\\U{o:08x}"


def literal(text, limit: int = MAX_TEXT) -> str:
    """``text`` (``str()`` of it) as a quoted single-line printable-ASCII form that is inert in
    every comment and docstring the emitters write (module docstring); a text longer than
    ``limit`` characters is cut there and followed by ``... (N characters)``."""
    s = str(text)
    more = len(s) > limit
    out = []
    prev = ""
    for c in s[:limit]:
        e = _char(c)
        if (prev, c) in _PAIRS:
            e = f"\\x{ord(c):02x}"
        out.append(e)
        prev = e[-1]
    q = "'" + "".join(out) + "'"
    return q + f"... ({len(s)} characters)" if more else q


def comment_text(text, limit: int = MAX_TEXT) -> str:
    """``text`` as it is when it is short plain text (letters, digits, space, ``_.,+-=()[]``),
    else :func:`literal` of it."""
    s = str(text)
    return s if _PLAIN.fullmatch(s) else literal(s, limit)


def python_string(text) -> str:
    """A Python string literal of ``text`` (``str()`` of it): one line of ASCII."""
    return ascii(str(text))


def identifier(name) -> str:
    """A C / GLSL / HLSL / Python identifier made of ``name``: every run of characters other
    than ASCII letters and digits becomes one ``_``, none at either end; ``m`` before a leading
    digit; at most :data:`MAX_IDENTIFIER` characters; ``fit`` when nothing is left."""
    s = re.sub(r"[^A-Za-z0-9]+", "_", str(name)).strip("_")
    if s[:1].isdigit():
        s = "m" + s
    s = s[:MAX_IDENTIFIER].rstrip("_")
    return s or "fit"


def is_identifier(name: str) -> bool:
    """Whether ``name`` is already an identifier by :func:`identifier`'s rule (the ``--name``
    rule: letters and digits joined by single ``_``, not starting with a digit, at most
    :data:`MAX_IDENTIFIER` characters)."""
    return isinstance(name, str) and identifier(name) == name
