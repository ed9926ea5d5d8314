"""Resampling onto the UBO-81 grid (docs/formats.md#readers-and-writers).

- A source that can be evaluated anywhere (RGL ``.bsdf``, MERL ``.binary``, UTIA ``.bin``) is
  re-evaluated at the 6561 UBO pairs (that is what ``load`` does by default).
- A UBO-81 measurement is returned unchanged.
- Scattered samples (Cornell ``.brdf``, any ``grid=None`` Measurement) are interpolated:

  * coordinates: isotropic (theta_light, theta_view, dphi) with dphi = |phi_view - phi_light|
    folded into [0, pi] — exact for isotropic BRDFs with the usual bilateral symmetry;
  * reciprocity: each sample is also used with light and view swapped (``reciprocal=True``,
    default). The Cornell data only light the sample from 10..80 degrees, but their views span
    0..79 degrees, so reciprocity covers the UBO lights at 0 and 75 degrees from measured data;
  * piecewise-linear interpolation over a Delaunay tetrahedralisation of those points
    (``scipy.interpolate.LinearNDInterpolator``), in radians;
  * outside the convex hull of the samples the nearest sample's value is used: that is the
    extrapolation. The result's metadata says how much: ``extrapolated`` (count of the 6561
    samples), ``max_extrapolation_deg`` (largest distance, in degrees of the (theta, theta, dphi)
    space, from an extrapolated grid point to the sample that gave its value), and
    ``max_gap_deg`` (the same distance for all grid points: how sparse the data are there);
  * weights: 1 for interpolated samples, 1 / (1 + (d / 10 deg)^2) for extrapolated ones at
    distance d, so a fit can trust them less.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..grid import cartesian_to_spherical, ubo_pairs
from ..measurement import Measurement

EVALUABLE = ("rgl", "merl", "utia")
#: distance (radians) at which an extrapolated sample's weight has dropped to 1/2
WEIGHT_SCALE = np.deg2rad(10.0)


def isotropic_coords(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """(N, 3) of (theta_light, theta_view, |dphi| in [0, pi])."""
    ti, pi_ = cartesian_to_spherical(wi)
    to, po = cartesian_to_spherical(wo)
    dphi = np.abs(np.mod(po - pi_ + np.pi, 2 * np.pi) - np.pi)
    # at a pole the azimuth is meaningless: any dphi describes the same pair
    return np.stack([ti, to, dphi], axis=1)


def interpolate_scattered(m: Measurement, *, reciprocal: bool = True) -> Measurement:
    from scipy.interpolate import LinearNDInterpolator
    from scipy.spatial import QhullError, cKDTree

    valid = m.valid_mask()
    if valid.sum() < 5:
        raise InputError(m.source or m.name, f"only {int(valid.sum())} valid samples: too few to interpolate")
    x = isotropic_coords(np.asarray(m.wi)[valid], np.asarray(m.wo)[valid])
    y = np.asarray(m.values, dtype=np.float64)[valid]
    if reciprocal:
        x = np.concatenate([x, x[:, [1, 0, 2]]])
        y = np.concatenate([y, y])
    # merge coincident points (e.g. theta_light == theta_view after the swap): Qhull needs distinct ones
    key = np.round(x, 9)
    uniq, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    counts = np.bincount(inverse)
    y_mean = np.stack([np.bincount(inverse, weights=y[:, c]) for c in range(y.shape[1])], axis=1) / counts[:, None]
    wi, wo = ubo_pairs()
    # many UBO pairs share their isotropic coordinates: interpolate each distinct point once
    q_all = isotropic_coords(wi, wo)
    q, q_inverse = np.unique(np.round(q_all, 12), axis=0, return_inverse=True)
    q_inverse = q_inverse.reshape(-1)
    try:
        if len(uniq) < 4:
            raise ValueError("fewer than 4 distinct points")
        values = LinearNDInterpolator(uniq, y_mean)(q)[q_inverse]
    except (ValueError, QhullError) as exc:  # all samples on one direction pair, one plane...
        raise InputError(m.source or m.name, f"the {int(valid.sum())} valid samples do not span the directions "
                         "(flat or coincident in theta_light, theta_view, dphi): cannot interpolate them onto "
                         f"the UBO-81 grid ({' '.join(str(exc).split())[:80]})") from None
    dist, nearest = (a[q_inverse] for a in cKDTree(uniq).query(q))
    outside = ~np.all(np.isfinite(values), axis=1)
    values[outside] = y_mean[nearest[outside]]
    weights = np.where(outside, 1.0 / (1.0 + (dist / WEIGHT_SCALE) ** 2), 1.0)
    extra = dict(m.extra)
    extra.update(
        {
            "resampled_from": f"{m.n_samples} scattered samples ({extra.get('format', 'measurement')})",
            "interpolation": "piecewise linear (Delaunay) in (theta_light, theta_view, |dphi|)"
            + (", with reciprocity (light/view swapped)" if reciprocal else "")
            + "; nearest sample outside the hull",
            "extrapolated": int(outside.sum()),
            "max_extrapolation_deg": float(np.degrees(dist[outside].max())) if outside.any() else 0.0,
            "max_gap_deg": float(np.degrees(dist.max())),
            "extrapolated_weight": "1 / (1 + (d / 10 deg)^2)",
        }
    )
    return Measurement(
        wi=wi, wo=wo, values=values, weights=weights, name=m.name, source=m.source, grid="ubo81",
        colour_space=m.colour_space, units=m.units, extra=extra,
    )


__all__ = ["isotropic_coords", "interpolate_scattered"]
