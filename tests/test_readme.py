"""README.md's code blocks, run exactly as written, so that a quick start cannot break unseen.

Every fenced block of README.md is extracted (:func:`readme_blocks`) and given a role
(:func:`role`):

* the *Set up* section's main job (``python3 -m venv .venv && ... pip install . && rbrdf render
  ...``) runs verbatim in a fresh copy of the checkout with a venv of its own
  (:func:`test_readme_main_job`, ~1 min: a real ``pip install .``);
* the *Set up* section's test command is the line ``.ci/run`` runs verbatim
  (:func:`test_ci_runs_the_readme_test_command`);
* every other ``bash`` / ``python`` block runs verbatim, in README order, in one copy of the
  checkout (:func:`checkout_copy`: ``git ls-files``, untracked files that git does not ignore
  too) that sits next to a ``shared/data`` link to the shared data, as a user's clone does; a
  ``toml`` block is saved under the name its paragraph gives it (``paper.toml``) first
  (:func:`test_readme_quick_starts`). Every output a block names (``--out X``,
  ``out/<scene>.exr`` and its ``_ev+0.0.png``, ``.save("X")``) must be written by that block
  and be a valid image (finite, not black) or a file that ``fit`` loads; an array a Python
  block annotates (``# (H, W, 3) float32``) must have that shape and type.

A block that fits none of these roles fails :func:`test_every_readme_block_has_a_role`, and a
fence the extraction misses fails :func:`test_extraction_finds_every_fence`. The two long tests
carry the ``readme`` marker: deselected by default, run by ``.ci/run`` after the suite
(``python -m pytest -m readme``). The shell blocks run with ``bash -e -o pipefail`` (a failing
command stops its block), without ``RBRDF_DATA`` in the environment (a block sets what it
needs), with this environment's ``rbrdf`` / ``rbrdf-fit`` / ``python`` first on ``PATH``.
"""
from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from conftest import DATA, ROOT, missing

README = ROOT / "README.md"
CI_RUN = ROOT / ".ci" / "run"
#: the shared data folder as an absolute path (``RBRDF_DATA`` may be relative to where pytest
#: started)
DATA_ABS = Path(os.path.abspath(DATA))
#: bound on one block's run (s): a hung block fails instead of stopping CI
BLOCK_TIMEOUT_S = 600
RUNNABLE = ("bash", "sh", "python")

_FENCE_LINE = re.compile(r"^\s*```")
_BLOCK = re.compile(r"^```([\w+-]*)[ \t]*\n(.*?)^```[ \t]*$", re.M | re.S)
_HEADING = re.compile(r"^(#{2,3}) +(.+?)\s*$", re.M)


@dataclass(frozen=True)
class Block:
    """One fenced block of README.md: ``lang`` as written after the fence, ``text`` its body,
    ``line`` the 1-based line of its opening fence, ``section`` the ``##`` heading above it,
    ``prose`` the text between the previous block and this one."""
    lang: str
    text: str
    line: int
    section: str
    prose: str

    @property
    def where(self) -> str:
        return f"README.md:{self.line} ({self.lang} block in '{self.section}')"

    @property
    def save_as(self) -> str | None:
        """For a ``toml`` block: the last ``NAME.toml`` its paragraph names (the file the quick
        start tells the user to save it as)."""
        names = re.findall(r"`([\w./-]+\.toml)`", self.prose)
        return names[-1] if names else None


def readme_blocks(text: str | None = None) -> list[Block]:
    """The fenced blocks of README.md (or of ``text``), in order."""
    text = README.read_text(encoding="utf-8") if text is None else text
    blocks, prev_end = [], 0
    for m in _BLOCK.finditer(text):
        sections = [h.group(2) for h in _HEADING.finditer(text, 0, m.start()) if h.group(1) == "##"]
        blocks.append(Block(lang=m.group(1), text=m.group(2), line=text.count("\n", 0, m.start()) + 1,
                            section=sections[-1] if sections else "", prose=text[prev_end:m.start()]))
        prev_end = m.end()
    return blocks


def role(block: Block) -> str | None:
    """``"main job"``, ``"test command"``, ``"run"``, ``"save"`` or None (no test runs it)."""
    if block.section == "Set up":
        if block.lang == "bash" and re.search(r"\bpip install \.(\s|$)", block.text):
            return "main job"
        if block.lang == "bash" and "python -m pytest" in block.text:
            return "test command"
        return None
    if block.lang in RUNNABLE:
        return "run"
    if block.lang == "toml" and block.save_as:
        return "save"
    return None


# ----------------------------------------------------------------------------------------------
# what a block says it writes, and checks of it

def _commands(block: Block) -> list[list[str]]:
    """The shell commands of a block, as argument lists (comments dropped; not expanded)."""
    return [shlex.split(line, comments=True) for line in block.text.splitlines()
            if shlex.split(line, comments=True)]


def expected_outputs(block: Block) -> list[str]:
    """The files a block says it writes, relative to its working directory: ``--out X`` of
    ``rbrdf-fit`` and ``rbrdf render`` (a render also writes ``X_ev+0.0.png`` next to its EXR;
    without ``--out``, ``out/<scene>.exr``), ``.save("X")`` of a Python block."""
    if block.lang == "python":
        return re.findall(r"""\.save\(\s*["']([^"']+)["']""", block.text)
    outs = []
    for args in _commands(block):
        out = args[args.index("--out") + 1] if "--out" in args else None
        if args[:2] == ["rbrdf", "render"]:
            if out is None:
                scenes = [a for a in args[2:] if a.endswith(".toml")]
                out = f"out/{Path(scenes[0]).stem if scenes else 'default'}.exr"
            outs += [out, str(Path(out).with_name(Path(out).stem + "_ev+0.0.png"))]
        elif args[:1] == ["rbrdf-fit"] and out is not None:
            outs.append(out)
    return outs


def check_output(path: Path, since: float, where: str) -> None:
    """``path`` was written at or after ``since`` (s, epoch) and is valid: an image that reads
    back finite, non-negative and not black; a JSON file that ``fit`` loads."""
    assert path.is_file(), f"{where}: {path.name} was not written"
    assert path.stat().st_mtime >= since - 1.0, f"{where}: {path} is older than the block"
    if path.suffix in (".exr", ".png"):
        from warp_rbrdf.image_io import read_image

        img = np.asarray(read_image(path))
        assert img.ndim == 3 and img.shape[2] >= 3 and img.size, (where, path, img.shape)
        assert np.isfinite(img).all() and (img >= 0).all() and img[..., :3].max() > 0, (where, path)
    elif path.suffix == ".json":
        import fit

        fmt = json.loads(path.read_text()).get("format")
        loaded = fit.load_cdf(path) if fmt == "rbrdf-cdf" else fit.load_coefficients(path)
        assert loaded is not None, (where, path)
    else:
        assert path.stat().st_size > 0, (where, path)


# an assignment that states its array's shape and type: ``x = ...  # (H, W, 3) float32``
_ARRAY_CLAIM = re.compile(r"^(\w+)\s*=.*#\s*\(([^)]*)\)\s+(\w+)", re.M)

_PY_RUNNER = """\
import json, sys
import numpy as np
path, name = sys.argv[1], sys.argv[2]
ns = {"__name__": "__main__"}
exec(compile(open(path, encoding="utf-8").read(), name, "exec"), ns)
arrays = {k: [list(np.shape(v)), str(np.asarray(v).dtype), bool(np.isfinite(v).all())]
          for k, v in ns.items() if isinstance(v, np.ndarray)}
print("README-ARRAYS " + json.dumps(arrays))
"""


def check_array_claims(block: Block, stdout: str) -> None:
    """Each ``x = ...  # (A, B, 3) dtype`` of a Python block: ``x`` has that many dimensions,
    the literal sizes and that dtype, and is finite."""
    lines = [ln for ln in stdout.splitlines() if ln.startswith("README-ARRAYS ")]
    assert lines, f"{block.where}: the block did not finish"
    arrays = json.loads(lines[-1].split(" ", 1)[1])
    for name, dims, dtype in _ARRAY_CLAIM.findall(block.text):
        dims = [d.strip() for d in dims.split(",")]
        assert name in arrays, f"{block.where}: {name} is not an array"
        shape, got_dtype, finite = arrays[name]
        assert len(shape) == len(dims), (block.where, name, shape, dims)
        assert all(not d.isdigit() or int(d) == s for d, s in zip(dims, shape)), (block.where, name, shape)
        assert got_dtype == dtype and finite, (block.where, name, got_dtype, dtype, finite)


# ----------------------------------------------------------------------------------------------
# running blocks

def checkout_copy(dest: Path) -> Path:
    """A copy of the working tree's files (tracked, and untracked ones git does not ignore: no
    ``.venv``, outputs or caches) in ``dest``, as a fresh clone of it would hold them."""
    try:
        out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                             cwd=ROOT, capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        missing(f"the README tests copy the checkout with git ls-files: {e}")
    for name in filter(None, out.split(b"\0")):
        src = ROOT / os.fsdecode(name)
        if src.is_file():                    # a file deleted in the working tree is not copied
            dst = dest / os.fsdecode(name)
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst)
    return dest


def block_env(**extra) -> dict:
    """The environment a block runs in: this one without ``RBRDF_DATA``, with this Python's
    scripts (``rbrdf``, ``rbrdf-fit``, ``python``) first on ``PATH``."""
    env = {k: v for k, v in os.environ.items() if k != "RBRDF_DATA"}
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["MPLBACKEND"] = "Agg"
    env.update(extra)
    return env


def run_block(block: Block, cwd: Path, env: dict, scratch: Path) -> str:
    """Run a ``bash`` / ``python`` block verbatim in ``cwd``; its output (stdout and stderr);
    a test failure naming the block when it exits non-zero or runs past
    :data:`BLOCK_TIMEOUT_S`."""
    if block.lang == "python":
        script = scratch / f"readme_line{block.line}.py"
        script.write_text(block.text, encoding="utf-8")
        runner = scratch / "readme_runner.py"
        runner.write_text(_PY_RUNNER, encoding="utf-8")
        argv = [sys.executable, str(runner), str(script), block.where]
    else:
        argv = ["bash", "-e", "-o", "pipefail", "-c", block.text]
    t0 = time.monotonic()
    try:
        r = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=BLOCK_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{block.where} ran past {BLOCK_TIMEOUT_S} s")
    print(f"{block.where}: exit {r.returncode} after {time.monotonic() - t0:.1f} s")   # shown with -s
    output = r.stdout + r.stderr
    assert r.returncode == 0, f"{block.where} exited {r.returncode}:\n{block.text}\n{output[-4000:]}"
    return r.stdout if block.lang == "python" else output


# ----------------------------------------------------------------------------------------------
# fast tests (default run)

def test_extraction_finds_every_fence():
    """Every fence line of README.md opens or closes an extracted block (an indented, unclosed
    or oddly written fence would otherwise be skipped silently), and a README with one more
    block gives one more block."""
    text = README.read_text(encoding="utf-8")
    fences = sum(1 for ln in text.splitlines() if _FENCE_LINE.match(ln))
    blocks = readme_blocks(text)
    assert fences == 2 * len(blocks), (fences, len(blocks))
    assert len(readme_blocks(text + "\n```bash\necho extra\n```\n")) == len(blocks) + 1


def test_every_readme_block_has_a_role():
    """Every block is run by a test here, or (the test command) by .ci/run; the README has the
    main job, the test command and the quick starts' blocks."""
    blocks = readme_blocks()
    unrun = [b.where for b in blocks if role(b) is None]
    assert not unrun, f"README blocks that no test runs (give them a role in tests/test_readme.py): {unrun}"
    roles = [role(b) for b in blocks]
    assert roles.count("main job") == 1 and roles.count("test command") == 1, roles
    assert roles.count("run") >= 1
    for b in blocks:
        if role(b) == "run":
            assert b.lang == "python" or _commands(b), b.where


def test_role_rejects_what_no_test_runs():
    """A block in an unknown language, a toml block no paragraph names, and an unknown Set up
    block get no role (so the test above would fail on them)."""
    assert role(Block("yaml", "a: 1\n", 1, "Quick start", "")) is None
    assert role(Block("toml", "[camera]\n", 1, "Quick start", "a scene:\n")) is None
    assert role(Block("bash", "make\n", 1, "Set up", "")) is None
    assert role(Block("toml", "[camera]\n", 1, "Quick start", "a scene, `x.toml`:\n")) == "save"


def test_ci_runs_the_readme_test_command():
    """.ci/run holds the README's test command verbatim, and runs the ``readme`` tests after it."""
    (cmd,) = [b.text.strip() for b in readme_blocks() if role(b) == "test command"]
    lines = [ln.strip() for ln in CI_RUN.read_text().splitlines()]
    assert cmd in lines, f".ci/run lacks the README's test command {cmd!r}"
    after = lines[lines.index(cmd) + 1:]
    assert "python -m pytest -m readme" in after, ".ci/run does not run the readme tests after the suite"


def test_expected_outputs_follow_the_commands():
    """The outputs a block is checked for come from its commands (so a new command's outputs
    are checked too)."""
    b = Block("bash", "rbrdf render --out out/a.exr   # x\nrbrdf render scenes/s.toml --spp 4\n"
                      "rbrdf-fit cdf F --out fits/c.json\nexport X=1\n", 1, "Quick start", "")
    assert expected_outputs(b) == ["out/a.exr", "out/a_ev+0.0.png", "out/s.exr", "out/s_ev+0.0.png",
                                   "fits/c.json"]
    assert expected_outputs(Block("python", 'f.save("fits/p.json")\n', 1, "Quick start", "")) == ["fits/p.json"]


def test_relative_rbrdf_data_is_relative_to_the_working_directory(tmp_path, monkeypatch):
    """A relative ``RBRDF_DATA`` (and a relative path in any variable that starts a scene path)
    names a folder relative to the current directory, not to the scene file's folder: the scene
    sits in a sub-folder, the working directory is the project root."""
    from warp_rbrdf import paths

    (tmp_path / "data" / "envmaps").mkdir(parents=True)
    (tmp_path / "scenes").mkdir()
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("RBRDF_DATA", "data")
    monkeypatch.setenv("MY_ASSETS", "data/envmaps")
    scene_dir = tmp_path / "scenes"
    want = tmp_path / "data" / "envmaps" / "a.hdr"
    assert paths.data_root() == tmp_path / "data" and paths.data_root().is_absolute()
    for text in ("${RBRDF_DATA}/envmaps/a.hdr", "$RBRDF_DATA/envmaps/a.hdr", "data:envmaps/a.hdr",
                 "${MY_ASSETS}/a.hdr", "$MY_ASSETS/a.hdr"):
        assert paths.resolve_path(text, scene_dir) == want, text
    # a plain relative path stays relative to the scene's folder; an unset variable stays as written
    assert paths.resolve_path("envmaps/a.hdr", scene_dir) == scene_dir / "envmaps" / "a.hdr"
    monkeypatch.delenv("MY_ASSETS")
    assert paths.resolve_path("${MY_ASSETS}/a.hdr", scene_dir) == scene_dir / "${MY_ASSETS}" / "a.hdr"


def test_quick_start_scene_in_a_subfolder_finds_the_shared_data(monkeypatch):
    """Quick start 1's scene (``scenes/teapot_studio.toml``) with ``RBRDF_DATA`` relative to the
    project root, run from the project root: every file it names is found in the shared data."""
    from warp_rbrdf import parse_scene

    scene_file = ROOT / "scenes" / "teapot_studio.toml"
    if not (DATA_ABS / "meshes" / "teapot.obj").is_file():
        missing(f"shared data missing: {DATA_ABS} (set RBRDF_DATA)")
    monkeypatch.chdir(ROOT)
    monkeypatch.setenv("RBRDF_DATA", os.path.relpath(DATA_ABS, ROOT))
    scene = parse_scene(scene_file.read_text(), path="scenes/teapot_studio.toml")
    files = [Path(x.file) for x in (*scene.shapes, *scene.lights, *scene.materials.values())
             if getattr(x, "file", None)]
    assert len(files) == 3, files
    for f in files:
        assert f.is_file() and f.resolve().is_relative_to(DATA_ABS.resolve()), f


# ----------------------------------------------------------------------------------------------
# the README as a user runs it (``python -m pytest -m readme``)

@pytest.mark.readme
def test_readme_main_job(tmp_path):
    """The *Set up* main job, verbatim, in a fresh copy of the checkout: a new venv, ``pip
    install .``, the default render; it needs no shared data; it writes the two images the
    README names and says the shipped fit's grazing band is not within its bound in blue."""
    (block,) = [b for b in readme_blocks() if role(b) == "main job"]
    work = checkout_copy(tmp_path / "clone")
    env = {k: v for k, v in os.environ.items()
           if k not in ("RBRDF_DATA", "VIRTUAL_ENV", "PYTHONPATH", "WARP_CACHE_PATH")}
    env["WARP_CACHE_PATH"] = str(tmp_path / "warp_cache")      # a first run: no kernel cache
    env["MPLBACKEND"] = "Agg"
    t0 = time.time()
    output = run_block(block, work, env, tmp_path)
    for out in expected_outputs(block):
        check_output(work / out, t0, block.where)
    assert (work / ".venv" / "bin" / "rbrdf").is_file(), "the main job's venv has no rbrdf"
    text = " ".join(output.split())
    assert "not within its bound" in text and "blue" in text and "projected" in text, output[-2000:]


@pytest.mark.readme
def test_readme_quick_starts(tmp_path):
    """Every quick-start block, verbatim and in order, in a copy of the checkout next to
    ``shared/data`` (the layout the README assumes): each exits 0 and writes what it names."""
    if not DATA_ABS.is_dir():
        missing(f"shared data missing: {DATA_ABS} (set RBRDF_DATA)")
    (tmp_path / "shared").mkdir()
    (tmp_path / "shared" / "data").symlink_to(DATA_ABS, target_is_directory=True)
    work = checkout_copy(tmp_path / "main")
    env = block_env()
    blocks = [b for b in readme_blocks() if role(b) in ("run", "save")]
    assert blocks
    for block in blocks:
        if role(block) == "save":
            (work / block.save_as).write_text(block.text, encoding="utf-8")
            continue
        t0 = time.time()
        output = run_block(block, work, env, tmp_path)
        for out in expected_outputs(block):
            check_output(work / out, t0, block.where)
        if block.lang == "python":
            check_array_claims(block, output)
