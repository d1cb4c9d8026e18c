"""A rational BRDF fit as data: the records of ``Materials.coef_i`` / ``coef_f`` / ``coef_q`` that
the Warp evaluators of :mod:`.rational_kernel` walk (:func:`pack_model`).

Records, offsets relative to the material's own starts, the root at int 0:

* a **domain record** (only at the root of a fit with a measured domain,
  :func:`fit.rational.domain.measured_domain`): kind, the float offset of ``(cos c, c)`` (c: the
  grazing cut-off, radians), the fit's int offset;
* a **split record** per piecewise level: kind, the split variable
  (:data:`SUPPORTED_VARIABLES`), the number of pieces K, the float offset of its K - 1 inner
  edges, the K children's int offsets;
* a **flat record** (after the domain record, or at the root without one) of a fit whose pieces
  are boxes in one split of theta_h or theta_d (or one box), each of a degree class: at most
  :data:`FLAT_MAX_PIECES` boxes of (theta_h, theta_d) without a value factor, in one split or
  in one split whose pieces are boxes or splits of boxes in one more variable (kind
  :data:`NODE_FLAT2D`, read by :mod:`.rational_flat2d`), or at most :data:`FLAT3_MAX_PIECES`
  boxes of (theta_h, theta_d, phi_d) (kind :data:`NODE_FLAT3D`, read by :mod:`.rational_flat3d`):
  kind, the int offset of the fit's tree (the records below, which the flat record repeats),
  the float offset of its floats, the number of boxes K, the split variable, then per box
  :data:`FLAT_NI` ints (flags, the inputs' sqrt bits, class, the float offset of its dense
  rows, the three channel modes); its floats: ``(cos c, c)`` of the domain record (``(-2, 0)``
  without one), the split's inner edges padded with +inf to the kind's maximum minus one (2-D:
  :data:`FLAT_MAX_OUTER` minus one), (2-D only, :data:`FF_INNER` to :data:`FF_HEADS`) per outer
  piece its own inner edges (padded to :data:`FLAT_MAX_PIECES` minus one), per outer piece its
  first box, and the nesting variable, then per box a copy of its leaf header (:data:`N_FH` floats, from :data:`FLAT_KINDS`' offset): one
  contiguous run per fit that is read without a walk;
* a **leaf record** per single-box piece: kind, variables, flags, the float offset of its
  header, three variable codes (source angle | transform << 2), the int and row offsets of its
  numerators and denominators packed as one group of six Chebyshev polynomials
  (:mod:`warp_rbrdf.chebyshev`: the form every fit has), per channel its mode, then its degree
  class (:mod:`warp_rbrdf.chebyshev_dense`; 0: none) and the float offset of the same
  polynomials stored densely for that class (the form the scene's specialised code reads).

Leaf flags: :data:`LEAF_CLAMP` (inputs clamped onto the box), :data:`LEAF_LOG` (log values),
:data:`LEAF_MIN` / :data:`LEAF_MAX` (value clamps), :data:`LEAF_TABLE` (a channel reads the
fallback table), :data:`LEAF_INV_COS` (step 8, the whole model's value factor
``"1/cos_theta_i"``, :data:`fit.rational.model.VALUE_FACTORS`: the channels after step 7 are
divided by ``max(cos theta_i, COS_FLOOR)``, cos theta_i = ``wi.z`` of the light's local
direction; set on every leaf of such a model, whose pieces carry no factor of their own).

The leaf header (floats): value offset, min, max, ``log(max + offset)``; per variable (lo, hi,
u_lo + u_hi, 1 / (u_hi - u_lo)); per channel the step-7 range (lo, hi); the fallback table's
box (theta_h lo, hi, theta_d lo, hi). Pure NumPy (the Warp types of the packed forms come with
:mod:`warp_rbrdf.chebyshev`).
"""
from __future__ import annotations

import numpy as np

from fit.rational.model import VALUE_FACTORS, flagged, output_clamp

from ..chebyshev import FlatData
from ..chebyshev_dense import dense_class, pack_dense

SUPPORTED_VARIABLES = {"theta_h": 0, "theta_d": 1, "phi_d": 2}
NODE_LEAF, NODE_SPLIT, NODE_DOMAIN, NODE_FLAT2D, NODE_FLAT3D = 0, 1, 2, 3, 4
FLAT_TREE, FLAT_FLOATS, FLAT_K, FLAT_VAR, FLAT_PIECES = 1, 2, 3, 4, 8    # flat record (ints)
FLAT_NI = 8                   # ints per piece: flags, sqrt bits, class, dense offset, modes (3)
FLAT_MAX_PIECES = 6           # boxes of a 2-D flat record
FLAT_MAX_OUTER = 4            # pieces of a 2-D flat record's outer split (each one box or a split of boxes)
FLAT3_MAX_PIECES = 8          # pieces of a 3-D flat record (the 3-D fitter's theta_h pieces: 6)
FF_COS_CUT, FF_CUT, FF_EDGES = 0, 1, 2         # flat record (floats): the domain, the outer edges
# 2-D flat record (floats), after its outer edges: per outer piece its inner edges (the second
# level of a nested fit, padded with +inf), per outer piece the index of its first box, whether
# and in which variable the fit is nested (0: one level, the outer piece is the box; 1 + the
# inner split variable, 0 theta_h, 1 theta_d), then the headers
FF_INNER = FF_EDGES + FLAT_MAX_OUTER - 1
FF_BASES = FF_INNER + FLAT_MAX_OUTER * (FLAT_MAX_PIECES - 1)
FF_VAR2 = FF_BASES + FLAT_MAX_OUTER
FF_HEADS = FF_VAR2 + 1                        # the first header of a 2-D flat record
FF3_HEADS = 2 + FLAT3_MAX_PIECES - 1          # the first header of a 3-D flat record
#: the flat record's kind, most boxes, most outer pieces and first header's float, by number of variables
FLAT_KINDS = {2: (NODE_FLAT2D, FLAT_MAX_PIECES, FLAT_MAX_OUTER, FF_HEADS),
              3: (NODE_FLAT3D, FLAT3_MAX_PIECES, FLAT3_MAX_PIECES, FF3_HEADS)}
DOMAIN_FLOATS, DOMAIN_CHILD = 1, 2                       # domain record (ints)
SPLIT_VAR, SPLIT_N, SPLIT_EDGES, SPLIT_CHILDREN = 1, 2, 3, 4   # split record (ints)
# leaf record (ints)
LEAF_NV, LEAF_FLAGS, LEAF_FH, LEAF_VARS, LEAF_POLY, LEAF_MODES, LEAF_CLASS, LEAF_DENSE = 1, 2, 3, 4, 7, 9, 12, 13
N_LEAF = 14
LEAF_CLAMP, LEAF_LOG, LEAF_MIN, LEAF_MAX, LEAF_TABLE, LEAF_INV_COS = 1, 2, 4, 8, 16, 32   # flags
#: the leaf flags of each value factor (:data:`fit.rational.model.VALUE_FACTORS`)
FACTOR_FLAGS = {"none": 0, "1/cos_theta_i": LEAF_INV_COS}
assert set(FACTOR_FLAGS) == set(VALUE_FACTORS)
CH_TABLE, CH_RANGE = 1, 2                                               # channel mode bits
TRANSFORM_CODES = {"identity": 0, "sqrt": 1}
# leaf header (floats)
FH_OFFSET, FH_MIN, FH_MAX, FH_LOGMAX, FH_VARS, FH_RANGES, FH_BOX = 0, 1, 2, 3, 4, 16, 22
N_FH = 26


def channel_modes(model, table: bool = False) -> list:
    """Per output of a single-box model: ``(from_table, range)``: whether the channel reads the
    fallback table (``table`` and the function is flagged) and its step-7 clamp
    (:func:`fit.rational.model.output_clamp`; None: none)."""
    return [(bool(table and flagged(i)), output_clamp(i)) for i in model.function_info]


def pack_model(model, table: bool = False, cutoff_deg: float | None = None) -> tuple:
    """``(ints int32, floats float64, rows float64 (n, 6))``: a
    :class:`~fit.rational.model.RationalModel` or :class:`~fit.rational.model.PiecewiseRationalModel`
    (nested pieces included) as the records of the module docstring, the root at int 0; offsets
    are relative to the material's starts. ``table``: flagged channels read the fallback table
    (:mod:`.rational`). ``cutoff_deg``: the angles are first moved onto the measured domain of
    that grazing cut-off (:func:`fit.rational.domain.onto_measured_domain`; a domain record at
    the root); None (default): the file's recipe alone. The model's ``value_factor`` (step 8)
    becomes a flag of every leaf (:data:`FACTOR_FLAGS`); ValueError for an unknown one."""
    factor = getattr(model, "value_factor", "none")
    if factor not in FACTOR_FLAGS:
        raise ValueError(f"unknown value factor {factor!r}")
    leaf_flags = FACTOR_FLAGS[factor]
    fd = FlatData(6)
    if cutoff_deg is None:
        _pack_flat(fd, model, table, (-2.0, 0.0), leaf_flags)
    else:
        cut = np.radians(float(cutoff_deg))
        n = fd.add_ints([NODE_DOMAIN, 0, 0])
        fd.ints[n + DOMAIN_FLOATS] = fd.add_floats([np.cos(cut), cut])
        fd.ints[n + DOMAIN_CHILD] = _pack_flat(fd, model, table, (np.cos(cut), cut), leaf_flags)
    return fd.arrays()


#: the variables of a flat record's pieces, in this order, by number of variables
_FLAT_VARIABLES = {2: ["theta_h", "theta_d"], 3: ["theta_h", "theta_d", "phi_d"]}


def _flat_layout(model, table, leaf_flags):
    """``(number of variables, split variable, its inner edges, leaves, nested)`` of a fit a flat
    record can hold (module docstring), else None; ``leaves``: the boxes in the order of the
    tree; ``nested`` (2-D only; None for a fit of one level): ``(inner split variable, per outer
    piece its inner edges, per outer piece the index of its first box)`` of a fit whose outer
    pieces are boxes or one more split of boxes, all in the same variable. A 2-D fit with a
    value factor has none (its function has no step 8)."""
    pieces = getattr(model, "pieces", None)
    outer = [model] if pieces is None else list(pieces)
    first = outer[0] if getattr(outer[0], "pieces", None) is None else outer[0].pieces[0]
    names = [v.name for v in first.variables]
    nv = next((k for k, v in _FLAT_VARIABLES.items() if v == names), None)
    if nv is None or (nv == 2 and leaf_flags):
        return None
    if pieces is not None and model.split_variable not in ("theta_h", "theta_d"):
        return None
    inner_vars = {p.split_variable for p in outer if getattr(p, "pieces", None) is not None}
    if inner_vars and (nv != 2 or len(inner_vars) > 1 or not inner_vars <= {"theta_h", "theta_d"}):
        return None
    leaves, inner_edges, bases = [], [], []
    for p in outer:
        bases.append(len(leaves))
        sub = getattr(p, "pieces", None)
        inner_edges.append([] if sub is None else list(p.edges[1:-1]))
        leaves += [p] if sub is None else list(sub)
    if len(leaves) > FLAT_KINDS[nv][1] or len(outer) > FLAT_KINDS[nv][2]:
        return None
    for leaf in leaves:
        if getattr(leaf, "pieces", None) is not None or [v.name for v in leaf.variables] != names:
            return None
        if _leaf_class(leaf, table) is None:
            return None
    var = 0 if pieces is None else SUPPORTED_VARIABLES[model.split_variable]
    nested = None
    if inner_vars:
        nested = (SUPPORTED_VARIABLES[inner_vars.pop()], inner_edges, bases)
    return nv, var, ([] if pieces is None else list(model.edges[1:-1])), leaves, nested


def _pack_flat(fd, model, table, domain, leaf_flags) -> int:
    """The flat record of ``model`` followed by its tree, or the tree alone (a fit no flat
    record can hold); the int offset of the first. ``leaf_flags``: the flags every leaf carries
    (:data:`FACTOR_FLAGS`)."""
    layout = _flat_layout(model, table, leaf_flags)
    if layout is None:
        return _pack_node(fd, model, table, leaf_flags)
    nv, var, edges, leaves, nested = layout
    kind, max_pieces, max_outer, _ = FLAT_KINDS[nv]
    k = len(leaves)
    n = fd.add_ints([kind, 0, 0, k, var, 0, 0, 0] + [0] * (FLAT_NI * k))
    tree = _pack_node(fd, model, table, leaf_flags)
    fd.ints[n + FLAT_TREE] = tree
    outer = [tree] if len(edges) == 0 and fd.ints[tree] != NODE_SPLIT else \
        [fd.ints[tree + SPLIT_CHILDREN + j] for j in range(len(edges) + 1)]
    nodes = []
    for node in outer:      # a box, or one more split of boxes (nested)
        nodes += ([fd.ints[node + SPLIT_CHILDREN + j] for j in range(fd.ints[node + SPLIT_N])]
                  if fd.ints[node] == NODE_SPLIT else [node])
    assert len(nodes) == k
    floats = [*domain, *edges, *[np.inf] * (max_outer - 1 - len(edges))]
    if nv == 2:             # the second level: none (every outer piece one box) or nested
        nest, inner, bases = ((1 + nested[0], nested[1], nested[2]) if nested is not None
                              else (0, [[]] * (len(edges) + 1), range(len(edges) + 1)))
        pad = max_outer - len(inner)
        floats += [e for row in [*inner, *[[]] * pad] for e in [*row, *[np.inf] * (max_pieces - 1 - len(row))]]
        floats += [*[float(b) for b in bases], *[0.0] * pad, float(nest)]
    for j, leaf in enumerate(nodes):
        li = fd.ints
        codes = li[leaf + LEAF_VARS:leaf + LEAF_VARS + nv]
        fd.ints[n + FLAT_PIECES + FLAT_NI * j:n + FLAT_PIECES + FLAT_NI * (j + 1)] = [
            li[leaf + LEAF_FLAGS], sum((c >> 2) << v for v, c in enumerate(codes)), li[leaf + LEAF_CLASS],
            li[leaf + LEAF_DENSE], *li[leaf + LEAF_MODES:leaf + LEAF_MODES + 3], 0]
        h = li[leaf + LEAF_FH]
        floats += fd.floats[h:h + N_FH]
    fd.ints[n + FLAT_FLOATS] = fd.add_floats(floats)
    return n


def _leaf_class(model, table):
    """The degree class of a single-box piece's dense form (:func:`warp_rbrdf.chebyshev_dense.dense_class`)
    or None."""
    modes = channel_modes(model, table)
    nums = [None if t else (f.num_exponents, f.num_coef) for f, (t, _) in zip(model.functions, modes)]
    dens = [None if t else (f.den_exponents, f.den_coef) for f, (t, _) in zip(model.functions, modes)]
    return dense_class(nums, dens, len(model.variables))


def _pack_node(fd, model, table, leaf_flags) -> int:
    pieces = getattr(model, "pieces", None)
    if pieces is None:
        return _pack_leaf(fd, model, table, leaf_flags)
    n = fd.add_ints([NODE_SPLIT, SUPPORTED_VARIABLES[model.split_variable], len(pieces), 0] + [0] * len(pieces))
    fd.ints[n + SPLIT_EDGES] = fd.add_floats(model.edges[1:-1])
    for k, piece in enumerate(pieces):
        fd.ints[n + SPLIT_CHILDREN + k] = _pack_node(fd, piece, table, leaf_flags)
    return n


def _pack_leaf(fd, model, table, leaf_flags) -> int:
    nv = len(model.variables)
    modes = channel_modes(model, table)
    vmax, vmin, off = model.value_max, model.value_min, float(model.value_offset)
    flags = (leaf_flags | (LEAF_CLAMP if model.domain_policy.get("outside", "clamp") == "clamp" else 0)
             | (LEAF_LOG if model.value_transform == "log" else 0)
             | (LEAF_MIN if vmin is not None else 0) | (LEAF_MAX if vmax is not None else 0)
             | (LEAF_TABLE if any(t for t, _ in modes) else 0))
    codes = [SUPPORTED_VARIABLES[v.name] | TRANSFORM_CODES[v.transform] << 2 for v in model.variables]
    n = fd.add_ints([NODE_LEAF, nv, flags, 0] + codes + [0] * (3 - nv) + [0, 0] + [0] * 3 + [0, 0])
    head = np.zeros(N_FH)
    head[[FH_OFFSET, FH_MIN, FH_MAX]] = off, vmin or 0.0, vmax or 0.0
    if vmax is not None and model.value_transform == "log":
        head[FH_LOGMAX] = np.log(vmax + off)
    for v, var in enumerate(model.variables):
        ulo, uhi = var.rf_domain
        head[FH_VARS + 4 * v: FH_VARS + 4 * v + 4] = var.domain[0], var.domain[1], ulo + uhi, 1.0 / (uhi - ulo)
    for c, (_, rng) in enumerate(modes):
        if rng is not None:
            head[FH_RANGES + 2 * c: FH_RANGES + 2 * c + 2] = rng
    if flags & LEAF_TABLE:
        box = {v.name: v.domain for v in model.variables}
        head[FH_BOX:FH_BOX + 4] = (*box["theta_h"], *box["theta_d"])
    fd.ints[n + LEAF_FH] = fd.add_floats(head)
    fits = [(f, t) for f, (t, _) in zip(model.functions, modes)]
    nums = [None if t else (f.num_exponents, f.num_coef) for f, t in fits]
    dens = [None if t else (f.den_exponents, f.den_coef) for f, t in fits]
    fd.ints[n + LEAF_POLY:n + LEAF_POLY + 2] = fd.add_polynomials(nums + dens, nv)
    for c, (from_table, rng) in enumerate(modes):
        fd.ints[n + LEAF_MODES + c] = (CH_TABLE if from_table else 0) | (CH_RANGE if rng is not None else 0)
    key = dense_class(nums, dens, nv)
    if key is not None:
        fd.ints[n + LEAF_CLASS] = key
        fd.ints[n + LEAF_DENSE] = fd.add_floats(pack_dense(nums, dens, nv, key).reshape(-1))
    return n


def packed_classes(ints) -> set:
    """The degree classes (:func:`warp_rbrdf.chebyshev_dense.class_key`) of the leaves of a
    packed fit (``ints`` of :func:`pack_model`); 0 stands for the leaves without one (read from
    their packed group)."""
    ints = np.asarray(ints)
    out, todo = set(), [0]
    while todo:
        n = todo.pop()
        kind = int(ints[n])
        if kind == NODE_DOMAIN:
            todo.append(int(ints[n + DOMAIN_CHILD]))
        elif kind in (NODE_FLAT2D, NODE_FLAT3D):
            todo.append(int(ints[n + FLAT_TREE]))
        elif kind == NODE_SPLIT:
            todo += [int(c) for c in ints[n + SPLIT_CHILDREN:n + SPLIT_CHILDREN + int(ints[n + SPLIT_N])]]
        else:
            out.add(int(ints[n + LEAF_CLASS]))
    return out
