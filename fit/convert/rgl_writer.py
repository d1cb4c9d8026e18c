"""Any :class:`fit.convert.source.Source` as an RGL-EPFL ``.bsdf`` tensor file: the format's
adaptive parameterization (Dupuy & Jakob 2018, "An adaptive parameterization for efficient
material acquisition and rendering"), built from the source's values so that Mitsuba 3's
``measured`` plugin and :mod:`fit.formats.rgl` read and evaluate it, and, written spectral
(step 7, ``n_wavelengths``), pbrt-v4's ``MeasuredBxDF`` and Mitsuba's spectral variants.

Roles: the tensors are indexed by the incident direction ``wt`` of the reference
implementations, the direction towards the **viewer** (:mod:`fit.formats.rgl`); the other
direction ``wx`` is the light. A node of the tables stores the source's
``f(light=wx, view=wt)``, so an RGL source keeps its own (non-reciprocal) roles.

Construction (angles in radians; ``u = sqrt(2 theta / pi)`` is the tables' polar coordinate):

1. **NDF** ``D(theta_m)`` from the retro-reflection ``R(theta) = Y(f(w, w))`` (Rec.709
   luminance, ``w`` at polar angle ``theta``) by power iteration (Dupuy & Jakob, section 4):
   a microfacet BRDF at retro-reflection is ``D(w) / (4 sigma(w) cos theta)`` up to Fresnel,
   so ``D <- R cos(theta) sigma[D]``, normalized to ``int D(m) cos(theta_m) dm = 1``, starting
   from ``D = R cos^2 theta`` (``sigma = cos``), ``power_iterations`` times. ``D`` is floored
   at 1e-6 of its maximum (the rgb table divides by it).
2. **sigma** ``(theta) = int D(m) max(0, w . m) dm``, the projected area of the microsurface
   (midpoint quadrature, 256 x 128 over the upper hemisphere, D interpolated linearly in u).
   ``ndf`` and ``sigma`` are ``(2, n_ndf)`` tables over (phi, u) with equal rows (isotropic).
3. **VNDF warp**: ``vndf[0, k, y, x]`` is the density of visible normals
   ``D(m) max(0, wt . m) / sigma(theta_k)`` at ``theta_m = u_x^2 pi/2``,
   ``phi_m - phi_t = (2 u_y - 1) pi`` (``u_x = x / (n_vndf - 1)``, ``u_y = y / (n_vndf - 1)``),
   times the Jacobian ``2 pi^2 u_x sin theta_m`` of the unit square; readers build its
   marginal/conditional CDFs per ``theta_i`` slice (:class:`fit.formats.rgl_interpolants.VNDFWarp`).
4. **rgb** on the warped grid: node ``s = (x, y) / (n_rgb - 1)`` of slice ``k`` is mapped by
   the forward VNDF warp (the readers' own, from the float32 tables) to ``m``, ``wx`` is ``wt``
   reflected about ``m``, and the node stores ``f(wx, wt) cos(theta_x) 4 sigma(u_t) / ndf(u_m)``
   with ``sigma`` and ``ndf`` interpolated as the readers do (``jacobian`` flag 1): the
   readers' ``eval`` returns exactly the source's ``f cos(theta_x)`` at every node.
   Nodes whose ``wx`` is at or below the horizon take the value of the nearest node of their
   slice that is above it (a continuation: ``1 / ndf`` explodes towards theta_m = 90 deg, and
   a lifted evaluation there put spikes of 60x into the cells next to them); the 90 deg
   slice, whose ``wt`` is on the horizon, is evaluated with ``wt`` lifted to ``cos = 1e-3``.
   (``jacobian = 0`` -- rgb = ``f cos`` itself -- was measured too and interpolates worse:
   RMS 1.3 against 0.06 on a Blinn-Phong lobe of exponent 80 at 32 x 32 nodes.)
5. **luminance** ``= max(Y(rgb), 1e-6 max)`` on the same grid: the luminance warp of the
   readers' importance sampling then has the pdf ``Y(f cos(theta_x)) / ...`` at the nodes
   (``pdf(wx) = lum(s) D / (4 sigma)`` after the VNDF warp and the reflection).
6. **valid**: bit-packed (``numpy.packbits``, most significant bit first) over
   ``(n_theta_i, n_rgb, n_rgb)``, C order; a bit is **set where the node's reflected direction
   is at or below the horizon**. That is what the field holds in the RGL-EPFL files (checked
   bit for bit against ``satin_rosaline_rgb.bsdf``); no reader uses it.
7. **spectra** (``n_wavelengths`` given: a *spectral* file, the only kind pbrt-v4 reads):
   every rgb node is upsampled to a smooth non-negative reflectance spectrum at
   ``wavelengths`` (nm, float32, uniform over [360, 830]) by :mod:`fit.convert.spectral`, stored
   as ``spectra`` ``(1, n_theta_i, n_wavelengths, n_rgb, n_rgb)`` float32 (the layout of the
   RGL-EPFL spectral files: the ``rgb`` layout with the wavelengths in place of the channels).
   ``rgb`` is then kept as the linear sRGB of the stored spectra (what a spectral renderer shows
   under a D65 white; readers of spectral files ignore it, our reader :mod:`fit.formats.rgl`
   uses it), and ``luminance`` is its luminance. Mitsuba 3 reads a file with ``wavelengths``
   as spectral in its spectral variants only; pbrt-v4 requires ``spectra`` and ``wavelengths``.
8. ``theta_i``: ``n_theta_i`` angles uniform in [0, 90] deg (the last one the float32 just
   below pi/2, as the files store it); ``phi_i = [0]``; ``jacobian = [1]``; ``description``:
   UTF-8 text; ``version = [1, 0]`` (uint32, as in the files). Every float field is float32
   (Mitsuba 3 requires it).

Sizes (the RGL-EPFL files: 8 x (128 x 128 vndf, 32 x 32 rgb), ndf 128): ``n_theta_i``
slices, ``n_vndf`` x ``n_vndf`` VNDF densities, ``n_rgb`` x ``n_rgb`` rgb and luminance nodes,
``n_ndf`` ndf and sigma columns.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import BRDFFileError, FlagError
from ..formats.angles import HALF_PI
from ..formats.colour import LUMINANCE
from ..formats.rgl import GRAZING_Z, _lift
from ..formats.rgl_interpolants import Bilinear, VNDFWarp, interval
from ..limits import MAX_RGL_ELEMENTS, MAX_RGL_FIELD_ABS, MIN_RGL_SIGMA
from .source import Source

#: Default sizes: more theta_i slices (8) and rgb nodes (32 x 32) than the RGL-EPFL files,
#: their VNDF and NDF sizes.
DEFAULT_N_THETA_I = 16
DEFAULT_N_VNDF = 128
DEFAULT_N_RGB = 64
DEFAULT_N_NDF = 128
DEFAULT_POWER_ITERATIONS = 4
#: Lowest cos(theta) a direction is lifted to where it lies at or below the horizon (the
#: reader's :data:`fit.formats.rgl.GRAZING_Z`, same lift).
LIFT_Z = GRAZING_Z
#: Floor of the NDF, relative to its maximum (the rgb table divides by it).
NDF_FLOOR = 1e-6
_QUAD_THETA = 256
_QUAD_PHI = 128


@dataclass
class RGLBuild:
    """The fields of the file (``fields``: name -> array, in the files' order) and what the
    construction measured: ``n_below_horizon`` nodes (bits set in ``valid``), ``n_nodes``."""

    fields: dict
    n_nodes: int
    n_below_horizon: int
    #: spectral files: :class:`fit.convert.spectral.RoundTrip` of the stored spectra against the
    #: rgb nodes they were upsampled from (None for an RGB file)
    round_trip: object = None

    def describe(self) -> str:
        f = self.fields
        text = (f"RGL parameterization: {f['theta_i'].size} theta_i slices, vndf {f['vndf'].shape[2]} x "
                f"{f['vndf'].shape[3]}, rgb {f['rgb'].shape[3]} x {f['rgb'].shape[4]}, ndf/sigma "
                f"{f['ndf'].shape[1]}; {self.n_below_horizon} of {self.n_nodes} rgb nodes reflect below "
                "the horizon (marked in 'valid'; they hold the nearest node above it)")
        if "wavelengths" in f:
            wl = f["wavelengths"]
            text += (f"\n  spectral: {wl.size} wavelengths {float(wl[0]):g}-{float(wl[-1]):g} nm; "
                     f"{self.round_trip.describe()}")
        return text


def check_sizes(n_theta_i: int, n_vndf: int, n_rgb: int, n_ndf: int, n_wavelengths: int | None = None) -> None:
    """Refuse sizes whose tables would exceed :data:`fit.limits.MAX_RGL_ELEMENTS` (the readers
    refuse such files): one-line :class:`FlagError`. ``n_wavelengths``: a spectral file's
    ``spectra`` count too."""
    total = n_theta_i * (n_vndf * n_vndf + 4 * n_rgb * n_rgb) + 4 * n_ndf + n_theta_i + 1
    flags = "--n-vndf/--n-rgb/--theta-i"
    if n_wavelengths:
        total += n_theta_i * n_wavelengths * n_rgb * n_rgb + n_wavelengths
        flags += "/--n-wavelengths"
    if total > MAX_RGL_ELEMENTS:
        raise FlagError(flags, f"the tables would hold {total} values, above the "
                                                      f"readers' limit {MAX_RGL_ELEMENTS} "
                                                      "(fit.limits.MAX_RGL_ELEMENTS)")


def _polar(theta):
    return np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], axis=-1)


def _luminance(rgb):
    return np.asarray(rgb) @ LUMINANCE


def _u_to_theta(u):
    return np.square(u) * HALF_PI


def retro_reflection(source: Source, theta: np.ndarray) -> np.ndarray:
    """Luminance of ``f(w, w)`` (1/sr) at polar angles ``theta`` (radians), directions lifted
    above the horizon; clamped at 0."""
    w = _lift(_polar(theta))
    return np.maximum(_luminance(source.evaluate(w, w)), 0.0)


def _quadrature():
    tm = (np.arange(_QUAD_THETA) + 0.5) * (HALF_PI / _QUAD_THETA)
    pm = (np.arange(_QUAD_PHI) + 0.5) * (np.pi / _QUAD_PHI)
    dA = 2.0 * (HALF_PI / _QUAD_THETA) * (np.pi / _QUAD_PHI) * np.sin(tm)   # both phi halves
    return tm, pm, dA


def projected_area(d_nodes: np.ndarray, u_nodes: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """sigma(theta) = int D(m) max(0, w . m) dm for ``D`` given at ``u_nodes`` (linear in u)."""
    tm, pm, dA = _quadrature()
    d = np.interp(np.sqrt(tm / HALF_PI), u_nodes, d_nodes) * dA        # (T,)
    st, ct = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    dot = st * np.sin(tm)[None, :, None] * np.cos(pm)[None, None, :] + ct * np.cos(tm)[None, :, None]
    return np.einsum("t,itp->i", d, np.maximum(dot, 0.0))


def estimate_ndf(source: Source, n_ndf: int, power_iterations: int = DEFAULT_POWER_ITERATIONS):
    """``(u_nodes, D, sigma)`` at ``n_ndf`` nodes of u in [0, 1] (step 1-2 of the module
    docstring); ``D`` normalized so that ``int D cos = 1``."""
    u = np.linspace(0.0, 1.0, n_ndf)
    theta = _u_to_theta(u)
    retro = retro_reflection(source, theta)
    if not np.isfinite(retro).all() or retro.max() <= 0:
        retro = np.ones_like(retro)            # no retro-reflection at all: a uniform NDF
    retro = np.maximum(retro, 1e-6 * retro.max())
    cos = np.maximum(np.cos(theta), LIFT_Z)
    tm, _, dA = _quadrature()

    def normalized(d):
        d = np.maximum(d, NDF_FLOOR * d.max())
        total = np.sum(np.interp(np.sqrt(tm / HALF_PI), u, d) * np.cos(tm) * dA) * _QUAD_PHI
        return d / total

    d = normalized(retro * cos * cos)
    for _ in range(int(power_iterations)):
        sigma = projected_area(d, u, theta)
        d = normalized(retro * cos * sigma)
    sigma = projected_area(d, u, theta)
    return u, d, sigma


def _theta_i_axis(n: int) -> np.ndarray:
    t = np.linspace(0.0, HALF_PI, n).astype(np.float32)
    if float(t[-1]) > HALF_PI:
        t[-1] = np.nextafter(np.float32(HALF_PI), np.float32(0))
    return t


def _fill_below(rgb: np.ndarray, below: np.ndarray) -> np.ndarray:
    """``rgb`` (S, 3, n, n) with every node of ``below`` (S, n, n) replaced by the nearest node
    of its slice that is above the horizon (Euclidean distance on the grid)."""
    from scipy.ndimage import distance_transform_edt

    out = rgb.copy()
    for k in range(rgb.shape[0]):
        if below[k].any() and not below[k].all():
            _, (iy, ix) = distance_transform_edt(below[k], return_indices=True)
            out[k] = rgb[k][:, iy, ix]
    return out


def build_rgl(source: Source, n_theta_i: int = DEFAULT_N_THETA_I, n_vndf: int = DEFAULT_N_VNDF,
              n_rgb: int = DEFAULT_N_RGB, n_ndf: int = DEFAULT_N_NDF,
              power_iterations: int = DEFAULT_POWER_ITERATIONS, description: str | None = None,
              n_wavelengths: int | None = None) -> RGLBuild:
    """The tensor-file fields of ``source`` (module docstring); write them with
    :func:`fit.formats.tensor_file.write_tensor_file`. ``n_wavelengths`` (None: an RGB file)
    makes a spectral file (step 7)."""
    check_sizes(n_theta_i, n_vndf, n_rgb, n_ndf, n_wavelengths)
    u_nodes, d_nodes, sigma_nodes = estimate_ndf(source, n_ndf, power_iterations)
    ndf32 = np.repeat(d_nodes[None, :], 2, axis=0).astype(np.float32)
    sigma32 = np.repeat(sigma_nodes[None, :], 2, axis=0).astype(np.float32)
    theta_i32 = _theta_i_axis(n_theta_i)
    theta_i = theta_i32.astype(np.float64)

    # VNDF densities on the (u_x, u_y) grid of every theta_i slice
    ux = np.linspace(0.0, 1.0, n_vndf)
    uy = np.linspace(0.0, 1.0, n_vndf)
    tm = _u_to_theta(ux)[None, None, :]
    pm = ((2.0 * uy - 1.0) * np.pi)[None, :, None]
    ti = theta_i[:, None, None]
    dot = np.sin(ti) * np.sin(tm) * np.cos(pm) + np.cos(ti) * np.cos(tm)
    d_m = np.interp(ux, u_nodes, d_nodes)[None, None, :]
    sig_i = np.interp(np.sqrt(theta_i / HALF_PI), u_nodes, sigma_nodes)[:, None, None]
    vndf = 2.0 * np.pi ** 2 * ux[None, None, :] * np.sin(tm) * d_m * np.maximum(dot, 0.0) / sig_i
    vndf32 = vndf[None].astype(np.float32)

    # the readers' interpolants, from the float32 tables
    warp = VNDFWarp(vndf32[0].astype(np.float64), theta_i)
    ndf_i = Bilinear(ndf32.astype(np.float64))
    sigma_i = Bilinear(sigma32.astype(np.float64))

    # rgb on the warped grid
    s = np.linspace(0.0, 1.0, n_rgb)
    sy, sx = np.meshgrid(s, s, indexing="ij")
    sx, sy = sx.ravel(), sy.ravel()
    rgb = np.zeros((n_theta_i, 3, n_rgb, n_rgb))
    below = np.zeros((n_theta_i, n_rgb, n_rgb), bool)
    for k in range(n_theta_i):
        t0, w1 = interval(theta_i, np.full(sx.shape, theta_i[k]))
        um_x, um_y, _ = warp.sample(sx, sy, t0, w1)
        th_m = _u_to_theta(um_x)
        ph_m = (2.0 * um_y - 1.0) * np.pi
        m = np.stack([np.sin(th_m) * np.cos(ph_m), np.sin(th_m) * np.sin(ph_m), np.cos(th_m)], axis=-1)
        wt = np.broadcast_to(_polar(np.array(theta_i[k])), m.shape)
        wx = 2.0 * (m @ wt[0])[:, None] * m - wt
        below[k] = (wx[:, 2] <= 0.0).reshape(n_rgb, n_rgb)
        wx_l, wt_l = _lift(wx), _lift(wt)
        fcos = source.evaluate(wx_l, wt_l) * wx_l[:, 2:3]             # f(light=wx, view=wt) cos
        u_t = np.sqrt(np.full(sx.shape, theta_i[k]) / HALF_PI)
        scale = 4.0 * sigma_i.eval(u_t, np.zeros_like(u_t)) / ndf_i.eval(um_x, um_y)
        rgb[k] = (fcos * scale[:, None]).T.reshape(3, n_rgb, n_rgb)
    rgb = _fill_below(np.maximum(rgb, 0.0), below)
    spectral = {}
    trip = None
    if n_wavelengths:
        from . import spectral as sp

        wl32 = sp.default_wavelengths(n_wavelengths)
        rgb_nodes = np.moveaxis(rgb, 1, -1)                                       # (S, n, n, 3)
        spectra32 = sp.upsample(rgb_nodes, wl32).astype(np.float32)              # (S, n, n, N)
        trip = sp.round_trip(rgb_nodes, spectra32, wl32)
        rgb = np.moveaxis(np.maximum(sp.to_rgb(spectra32, wl32), 0.0), -1, 1)      # what they show
        spectral = {"wavelengths": wl32, "spectra": np.moveaxis(spectra32, -1, 1)[None]}
    lum = _luminance(np.moveaxis(rgb, 1, -1))
    top = lum.reshape(n_theta_i, -1).max(axis=1)
    top = np.where(top > 0, top, 1.0)[:, None, None]
    lum = np.maximum(lum, 1e-6 * top)

    for name, a in (("sigma", sigma32), ("ndf", ndf32), ("vndf", vndf32), ("rgb", rgb), ("luminance", lum),
                    *spectral.items()):
        if not np.all(np.isfinite(a)) or float(np.abs(a).max()) > MAX_RGL_FIELD_ABS:
            raise BRDFFileError(source.path or None, f"the RGL field {name!r} built from this source holds "
                                                     f"values that are not finite or above {MAX_RGL_FIELD_ABS:g} "
                                                     "(fit.limits.MAX_RGL_FIELD_ABS): the readers would refuse it")
    if float(sigma32.min()) < MIN_RGL_SIGMA:
        raise BRDFFileError(source.path or None, f"the projected area sigma of its NDF falls to "
                                                 f"{float(sigma32.min()):.3g} (readers need >= {MIN_RGL_SIGMA:g})")
    text = description if description is not None else (source.description or source.name)
    text = f"{text} (converted by rbrdf-fit convert from {source.kind})"
    fields = {
        "version": np.array([1, 0], np.uint32),
        "description": np.frombuffer(text.encode("utf-8")[:1000], np.uint8).copy(),
        "phi_i": np.zeros(1, np.float32),
        "theta_i": theta_i32,
        "sigma": sigma32,
        "ndf": ndf32,
        "vndf": vndf32,
        "luminance": lum[None].astype(np.float32),
        "rgb": rgb[None].astype(np.float32),
        **spectral,
        "jacobian": np.array([1], np.uint8),
        "valid": np.packbits(below.astype(np.uint8).ravel()),
    }
    return RGLBuild(fields, int(below.size), int(below.sum()), trip)
