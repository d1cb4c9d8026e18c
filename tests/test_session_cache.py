"""conftest.session_cached: a value made once per test session for all pytest-xdist workers
(the resampled RGL files of conftest.rgl_measured)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import SESSION_CACHE_ENV, session_cached

HERE = Path(__file__).resolve().parent

# a worker: asks for the value of the key, its make() slow and counted (one line per call)
_WORKER = r"""
import sys, time
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from conftest import session_cached

calls = Path(sys.argv[3])

def make():
    with open(calls, "a") as f:
        f.write("made\n")
    time.sleep(1.0)
    return {"value": list(range(5)), "by": sys.argv[4]}

print(session_cached(Path(sys.argv[2]), "what", make)["by"])
"""


def test_two_workers_make_the_value_once(tmp_path, monkeypatch):
    """Two processes ask for the same key at once: one makes it, the other waits on the lock
    and loads the first one's value; a second key, or the same key of another file, is made
    again; no temporary file is left."""
    src = tmp_path / "file.bin"
    src.write_bytes(b"some file")
    folder = tmp_path / "session"
    folder.mkdir()
    calls = tmp_path / "calls"
    env = dict(os.environ, **{SESSION_CACHE_ENV: str(folder)})
    procs = [subprocess.Popen([sys.executable, "-c", _WORKER, str(HERE), str(src), str(calls), name],
                              env=env, stdout=subprocess.PIPE, text=True) for name in ("a", "b")]
    outs = [p.communicate(timeout=120)[0].strip() for p in procs]
    assert [p.returncode for p in procs] == [0, 0]
    assert calls.read_text() == "made\n"
    assert outs[0] == outs[1] in ("a", "b")          # both got the maker's value
    assert sorted(p.suffix for p in folder.iterdir()) == [".lock", ".pickle"]

    monkeypatch.setenv(SESSION_CACHE_ENV, str(folder))
    assert session_cached(src, "what", lambda: pytest.fail("made again"))["by"] == outs[0]
    assert session_cached(src, "other", lambda: "other") == "other"
    src.write_bytes(b"another file")
    assert session_cached(src, "what", lambda: "new") == "new"


def test_outside_a_session_it_makes_the_value(tmp_path, monkeypatch):
    monkeypatch.delenv(SESSION_CACHE_ENV, raising=False)
    n = []
    assert session_cached(tmp_path, "x", lambda: n.append(1) or 7) == 7
    assert session_cached(tmp_path, "x", lambda: n.append(1) or 7) == 7 and n == [1, 1]
