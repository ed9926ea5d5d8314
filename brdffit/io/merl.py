"""MERL BRDF database ``.binary`` files (Matusik, Pfister, Brand, McMillan 2003).

Published layout (MERL's ``BRDFRead.cpp``; pbrt-v2 ``measured.cpp``), little-endian:

- header: three int32, the table resolution (90, 90, 180) = (theta_h, theta_d, phi_d);
- then 3 x 90 x 90 x 180 float64: all red values, then all green, then all blue; within a colour
  phi_d is the fastest index, then theta_d, then theta_h;
- physical value = stored value x channel scale (1/1500, 1.15/1500, 1.66/1500);
- negative stored values mark directions that were not measured: those samples get weight 0
  (value 0).

Lookup (the reference code's, nearest cell, no interpolation) at light ``wi`` and view ``wo``:
half vector h = normalize(wi + wo) with (theta_h, phi_h); the difference vector is wi rotated by
-phi_h about z, then by -theta_h about y, giving (theta_d, phi_d);
index_h = floor(sqrt(theta_h / (pi/2)) * 90) (the square-root spacing that puts more cells near
the specular peak), index_d = floor(theta_d / (pi/2) * 90), index_phi = floor(phi_d' / pi * 180)
with phi_d' = phi_d + pi when phi_d < 0 (reciprocity folds phi_d into [0, pi)), each clamped to
the table. By default the BRDF is sampled at the UBO-81 pairs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..grid import half_diff
from ..measurement import Measurement
from ._common import query_directions, sampled

RES = (90, 90, 180)  # theta_h, theta_d, phi_d
SCALES = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
HEADER_BYTES = 12


def read_table(path: Path) -> np.ndarray:
    """(3, 90, 90, 180) stored (unscaled) values."""
    size = path.stat().st_size
    if size == 0:
        raise InputError(path, "empty file (expected a MERL .binary)")
    if size < HEADER_BYTES:
        raise InputError(path, f"truncated: {size} bytes, not even the 12-byte header")
    with open(path, "rb") as fh:
        dims = tuple(int(d) for d in np.frombuffer(fh.read(HEADER_BYTES), dtype="<i4"))
        if dims != RES:
            raise InputError(path, f"header says resolution {dims}; a MERL table is {RES} (theta_h, theta_d, phi_d)")
        n = 3 * int(np.prod(RES))
        expected = HEADER_BYTES + 8 * n
        if size != expected:
            what = "truncated" if size < expected else "trailing data"
            raise InputError(path, f"{what}: {size} bytes, a MERL .binary has {expected}")
        data = np.frombuffer(fh.read(8 * n), dtype="<f8")
    return data.reshape(3, *RES)


def indices(theta_h, theta_d, phi_d) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ih = np.floor(np.sqrt(np.maximum(theta_h, 0.0) / (np.pi / 2)) * RES[0]).astype(int)
    idd = np.floor(theta_d / (np.pi / 2) * RES[1]).astype(int)
    phi = np.where(phi_d < 0, phi_d + np.pi, phi_d)
    ip = np.floor(phi / np.pi * RES[2]).astype(int)
    return np.clip(ih, 0, RES[0] - 1), np.clip(idd, 0, RES[1] - 1), np.clip(ip, 0, RES[2] - 1)


def read(path, *, wi=None, wo=None, name: str | None = None) -> Measurement:
    """Sample a MERL ``.binary`` at (light ``wi``, view ``wo``): the UBO-81 pairs by default."""
    path = Path(path)
    table = read_table(path)
    light, view, grid = query_directions(wi, wo)
    ih, idd, ip = indices(*half_diff(light, view))
    raw = table[:, ih, idd, ip].T  # (N, 3)
    above = (light[:, 2] > 0) & (view[:, 2] > 0)
    negative = above & np.any(raw < 0, axis=1)  # cells MERL did not measure
    ok = above & ~negative & np.all(np.isfinite(raw), axis=1)
    if not ok.any():
        raise InputError(path, "no valid sample at the requested directions (all negative = unmeasured, or NaN)")
    return sampled(
        path, light, view, raw * SCALES, ok, name=name, grid=grid,
        extra={
            "format": "merl",
            "lookup": "nearest cell, sqrt(theta_h) indexing (MERL reference code)",
            "channel_scales": tuple(float(s) for s in SCALES),
            "invalid_negative": int(np.sum(negative)),  # below the horizon: weight 0, not counted here
        },
    )
