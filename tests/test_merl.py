"""MERL .binary reader/writer: exact layout, lookup conventions, reciprocity, bad files."""
import os

import numpy as np
import pytest

from lab.analytic import glossy_lobe, lambert
from fit.errors import BRDFFileError
from fit.formats.angles import half_diff_to_directions, spherical_to_direction
from fit.formats.grid import (MERL_SHAPE, phi_d_centres, phi_d_index, theta_d_centres, theta_d_index,
                              theta_h_centres, theta_h_index)
from fit.formats.measured import MeasuredBRDF
from fit.formats.merl import MERL_FILE_BYTES, MERL_SCALE, read_merl, write_merl


@pytest.fixture(scope="module")
def glossy_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("merl") / "glossy.binary"
    write_merl(MeasuredBRDF.from_function(glossy_lobe(phi_mod=0.3), name="glossy"), path)
    return path


def test_index_conventions():
    # Bin edges exactly as the MERL format defines them.
    assert theta_h_index(0.0) == 0
    assert theta_h_index((1 / 90) ** 2 * np.pi / 2 * 1.0001) == 1
    assert theta_h_index(np.pi / 2) == 89 and theta_h_index(3.0) == 89
    assert theta_d_index(np.pi / 180 * 0.9999) == 0 and theta_d_index(np.pi / 180 * 1.0001) == 1
    assert theta_d_index(np.pi) == 89
    assert phi_d_index(0.0) == 0 and phi_d_index(np.pi * 1.0001) == 0  # folded by reciprocity
    assert phi_d_index(-np.pi / 180 * 0.5) == 179
    for centres, index in ((theta_h_centres(), theta_h_index), (theta_d_centres(), theta_d_index),
                           (phi_d_centres(), phi_d_index)):
        np.testing.assert_array_equal(index(centres), np.arange(centres.size))


def test_exact_byte_layout(tmp_path):
    f = glossy_lobe(phi_mod=0.3)
    b = MeasuredBRDF.from_function(f)
    path = tmp_path / "x.binary"
    write_merl(b, path)
    assert os.path.getsize(path) == MERL_FILE_BYTES == 12 + 3 * 8 * 90 * 90 * 180
    raw = np.fromfile(path, dtype="<f8", offset=12)
    assert tuple(np.fromfile(path, dtype="<i4", count=3)) == (90, 90, 180)
    n = 90 * 90 * 180
    for (i, j, k) in [(0, 0, 0), (3, 40, 17), (10, 20, 179), (60, 5, 90)]:
        wi, wo = half_diff_to_directions(theta_h_centres()[i], 0.0, theta_d_centres()[j], phi_d_centres()[k])
        expected = f(wi, wo)
        for c in range(3):
            stored = raw[c * n + (i * 90 + j) * 180 + k]  # phi_d fastest, then theta_d, then theta_h
            if wi[2] > 0 and wo[2] > 0:
                assert stored == pytest.approx(expected[c] / MERL_SCALE[c], rel=1e-12)
            else:
                assert stored < 0


def test_round_trip(tmp_path, glossy_file):
    b = read_merl(glossy_file)
    path = tmp_path / "again.binary"
    write_merl(b, path)
    b2 = read_merl(path)
    np.testing.assert_array_equal(b.valid, b2.valid)
    np.testing.assert_allclose(b.values, b2.values, rtol=1e-14)
    assert b.name == "glossy" and len(b.source_sha256) == 64


def test_lambert_lookup_everywhere(tmp_path):
    path = tmp_path / "lambert.binary"
    write_merl(MeasuredBRDF.from_function(lambert((0.8, 0.5, 0.2))), path)
    b = read_merl(path)
    rng = np.random.default_rng(0)
    wi = spherical_to_direction(rng.uniform(0, 1.5, 2000), rng.uniform(-np.pi, np.pi, 2000))
    wo = spherical_to_direction(rng.uniform(0, 1.5, 2000), rng.uniform(-np.pi, np.pi, 2000))
    v = b.evaluate(wi, wo)
    # Every measured (above-horizon) bin reached by a valid pair holds albedo / pi.
    np.testing.assert_allclose(v, np.broadcast_to(np.array([0.8, 0.5, 0.2]) / np.pi, v.shape), rtol=1e-12)
    # Below the horizon: zero.
    below = b.evaluate(spherical_to_direction(2.0, 0.0), spherical_to_direction(0.3, 0.0))
    np.testing.assert_array_equal(below, 0.0)


def test_glossy_lookup_equals_analytic_at_bin_centres(glossy_file):
    b = read_merl(glossy_file)
    f = glossy_lobe(phi_mod=0.3)
    rng = np.random.default_rng(2)
    i = rng.integers(0, 90, 500)
    j = rng.integers(0, 90, 500)
    k = rng.integers(0, 180, 500)
    ph = rng.uniform(-np.pi, np.pi, 500)  # isotropy: any phi_h
    wi, wo = half_diff_to_directions(theta_h_centres()[i], ph, theta_d_centres()[j], phi_d_centres()[k])
    ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    assert ok.sum() > 200
    np.testing.assert_allclose(b.evaluate(wi, wo)[ok], f(wi, wo)[ok], rtol=1e-9)


def test_reciprocity(glossy_file):
    b = read_merl(glossy_file)
    rng = np.random.default_rng(3)
    wi = spherical_to_direction(rng.uniform(0, np.pi / 2, 5000), rng.uniform(-np.pi, np.pi, 5000))
    wo = spherical_to_direction(rng.uniform(0, np.pi / 2, 5000), rng.uniform(-np.pi, np.pi, 5000))
    np.testing.assert_array_equal(b.evaluate(wi, wo, "nearest"), b.evaluate(wo, wi, "nearest"))
    # trilinear: phi_d and phi_d + pi are the same coordinate, up to rounding
    np.testing.assert_allclose(b.evaluate(wi, wo), b.evaluate(wo, wi), rtol=1e-12, atol=1e-15)


def _write_raw(path, header=(90, 90, 180), values=None, extra=b""):
    if values is None:
        values = np.ones(3 * int(np.prod(MERL_SHAPE)))
    with open(path, "wb") as f:
        f.write(np.asarray(header, "<i4").tobytes())
        f.write(np.asarray(values, "<f8").tobytes())
        f.write(extra)


@pytest.mark.parametrize("case, message", [
    ("header", "wrong MERL header"),
    ("short-header", "truncated"),
    ("truncated", "truncated MERL file"),
    ("oversized", "oversized MERL file"),
    ("nan", "NaN/inf"),
    ("inf", "NaN/inf"),
    ("missing", "file not found"),
    ("directory", "is a directory"),
])
def test_bad_files(tmp_path, case, message):
    path = tmp_path / f"{case}.binary"
    n = 3 * int(np.prod(MERL_SHAPE))
    if case == "header":
        _write_raw(path, header=(90, 90, 360))
    elif case == "short-header":
        path.write_bytes(b"\x5a\x00\x00")
    elif case == "truncated":
        _write_raw(path, values=np.ones(n - 1))
    elif case == "oversized":
        _write_raw(path, extra=b"\0" * 8)
    elif case in ("nan", "inf"):
        v = np.ones(n)
        v[n // 2] = np.nan if case == "nan" else np.inf
        _write_raw(path, values=v)
    elif case == "directory":
        path.mkdir()
    with pytest.raises(BRDFFileError) as e:
        read_merl(path)
    assert str(path) in str(e.value) and message in str(e.value)
    assert "\n" not in str(e.value)


def test_writer_rejects_bad_values(tmp_path):
    b = MeasuredBRDF.from_function(lambert())
    b.values[0, 0, 0, 0] = -0.5
    with pytest.raises(ValueError):
        write_merl(b, tmp_path / "neg.binary")
