"""The device a render runs on when none is named: ``$RBRDF_DEVICE``, else the CPU; a bad value
is one error naming the variable (``rbrdf render``: one line, exit status 2); so is a bad
``$RBRDF_CPU_ISA``."""
from __future__ import annotations

import pytest

from warp_rbrdf.errors import RenderError
from warp_rbrdf.runtime import get_device


def test_unset_or_empty_is_the_cpu(monkeypatch):
    monkeypatch.delenv("RBRDF_DEVICE", raising=False)
    assert get_device().is_cpu
    monkeypatch.setenv("RBRDF_DEVICE", " ")
    assert get_device().is_cpu


def test_the_variable_names_the_device_and_a_named_device_wins(monkeypatch):
    monkeypatch.setenv("RBRDF_DEVICE", "CPU")
    assert get_device().is_cpu
    monkeypatch.setenv("RBRDF_DEVICE", "tpu")
    assert get_device("cpu").is_cpu
    with pytest.raises(RenderError, match=r"^RBRDF_DEVICE: unknown device 'tpu'"):
        get_device()


@pytest.mark.parametrize("var, value", [("RBRDF_DEVICE", "tpu"), ("RBRDF_CPU_ISA", "avx9000")])
def test_cli_reports_a_bad_variable_in_one_line(monkeypatch, tmp_path, capsys, var, value):
    """A bad ``$RBRDF_DEVICE`` or ``$RBRDF_CPU_ISA`` (the render kernels' ISA level cap): one
    line naming the variable and its value, exit status 2, nothing written."""
    from warp_rbrdf.cli import main

    monkeypatch.setenv(var, value)
    out = tmp_path / "x.exr"
    assert main(["render", "--spp", "1", "--resolution", "8", "8", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and var in err[0] and value in err[0], err
    assert not out.exists()
