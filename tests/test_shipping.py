"""What ``warp_rbrdf`` ships is built and loaded through public APIs, for a Warp range that is
true: the declared ``warp-lang`` range holds the installed Warp and no other minor version
(the shipped kernel and Warp's AOT API are per version), the shipped kernel folder is the
installed version's, the shipping code uses no private Warp name, and the regenerate tools live
in ``tools/`` (outside the wheel), which no runtime module imports."""
from __future__ import annotations

import ast
import re
import tomllib
from importlib.metadata import version
from pathlib import Path

from packaging.specifiers import SpecifierSet
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]
KERNELS = ROOT / "warp_rbrdf" / "data" / "kernels"
SHIPPING = [ROOT / "warp_rbrdf" / "shipped_kernels.py", ROOT / "warp_rbrdf" / "techniques" / "table_cache.py",
            *sorted((ROOT / "tools").glob("*.py"))]


def _warp_requirement() -> SpecifierSet:
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    (req,) = [d for d in deps if re.match(r"warp-lang\b", d)]
    return SpecifierSet(req[len("warp-lang"):].strip())


def test_declared_warp_range_is_the_tested_one_and_the_shipped_kernels():
    spec = _warp_requirement()
    installed = Version(version("warp-lang"))
    assert installed in spec, f"installed warp-lang {installed} is outside pyproject's {spec}"
    major, minor = installed.major, installed.minor
    # the range admits exactly the installed minor version: the one the tests ran with
    assert Version(f"{major}.{minor}.0") in spec and Version(f"{major}.{minor}.99") in spec, spec
    assert Version(f"{major}.{minor + 1}.0") not in spec, f"{spec} admits an untested Warp {major}.{minor + 1}"
    assert Version(f"{major}.{minor - 1}.99") not in spec, f"{spec} admits an untested Warp {major}.{minor - 1}"
    # the shipped kernels are this Warp's (one version folder, the installed one)
    import warp as wp

    assert wp.config.version == str(installed)
    folders = [p.name for p in KERNELS.iterdir() if p.is_dir()]
    assert folders == [wp.config.version], folders


def _names(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            yield node.attr
        elif isinstance(node, ast.ImportFrom) and node.module:
            yield node.module
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.Import):
            yield from (a.name for a in node.names)


def test_shipping_uses_no_private_warp_name():
    """No ``warp._src`` import and no private attribute (``._get_cpu_feature_set``,
    ``._resolve_launch_block_dim``, ``Module._get_compile_output_name``, ...): only Warp's
    public API (``wp.compile_aot_module``, ``wp.load_aot_module``, ``Module.get_module_hash``)."""
    for path in SHIPPING:
        tree = ast.parse(path.read_text())
        bad = sorted({n for n in _names(tree) if "._src" in n or n.startswith("_src")
                      or (n.startswith("_") and not n.startswith("__"))})
        assert not bad, f"{path.relative_to(ROOT)} uses private names {bad}"


def test_runtime_holds_no_ship_tool():
    """The regenerate-and-ship tools are in ``tools/``: no module of the two packages imports
    ``tools`` or has a ``__main__`` entry point that writes shipped data, and the wheel's package
    list excludes ``tools``."""
    for pkg in ("fit", "warp_rbrdf"):
        for path in (ROOT / pkg).rglob("*.py"):
            tree = ast.parse(path.read_text())
            mods = {n for n in _names(tree)}
            assert not any(m == "tools" or m.startswith("tools.") for m in mods), path
    for path in (ROOT / "warp_rbrdf" / "shipped_kernels.py", ROOT / "warp_rbrdf" / "techniques" / "table_cache.py"):
        text = path.read_text()
        assert "__main__" not in text and "def regenerate" not in text and "def ship_" not in text, path
    include = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]["include"]
    assert not any(re.fullmatch(p.replace("*", ".*"), "tools") for p in include), include
