"""UTIA BRDF database ``.bin`` files (Filip & Vavra, "Template-based sampling of anisotropic
BRDFs", Pacific Graphics 2014; http://btf.utia.cas.cz).

Published layout (the database's reference loader by J. Filip): raw little-endian float64,
``3 x 6 x 48 x 6 x 48`` in C order = [channel, theta_i, phi_i, theta_v, phi_v], i.e. the
value of channel c at index (ti, pi, tv, pv) is at
``c*(6*48*6*48) + (48*6)*(48*ti + pi) + 48*tv + pv``. theta steps 15 degrees (0..75), phi steps
7.5 degrees (0..352.5); i = illumination (light), v = view. Values are taken as f_r in linear RGB.

Evaluation follows the reference loader: multilinear interpolation in (theta_i, phi_i, theta_v,
phi_v) degrees, periodic in phi, theta above 75 degrees extrapolated linearly from the last two
rows. The UBO-81 thetas lie on the table's theta grid, so only azimuths are interpolated there.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..grid import cartesian_to_spherical
from ..measurement import Measurement
from ._common import query_directions, sampled

SHAPE = (3, 6, 48, 6, 48)
STEP_THETA, STEP_PHI = 15.0, 7.5


def read_table(path: Path) -> np.ndarray:
    size = path.stat().st_size
    expected = 8 * int(np.prod(SHAPE))
    if size == 0:
        raise InputError(path, "empty file (expected a UTIA BRDF .bin)")
    if size != expected:
        what = "truncated" if size < expected else "too long"
        raise InputError(path, f"{what}: {size} bytes, a UTIA BRDF .bin (3x6x48x6x48 float64) has {expected}")
    data = np.fromfile(path, dtype="<f8").reshape(SHAPE)
    if not np.any(np.isfinite(data)):
        raise InputError(path, "no finite value in the table")
    return data


def _theta_weights(theta_deg: np.ndarray, n: int):
    i0 = np.clip(np.floor(theta_deg / STEP_THETA).astype(int), 0, n - 2)
    t = theta_deg / STEP_THETA - i0  # may exceed 1 above the last row: linear extrapolation
    return i0, i0 + 1, 1.0 - t, t


def _phi_weights(phi_deg: np.ndarray, n: int):
    x = np.mod(phi_deg, 360.0) / STEP_PHI
    i0 = np.floor(x).astype(int) % n
    t = x - np.floor(x)
    return i0, (i0 + 1) % n, 1.0 - t, t


def evaluate(table: np.ndarray, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """(N, 3) multilinear lookup at light/view unit vectors."""
    ti, pi_ = (np.degrees(a) for a in cartesian_to_spherical(light))
    tv, pv = (np.degrees(a) for a in cartesian_to_spherical(view))
    # at a pole the azimuth is undefined (atan2 of +-0 can give 180 deg): use the phi = 0 row
    pi_ = np.where(ti < 1e-9, 0.0, pi_)
    pv = np.where(tv < 1e-9, 0.0, pv)
    a = _theta_weights(ti, SHAPE[1])
    b = _phi_weights(pi_, SHAPE[2])
    c = _theta_weights(tv, SHAPE[3])
    d = _phi_weights(pv, SHAPE[4])
    out = np.zeros((light.shape[0], SHAPE[0]))
    for ia, wa in ((a[0], a[2]), (a[1], a[3])):
        for ib, wb in ((b[0], b[2]), (b[1], b[3])):
            for ic, wc in ((c[0], c[2]), (c[1], c[3])):
                for id_, wd in ((d[0], d[2]), (d[1], d[3])):
                    w = wa * wb * wc * wd
                    out += (w[:, None] * table[:, ia, ib, ic, id_].T)
    return out


def read(path, *, wi=None, wo=None, name: str | None = None) -> Measurement:
    """Sample a UTIA ``.bin`` at (light ``wi``, view ``wo``): the UBO-81 pairs by default."""
    path = Path(path)
    table = read_table(path)
    light, view, grid = query_directions(wi, wo)
    values = evaluate(table, light, view)
    ok = np.all(np.isfinite(values), axis=1) & (light[:, 2] > 0) & (view[:, 2] > 0)
    return sampled(
        path, light, view, values, ok, name=name, grid=grid,
        extra={
            "format": "utia",
            "lookup": "multilinear in (theta_i, phi_i, theta_v, phi_v), 15 / 7.5 degree steps (UTIA reference loader)",
            "light_directions": "nominal (the .bin table is on a regular grid)",
        },
    )
