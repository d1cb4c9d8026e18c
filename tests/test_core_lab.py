"""Core and lab: ``fit/`` and ``warp_rbrdf/`` (the core, what users run and the wheel ships)
never import the lab (``lab/``, ``studies/``, ``benchmarks/``, ``tests/``), the wheel holds core
code only, and tests of lab code only carry the ``lab`` marker, which the default run leaves
out and ``.ci/run`` runs.

* :func:`lab_imports` is a static check (:mod:`ast`): every ``import`` / ``from ... import``
  statement of a file, wherever it stands (module level, in a function, under ``try``), and every
  ``importlib.import_module("...")`` / ``__import__("...")`` with a literal name.
* The packages of the wheel are setuptools' own discovery over the checkout with the
  ``[tool.setuptools.packages.find]`` table of ``pyproject.toml`` (fast); the wheel itself is
  built in a copy of the checkout under the ``slow`` marker (about 20 s: ``pip wheel`` with
  build isolation).
"""
from __future__ import annotations

import ast
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: What users run: the two packages of the wheel.
CORE = ("fit", "warp_rbrdf")
#: Top-level packages (and the tests' own modules) that the core must never import.
LAB = ("lab", "studies", "benchmarks", "tests", "conftest", "hostile", "chi2")
#: Modules that live in ``lab/`` and must not come back into the core.
LAB_MODULES = ("mitsuba_reference", "testing")


def _literal_import_calls(tree: ast.AST):
    """Module names given as a literal to ``importlib.import_module`` / ``__import__``."""
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
                and isinstance(node.args[0].value, str)):
            continue
        f = node.func
        name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
        if name in ("import_module", "__import__"):
            yield node.lineno, node.args[0].value


def lab_imports(source: str, filename: str = "<source>") -> list[str]:
    """``"file:line: module"`` for every import of ``source`` whose top-level name is in
    :data:`LAB` (relative imports stay inside their package and are not counted)."""
    tree = ast.parse(source, filename=filename)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        found += [f"{filename}:{node.lineno}: {n}" for n in names if n.split(".")[0] in LAB]
    found += [f"{filename}:{line}: {n}" for line, n in _literal_import_calls(tree)
              if n.split(".")[0] in LAB]
    return found


def core_files() -> list[Path]:
    return [p for pkg in CORE for p in sorted((ROOT / pkg).rglob("*.py"))]


def test_the_checker_sees_every_kind_of_import():
    src = ("import numpy\nfrom . import lab\nfrom .lab import x\n"
           "def f():\n    from lab import testing as T\n    import studies.common\n"
           "    try:\n        from benchmarks.bench_fit import main\n    except ImportError:\n        pass\n"
           "    import importlib\n    importlib.import_module('tests.hostile')\n    __import__('lab.mitsuba_reference')\n"
           "from fit.formats import rgl\nimport laboratory\n")
    assert [s.split(": ")[1] for s in lab_imports(src)] == [
        "lab", "studies.common", "benchmarks.bench_fit", "tests.hostile", "lab.mitsuba_reference"]


def test_core_never_imports_the_lab():
    files = core_files()
    assert len(files) > 50 and all(p.parts[-2] != "lab" for p in files)
    bad = [hit for p in files
           for hit in lab_imports(p.read_text(encoding="utf-8"), str(p.relative_to(ROOT)))]
    assert not bad, "the core imports lab code:\n" + "\n".join(bad)


def test_lab_modules_live_outside_the_core():
    assert (ROOT / "lab" / "__init__.py").is_file()
    for name in LAB_MODULES:
        assert (ROOT / "lab" / f"{name}.py").is_file(), name
    back = [str(p.relative_to(ROOT)) for p in core_files() if p.stem in LAB_MODULES]
    assert not back, back


def _find_table() -> dict:
    with open(ROOT / "pyproject.toml", "rb") as f:
        return tomllib.load(f)["tool"]["setuptools"]["packages"]["find"]


def test_wheel_packages_are_core_only():
    """setuptools' discovery with the project's own ``find`` table: the packages the wheel gets."""
    import setuptools

    table = _find_table()
    found = setuptools.find_packages(where=str(ROOT), include=table["include"],
                                     exclude=table.get("exclude", ()))
    assert "fit" in found and "warp_rbrdf" in found
    assert all(p.split(".")[0] in CORE for p in found), found
    shipped = [f"{p}.{f.stem}" for p in found for f in (ROOT / p.replace(".", "/")).glob("*.py")]
    assert not [m for m in shipped if m.rpartition(".")[2] in LAB_MODULES], shipped
    # the lab folders are packages that discovery would take if the table let it
    everything = setuptools.find_packages(where=str(ROOT))
    assert {"lab", "studies", "benchmarks"} <= set(everything)


@pytest.mark.slow
def test_built_wheel_holds_core_code_only(tmp_path):
    """``pip wheel`` in a copy of the checkout (its build/ folder stays out of the tree)."""
    src = tmp_path / "src"
    ignore = shutil.ignore_patterns(".git", ".venv", "build", "*.egg-info", "__pycache__", ".warp_cache",
                                    ".pytest_cache", ".hypothesis", ".benchmarks")
    shutil.copytree(ROOT, src, ignore=ignore)
    out = tmp_path / "wheel"
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(src)],
                       capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL)
    assert r.returncode == 0, r.stderr[-2000:]
    (wheel,) = out.glob("*.whl")
    py = [n for n in zipfile.ZipFile(wheel).namelist() if n.endswith(".py")]
    assert any(n.startswith("warp_rbrdf/") for n in py) and any(n.startswith("fit/") for n in py)
    assert all(n.split("/")[0] in CORE for n in py), [n for n in py if n.split("/")[0] not in CORE]
    assert not [n for n in py if Path(n).stem in LAB_MODULES]


# --------------------------------------------------------------------------------------------
# the lab marker
def is_lab_test(name: str, tree: ast.Module) -> bool:
    """A test module of lab code only: named ``test_bench*``, or importing at module level
    ``studies`` or ``benchmarks``, or the Mitsuba harness module ``lab.mitsuba_reference`` itself
    (``import lab.mitsuba_reference``, ``from lab import mitsuba_reference``). A core test may
    still import lab code inside a test function or use one of the harness's scene builders
    (``from lab.mitsuba_reference import sphere_scene``)."""
    if name.startswith("test_bench"):
        return True
    for node in tree.body:
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            if node.module.startswith("lab.mitsuba_reference"):   # names from it: a scene builder
                names = []
        else:
            continue
        if any(n.split(".")[0] in ("studies", "benchmarks") or n == "lab.mitsuba_reference"
               for n in names):
            return True
    return False


def has_lab_mark(tree: ast.Module) -> bool:
    """The module sets ``pytestmark`` to ``pytest.mark.lab`` (alone or in a list)."""
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "pytestmark" for t in node.targets):
            marks = node.value.elts if isinstance(node.value, (ast.List, ast.Tuple)) else [node.value]
            return any(ast.unparse(m) == "pytest.mark.lab" for m in marks)
    return False


def test_lab_tests_carry_the_lab_marker():
    with open(ROOT / "pyproject.toml", "rb") as f:
        markers = tomllib.load(f)["tool"]["pytest"]["ini_options"]["markers"]
    assert any(m.startswith("lab:") for m in markers), markers
    lab, unmarked = [], []
    for p in sorted((ROOT / "tests").glob("test_*.py")):
        tree = ast.parse(p.read_text(encoding="utf-8"), filename=str(p))
        if is_lab_test(p.name, tree):
            lab.append(p.name)
            if not has_lab_mark(tree):
                unmarked.append(p.name)
    assert {"test_parity_mitsuba.py", "test_convert_mitsuba.py", "test_studies.py",
            "test_benchmarks.py", "test_profile_render.py"} <= set(lab), lab
    assert "test_grazing.py" not in lab   # a core test using the harness's scene builder
    assert not unmarked, f"tests of lab code without pytestmark = pytest.mark.lab: {unmarked}"


def test_lab_tests_are_opt_in_and_ci_runs_them():
    """The default run (``addopts``) deselects the ``lab``, ``extended`` and ``heavy`` tests, like
    the ``slow`` and ``readme`` ones; ``.ci/run`` runs them after the README's test command."""
    import shlex

    with open(ROOT / "pyproject.toml", "rb") as f:
        addopts = shlex.split(tomllib.load(f)["tool"]["pytest"]["ini_options"]["addopts"])
    expr = addopts[addopts.index("-m") + 1]
    assert {"not lab", "not extended", "not heavy", "not slow", "not readme"} <= {t.strip() for t in expr.split(" and ")}, expr
    lines = [ln.strip() for ln in (ROOT / ".ci" / "run").read_text().splitlines()]
    test_command = next(i for i, ln in enumerate(lines) if ln.endswith("&& python -m pytest"))
    assert 'python -m pytest -m "(lab or extended or heavy) and not slow"' in lines[test_command + 1:], \
        ".ci/run does not run the lab, extended and heavy tests"
