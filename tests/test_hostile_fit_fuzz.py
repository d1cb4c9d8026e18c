"""Seeded fuzzing of every file format the fitter reads (issue 22): truncations and bit flips
of MERL ``.binary``, RGL ``.bsdf``, ``rbrdf-rational`` and ``rbrdf-cdf`` JSON (bytes) and
projected ``.npz``, and structural mutations of the two JSON formats (a value replaced by
another type or an extreme number, a key deleted, a list shortened or grown).

Each mutated input must either load and then satisfy what the format promises (finite values
in range, a model without poles, a sampler with finite samples and positive densities), or be
refused with one :class:`fit.errors.BRDFFileError` line naming the file. Any other exception,
a multi-line message or an invariant that fails is a bug. The seeds are fixed: a failure
reproduces.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import data_file
from hostile import (
    bit_flips,
    json_mutations,
    small_cdf_dict,
    small_rational_dict,
    truncations,
)

from fit.errors import BRDFFileError
from fit.formats.merl import MERL_SHAPE, read_merl
from fit.formats.rgl import read_rgl
from fit.limits import MAX_BRDF_VALUE


def _outcome(path, load, check):
    """``"ok"`` (loaded, invariants hold) or ``"refused"`` (one-line error naming the file)."""
    try:
        obj = load(path)
    except BRDFFileError as e:
        msg = str(e)
        assert "\n" not in msg and str(path) in msg, msg
        return "refused"
    check(obj)
    return "ok"


def _run(tmp_path, suffix, blobs, load, check):
    outcomes = []
    for i, data in enumerate(blobs):
        p = tmp_path / f"fuzz{i}{suffix}"
        if isinstance(data, str):
            p.write_text(data, encoding="utf-8")
        else:
            p.write_bytes(data)
        outcomes.append(_outcome(p, load, check))
        p.unlink()
    return outcomes


# ----------------------------------------------------------------------------------------------
def _check_measured(b):
    assert np.all(np.isfinite(b.values)) and b.values.min() >= 0 and b.values.max() <= MAX_BRDF_VALUE
    assert b.valid.reshape(-1, 3).any(axis=0).all()


def test_fuzz_merl(tmp_path):
    rng = np.random.default_rng(22)
    stored = rng.uniform(0.0, 50.0, (3,) + MERL_SHAPE)
    data = np.asarray(MERL_SHAPE, "<i4").tobytes() + stored.astype("<f8").tobytes()
    blobs = truncations(data, 24, seed=1, header=12)
    blobs += bit_flips(data, 8, seed=2, flips=2, region=(0, 12))          # the header
    # the data: flips in the high bytes of the doubles (sign and exponent: NaN, inf, huge, negative)
    for k in range(8):
        b = bytearray(data)
        for pos in rng.integers(0, 3 * int(np.prod(MERL_SHAPE)), 3):
            b[12 + 8 * int(pos) + 7] ^= 1 << int(rng.integers(4, 8))
        blobs.append(bytes(b))
    outcomes = _run(tmp_path, ".binary", blobs, read_merl, _check_measured)
    assert outcomes.count("refused") >= 24 and len(outcomes) == 40


def test_fuzz_rgl(tmp_path):
    data = data_file("rgl/paper_white_rgb.bsdf").read_bytes()
    blobs = truncations(data, 40, seed=3, header=600)
    blobs += bit_flips(data, 30, seed=4, flips=2, region=(0, 600))       # field table
    blobs += bit_flips(data, 30, seed=5, flips=4)                        # anywhere

    def check(b):
        w = np.array([[0.3, 0.1, 0.95], [0.0, 0.6, 0.8]])
        v = b.evaluate(w / np.linalg.norm(w, axis=1, keepdims=True), np.array([0.1, -0.2, 0.97]))
        assert np.all(np.isfinite(v)) and v.min() >= 0

    outcomes = _run(tmp_path, ".bsdf", blobs, read_rgl, check)
    assert outcomes.count("refused") >= 40


# ----------------------------------------------------------------------------------------------
def _check_model(m):
    rng = np.random.default_rng(0)
    x = rng.uniform([-0.5, -0.5], [2.5, 2.5], size=(400, 2))          # inside and outside the box
    v = m(x)
    assert np.all(np.isfinite(v)) and v.min() >= 0


def test_fuzz_rational_json(tmp_path):
    from fit.rational.coefficient_file import load

    base = small_rational_dict()
    text = json.dumps(base, indent=1)
    blobs = [t.decode("utf-8", "replace") for t in truncations(text.encode(), 30, seed=6)]
    blobs += bit_flips(text.encode(), 30, seed=7, flips=1)
    blobs += [json.dumps(d) for d in json_mutations(base, 120, seed=8)]
    blobs += [json.dumps(d) for d in json_mutations(small_rational_dict(False), 40, seed=9)]
    outcomes = _run(tmp_path, ".json", blobs, load, _check_model)
    assert outcomes.count("refused") >= 100 and outcomes.count("ok") >= 5


def test_fuzz_cdf_json(tmp_path):
    from fit.sampling.cdf_file import load

    base = small_cdf_dict()
    text = json.dumps(base)

    def check(fit):
        rng = np.random.default_rng(1)
        tv, mu, tau = rng.uniform(0, 1.5, 200), rng.random(200), rng.random(200)
        tl, pl, pdf = fit.table.sample(tv, mu, tau)
        assert np.all(np.isfinite(tl)) and np.all(np.isfinite(pl)) and np.all(pdf > 0)
        if not fit.fallback:
            tl, pl, alpha = fit.sample(tv, mu, tau)
            assert np.all(np.isfinite(tl)) and np.all(np.isfinite(alpha)) and np.all(alpha >= 0)

    blobs = [t.decode("utf-8", "replace") for t in truncations(text.encode(), 20, seed=10)]
    blobs += bit_flips(text.encode(), 20, seed=11, flips=1)
    blobs += [json.dumps(d) for d in json_mutations(base, 100, seed=12)]
    outcomes = _run(tmp_path, ".json", blobs, load, check)
    assert outcomes.count("refused") >= 80 and outcomes.count("ok") >= 5


# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def npz_bytes(tmp_path_factory):
    from lab.analytic import glossy_lobe
    from fit.formats.measured import MeasuredBRDF
    from fit.projection.project import project

    p = tmp_path_factory.mktemp("npz") / "p.npz"
    project(MeasuredBRDF.from_function(glossy_lobe()), grazing_cutoff_deg=80.0).save(p)
    return p.read_bytes()


def test_fuzz_npz(tmp_path, npz_bytes):
    from fit.projection.projected import ProjectedBRDF

    def check(p):
        full = p.count > 0
        for a in (p.value, p.median, p.mean, p.variance):
            assert np.all(np.isfinite(a[full])) and a[full].min() >= 0 and np.all(np.isnan(a[~full]))

    blobs = truncations(npz_bytes, 20, seed=13) + bit_flips(npz_bytes, 30, seed=14, flips=2)
    outcomes = _run(tmp_path, ".npz", blobs, ProjectedBRDF.load, check)
    assert outcomes.count("refused") >= 20
