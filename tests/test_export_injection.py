"""Code injection through ``rbrdf-fit export`` (docs/exports.md, "Text from the fit file"): text
of a coefficient file -- its name, its source file, its tolerance record, channel names -- must
never become code in the ``.c``, ``.h``, ``.glsl``, ``.hlsl``, ``.brdf`` or ``.py`` output.

Every hostile text is exported to every format and the output is proved to hold no code beyond
the fit, by the languages' own tools: what each tool sees of it equals what it sees of the same
fit exported under a plain name (the function name aside), and that plain export compiles.

* C (``.c``, ``.h``): the preprocessed text (``cc -std=c99 -E -P -dD``: comments gone,
  trigraphs and line continuations applied, every ``#define`` kept); the ``.c`` is also
  compiled (``cc -c``) and ``nm`` lists exactly the fit's functions;
* GLSL, HLSL and the ``.brdf`` shader block: ``glslangValidator -E`` (the ``.glsl`` is also
  compiled); the ``.brdf`` file has exactly its four block markers, every line before them a
  ``#`` comment;
* Python: ``ast.parse`` and ``compile`` (SyntaxWarnings as errors); the module's top-level
  statements are the plain export's (a docstring, the imports, the runtime's definitions,
  ``PLAN``, ``NAME``, ``register``), no other import or expression, the plan's ``name`` is the
  text itself.

And the text is still there, readable: the comment's quoted form reads back (``ast.literal_eval``)
as the text (its first 200 characters for a longer one), the plugin's docstring holds it.
3-D fits (theta_h, theta_d, |phi_d|), whose exports have their own header lines and functions,
go through the same cases, against the plain 3-D fit's export; as version 4, the fitter's
default, with the value factor 1/cos theta_i (its header lines, its statements and C prelude).
The loader may refuse some texts (control characters, long names): then the run must be one
line naming the file, exit 2, nothing written -- and the same fit with the text set in memory
is exported through the library and checked as above.

Tools: ``cc``, ``nm`` and ``glslangValidator`` (Debian ``glslang-tools``); locally a missing
``cc`` or ``nm`` skips the test and a missing ``glslangValidator`` its shader checks only; under
CI either fails (:func:`conftest.missing`).
"""
from __future__ import annotations

import ast
import json
import re
import shutil
import subprocess
import warnings

import numpy as np
import pytest
from conftest import IN_CI, missing
from hostile import CLASSES, assert_bad_input, assert_unchanged, run, small_rational_dict, snapshot, write_json

from fit.export import to_brdf_explorer, to_c, to_glsl, to_hlsl, to_mitsuba_plugin
from fit.export.brdf_explorer import extract_shader
from fit.export.emitter import leaves
from fit.rational.coefficient_file import from_dict

FORMATS = (".c", ".h", ".glsl", ".hlsl", ".brdf", ".py")

#: (case id, text, what it broke in the export before): put in the fit's name, source file and
#: tolerance record, and exported to every format
HOSTILE = [
    ("c-comment-close", "x */ static int INJECTED_C = 1; /*", "C, GLSL, HLSL, .brdf: a symbol, code"),
    ("py-docstring-close", 'x"""; import os; os.system("echo INJECTED_PY"); """', ".py: import os at top level"),
    ("py-mixed-quotes", "x'\"\"\" + __import__('os').system('echo INJECTED_PY') + \"\"\"'",
     ".py: a call in the docstring's place"),
    ("quotes-and-backslash", "x\"\"\"'''\\", ".py: a SyntaxError"),
    ("newline-define", "x\n#define INJECTED_DEFINE 1\nint INJECTED_NL = 1;\n", ".brdf: lines outside its comments"),
    ("carriage-return", "x\rint INJECTED_CR = 1;\r", ".brdf: a line outside its comments"),
    ("backslash-newline", "x //\\\nint INJECTED_BS = 1;", "GLSL, .brdf: glslang refuses a continued comment"),
    ("trigraph-continuation", "x ??/\n*/ int INJECTED_TRI = 1; /* ?> <?php", "C, GLSL, HLSL, .brdf"),
    ("control-characters", "x\x00\x07\x1b[2J\x7f\x85 */ int INJECTED_CTL = 1; /*", "C, GLSL, HLSL, .brdf"),
    ("line-separators", "x\u2028*/ int INJECTED_LS = 1; /*\u2029", "C, GLSL, HLSL, .brdf"),
    ("brdf-markers-lines", "x\n::end shader\n::begin shader\nvec3 INJECTED_BRDF() { return vec3(1.0); }\n",
     ".brdf: a second shader block"),
    ("brdf-markers-inline", "x ::end shader ::begin parameters float INJECTED 0 1 1 ::end parameters",
     ".brdf: block markers inside a comment line"),
    ("long", "*/ int INJECTED_LONG = 1; /*" * 35, "C, GLSL, HLSL, .brdf (980 characters; the loader allows 1000)"),
    ("unicode", "caf\u00e9 \u2615 \U0001d501 */ int INJECTED_U = 1; /*", "C, GLSL, HLSL, .brdf"),
]
#: (case id, where, text, formats): texts put through the library where a file cannot put them
#: (channel names: a loaded BRDF's are R, G, B) or beyond the loader's limits (a 100 800-character name)
LIBRARY = [
    ("channel-comment-close", "channel", "R */ int INJECTED_CH = 1; /*", (".c", ".h", ".glsl", ".hlsl", ".brdf")),
    ("channel-brdf-marker", "channel", "R\n::end shader\nvec3 INJECTED_CH() { return vec3(1.0); }", (".brdf",)),
    ("huge-name", "name", "*/ int INJECTED_HUGE = 1; /*" * 3600, FORMATS),
]
PLAIN = "plain"


def case_counts() -> dict:
    """Named cases per class (docs/robustness.md): code in an output with exit 0 is a silent
    wrong result (each case exports to every format its text reaches, as a 2-D and as a 3-D
    fit); a version-3 fit to .brdf and a cut-off record that is not a number were tracebacks; a
    ``--name`` whose identifiers hold ``__`` (reserved in GLSL) or run to any length was
    accepted."""
    out = dict.fromkeys(CLASSES, 0)
    out["silent"] += 2 * (len(HOSTILE) + len(LIBRARY)) + len(BAD_NAMES)
    out["traceback"] += 2
    return out


# ----------------------------------------------------------------------------------------------
# inputs
def fit_dict(text: str) -> dict:
    """A small valid BRDF file (tests/hostile.py) with ``text`` as its name, source file and
    tolerance record, and one flagged channel (so that the flagged-pieces lines are written)."""
    d = small_rational_dict()
    d["name"] = text
    d["source"] = {"file": text, "sha256": ""}
    d["fit"] = {"tolerance": text, "grazing_cutoff_deg": 79.0}
    d["pieces"][0]["functions"][1]["valid"] = False
    return d


def fit3d_dict(text: str) -> dict:
    """A small valid version-4 (3-D, with the value factor 1/cos theta_i) BRDF file with
    ``text`` as its name, source file and tolerance record, and one flagged channel."""
    d = v3_dict(text, "1/cos_theta_i")
    d["source"] = {"file": text, "sha256": ""}
    d["fit"] = {"tolerance": text}
    d["functions"][1].update(valid=False, measured_range=[0.0, 1.0])
    return d


def library_model(text: str, channel: bool, three: bool = False):
    """The model of :func:`fit_dict` (:func:`fit3d_dict` if ``three``; plain texts) with
    ``text`` as every leaf's first channel name (``channel``), or as its name, source file and
    tolerance record, set in memory (no loader in the way)."""
    m = from_dict(fit3d_dict(PLAIN) if three else fit_dict(PLAIN), "plain.json")
    if channel:
        for leaf in leaves(m):
            leaf.outputs = (text,) + tuple(leaf.outputs[1:])
    else:
        m.name = text
        m.source = {"file": text, "sha256": ""}
        m.fit_info = dict(m.fit_info, tolerance=text)
    return m


def export_text(model, ext: str) -> str:
    return {".c": lambda: to_c(model, header=False), ".h": lambda: to_c(model), ".glsl": lambda: to_glsl(model),
            ".hlsl": lambda: to_hlsl(model), ".brdf": lambda: to_brdf_explorer(model),
            ".py": lambda: to_mitsuba_plugin(model)}[ext]()


# ----------------------------------------------------------------------------------------------
# the checks
def tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        missing(f"{name} not found (Debian: apt-get install glslang-tools / a C compiler and binutils)")
    return path


def sh(*args) -> str:
    """stdout of a tool that must succeed."""
    r = subprocess.run([str(a) for a in args], capture_output=True, text=True, check=False)
    assert r.returncode == 0, (args, (r.stdout + r.stderr)[-3000:])
    return r.stdout


IDENT = re.compile(r"rbrdf_[A-Za-z0-9]+(?:_[A-Za-z0-9]+)*")


def function_name(text: str, pattern: str) -> str:
    """The exported function name (found by ``pattern``); letters and digits joined by single
    '_' (no ``__``, which GLSL reserves), at most 6 + 64 characters."""
    m = re.search(pattern, text)
    assert m, pattern
    fn = m.group(1)
    assert IDENT.fullmatch(fn) and len(fn) <= 70, fn
    return fn


def normalised(code: str, fn: str) -> list:
    """Preprocessed text without blank lines and with the function name replaced."""
    code = code.replace(fn, "FN").replace(fn.upper(), "FN_UPPER")
    return [" ".join(ln.split()) for ln in code.splitlines() if ln.strip()]


def assert_readable(text: str, original: str) -> None:
    """The fit's name reads back from the comment line ``Fit '...'`` (its first 200
    characters)."""
    m = re.search(r"Fit ('(?:[^'\\]|\\.)*')", text)
    assert m, text[:500]
    assert ast.literal_eval(m.group(1)) == original[:200]


def c_check_symbols(src, folder, fn: str) -> None:
    """``cc -c`` compiles ``src`` and ``nm`` lists exactly the fit's functions."""
    obj = folder / "x.o"
    sh(tool("cc"), "-std=c99", "-c", "-DRBRDF_API=", "-x", "c", src, "-o", obj)
    symbols = {ln.split()[-1] for ln in sh(tool("nm"), "--defined-only", obj).splitlines() if ln.strip()}
    assert symbols == {fn, f"{fn}_angles", f"{fn}_frame", f"{fn}_local_", "rbrdf_clamp_"}, symbols


FRAGMENT = ("#version 330 core\n{uniforms}{code}\nout vec4 colour;\nvoid main()\n{{\n"
            "    colour = vec4({call}(vec3(0.0, 0.0, 1.0), vec3(0.0, 0.6, 0.8), vec3(0.0, 0.0, 1.0), "
            "vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0)), 1.0);\n}}\n")
HLSL_MAIN = ("float4 main(float4 pos : SV_Position) : SV_Target\n{{\n    return float4({fn}(normalize(pos.xyz), "
             "normalize(float3(-0.2, 0.1, 0.9))), 1.0);\n}}\n")


def tool_view(text: str, ext: str, folder, build: bool) -> list | None:
    """What the language's own tool sees of an export: its preprocessed text (comments gone,
    continuations and trigraphs applied, ``#define`` lines kept for C), :func:`normalised`;
    ``build``: also compiled (C: and its symbols listed). None for a shader when
    ``glslangValidator`` is missing locally."""
    if ext in (".c", ".h"):
        cc = tool("cc")
        fn = function_name(text, r"RBRDF_API void (\w+)_angles\(")
        src = folder / f"x{ext}"
        src.write_text(text, encoding="utf-8")
        pre = sh(cc, "-std=c99", "-E", "-P", "-dD", "-x", "c", src)
        if build:
            c_check_symbols(src, folder, fn)
        return normalised(pre, fn)
    exe = shutil.which("glslangValidator")
    if exe is None:          # this one check is skipped locally (not under CI); the others run
        if IN_CI:
            pytest.fail("glslangValidator not found (Debian: apt-get install glslang-tools)")
        return None
    if ext == ".hlsl":
        fn = function_name(text, r"float3 (\w+)_angles\(")
        src = folder / "x.hlsl"
        src.write_text(text + "\n" + HLSL_MAIN.format(fn=fn), encoding="utf-8")
        if build:
            sh(exe, "-D", "-V", "-e", "main", "-S", "frag", "-o", folder / "x.spv", src)
        return normalised(sh(exe, "-D", "-E", "-e", "main", "-S", "frag", src), fn)
    brdf = ext == ".brdf"
    code = extract_shader(text) if brdf else text
    fn = function_name(code, r"vec3 (\w+)_angles\(")
    src = folder / "x.frag"
    src.write_text(FRAGMENT.format(uniforms="uniform float scale;\n" if brdf else "", code=code,
                                   call="BRDF" if brdf else f"{fn}_frame"), encoding="utf-8")
    if build:
        sh(exe, src)
    return normalised(sh(exe, "-E", src), fn)


def brdf_structure(text: str) -> None:
    """A BRDF Explorer file: ``analytic``, ``#`` comment lines, then exactly the four block
    markers (which its reader finds by substring) and the one parameter."""
    lines = text.splitlines()
    assert lines[0] == "analytic"
    markers = [ln for ln in lines if "::" in ln]
    assert markers == ["::begin parameters", "::end parameters", "::begin shader", "::end shader"], markers
    head = lines[1:lines.index("::begin parameters")]
    assert all(ln == "" or ln.startswith("#") for ln in head), head
    params = lines[lines.index("::begin parameters") + 1:lines.index("::end parameters")]
    assert params == ["float scale 0.0 4.0 1.0"]


def top_level(tree) -> list:
    """The module's top-level statements, the docstring and the values of PLAN and NAME aside."""
    out = []
    for k, node in enumerate(tree.body):
        if k == 0 and isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
            out.append("docstring")
        elif isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] in (["PLAN"], ["NAME"]):
            out.append(f"assign {node.targets[0].id}")
        else:
            out.append(ast.dump(node))
    return out


def python_view(text: str) -> list:
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # an invalid escape in the docstring is a SyntaxWarning
        tree = ast.parse(text)
        compile(text, "plugin.py", "exec")
    return top_level(tree)


def python_check(text: str, original: str) -> None:
    """Beyond the statement list: no expression statement after the docstring, only the
    runtime's imports, the plan's name the text itself, the docstring holding it."""
    tree = ast.parse(text)
    assert not any(isinstance(n, ast.Expr) for n in tree.body[1:])
    imports = {a.name for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom)) for a in n.names}
    assert imports <= {"json", "bisect", "math"}, imports
    values = {n.targets[0].id: n.value for n in tree.body if isinstance(n, ast.Assign)}
    plan = json.loads(ast.literal_eval(values["PLAN"].args[0]))
    name = ast.literal_eval(values["NAME"])
    assert IDENT.fullmatch(name) and len(name) <= 70, name
    assert plan["name"] == original
    assert original[:200] in ast.get_docstring(tree, clean=False)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """``ref(ext, three=False)``: what the tools see of the plain fit's export (the plain 3-D
    fit's if ``three``; compiled once per format)."""
    folder = tmp_path_factory.mktemp("plain")
    cache = {}

    def ref(ext: str, three: bool = False) -> list:
        if (ext, three) not in cache:
            d = fit3d_dict(PLAIN) if three else fit_dict(PLAIN)
            text = export_text(from_dict(d, "plain.json"), ext)
            cache[ext, three] = python_view(text) if ext == ".py" else tool_view(text, ext, folder, build=True)
        return cache[ext, three]

    return ref


def check_output(text: str, ext: str, tmp_path, reference, original: str, three: bool = False) -> None:
    """The proof for one output (module docstring): what the tools see equals the plain
    export's (of the plain 3-D fit if ``three``); the .c is compiled (symbols), the .glsl
    compiled; the text is readable."""
    if ext == ".py":
        assert python_view(text) == reference(ext, three), "top-level statements differ from the plain export's"
        python_check(text, original)
        return
    if ext == ".brdf":
        brdf_structure(text)
    view = tool_view(text, ext, tmp_path, build=ext in (".c", ".glsl"))
    assert view == reference(ext, three), f"the preprocessed {ext} differs from the plain export's"
    assert_readable(text, original)


#: the parser built once for the module's in-process runs (conftest.fit_parser_once)
pytestmark = pytest.mark.usefixtures("fit_parser_once")


# ----------------------------------------------------------------------------------------------
# the cases
@pytest.mark.parametrize("three", [False, True], ids=["2d", "3d"])
@pytest.mark.parametrize("text", [c[1] for c in HOSTILE], ids=[c[0] for c in HOSTILE])
def test_cli_export_holds_no_code_beyond_the_fit(tmp_path, capsys, reference, text, three):
    """``rbrdf-fit export FIT OUT`` to every format (:data:`HOSTILE` says what each text broke),
    for a 2-D and a 3-D (version-3) fit. Where the loader refuses the text, the same fit with
    that text set in memory is exported by the library and checked the same way."""
    fit = write_json(tmp_path / "hostile.json", fit3d_dict(text) if three else fit_dict(text))
    for ext in FORMATS:
        out = tmp_path / f"out{ext}"
        rc, stdout, err = run(capsys, ["export", fit, out])
        if rc != 0:      # the loader refuses this text: one line naming the file, nothing written;
            assert_bad_input(rc, err, "hostile.json")      # the emitters must be safe regardless:
            assert not out.exists()
            check_output(export_text(library_model(text, channel=False, three=three), ext), ext, tmp_path,
                         reference, text, three)
            continue
        assert err == "" and f"wrote {out}" in stdout
        check_output(out.read_text(encoding="utf-8"), ext, tmp_path, reference, text, three)


@pytest.mark.parametrize("three", [False, True], ids=["2d", "3d"])
@pytest.mark.parametrize("where, text, formats", [c[1:] for c in LIBRARY], ids=[c[0] for c in LIBRARY])
def test_library_export_holds_no_code_beyond_the_fit(tmp_path, reference, where, text, formats, three):
    channel = where == "channel"
    model = library_model(text, channel, three)
    for ext in formats:
        check_output(export_text(model, ext), ext, tmp_path, reference, PLAIN if channel else text, three)


def v3_dict(name: str, value_factor: str = "none") -> dict:
    """A small version-3 BRDF file (theta_h, theta_d, |phi_d|); version 4 with a
    ``value_factor`` other than ``"none"``."""
    from fit.rational.coefficient_file import to_dict
    from fit.rational.function import RationalFunction
    from fit.rational.model import RationalModel, Variable

    var = [Variable("theta_h", "rad", "identity", (0.0, np.pi / 2)),
           Variable("theta_d", "rad", "identity", (0.0, np.pi / 2)),
           Variable("phi_d", "rad", "identity", (0.0, np.pi))]
    dom = [v.domain for v in var]
    fs = [RationalFunction(dom, [[0, 0, 0], [1, 0, 0], [0, 0, 1]], [0.1 * (c + 1), 0.01, 0.02], [[0, 0, 0]], [1.0])
          for c in range(3)]
    return to_dict(RationalModel(name=name, variables=var, functions=fs, value_factor=value_factor))


@pytest.mark.parametrize("value_factor", ["none", "1/cos_theta_i"], ids=["version-3", "version-4"])
def test_version_3_fit_is_exported_in_its_own_variables(tmp_path, capsys, value_factor):
    """A version-3 fit (phi_d; .brdf was a traceback, then a one-line refusal) and a version-4
    one (its value factor) are exported to every format with phi_d in their functions (and the
    factor, in the plugin's plan or the code's header, in version 4's), and an earlier output is
    replaced."""
    d = v3_dict(PLAIN, value_factor)
    assert d["version"] == (3 if value_factor == "none" else 4)
    fit = write_json(tmp_path / "v3.json", d)
    for ext in FORMATS:
        out = tmp_path / f"old{ext}"
        out.write_text("earlier output\n")
        rc, stdout, err = run(capsys, ["export", fit, out])
        assert rc == 0 and err == "" and f"wrote {out}" in stdout
        text = out.read_text(encoding="utf-8")
        assert "phi_d" in text and "earlier output" not in text
        factor = '"value_factor": {"kind": "1/cos_theta_i"' if ext == ".py" else "max(cos(theta_i), 0.001)"
        assert (factor in text) == (value_factor != "none")


def test_cutoff_record_not_a_number_is_refused(tmp_path, capsys):
    """``fit.grazing_cutoff_deg`` of another type than a number: one line, not a traceback."""
    d = fit_dict(PLAIN)
    d["fit"]["grazing_cutoff_deg"] = "*/ int INJECTED = 1; /*"
    fit = write_json(tmp_path / "cut.json", d)
    for ext in FORMATS:
        rc, stdout, err = run(capsys, ["export", fit, tmp_path / f"x{ext}"])
        assert_bad_input(rc, err, "cut.json", "grazing_cutoff_deg", out=stdout)
        assert not (tmp_path / f"x{ext}").exists()


BAD_NAMES = [("leading-underscore", "_x"), ("trailing-underscore", "x_"), ("too-long", "a" * 65)]


@pytest.mark.parametrize("name", [n for _, n in BAD_NAMES], ids=[i for i, _ in BAD_NAMES])
def test_name_flag_rule(tmp_path, capsys, name):
    """``--name`` must give identifiers without ``__`` (``rbrdf_`` + name + ``_angles``) and of a
    bounded length."""
    fit = write_json(tmp_path / "f.json", fit_dict(PLAIN))
    rc, stdout, err = run(capsys, ["export", fit, tmp_path / "x.glsl", "--name", name])
    assert_bad_input(rc, err, "--name", out=stdout)
    assert not (tmp_path / "x.glsl").exists()
    assert run(capsys, ["export", fit, tmp_path / "x.glsl", "--name", "a" * 64])[0] == 0


def test_identifiers_of_file_names(tmp_path):
    """A fit's name becomes letters and digits joined by single '_' (no '__': GLSL reserves it),
    at most 64 characters, never empty."""
    for name, want in (("__x__", "rbrdf_x"), ("9 lives", "rbrdf_m9_lives"), ("*/", "rbrdf_fit"),
                       ("a" * 1000, "rbrdf_" + "a" * 64), ("caf\u00e9 au lait", "rbrdf_caf_au_lait")):
        m = library_model(name, channel=False)
        assert function_name(to_glsl(m), r"vec3 (\w+)_angles\(") == want
