"""Structure checks of mesh files that trimesh's readers do not make (it accepts both
silently): the face indices of a Wavefront OBJ and the element counts of an ASCII PLY.

* **OBJ** (:func:`check_obj`): a face's vertex index (the first number of each ``v/vt/vn``
  group of an ``f`` line) is a non-zero integer: ``1`` .. ``n`` count from the first vertex of
  the file, ``-1`` .. ``-k`` back from the last vertex defined before that line (``k`` of
  them). ``0`` is no vertex (trimesh read ``f 0 1 2`` as a triangle of the *last* vertex and
  the first two); an index beyond the vertices, or that is not an integer, is refused too.
* **ASCII PLY** (:func:`check_ply`): one element per line, so the lines after ``end_header``
  that hold data must be exactly as many as the header's ``element`` counts together (trimesh
  read a header that declares 10 M faces over a body that holds 1 as a mesh of 1 face, and a
  body with more lines than declared as the declared part of it). Binary PLY bodies are
  checked against their header by trimesh itself (an unexpected length is its error).

Each problem is a ``ValueError`` with a one-line message (the caller adds the scene key and the
file's name); line numbers are 1-based. The checks read the file once more (it is at most
:data:`warp_rbrdf.limits.MAX_MESH_BYTES`) and run before trimesh parses it.
"""
from __future__ import annotations

import re

import numpy as np

#: The header of a PLY file is read from at most this many first bytes (the shared bunny's is
#: 250 bytes); a longer header is left to trimesh.
PLY_HEADER_BYTES = 1 << 16

_OBJ_VERTEX = re.compile(rb"^[ \t]*v[ \t]", re.M)
_OBJ_FACE = re.compile(rb"^[ \t]*f[ \t]([^\r\n]*)", re.M)


def check_obj(data: bytes) -> None:
    """``ValueError`` naming the line when a face of the OBJ text ``data`` has a vertex index
    that is 0, not an integer, or outside the vertices (module docstring)."""
    vstarts = np.array([m.start() for m in _OBJ_VERTEX.finditer(data)], dtype=np.int64)
    n_total = len(vstarts)
    for m in _OBJ_FACE.finditer(data):
        before = None          # vertices defined before this line (counted when a negative needs it)
        for tok in m.group(1).split(b"#", 1)[0].split():
            first = tok.split(b"/", 1)[0]
            why = None
            try:
                i = int(first)
            except ValueError:
                why = "is not an integer"
            else:
                if i == 0:
                    why = "is 0 (OBJ indices start at 1; negative ones count back from the last vertex)"
                elif i > n_total:
                    why = f"is beyond the file's {n_total} vertices"
                elif i < 0:
                    if before is None:
                        before = int(np.searchsorted(vstarts, m.start()))
                    if -i > before:
                        why = f"counts back past the {before} vertices defined before this line"
            if why is not None:
                line = data.count(b"\n", 0, m.start()) + 1
                raise ValueError(f"line {line}: face vertex index {first[:20].decode('ascii', 'replace')!r} {why}")


def check_ply(head: bytes, read_all) -> None:
    """``ValueError`` when an ASCII PLY's data lines do not match its header's element counts.
    ``head``: the file's first :data:`PLY_HEADER_BYTES` bytes; ``read_all()``: the whole file
    (read only for an ASCII body). A file whose header is not found there is left to trimesh."""
    end = re.search(rb"^end_header[ \t]*\r?\n", head, re.M)
    if not head.startswith(b"ply") or end is None:
        return
    header = head[:end.start()].decode("ascii", "replace").splitlines()
    fmt = next((ln.split()[1] for ln in header if ln.startswith("format ") and len(ln.split()) > 1), "")
    if fmt != "ascii":
        return
    counts = []
    for ln in header:
        parts = ln.split()
        if parts and parts[0] == "element":
            if len(parts) != 3 or not parts[2].isdigit():
                raise ValueError(f"PLY header line {ln[:60]!r} is not 'element NAME COUNT'")
            counts.append((parts[1], int(parts[2])))
    body = read_all()[end.end():]
    lines = sum(1 for ln in body.splitlines() if ln.strip())
    declared = sum(n for _, n in counts)
    if lines != declared:
        what = ", ".join(f"{n} {name}" for name, n in counts)
        raise ValueError(f"its ASCII PLY header declares {declared} elements ({what}) but the body holds "
                         f"{lines} data lines (one element per line)")
