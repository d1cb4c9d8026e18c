"""Spectral RGL ``.bsdf`` output (``rbrdf-fit convert IN OUT.bsdf --spectral``): the RGB ->
spectrum upsampling (:mod:`fit.convert.spectral`), the file's fields against what pbrt-v4's
reader requires, the file in Mitsuba 3's ``scalar_spectral`` ``measured`` plugin (in a
subprocess: this process may hold another variant), and the command line's errors.

Measured at the time of writing (vch_golden_yellow_rgb.bsdf converted at 6 x (32 x 32 vndf,
24 x 24 nodes), 48 wavelengths; 300 pairs, seed 3, both directions within 80 deg; Mitsuba's
spectral eval at 360, 365, ..., 830 nm projected to linear sRGB under D65): Mitsuba against our
reader of the same file and against the RGB conversion at the same sizes, at most 4.3e-6 of the
pair's largest channel (float32), ΔE2000 at most 9.4e-5 over the 119 pairs above 1e-3 of the
peak; against the source file (what the parameterization at these small sizes loses, the same
for the RGB file): mean colour over the pairs ΔE2000 0.53, channel means x 0.997, 1.007, 1.037.
The upsampling alone (:func:`fit.convert.spectral.round_trip`) keeps every node's sRGB within
2e-7 of its largest channel (ΔE2000 < 1e-4) on the 20 RGL-EPFL materials and the sRGB cube.

Locally the Mitsuba and colour-science parts skip when those packages are missing; under CI
(``CI=true``) that is a failure.
"""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import data_file, missing

from fit.cli import main as cli_main
from fit.convert import convert
from fit.convert import spectral as sp
from fit.convert.summary import random_pairs
from fit.formats.rgl import read_rgl
from fit.formats.tensor_file import MAGIC, read_tensor_file

SIZES = {"n_theta_i": 6, "n_vndf": 32, "n_rgb": 24, "n_ndf": 32}
SOURCE = "rgl/vch_golden_yellow_rgb.bsdf"


def _need(module: str):
    try:
        return __import__(module)
    except ImportError:
        missing(f"{module} is not installed (the test extra installs it)")


def _delta_e2000(a, b):
    """CIE ΔE2000 between linear-sRGB colours ``a`` and ``b`` (..., 3) (colour-science)."""
    colour = _need("colour")

    def lab(c):
        return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(np.clip(c, 0, None), apply_cctf_decoding=False))

    return colour.delta_E(lab(a), lab(b), method="CIE 2000")


@pytest.fixture(scope="module")
def spectral_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("spectral") / "yellow.bsdf"
    summary = convert(data_file(SOURCE), out, n_pairs=0, n_wavelengths=sp.DEFAULT_N_WAVELENGTHS, **SIZES)
    return out, summary


# -- the upsampling -----------------------------------------------------------------------------
def test_projection_matches_colour_science():
    """The embedded CIE tables against colour-science's: a smooth test spectrum's sRGB (D65,
    CIE 1931 2 deg, 1 nm) agrees to 1e-3, and a constant spectrum is white."""
    colour = _need("colour")
    lam = np.arange(360, 831, 1.0)
    s = 0.3 + 0.5 * np.exp(-0.5 * ((lam - 600) / 40) ** 2)
    ours = sp.projection(lam) @ s
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    sd = colour.SpectralDistribution(dict(zip(lam, s)))
    ill = colour.SDS_ILLUMINANTS["D65"]
    xyz = colour.sd_to_XYZ(sd, cmfs, ill, method="Integration", shape=colour.SpectralShape(360, 830, 1)) / 100
    ref = colour.XYZ_to_sRGB(xyz, apply_cctf_encoding=False)
    assert np.abs(ours - ref).max() < 1e-3, (ours, ref)
    assert np.allclose(sp.projection(sp.default_wavelengths()) @ np.ones(sp.DEFAULT_N_WAVELENGTHS), 1.0)


def test_upsampling_keeps_the_colour():
    rng = np.random.default_rng(1)
    prim = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1], [1, 0, 1], [1, 1, 1]], float)
    rgb = np.concatenate([rng.random((3000, 3)) ** 2 * rng.uniform(0.01, 30, (3000, 1)), prim])
    wl = sp.default_wavelengths()
    s = sp.upsample(rgb, wl)
    assert s.shape == (len(rgb), wl.size)
    assert s.min() >= 0 and np.all(s.max(axis=1) <= 2 * rgb.max(axis=1) + 1e-12)
    trip = sp.round_trip(rgb, s, wl)
    assert trip.n > 0.99 * len(rgb) and trip.rel_max < 1e-5, trip.describe()
    m = rgb.max(axis=1, keepdims=True)
    assert _delta_e2000(rgb / m, sp.to_rgb(s, wl) / m).max() < 1e-3
    # smooth: a sigmoid of a quadratic has at most one interior peak/valley over the range
    d = np.sign(np.diff(s[:-len(prim)], axis=1))
    assert np.all(np.sum(np.abs(np.diff(d, axis=1)) > 0, axis=1) <= 2)
    assert np.all(sp.upsample(np.zeros((2, 3)), wl) == 0)


def test_upsampling_the_nodes_of_a_measured_material():
    b = read_rgl(data_file(SOURCE))
    rgb = np.moveaxis(b.rgb, 1, -1)[::2, ::2, ::2].reshape(-1, 3)
    wl = sp.default_wavelengths()
    s = sp.upsample(rgb, wl)
    m = rgb.max(axis=1)
    keep = m > 1e-3 * m.max()
    assert sp.round_trip(rgb, s, wl).rel_max < 1e-5
    assert _delta_e2000(rgb[keep] / m[keep, None], sp.to_rgb(s[keep], wl) / m[keep, None]).max() < 1e-3


# -- the file against pbrt-v4's reader ------------------------------------------------------------
def test_spectral_file_has_what_pbrt_v4_requires(spectral_file):
    """The requirements of pbrt-v4's reader (github.com/mmp/pbrt-v4, commit 5f7a6068,
    src/pbrt/bxdfs.cpp): ``Tensor::Tensor`` (lines 745-818) checks the 12-byte magic
    "tensor_file\\0" and file version 1.0 (765-768); ``Tensor::field`` CHECK-fails on a missing
    field (819-823); ``MeasuredBxDFData::Create`` (889-988) reads theta_i, phi_i, ndf, sigma,
    vndf, spectra, luminance, wavelengths, description, jacobian (891-900) and requires
    (902-932): description 1-D uint8; theta_i, phi_i, wavelengths 1-D float32; ndf, sigma 2-D
    float32; vndf 4-D float32 with shape[0] = |phi_i|, shape[1] = |theta_i|; luminance 4-D float32
    (|phi_i|, |theta_i|, n, n); spectra 5-D float32 (|phi_i|, |theta_i|, |wavelengths|, n, n)
    with n that of luminance; jacobian 1 uint8. Isotropic when |phi_i| <= 2 (938).
    ``MeasuredBxDF::f`` (999-1034) always multiplies by ndf / (4 sigma cos) (the ``jacobian``
    flag is not read: the file must hold 1) and looks the spectra up at the sampled
    wavelengths, 360-830 nm (src/pbrt/util/spectrum.h, Lambda_min/Lambda_max), with
    ``PiecewiseLinear2D<3>`` over (phi_i, theta_i, wavelengths): increasing axes (its
    ``FindInterval``), clamped outside (src/pbrt/util/sampling.h, 1664-1672)."""
    out, summary = spectral_file
    raw = out.read_bytes()
    assert raw[:12] == MAGIC == b"tensor_file\x00" and raw[12:14] == bytes([1, 0])
    f = read_tensor_file(out)
    u8, f32 = 1, 10                                           # pbrt-v4's Tensor::Type codes
    need = ["theta_i", "phi_i", "ndf", "sigma", "vndf", "spectra", "luminance", "wavelengths",
            "description", "jacobian"]
    assert all(k in f for k in need), sorted(f)
    shape = {k: tuple(int(s) for s in f[k].shape) for k in need}
    code = {k: f[k].dtype_code for k in need}
    assert code["description"] == u8 and len(shape["description"]) == 1
    for k in ("theta_i", "phi_i", "wavelengths"):
        assert code[k] == f32 and len(shape[k]) == 1, k
    for k in ("ndf", "sigma"):
        assert code[k] == f32 and len(shape[k]) == 2, k
    n_phi, n_theta, n_wl = shape["phi_i"][0], shape["theta_i"][0], shape["wavelengths"][0]
    assert n_phi <= 2                                         # isotropic
    assert code["vndf"] == f32 and len(shape["vndf"]) == 4 and shape["vndf"][:2] == (n_phi, n_theta)
    lum, spec = shape["luminance"], shape["spectra"]
    assert code["luminance"] == f32 and len(lum) == 4 and lum[:2] == (n_phi, n_theta) and lum[2] == lum[3]
    assert code["spectra"] == f32 and len(spec) == 5 and spec[:3] == (n_phi, n_theta, n_wl)
    assert spec[3] == spec[4] == lum[2] == lum[3]
    assert code["jacobian"] == u8 and shape["jacobian"] == (1,) and int(f["jacobian"].data[0]) == 1
    wl = np.asarray(f["wavelengths"].data, np.float64)
    assert np.all(np.diff(wl) > 0) and wl[0] <= 360 and wl[-1] >= 830
    assert np.all(np.diff(np.asarray(f["theta_i"].data, np.float64)) > 0)
    spectra = np.asarray(f["spectra"].data, np.float64).reshape(spec)
    assert np.isfinite(spectra).all() and spectra.min() >= 0        # pbrt clamps negatives at 0
    # the rgb kept beside them is the spectra's sRGB (our reader, the RGB tools)
    rgb = np.asarray(f["rgb"].data, np.float64).reshape(f["rgb"].shape)
    back = np.maximum(sp.to_rgb(np.moveaxis(spectra, 2, -1), wl), 0)
    assert np.abs(np.moveaxis(back, -1, 2) - rgb).max() <= 1e-5 * rgb.max()
    assert summary.build.round_trip.rel_max < 1e-5
    assert "spectral: 48 wavelengths 360-830 nm" in str(summary)


# -- the file in Mitsuba 3 (scalar_spectral) ------------------------------------------------------
_MITSUBA_SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    import mitsuba as mi
    mi.set_variant("scalar_spectral")
    a = np.load(sys.argv[1])
    bsdf = mi.load_dict({"type": "measured", "filename": sys.argv[2]})
    ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    lam = a["lam"]
    out = np.zeros((len(a["view"]), lam.size))
    for k in range(len(a["view"])):
        si.wi = mi.Vector3f(a["view"][k])
        wo = mi.Vector3f(a["light"][k])
        for j in range(0, lam.size, 4):
            si.wavelengths = mi.Spectrum([float(x) for x in np.resize(lam[j:j + 4], 4)])
            v = bsdf.eval(ctx, si, wo)
            n = min(4, lam.size - j)
            out[k, j:j + n] = [v[i] for i in range(n)]
    np.save(sys.argv[3], out)
    print(json.dumps({"variant": mi.variant(), "version": mi.__version__}))
""")


def _mitsuba_spectral_eval(tmp_path, path, view, light, lam):
    """Mitsuba's ``measured`` eval (``f cos(theta_light)``) at ``lam`` (nm) per pair, (n, L)."""
    _need("mitsuba")
    np.savez(tmp_path / "pairs.npz", view=view, light=light, lam=lam)
    script = tmp_path / "mi_eval.py"
    script.write_text(_MITSUBA_SCRIPT)
    res = subprocess.run([sys.executable, str(script), str(tmp_path / "pairs.npz"), str(path),
                          str(tmp_path / "out.npy")], check=False, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    assert json.loads(res.stdout.strip().splitlines()[-1])["variant"] == "scalar_spectral"
    return np.load(tmp_path / "out.npy")


def test_spectral_file_in_mitsuba(spectral_file, tmp_path):
    out, _ = spectral_file
    rgb_file = tmp_path / "rgb.bsdf"                  # the RGB conversion at the same sizes
    convert(data_file(SOURCE), rgb_file, n_pairs=0, **SIZES)
    light, view = random_pairs(300, seed=3, max_theta_deg=80.0)
    lam = np.arange(360.0, 830.5, 5.0)            # the 10 nm nodes are on this grid: exact projection
    values = _mitsuba_spectral_eval(tmp_path, out, view, light, lam)
    assert np.isfinite(values).all() and values.min() >= 0
    mi_rgb = sp.to_rgb(values, lam) / light[:, 2:3]                    # rho, linear sRGB under D65
    ours = read_rgl(out).evaluate(light, view)                       # the file's rgb, our reader
    rgb = read_rgl(rgb_file).evaluate(light, view)
    src = read_rgl(data_file(SOURCE)).evaluate(light, view)
    scale = ours.max(axis=1)
    # Mitsuba's spectral evaluation is the layout we wrote (float32 rounding only)
    assert np.all(np.abs(mi_rgb - ours).max(axis=1) <= 1e-4 * scale + 1e-7 * scale.max())
    # the spectral file shows the colours of the RGB conversion: the upsampling loses nothing
    assert np.all(np.abs(mi_rgb - rgb).max(axis=1) <= 1e-4 * scale + 1e-7 * scale.max())
    bright = src.max(axis=1) > 1e-3 * src.max()
    m = rgb[bright].max(axis=1, keepdims=True)
    assert _delta_e2000(mi_rgb[bright] / m, rgb[bright] / m).max() < 1e-2
    # against the source: the parameterization at these small sizes (the RGB file the same)
    ratio = mi_rgb.mean(axis=0) / src.mean(axis=0)
    assert np.all(np.abs(ratio - 1) < 0.06), ratio
    m = src.mean(axis=0).max()
    de = float(_delta_e2000(mi_rgb.mean(axis=0) / m, src.mean(axis=0) / m))
    de_rgb = float(_delta_e2000(rgb.mean(axis=0) / m, src.mean(axis=0) / m))
    assert de < 1.5 and abs(de - de_rgb) < 1e-3, (de, de_rgb, ratio)


# -- the command line -----------------------------------------------------------------------------
@pytest.mark.parametrize("args, needle", [
    (["--n-wavelengths", "20"], "--n-wavelengths: only applies to a spectral output"),
    (["--spectral", "--n-wavelengths", "5"], "argument --n-wavelengths: 5 is outside [16, 471]"),
    (["--spectral", "--n-wavelengths", "x"], "argument --n-wavelengths: expected an integer"),
    (["--spectral", "--n-wavelengths", "471", "--n-rgb", "128"], "--n-wavelengths: the tables would hold"),
])
def test_cli_flag_errors(args, needle, tmp_path, capsys):
    out = tmp_path / "o.bsdf"
    assert cli_main(["convert", str(data_file(SOURCE)), str(out), *args]) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_cli_spectral_to_merl_is_refused(tmp_path, capsys):
    out = tmp_path / "o.binary"
    assert cli_main(["convert", str(data_file(SOURCE)), str(out), "--spectral"]) == 2
    err = capsys.readouterr().err
    assert "--spectral: a spectral output needs a .bsdf file" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


def test_cli_spectral_writes_the_file(tmp_path, capsys):
    out = tmp_path / "o.bsdf"
    code = cli_main(["convert", str(data_file(SOURCE)), str(out), "--spectral", "--n-wavelengths", "24",
                     "--theta-i", "4", "--n-vndf", "16", "--n-rgb", "8", "--n-ndf", "16", "--pairs", "200"])
    assert code == 0
    text = capsys.readouterr().out
    assert "spectral: 24 wavelengths 360-830 nm" in text and "round trip" in text
    f = read_tensor_file(out)
    assert tuple(f["spectra"].shape) == (1, 4, 24, 8, 8) and tuple(f["wavelengths"].shape) == (24,)
