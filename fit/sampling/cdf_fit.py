"""The rational inverse CDFs of one material as an object and as a file: :class:`CDFFit` (the
tabulated sampler, the maps of one layout, their verification and the fallback decision; the
NumPy reference of the renderer's sampler; :meth:`CDFFit.to_dict`, :meth:`CDFFit.save`) and the
identity of the ``rbrdf-cdf`` format (:data:`FORMAT`, :data:`VERSION`, :data:`SAMPLER`). The
format: docs/formats.md ("Importance-sampling CDFs"); how a fit is made: :mod:`fit.sampling.cdf_file`;
how a file is read: :mod:`fit.sampling.cdf_reader`.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..formats.angles import HALF_PI
from ..rational.coefficient_file import jsonable
from .maps import sample_maps
from .pieces import PieceMaps
from .table import CDFTable, table_where

if TYPE_CHECKING:   # the global layout imports the fitter (SciPy): not needed to hold or read maps
    from .global_layout import GlobalMaps

FORMAT = "rbrdf-cdf"
VERSION = 2   # 2: "layout" key (pieces or global); version-1 files (global layout) still load
#: The file's description of the sampler, as files have always stated it: its "rows" entry
#: describes the removed per-row layout (readers refuse "rows" files) and its "pieces" entry
#: names build_pieces by its old module (now fit.sampling.pieces.build_pieces); both stay so
#: that files written for the same input keep their content.
SAMPLER = {
    "theta_l": "pi/2 (F(theta_v, mu) - F(theta_v, 0)) / (F(theta_v, 1) - F(theta_v, 0))",
    "phi_l": "sign(tau - 1/2) pi (G(theta_v, theta_l, u) - G(.., 0)) / (G(.., 1) - G(.., 0)), u = |2 tau - 1|",
    "alpha": "dtheta_l/dmu * dphi_l/dtau * sin(theta_l)",
    "phi_origin": "azimuth of the view direction",
    "rows": "layout 'rows': row v = floor(theta_v / (pi/2) * n_v) uses F_v(mu), G_v(theta_l, u) "
            "in the same formulas; a null row is sampled with the table",
    "pieces": "layout 'pieces': rational-quadratic pieces uniform in mu / u, rebuilt from "
              "table_data by fit.cdf_pieces.build_pieces(n_mu, n_u); rows with row_ok false "
              "are sampled with the table",
}


@dataclass
class CDFFit:
    """Rational inverse CDFs of one material, with their verification and the table they fit.

    ``maps``: the layout's maps (:class:`fit.sampling.pieces.PieceMaps` or
    :class:`fit.sampling.global_layout.GlobalMaps`), None for a table-only fit or a pieces fit
    without a rational row. ``fallback`` True: the rational sampler must not be used;
    renderers use ``table``."""

    table: CDFTable
    table_params: dict
    maps: PieceMaps | GlobalMaps | None
    verification: dict
    fallback: bool
    reason: str = ""
    fit_info: dict = field(default_factory=dict)
    name: str = ""
    source: dict = field(default_factory=lambda: {"file": "", "sha256": ""})

    @property
    def layout(self) -> str:
        """``"pieces"`` or ``"global"`` (also without maps: what the files have always said)."""
        return "global" if self.maps is None else self.maps.layout

    # Sampling (NumPy reference of the Warp sampler) ------------------------------------------
    def _maps(self):
        if self.maps is None:
            raise ValueError("no rational fit (fallback); use .table")
        return self.maps

    def _theta_map(self, tv, mu):
        """(theta_l, dtheta_l/dmu) of the rational map; NaN on table rows."""
        return self._maps().theta_map(self.table, tv, mu)

    def _phi_map(self, tv, tl, u):
        return self._maps().phi_map(self.table, tv, tl, u)

    def _table_rows(self, tv) -> np.ndarray:
        """True where the sample's row is sampled with the table (pieces layout, failed row)."""
        return self._maps().table_rows(self.table, tv)

    def inverse_theta(self, theta_v, mu) -> np.ndarray:
        """theta_l = the rational CDF^-1_v(mu) (rad); NaN on table rows."""
        tv, mu = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(mu, float))
        return self._theta_map(tv, mu)[0]

    def inverse_phi(self, theta_v, theta_l, u) -> np.ndarray:
        """|phi_l| = the rational CDF^-1_v(u | theta_l) (rad, u = |2 tau - 1|); NaN on table rows."""
        tv, tl, u = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_v, theta_l, u)))
        return self._phi_map(tv, tl, u)[0]

    def sample(self, theta_v, mu, tau):
        """``(theta_l, phi_l, alpha)``; alpha = dtheta/dmu * dphi/dtau * sin(theta_l) (= 1/pdf
        in 1/sr^-1), 0 where a clamp is active. Rows without a rational map are sampled with the
        table (alpha = 1 / the table's pdf)."""
        maps = self._maps()
        tv, mu, tau = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(mu, float),
                                          np.asarray(tau, float))
        tl, pl, alpha = sample_maps(lambda m: self._theta_map(tv, m), lambda t, u: self._phi_map(tv, t, u),
                                    mu, tau)
        return table_where(self.table, maps.table_rows(self.table, tv), tv, mu, tau, tl, pl, alpha)

    def theta_cdf(self, theta_v, theta_l, iters: int = 40) -> np.ndarray:
        """P(theta <= theta_l) under the rational sampler (bisection of the monotone F; the
        table's CDF on table rows)."""
        tv, t = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(theta_l, float))
        lo, hi = np.zeros(t.shape), np.ones(t.shape)
        for _ in range(iters):
            m = 0.5 * (lo + hi)
            below = self._theta_map(tv, m)[0] <= t
            lo, hi = np.where(below, m, lo), np.where(below, hi, m)
        out = 0.5 * (lo + hi)
        tab = self._table_rows(tv)
        if tab.any():
            edges = np.linspace(0.0, HALF_PI, self.table.n_t + 1)
            v = self.table.row(tv)
            for r in np.unique(v[tab]):
                k = tab & (v == r)
                out[k] = np.interp(t[k], edges, self.table.cdf_theta[r])
        return np.where(t >= HALF_PI, 1.0, np.where(t <= 0, 0.0, out))

    def phi_cdf_half(self, theta_v, theta_l, phi_abs, iters: int = 40) -> np.ndarray:
        """P(|phi| <= phi_abs | theta_l) under the rational sampler (bisection in u)."""
        tv, tl, p = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(theta_l, float),
                                        np.asarray(phi_abs, float))
        lo, hi = np.zeros(p.shape), np.ones(p.shape)
        for _ in range(iters):
            m = 0.5 * (lo + hi)
            below = self._phi_map(tv, tl, m)[0] <= p
            lo, hi = np.where(below, m, lo), np.where(below, hi, m)
        out = 0.5 * (lo + hi)
        tab = self._table_rows(tv)
        if tab.any():
            edges = np.linspace(0.0, np.pi, self.table.n_p + 1)
            v = self.table.row(tv)
            j = np.clip(np.floor(tl / (HALF_PI / self.table.n_t)), 0, self.table.n_t - 1).astype(np.intp)
            for r, c in {(int(a), int(b)) for a, b in zip(v[tab], j[tab])}:
                k = tab & (v == r) & (j == c)
                out[k] = np.interp(p[k], edges, self.table.cdf_phi[r, c])
        return np.where(p >= np.pi, 1.0, np.where(p <= 0, 0.0, out))

    # Persistence ------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        t = self.table
        d = {
            "format": FORMAT, "version": VERSION, "name": self.name,
            "sampler": dict(SAMPLER),
            "table": dict(self.table_params),
            "table_data": {"theta_v": t.theta_v.tolist(), "cdf_theta": t.cdf_theta.tolist(),
                           "cdf_phi": t.cdf_phi.tolist(), "row_fallback": t.row_fallback.tolist(),
                           "eps": t.eps, "albedo": t.albedo.tolist()},
            "theta": None, "phi": None,            # global layout: rational-function files
            "layout": self.layout,
            "pieces": None,                        # pieces layout: n_mu, n_u, row_ok
            "rows": None,                          # (the removed per-row layout; always null)
            "verification": jsonable(self.verification),
            "fallback": bool(self.fallback),
            "reason": self.reason,
            "fit": jsonable(self.fit_info),
            "source": dict(self.source),
        }
        if self.maps is not None:
            d.update(self.maps.to_dict(self.name))
        return d

    def save(self, path) -> None:
        """Write the ``rbrdf-cdf`` JSON file through a temporary file renamed onto ``path`` when
        complete (:func:`fit.outputs.atomic_write`)."""
        from ..outputs import atomic_write

        text = json.dumps(self.to_dict(), allow_nan=False)
        with atomic_write(Path(path)) as f:
            f.write(text + "\n")
