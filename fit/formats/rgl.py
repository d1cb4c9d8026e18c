"""RGL-EPFL measured BRDFs (``.bsdf`` tensor files, Dupuy & Jakob 2018).

The RGL-EPFL material database stores each material in a *tensor file*: a small binary
container of named n-dimensional arrays (:mod:`fit.formats.tensor_file`). This module builds
the BRDF from its fields, validated defensively, and evaluates it with the semantics of the
authors' reference loader ("powitacq", rgl-epfl/brdf-loader, and Mitsuba's ``measured``
plugin), vectorized with NumPy (its interpolants: :mod:`fit.formats.rgl_interpolants`).

Fields of an isotropic RGB material: ``description`` (u8 text), ``phi_i`` (1), ``theta_i``
(n_theta, radians), ``ndf`` and ``sigma`` (2-D tables over (phi, sqrt-theta)), ``vndf``
(1, n_theta, ny, nx), ``luminance`` (1, n_theta, n, n), ``rgb`` (1, n_theta, 3, n, n),
``jacobian`` (u8 flag) and ``valid`` (bit-packed u8 mask, not used by the evaluation).

Roles of the two directions. The tensors are indexed by an *incident* direction ``wt`` (the
``theta_i`` axis) and tabulate the other direction ``wx`` through the VNDF warp. The reference
implementations look the tables up with the direction towards the **viewer** as ``wt``:
Mitsuba 3's ``measured`` plugin passes its ``si.wi`` (in radiance transport, the direction
towards the camera) and returns ``eval = value`` as ``f * cos(theta_wo)`` with ``wo`` the light;
pbrt-v4's ``MeasuredBxDF::f(wo, wi)`` maps its ``wo`` (towards the camera) and divides by
``|cos theta_wi|`` (the light). :class:`RGLBRDF` therefore defaults to ``incident="view"``;
``incident="light"`` swaps the roles (the gonio-photometer's physical illumination direction;
the films are not reciprocal, so the two differ by up to a factor 0.34-1.66 at grazing views).
docs/formats.md records the evidence.

Evaluation (what :meth:`RGLBRDF.reference_eval` computes) for ``wt`` (the tensors' incident
direction) and ``wx`` (the other one), both above the tangent plane:

1. ``wm = normalize(wt + wx)``; ``u_wt = (sqrt(2 theta_t / pi), (phi_t + pi) / 2pi)`` and
   ``u_wm = (sqrt(2 theta_m / pi), frac((phi_m - phi_t + pi) / 2pi))``.
2. The VNDF warp of the incidence ``theta_t`` (a marginal/conditional warp built from the
   ``vndf`` table, with its CDFs linearly interpolated between the two nearest ``theta_i``
   slices) is inverted at ``u_wm``: this gives the 2-D coordinate ``s`` in [0, 1]^2 of the
   ``rgb`` table. (The ``luminance`` warp is only used for importance sampling; the reference
   evaluation does not invert it, nor does this one.)
3. ``rgb`` is interpolated bilinearly at ``s`` and linearly in ``theta_t``.
4. If the ``jacobian`` flag is set, the value is multiplied by ``ndf(u_wm) / (4 sigma(u_wt))``
   (bilinear look-ups of the raw tables). The result is the reference's ``eval``:
   ``f_r * cos(theta_x)``.
5. rho = that value divided by ``cos(theta_x)`` (our convention: the BRDF *without* cosine);
   :meth:`RGLBRDF.evaluate` takes (light, view) and assigns ``wt``/``wx`` by ``incident``.

Negative ``rgb`` entries (measurement noise, down to about -0.04) are clamped to 0 when the
file is read (conventions.md). The reference loader (powitacq) clamps after interpolation;
Mitsuba 3's ``measured`` plugin does not clamp at all (its eval goes negative on 7 of the 20
shared files, down to -1.6 on chm_mint), so the parity tests give it clamped copies
(:func:`lab.mitsuba_reference.clamped_copy`).

Incidence beyond the last measured angle: these files store a last ``theta_i`` slice at
90 deg whose ``rgb`` is a copy of the previous (last measured) slice, e.g. 78.5 deg
(:attr:`RGLBRDF.theta_i_max`). Between ``theta_i_max`` and 90 deg the ``rgb`` values therefore
stay those of the last measured incidence at the same warped coordinate ``s`` (clamped
interpolation), while the VNDF warp, ``ndf`` and ``sigma`` continue to vary; the result is an
extrapolation, not a measurement.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import BRDFFileError
from ..limits import (
    MAX_RGL_ELEMENTS,
    MAX_RGL_FIELD_ABS,
    MAX_RGL_TABLE_SIDE,
    MAX_RGL_THETA_I,
    MIN_RGL_SIGMA,
)
from .angles import HALF_PI, half_diff_to_directions
from .grid import (
    FULL_SHAPE,
    N_PHI_D_FULL,
    phi_d_centres,
    theta_d_centres,
    theta_h_centres,
)
from .measured import MeasuredBRDF, check_values, file_sha256
from .rgl_interpolants import Bilinear, RGBTable, VNDFWarp, interval
from .tensor_file import read_tensor_file

#: Evaluation tables are built from these fields; the others are optional.
REQUIRED_FIELDS = ("description", "phi_i", "theta_i", "ndf", "sigma", "vndf", "luminance",
                   "rgb", "jacobian")
_CHUNK = 1 << 15


def _theta_to_u(theta):
    return np.sqrt(theta * (2.0 / np.pi))


def _elevation(v):
    return np.arctan2(np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1]), v[:, 2])


class RGLBRDF:
    """An isotropic RGB material of the RGL-EPFL database.

    Attributes
    ----------
    name, source, source_sha256, description : str
    theta_i : float64 (n_theta,)  incidence angles of the tables (radians)
    theta_i_max : float  last *measured* incidence (radians); trailing slices whose ``rgb``
        is an exact copy of the previous one (the 90 deg padding slice) are not counted.
    jacobian : bool  the file's flag; when set the ndf / (4 sigma) factor is applied.
    rgb : float64 (n_theta, 3, ny, nx)  the ``rgb`` tensor with negative values clamped to 0.
    n_negative_clamped : int  number of ``rgb`` entries that were negative in the file.
    valid_bits : uint8 array or None  the raw bit-packed ``valid`` field (not used here).
    fields : dict  every :class:`TensorField` of the file.
    incident : str  which direction of :meth:`evaluate` is the tensors' incident one:
        ``"view"`` (default, the reference implementations' roles) or ``"light"``.
    """

    INCIDENT_ROLES = ("view", "light")

    def __init__(self, fields: dict, path=None, name: str | None = None, sha256: str = "",
                 incident: str = "view"):
        if incident not in self.INCIDENT_ROLES:
            raise ValueError(f"incident must be one of {self.INCIDENT_ROLES}, got {incident!r}")
        self.incident = incident
        self.fields = fields
        self.source = str(path) if path is not None else ""
        self.name = name or (Path(path).stem if path is not None else "rgl")
        self.source_sha256 = sha256
        self._path = path
        self._validate_and_build()

    # -- validation -----------------------------------------------------------------------
    def _fail(self, problem):
        raise BRDFFileError(self._path, problem)

    def _float_field(self, name, ndim):
        f = self.fields[name]
        if f.dtype_code not in (9, 10, 11):
            self._fail(f"field {name!r} must be floating point, got dtype {f.data.dtype}")
        if len(f.shape) != ndim:
            self._fail(f"field {name!r} must have {ndim} dimension(s), got shape {list(f.shape)}")
        with np.errstate(invalid="ignore", over="ignore"):
            a = np.asarray(f.data, np.float64)
        if not np.all(np.isfinite(a)):
            self._fail(f"field {name!r} contains NaN or infinite values")
        if a.size and float(np.abs(a).max()) > MAX_RGL_FIELD_ABS:
            self._fail(f"field {name!r} holds the absurd value {float(np.abs(a).max()):.4g} (magnitude "
                       f"above {MAX_RGL_FIELD_ABS:g}, fit.limits.MAX_RGL_FIELD_ABS): corrupt file")
        return a

    def _check_sizes(self):
        """Bound the tables before any of them is converted or copied (fit.limits)."""
        total = 0
        for name in ("phi_i", "theta_i", "ndf", "sigma", "vndf", "luminance", "rgb"):
            f = self.fields[name]
            total += int(np.prod(f.shape, dtype=object)) if f.shape else 1
            big = [int(s) for s in f.shape if int(s) > MAX_RGL_TABLE_SIDE]
            if big:
                self._fail(f"field {name!r} has shape {list(f.shape)}: a side of {big[0]} is above "
                           f"the limit {MAX_RGL_TABLE_SIDE} (fit.limits.MAX_RGL_TABLE_SIDE)")
        if total > MAX_RGL_ELEMENTS:
            self._fail(f"the tables hold {total} values, above the limit {MAX_RGL_ELEMENTS} "
                       "(fit.limits.MAX_RGL_ELEMENTS)")
        n = int(np.prod(self.fields["theta_i"].shape, dtype=object))
        if n > MAX_RGL_THETA_I:
            self._fail(f"field 'theta_i' has {n} entries, above the limit {MAX_RGL_THETA_I} "
                       "(fit.limits.MAX_RGL_THETA_I)")

    def _validate_and_build(self):
        f = self.fields
        if "rgb" not in f and ("spectra" in f or "wavelengths" in f):
            self._fail("spectral-only RGL file (has 'spectra' but no 'rgb' field); only the RGB "
                       "versions (*_rgb.bsdf) are supported")
        missing = [k for k in REQUIRED_FIELDS if k not in f]
        if missing:
            self._fail(f"not a complete RGL BRDF file: missing field(s) {', '.join(missing)}")
        self._check_sizes()

        phi_i = self._float_field("phi_i", 1)
        if phi_i.size > 1:
            self._fail(f"anisotropic measurements are not supported yet (phi_i has "
                       f"{phi_i.size} entries; only isotropic files with one phi_i are)")
        if phi_i.size != 1:
            self._fail("field 'phi_i' is empty")
        theta = self._float_field("theta_i", 1)
        n = theta.size
        if n < 1:
            self._fail("field 'theta_i' is empty")
        if np.any(np.diff(theta) <= 0):
            self._fail("field 'theta_i' is not strictly increasing")
        if theta[0] < -1e-6 or theta[-1] > HALF_PI + 1e-3:
            self._fail(f"field 'theta_i' outside [0, 90] deg: [{np.degrees(theta[0]):.3g}, "
                       f"{np.degrees(theta[-1]):.3g}]")
        d = f["description"]
        if len(d.shape) != 1 or d.dtype_code not in (1, 2):
            self._fail(f"field 'description' must be 1-D uint8 text, got shape {list(d.shape)}")
        self.description = bytes(np.asarray(d.data, np.uint8)).decode("utf-8", "replace").rstrip("\x00")
        jac = f["jacobian"]
        if jac.shape != (1,) or jac.dtype_code not in (1, 2):
            self._fail(f"field 'jacobian' must be a single uint8 flag, got shape {list(jac.shape)}")
        self.jacobian = bool(jac.data[0])

        ndf = self._float_field("ndf", 2)
        sigma = self._float_field("sigma", 2)
        for nm, a in (("ndf", ndf), ("sigma", sigma)):
            if min(a.shape) < 2:
                self._fail(f"field {nm!r} must be at least 2 x 2, got shape {list(a.shape)}")
        vndf = self._float_field("vndf", 4)
        lum = f["luminance"]
        rgb = self._float_field("rgb", 5)
        if vndf.shape[:2] != (1, n) or min(vndf.shape[2:]) < 2:
            self._fail(f"field 'vndf' has shape {list(vndf.shape)}; expected [1, {n}, ny >= 2, nx >= 2]")
        if rgb.shape[:3] != (1, n, 3) or min(rgb.shape[3:]) < 2:
            self._fail(f"field 'rgb' has shape {list(rgb.shape)}; expected [1, {n}, 3, ny >= 2, nx >= 2]")
        if len(lum.shape) != 4 or tuple(lum.shape[:2]) != (1, n) or tuple(lum.shape[2:]) != rgb.shape[3:]:
            self._fail(f"field 'luminance' has shape {list(lum.shape)}; expected "
                       f"[1, {n}, {rgb.shape[3]}, {rgb.shape[4]}]")
        if np.any(vndf < 0) or np.any(ndf < 0) or np.any(sigma <= 0):
            self._fail("fields 'vndf'/'ndf' must be >= 0 and 'sigma' > 0")
        if float(sigma.min()) < MIN_RGL_SIGMA:
            self._fail(f"field 'sigma' holds {float(sigma.min()):.3g}, below {MIN_RGL_SIGMA:g} "
                       "(fit.limits.MIN_RGL_SIGMA): the normalization would explode")
        self._float_field("luminance", 4)

        self.theta_i = theta
        self.phi_i = phi_i
        neg = rgb < 0
        self.n_negative_clamped = int(neg.sum())
        self.rgb = np.where(neg, 0.0, rgb)[0]
        v = f.get("valid")
        self.valid_bits = None if v is None else np.asarray(v.data, np.uint8)

        # last measured incidence: drop trailing slices that copy the previous one
        last = n - 1
        while last > 0 and np.array_equal(self.rgb[last], self.rgb[last - 1]):
            last -= 1
        self.theta_i_max = float(theta[last])

        self._ndf = Bilinear(ndf)
        self._sigma = Bilinear(sigma)
        self._vndf = VNDFWarp(vndf[0], theta, self._path)
        self._luminance = None
        self._rgb = RGBTable(self.rgb)
        self._sigma_iso = bool(np.all(sigma == sigma[:1]))

    # -- warps --------------------------------------------------------------------------------
    @property
    def vndf_warp(self) -> VNDFWarp:
        """The VNDF warp (marginal/conditional CDFs of the ``vndf`` densities over theta_i)."""
        return self._vndf

    @property
    def luminance_warp(self) -> VNDFWarp:
        """The luminance warp (the ``luminance`` densities, negatives clamped to 0) on the
        ``rgb`` grid: the first warp of the format's importance sampling. Built on first use."""
        if self._luminance is None:
            lum = np.clip(np.asarray(self.fields["luminance"].data, np.float64)[0], 0.0, None)
            self._luminance = VNDFWarp(lum, self.theta_i, self._path)
        return self._luminance

    # -- evaluation -----------------------------------------------------------------------
    def __repr__(self):
        return (f"RGLBRDF({self.name!r}, {self.description!r}, theta_i={self.theta_i.size}, "
                f"rgb={self.rgb.shape[2]}x{self.rgb.shape[3]}, vndf={self._vndf.ny}x{self._vndf.nx})")

    def _roles(self, wi, wo):
        """(tensor incident direction, other direction) of a (light, view) pair."""
        return (wo, wi) if self.incident == "view" else (wi, wo)

    def _eval_flat(self, wi, wo, cosine: bool):
        n = wi.shape[0]
        out = np.zeros((n, 3))
        for a in range(0, n, _CHUNK):
            b = min(a + _CHUNK, n)
            out[a:b] = self._eval_chunk(wi[a:b], wo[a:b], cosine)
        return out

    def _eval_chunk(self, wi, wo, cosine):
        # wi: the tensors' incident direction (wt), wo: the other one (wx)
        zi, zo = wi[:, 2], wo[:, 2]
        finite = np.isfinite(wi).all(axis=1) & np.isfinite(wo).all(axis=1)
        above = (zi > 0.0) & (zo > 0.0) & finite
        if not above.all():
            # below the horizon: 0; non-finite input: NaN
            res = np.where(finite, 0.0, np.nan)[:, None].repeat(3, axis=1)
            if above.any():
                res[above] = self._eval_chunk(wi[above], wo[above], cosine)
            return res
        m = wi + wo
        m /= np.sqrt(np.einsum("ij,ij->i", m, m))[:, None]
        theta_i = _elevation(wi)
        theta_m = _elevation(m)
        phi_i = np.arctan2(wi[:, 1], wi[:, 0])
        phi_m = np.arctan2(m[:, 1], m[:, 0])
        um_x = _theta_to_u(theta_m)
        um_y = (phi_m - phi_i + np.pi) * (0.5 / np.pi)
        um_y -= np.floor(um_y)
        t0, w1 = interval(self.theta_i, theta_i)
        sx, sy, _ = self._vndf.invert(um_x, um_y, t0, w1)
        val = self._rgb.eval(sx, sy, t0, w1)
        if self.jacobian:
            ui_x = _theta_to_u(theta_i)
            if self._sigma_iso:
                ui_y = np.zeros_like(ui_x)
            else:
                ui_y = (phi_i + np.pi) * (0.5 / np.pi)
            scale = self._ndf.eval(um_x, um_y) / (4.0 * self._sigma.eval(ui_x, ui_y))
            if not cosine:
                scale /= zo
            val *= scale[:, None]
        elif not cosine:
            val /= zo[:, None]
        return val

    def _prepare(self, wi, wo):
        wi = np.asarray(wi, np.float64)
        wo = np.asarray(wo, np.float64)
        if wi.shape[-1] != 3 or wo.shape[-1] != 3:
            raise ValueError("wi and wo must have shape (..., 3)")
        shape = np.broadcast_shapes(wi.shape, wo.shape)
        wi = np.ascontiguousarray(np.broadcast_to(wi, shape)).reshape(-1, 3)
        wo = np.ascontiguousarray(np.broadcast_to(wo, shape)).reshape(-1, 3)
        return wi, wo, shape

    def evaluate(self, wi, wo) -> np.ndarray:
        """rho(wi, wo) in 1/sr (RGB, without the cosine): the reference value / cos(theta_o).

        ``wi`` (towards the light) and ``wo`` (towards the viewer) are unit vectors
        ``(..., 3)`` in the local frame (z = normal), broadcastable; :attr:`incident` says
        which of them is the tensors' incident direction. Returns ``(..., 3)``;
        0 where either direction is at or below the tangent plane (NaN for non-finite
        input). Directions must be unit vectors. Beyond
        :attr:`theta_i_max` the ``rgb`` interpolation is clamped (see the module docstring).
        """
        wi, wo, shape = self._prepare(wi, wo)
        wt, wx = self._roles(wi, wo)
        return self._eval_flat(wt, wx, cosine=False).reshape(shape[:-1] + (3,))

    def reference_eval(self, wt, wx) -> np.ndarray:
        """The reference ``eval`` with the tensors' incident direction ``wt`` first:
        ``f_r * cos(theta_x)``, RGB, shape ``(..., 3)`` (Mitsuba 3: ``eval(si.wi=wt, wo=wx)``)."""
        wt, wx, shape = self._prepare(wt, wx)
        return self._eval_flat(wt, wx, cosine=True).reshape(shape[:-1] + (3,))

    # -- warped coordinates ---------------------------------------------------------------
    def vndf_sample(self, sx, sy, theta_i):
        """Forward VNDF warp at incidence ``theta_i`` (radians): points ``(sx, sy)`` of the
        ``rgb`` table's unit square -> micro-normal coordinates ``(u_x, u_y)`` with
        ``theta_m = u_x**2 * pi/2`` and ``phi_m - phi_i = (2 u_y - 1) pi``. Returns
        ``(u_x, u_y, pdf)``."""
        sx, sy, th = np.broadcast_arrays(np.asarray(sx, float), np.asarray(sy, float),
                                         np.asarray(theta_i, float))
        shape = sx.shape
        t0, w1 = interval(self.theta_i, th.ravel())
        ux, uy, pdf = self._vndf.sample(sx.ravel(), sy.ravel(), t0, w1)
        return ux.reshape(shape), uy.reshape(shape), pdf.reshape(shape)

    def vndf_invert(self, wi, wo):
        """Warped ``rgb``-table coordinates ``(sx, sy)`` of direction pairs (inverse VNDF warp);
        ``wi`` is the tensors' incident direction (``wt``), ``wo`` the other one."""
        wi, wo, shape = self._prepare(wi, wo)
        m = wi + wo
        m /= np.linalg.norm(m, axis=1, keepdims=True)
        theta_i = _elevation(wi)
        um_x = _theta_to_u(_elevation(m))
        um_y = (np.arctan2(m[:, 1], m[:, 0]) - np.arctan2(wi[:, 1], wi[:, 0]) + np.pi) / (2 * np.pi)
        um_y -= np.floor(um_y)
        t0, w1 = interval(self.theta_i, theta_i)
        sx, sy, _ = self._vndf.invert(um_x, um_y, t0, w1)
        return sx.reshape(shape[:-1]), sy.reshape(shape[:-1])

    def normalization(self, wi, wo) -> np.ndarray:
        """The reference's factor ``ndf(u_wm) / (4 sigma(u_wi))`` (1 if the jacobian flag is
        off) with ``wi`` the tensors' incident direction; shape ``(...)``."""
        wi, wo, shape = self._prepare(wi, wo)
        if not self.jacobian:
            return np.ones(shape[:-1])
        m = wi + wo
        m /= np.linalg.norm(m, axis=1, keepdims=True)
        phi_i = np.arctan2(wi[:, 1], wi[:, 0])
        um_y = (np.arctan2(m[:, 1], m[:, 0]) - phi_i + np.pi) / (2 * np.pi)
        um_y -= np.floor(um_y)
        ui_y = (phi_i + np.pi) / (2 * np.pi)
        r = self._ndf.eval(_theta_to_u(_elevation(m)), um_y) / (
            4.0 * self._sigma.eval(_theta_to_u(_elevation(wi)), ui_y))
        return r.reshape(shape[:-1])

    # -- MERL grid ------------------------------------------------------------------------
    def to_measured(self, horizon_margin_deg: float = 1.0):
        """Resample at the bin centres of the full-circle MERL grid (phi_h = 0): a
        :class:`MeasuredBRDF` of 90 x 90 x 360 bins, phi_d in [0, 2 pi), **not** folded by
        reciprocity (:mod:`fit.formats.grid`). The files are not reciprocal (10-27 % on the
        glossy films), so (light, view) and (view, light) keep their own bins, ``k`` and
        ``(k + 180) % 360``, each ``evaluate(light, view)`` with this object's :attr:`incident`
        roles; the table's ``evaluate`` reproduces :meth:`evaluate` at the bin centres.
        2.9 M evaluations.

        ``values`` (rho at the centres, what the projection and the fits use): bins whose light
        or view direction is at or below the horizon are invalid (value 0), and so are bins
        within ``horizon_margin_deg`` of it: there the stored f*cos(theta_x) is divided by a
        cosine below sin(margin) and the values explode (up to ~1e7 1/sr on the glossy films at
        cos ~ 1e-5, against <= 31 in the file). Set 0 to keep every above-horizon bin.

        ``weighted`` (what :meth:`MeasuredBRDF.evaluate` and the renderer look up): the file's
        own f*cos(theta_x) at every centre, divided at lookup by the pair's own cos(theta_x)
        (:class:`MeasuredBRDF`), directions of a centre below the horizon lifted to
        ``GRAZING_Z``; a further 2.9 M evaluations.
        """
        th = theta_h_centres()[:, None, None]
        td = theta_d_centres()[None, :, None]
        pd = phi_d_centres(N_PHI_D_FULL)[None, None, :]
        wi, wo = half_diff_to_directions(th, 0.0, td, pd)   # wi: the light, wo: the view
        vals = self.evaluate(wi, wo)
        c_min = max(np.sin(np.radians(horizon_margin_deg)), 0.0)
        above = (wi[..., 2] > c_min) & (wo[..., 2] > c_min)
        valid = np.broadcast_to(above[..., None], FULL_SHAPE + (3,)).copy()
        # f cos(theta_x) at every centre, directions lifted to GRAZING_Z where a centre dips
        # below the horizon (a pair of that bin with both directions above reads its grazing value)
        wt, wx = self._roles(_lift(wi), _lift(wo))
        weighted = self.reference_eval(wt, wx)
        # the fields are bounded (fit.limits.MAX_RGL_FIELD_ABS, MIN_RGL_SIGMA), so the values are
        # finite; they may still be large within horizon_margin_deg of the horizon (f cos / cos)
        check_values(vals, valid, self._path, max_value=None)
        if not np.all(np.isfinite(weighted)):
            raise BRDFFileError(self._path, "the file's f cos(theta) is not finite at some bin centre: "
                                            "corrupt tables")
        m = MeasuredBRDF(values=vals, valid=valid, name=self.name, source=self.source,
                         source_sha256=self.source_sha256, weighted=weighted,
                         weighted_by="light" if self.incident == "view" else "view")
        m.metadata.update({
            "description": self.description,
            "format": "rgl-epfl tensor_file (RGB), resampled at MERL bin centres over the full "
                      "phi_d circle",
            "phi_d": "[0, 2 pi), 360 bins, not folded (the file is not reciprocal)",
            "theta_i_max_deg": float(np.degrees(self.theta_i_max)),
            "rgb_resolution": [int(self.rgb.shape[2]), int(self.rgb.shape[3])],
            "n_theta_i": int(self.theta_i.size),
            "negative_values_clamped": self.n_negative_clamped,
            "horizon_margin_deg": float(horizon_margin_deg),
            "incident": self.incident,
        })
        return m


#: Lowest cos(theta) a bin centre is lifted to for the weighted table (0.06 deg above the plane).
GRAZING_Z = 1e-3


def _lift(w):
    """Unit directions with z raised to at least :data:`GRAZING_Z` (azimuth kept)."""
    w = np.array(w, dtype=np.float64)
    low = w[..., 2] < GRAZING_Z
    if np.any(low):
        r = np.hypot(w[..., 0], w[..., 1])
        s = np.sqrt(1.0 - GRAZING_Z**2) / np.maximum(r, 1e-300)
        w[low, 0] *= s[low]
        w[low, 1] *= s[low]
        w[low, 2] = GRAZING_Z
    return w


def read_rgl(path, incident: str = "view") -> RGLBRDF:
    """Read an isotropic RGB RGL-EPFL ``.bsdf`` file; one-line :class:`BRDFFileError` on
    any problem (bad magic, truncation, unknown dtype, missing fields, spectral-only or
    anisotropic files, inconsistent shapes). ``incident``: :attr:`RGLBRDF.incident`."""
    path = Path(path)
    fields = read_tensor_file(path)
    return RGLBRDF(fields, path=path, sha256=file_sha256(path), incident=incident)
