"""The module import graphs of ``fit/`` and ``warp_rbrdf/`` have no cycle, and the fitter never
imports Warp.

Static analysis: every ``.py`` file of the two packages is parsed with :mod:`ast`; every
``import`` / ``from ... import`` statement counts, wherever it stands (module level, inside a
function or a class, under ``try``/``if``), relative imports resolved against the importing
module's package. An edge ``A -> B`` means module ``A`` imports module ``B``:

* ``import a.b.c`` -> ``a.b.c``;
* ``from a.b import c`` -> ``a.b.c`` when that is a module of the tree, else ``a.b`` (the
  package's ``__init__`` or the module that defines ``c``).

Not edges: a package's ``__init__`` run implicitly when one of its sub-modules is imported
(every sub-module would otherwise sit on a cycle with its package's re-exports), and names
imported on first use through :func:`fit.lazy.lazy_attributes` tables (strings, not imports).
A cycle is a strongly connected component of more than one module, or a module importing
itself; the assertion message lists each with one closed path through it.

Run ``python tests/test_import_graph.py`` to print the cycles of both packages.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fit", "warp_rbrdf")


def module_files(package: str, root: Path = ROOT) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file under ``root / package``
    (``pkg/__init__.py`` is module ``pkg``)."""
    out = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _imported_names(tree: ast.AST, module: str, is_package: bool):
    """Yield ``(target, names)`` for every import statement of ``tree``: ``target`` the dotted
    module imported from (relative imports resolved), ``names`` the imported names for a
    ``from`` import, else ``()``."""
    package = module if is_package else module.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, ()
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            yield target, tuple(a.name for a in node.names)


def import_graph(packages=PACKAGES, root: Path = ROOT) -> dict[str, set[str]]:
    """Module -> set of modules of ``packages`` it imports (edges to other libraries are kept
    as their top-level name, e.g. ``warp``, so :func:`imports_of` can find them)."""
    modules = {}
    for p in packages:
        modules.update(module_files(p, root))
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        edges = set()
        for target, names in _imported_names(tree, name, path.name == "__init__.py"):
            subs = [f"{target}.{n}" for n in names if f"{target}.{n}" in modules]
            if subs:
                edges.update(subs)
                if len(subs) < len(names):  # other names come from the package itself
                    edges.add(target)
            elif target in modules:
                edges.add(target)
            else:
                # a module outside the tree, or an attribute path inside it: keep the
                # longest prefix that is a module of the tree, else the top-level name.
                parts = target.split(".")
                while parts and ".".join(parts) not in modules:
                    parts.pop()
                edges.add(".".join(parts) if parts else target.split(".")[0])
        graph[name] = edges
    return graph


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of ``graph`` (iterative), each sorted."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph.get(start, ()))))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, it = work[-1]
            for nxt in it:
                if nxt not in graph:
                    continue
                if nxt not in index:
                    index[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph.get(nxt, ())))))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    comp = []
                    while True:
                        m = stack.pop()
                        on_stack.discard(m)
                        comp.append(m)
                        if m == node:
                            break
                    out.append(sorted(comp))
    return out


def _closed_path(graph: dict[str, set[str]], component: list[str]) -> list[str]:
    """One shortest closed path through the first module of ``component`` (breadth-first,
    inside the component): ``[a, b, ..., a]``."""
    members = set(component)
    start = component[0]
    parent = {start: None}
    queue = [start]
    while queue:
        node = queue.pop(0)
        for nxt in sorted(graph[node] & members):
            if nxt == start:
                path = [node]
                while parent[path[-1]] is not None:
                    path.append(parent[path[-1]])
                return path[::-1] + [start]
            if nxt not in parent:
                parent[nxt] = node
                queue.append(nxt)
    return [start, start]


def cycles(package: str, root: Path = ROOT) -> list[str]:
    """The import cycles among the modules of ``package``: one line per strongly connected
    component, ``"a -> b -> a  (component: a, b)"``."""
    graph = {m: {t for t in e if t == package or t.startswith(package + ".")}
             for m, e in import_graph((package,), root).items()}
    lines = []
    for comp in strongly_connected(graph):
        if len(comp) > 1 or comp[0] in graph[comp[0]]:
            path = " -> ".join(_closed_path(graph, comp))
            lines.append(f"{path}  (component: {', '.join(comp)})")
    return lines


def imports_of(package: str, forbidden: tuple[str, ...], root: Path = ROOT) -> list[str]:
    """``"module -> target"`` for every import of a ``forbidden`` top-level package (or one of
    its sub-modules) by a module of ``package``."""
    hits = []
    for m, edges in sorted(import_graph((package,), root).items()):
        for t in sorted(edges):
            if t.split(".")[0] in forbidden:
                hits.append(f"{m} -> {t}")
    return hits


# --- the checker itself: it finds what it must ---------------------------------------------

def _write(root: Path, files: dict[str, str]):
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text, encoding="utf-8")


def test_checker_finds_function_level_and_relative_cycles(tmp_path):
    _write(tmp_path, {
        "pkg/__init__.py": "from .a import A\n",
        "pkg/a.py": "from .sub import b\nA = 1\n",
        "pkg/sub/__init__.py": "",
        "pkg/sub/b.py": "def f():\n    from ..a import A\n    return A\n",
        "pkg/c.py": "import pkg.d\n",
        "pkg/d.py": "class K:\n    def g(self):\n        from pkg import c\n",
        "pkg/e.py": "import pkg.a\nimport numpy\n",
    })
    found = cycles("pkg", tmp_path)
    assert len(found) == 2, found
    assert any("(component: pkg.a, pkg.sub.b)" in line for line in found), found
    assert any("(component: pkg.c, pkg.d)" in line for line in found), found
    assert imports_of("pkg", ("numpy",), tmp_path) == ["pkg.e -> numpy"]


def test_checker_accepts_an_acyclic_tree(tmp_path):
    _write(tmp_path, {
        "pkg/__init__.py": "from .a import A\nfrom . import b\n",
        "pkg/a.py": "from .b import B\nA = B\n",
        "pkg/b.py": "import os\nB = 2\n",
    })
    assert cycles("pkg", tmp_path) == []


# --- the project ----------------------------------------------------------------------------

def test_fit_has_no_import_cycle():
    found = cycles("fit")
    assert not found, "import cycles in fit/:\n" + "\n".join(found)


def test_warp_rbrdf_has_no_import_cycle():
    found = cycles("warp_rbrdf")
    assert not found, "import cycles in warp_rbrdf/:\n" + "\n".join(found)


def test_fit_never_imports_warp():
    hits = imports_of("fit", ("warp", "warp_rbrdf"))
    assert not hits, "fit/ imports Warp or the renderer:\n" + "\n".join(hits)


if __name__ == "__main__":
    for pkg in sys.argv[1:] or PACKAGES:
        found = cycles(pkg)
        print(f"{pkg}: {len(found)} import cycle(s)")
        for line in found:
            print("  " + line)
