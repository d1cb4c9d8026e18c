"""Writes that cannot lose data: a full disk, an I/O error or a short write while an output is
written (docs/robustness.md, "Writes that cannot lose data").

Two kinds of case:

* **a real full disk**: a 64 KiB tmpfs mounted inside the test (root and a working ``mount``
  needed, else skipped; CI runs as root), holding earlier outputs, then filled to the last block.
  ``rbrdf render`` used to exit 0 there, print "wrote" and leave the earlier EXR and PNG as
  0-byte files (OpenImageIO reports success for a file it could not write); ``rbrdf-fit
  export`` was an ``OSError`` traceback;
* **injected failures**, in-process and fast, for every writer of the project: OpenImageIO's
  ``write_image`` reporting success without writing, ``os.fsync`` failing with ``EIO`` (an error
  the file system reports late), and a file object whose ``write`` stores half of what it is
  handed while reporting all of it (a short write hidden below the writer).

Each case: exit status 2 (or one :class:`fit.errors.OutputError`) naming the output path as
given, saying nothing was written and the old file is unchanged; every existing file byte for
byte as it was; no temporary file left.
"""
from __future__ import annotations

import errno
import functools
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from hostile import (
    CLASSES,
    assert_bad_input,
    assert_one_line,
    assert_unchanged,
    render_run,
    run,
    small_cdf_dict,
    small_rational_dict,
    snapshot,
    write_json,
)

#: (test name, class of the issue) of every named case below (see :func:`case_counts`).
CASES: list = []


def case(klass, n: int = 1):
    """Register the decorated test as ``n`` named cases of ``klass`` (one per parameter)."""
    def deco(fn):
        CASES.extend([(fn.__name__, klass)] * n)
        return fn
    return deco


def case_counts() -> dict:
    """Named cases of this module per class."""
    out = dict.fromkeys(CLASSES, 0)
    for _, klass in CASES:
        out[klass] += 1
    return out


def assert_write_refused(rc, err, target, flag):
    """Exit 2 and one error line ``FLAG TARGET: ...; nothing written, TARGET unchanged``."""
    assert_bad_input(rc, err, f"{flag} {target}: ", f"nothing written, {target} unchanged")


def assert_output_error(exc, target):
    """A one-line :class:`fit.errors.OutputError` naming ``target`` (not a temporary file)."""
    from fit.errors import OutputError

    assert isinstance(exc, OutputError), exc
    assert_one_line(str(exc), f"{target}: ", f"nothing written, {target} unchanged")


# ----------------------------------------------------------------------------------------------
# inputs and earlier outputs

@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A small rational fit and a small CDF file, outside the folders the cases check."""
    d = tmp_path_factory.mktemp("inputs")
    return {"fit": write_json(d / "small.json", small_rational_dict()),
            "cdf": write_json(d / "cdf.json", small_cdf_dict())}


def _old_outputs(folder: Path) -> None:
    """Earlier outputs of each kind: a real EXR and PNG (``old.exr``, ``old_ev+0.0.png``), a
    JSON, a GLSL export."""
    from warp_rbrdf.image_io import write_exr, write_png

    img = np.linspace(0, 1, 8 * 8 * 3, dtype=np.float32).reshape(8, 8, 3)
    write_exr(folder / "old.exr", img)
    write_png(folder / "old_ev+0.0.png", img)
    (folder / "old.json").write_text('{"keep": "me"}\n')
    (folder / "old.glsl").write_text("// an earlier export\n")


@pytest.fixture
def work(tmp_path):
    w = tmp_path / "work"
    w.mkdir()
    _old_outputs(w)
    return w


def _mount_tmpfs(folder: Path) -> str | None:
    """Mount a 64 KiB tmpfs on ``folder``; None when done, else why not."""
    if os.geteuid() != 0:
        return "not root"
    if shutil.which("mount") is None:
        return "no mount command"
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", os.fspath(folder)],
                       capture_output=True, text=True, timeout=30)
    return None if r.returncode == 0 else (r.stderr.strip() or f"mount exit {r.returncode}")


def _fill(folder: Path) -> None:
    """Fill ``folder``'s file system to its last block (a ``fill`` file)."""
    with open(folder / "fill", "wb", buffering=0) as f:
        try:
            while True:
                f.write(b"\0" * 512)
        except OSError as e:
            assert e.errno == errno.ENOSPC, e
    assert os.statvfs(folder).f_bavail == 0


@pytest.fixture
def full_disk(tmp_path):
    """A full 64 KiB tmpfs holding earlier outputs (:func:`_old_outputs`); unmounted after."""
    d = tmp_path / "disk"
    d.mkdir()
    why = _mount_tmpfs(d)
    if why is not None:
        pytest.skip(f"cannot mount a small tmpfs here ({why}); the injected cases cover the writers")
    try:
        _old_outputs(d)
        _fill(d)
        yield d
    finally:
        if subprocess.run(["umount", os.fspath(d)], capture_output=True, timeout=30).returncode:
            subprocess.run(["umount", "-l", os.fspath(d)], capture_output=True, timeout=30)


# ----------------------------------------------------------------------------------------------
# a real full disk

RENDER = ["render", "--resolution", "16", "16", "--spp", "1", "--no-progress"]


@case("lost")
def test_full_disk_render_keeps_the_earlier_images(capsys, full_disk):
    """The case of the report: exit 0, "wrote", and both earlier images 0-byte files."""
    before = snapshot(full_disk)
    rc, out, err = render_run(capsys, [*RENDER, "--out", full_disk / "old.exr"])
    assert_write_refused(rc, err, full_disk / "old.exr", "--out")
    assert "No space left on device" in err and "wrote" not in out
    assert_unchanged(before, full_disk)


@case("traceback")
def test_full_disk_export(capsys, full_disk, inputs):
    before = snapshot(full_disk)
    rc, out, err = run(capsys, ["export", inputs["fit"], full_disk / "old.glsl"])
    assert_write_refused(rc, err, full_disk / "old.glsl", "OUT")
    assert "No space left on device" in err
    assert_unchanged(before, full_disk)


@case("unclear")
def test_full_disk_cdf_names_the_output(capsys, full_disk, inputs):
    """The error named the hidden temporary file, not ``--out``."""
    before = snapshot(full_disk)
    rc, out, err = run(capsys, ["cdf", inputs["cdf"], "--out", full_disk / "old.json"])
    assert_write_refused(rc, err, full_disk / "old.json", "--out")
    assert_unchanged(before, full_disk)


@case("lost", 2)
@pytest.mark.parametrize("which", ["exr", "png"])
def test_full_disk_image_library(full_disk, which):
    """``image_io.write_exr`` / ``write_png`` replaced the earlier file by an empty one."""
    from fit.errors import OutputError
    from warp_rbrdf import image_io

    target = full_disk / ("old.exr" if which == "exr" else "old_ev+0.0.png")
    before = snapshot(full_disk)
    with pytest.raises(OutputError) as e:
        getattr(image_io, f"write_{which}")(target, np.full((4, 4, 3), 0.5, np.float32))
    assert_output_error(e.value, target)
    assert_unchanged(before, full_disk)


# ----------------------------------------------------------------------------------------------
# injected failures

def _fsync_eio(monkeypatch):
    def fsync(fd):
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(os, "fsync", fsync)


class _Lossy:
    """A file whose ``write`` stores the first half of what it is handed and reports all of it
    written (a short write that the layer below hides)."""

    def __init__(self, f):
        self._f = f

    def write(self, data):
        n = len(data) if isinstance(data, str) else memoryview(data).nbytes
        half = data[: n // 2] if isinstance(data, str) else bytes(memoryview(data).cast("B")[: n // 2])
        self._f.write(half)
        return n

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()
        return False


def _lossy_writes(monkeypatch):
    """Every file :mod:`fit.atomic_files` opens for writing is :class:`_Lossy`."""
    import builtins

    import fit.atomic_files

    def lossy_open(path, mode="r", *a, **k):
        f = builtins.open(path, mode, *a, **k)
        return _Lossy(f) if "w" in mode else f

    monkeypatch.setattr(fit.atomic_files, "open", lossy_open, raising=False)


def _oiio_writes_nothing(monkeypatch, fmt):
    """OpenImageIO's ``write_image`` of the ``fmt`` writer ("openexr", "png") returns True
    without writing a pixel."""
    import OpenImageIO as oiio

    real = oiio.ImageOutput.write_image

    def write_image(self, *a, **k):
        return True if self.format_name() == fmt else real(self, *a, **k)

    monkeypatch.setattr(oiio.ImageOutput, "write_image", write_image)


@case("lost", 2)
@pytest.mark.parametrize("fmt", ["openexr", "png"])
def test_render_image_writer_fails_silently(capsys, monkeypatch, work, fmt):
    _oiio_writes_nothing(monkeypatch, fmt)
    before = snapshot(work)
    rc, out, err = render_run(capsys, [*RENDER, "--out", work / "old.exr"])
    target = work / ("old.exr" if fmt == "openexr" else "old_ev+0.0.png")
    assert_write_refused(rc, err, target, "--out")
    assert_unchanged(before, work)


@case("lost")
def test_render_fsync_error(capsys, monkeypatch, work):
    _fsync_eio(monkeypatch)
    before = snapshot(work)
    rc, out, err = render_run(capsys, [*RENDER, "--out", work / "old.exr"])
    assert_write_refused(rc, err, work / "old.exr", "--out")
    assert "Input/output error" in err
    assert_unchanged(before, work)


@case("lost", 2)
@pytest.mark.parametrize("fmt", ["openexr", "png"])
def test_image_library_writer_fails_silently(monkeypatch, work, fmt):
    from fit.errors import OutputError
    from warp_rbrdf import image_io

    _oiio_writes_nothing(monkeypatch, fmt)
    target = work / ("old.exr" if fmt == "openexr" else "old_ev+0.0.png")
    before = snapshot(work)
    with pytest.raises(OutputError) as e:
        (image_io.write_exr if fmt == "openexr" else image_io.write_png)(target, np.ones((4, 4, 3), np.float32))
    assert_output_error(e.value, target)
    assert_unchanged(before, work)


FIT_CLI = [
    # (id, arguments: the inputs' keys as {fit}/{cdf}, the output as {out}), output name, flag
    ("export", ["export", "{fit}", "{out}"], "old.glsl", "OUT"),
    ("cdf", ["cdf", "{cdf}", "--out", "{out}"], "old.json", "--out"),
]


@case("lost", 2 * len(FIT_CLI))
@pytest.mark.parametrize("failure", ["short-write", "fsync-eio"])
@pytest.mark.parametrize("name,argv,output,flag", FIT_CLI, ids=[c[0] for c in FIT_CLI])
def test_fit_cli_write_failure(capsys, monkeypatch, work, inputs, name, argv, output, flag, failure):
    (_lossy_writes if failure == "short-write" else _fsync_eio)(monkeypatch)
    before = snapshot(work)
    rc, out, err = run(capsys, [a.format(out=work / output, **inputs) for a in argv])
    assert_write_refused(rc, err, work / output, flag)
    assert_unchanged(before, work)


@functools.lru_cache(maxsize=1)
def _merl_brdf():
    from lab.analytic import lambert
    from fit.formats.measured import MeasuredBRDF

    return MeasuredBRDF.from_function(lambert())


def _save_rational(path):
    from fit.rational.coefficient_file import from_dict, save

    save(from_dict(small_rational_dict()), path)


def _save_cdf(path):
    from fit.sampling.cdf_file import from_dict

    from_dict(small_cdf_dict()).save(path)


def _write_tensor(path):
    from fit.formats.tensor_file import write_tensor_file

    write_tensor_file(path, {"theta_i": np.linspace(0, 1, 5, dtype=np.float32),
                             "data": np.ones((3, 4), np.float32)})


def _write_table(path):
    from lab.analytic import glossy_lobe
    from fit.sampling.table import tabulate
    from warp_rbrdf.techniques.table_cache import write

    write(path, tabulate(glossy_lobe(), n_v=2, n_t=4, n_p=4))


#: The library's writers of the commands' outputs (``brdf`` and ``convert`` save through them
#: into staged files) and of the renderer's table cache: name -> (earlier file, write(path)).
LIBRARY_WRITERS = {
    "coefficient_file.save": ("old.json", _save_rational),
    "CDFFit.save": ("old.json", _save_cdf),
    "write_tensor_file": ("old.bsdf", _write_tensor),
    "table_cache.write": ("old.npz", _write_table),
}


@case("lost", 2 * len(LIBRARY_WRITERS))
@pytest.mark.parametrize("failure", ["short-write", "fsync-eio"])
@pytest.mark.parametrize("name", sorted(LIBRARY_WRITERS))
def test_library_writer_failure(monkeypatch, tmp_path, name, failure):
    from fit.errors import OutputError

    old, write = LIBRARY_WRITERS[name]
    target = tmp_path / old
    target.write_bytes(b"an earlier good file")
    (_lossy_writes if failure == "short-write" else _fsync_eio)(monkeypatch)
    before = snapshot(tmp_path)
    with pytest.raises(OutputError) as e:
        write(target)
    assert_output_error(e.value, target)
    assert_unchanged(before, tmp_path)


@case("lost", 2)
@pytest.mark.parametrize("failure", ["short-write", "fsync-eio"])
def test_write_merl_failure(monkeypatch, tmp_path, failure):
    """``write_merl`` (35 MB): also what ``rbrdf-fit convert`` to ``.binary`` writes."""
    from fit.errors import OutputError
    from fit.formats.merl import write_merl

    brdf = _merl_brdf()
    target = tmp_path / "old.binary"
    target.write_bytes(b"an earlier good file")
    (_lossy_writes if failure == "short-write" else _fsync_eio)(monkeypatch)
    before = snapshot(tmp_path)
    with pytest.raises(OutputError) as e:
        write_merl(brdf, target)
    assert_output_error(e.value, target)
    assert_unchanged(before, tmp_path)


@case("lost", 2)
@pytest.mark.parametrize("failure", ["truncated", "fsync-eio"])
def test_save_figure_failure(monkeypatch, tmp_path, failure):
    """A figure (``plot``, ``plot-cdf``, the batch report's) cut short by its writer, or whose
    file system reports an error at fsync, does not replace the earlier PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fit.errors import OutputError
    from fit.outputs import OutputSet, save_figure

    target = tmp_path / "old.png"
    target.write_bytes(b"an earlier good png")
    fig = plt.figure(figsize=(1, 1))
    if failure == "truncated":
        real = fig.savefig

        def savefig(path, **k):
            real(path, **k)
            with open(path, "r+b") as f:
                f.truncate(os.path.getsize(path) - 20)

        fig.savefig = savefig
    else:
        _fsync_eio(monkeypatch)
    before = snapshot(tmp_path)
    with pytest.raises(OutputError) as e, OutputSet("--out") as outputs:
        save_figure(fig, target, outputs)
        outputs.commit()
    assert_one_line(str(e.value), f"--out {target}: ", f"nothing written, {target} unchanged")
    assert_unchanged(before, tmp_path)


def test_writes_that_succeed_are_whole(capsys, tmp_path, inputs):
    """Positive control: with nothing injected the same writers replace the earlier files, and
    no temporary file is left."""
    from fit.formats.merl import read_merl, write_merl
    from fit.formats.tensor_file import read_tensor_file
    from fit.rational.coefficient_file import load
    from fit.sampling.cdf_file import load as load_cdf
    from warp_rbrdf.image_io import read_image
    from warp_rbrdf.techniques.table_cache import read as read_table

    _old_outputs(tmp_path)
    rc, out, err = render_run(capsys, [*RENDER, "--out", tmp_path / "old.exr"])
    assert rc == 0, err
    assert read_image(tmp_path / "old.exr").shape == (16, 16, 3)
    assert read_image(tmp_path / "old_ev+0.0.png").shape == (16, 16, 3)
    rc, out, err = run(capsys, ["export", inputs["fit"], tmp_path / "old.glsl"])
    assert rc == 0 and "earlier" not in (tmp_path / "old.glsl").read_text(), err
    for k, (name, (old, write)) in enumerate(sorted(LIBRARY_WRITERS.items())):
        write(tmp_path / f"{k}_{old}")
    # sorted: 0 CDFFit.save, 1 coefficient_file.save, 2 table_cache.write, 3 write_tensor_file
    assert load_cdf(tmp_path / "0_old.json").name == "small"
    assert load(tmp_path / "1_old.json").name == "small"
    assert read_table(tmp_path / "2_old.npz") is not None
    assert set(read_tensor_file(tmp_path / "3_old.bsdf")) == {"theta_i", "data"}
    write_merl(_merl_brdf(), tmp_path / "x.binary")
    assert read_merl(tmp_path / "x.binary") is not None
    assert not [p for p in tmp_path.iterdir() if ".part" in p.name]
