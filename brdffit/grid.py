"""Direction conventions (docs/conventions.md#conventions) and the UBO-81 sampling of the Bonn / UTIA BTF databases.

Local frame: z is the normal, x the tangent at phi = 0, right-handed. theta is the polar angle
from z, phi the azimuth from x, counter-clockwise seen from above. Arrays hold radians.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


#: Polar angles of the six UBO rings, degrees.
UBO_THETA_DEG: tuple[int, ...] = (0, 15, 30, 45, 60, 75)
#: Azimuth step in each ring, degrees (the pole has a single direction at phi = 0).
UBO_PHI_STEP_DEG: tuple[int, ...] = (360, 60, 30, 20, 18, 15)
UBO_SIZE = 81


def ubo_angles_deg() -> Float[np.ndarray, "81 2"]:
    """(theta, phi) of the 81 UBO directions in integer degrees, ordered by theta, then phi."""
    rows = [
        (theta, phi)
        for theta, step in zip(UBO_THETA_DEG, UBO_PHI_STEP_DEG)
        for phi in range(0, 360, step)
    ]
    assert len(rows) == UBO_SIZE
    return np.asarray(rows, dtype=np.float64)


def ubo_angles() -> Float[np.ndarray, "81 2"]:
    """(theta, phi) of the 81 UBO directions in radians, ordered by theta, then phi."""
    return np.deg2rad(ubo_angles_deg())


def spherical_to_cartesian(theta, phi) -> np.ndarray:
    """Unit vectors (..., 3) from polar angle theta and azimuth phi (radians)."""
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


def cartesian_to_spherical(v) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) in radians of vectors (..., 3); phi in [0, 2 pi)."""
    v = np.asarray(v, dtype=np.float64)
    r = np.linalg.norm(v, axis=-1)
    theta = np.arccos(np.clip(v[..., 2] / np.where(r > 0, r, 1.0), -1.0, 1.0))
    phi = np.mod(np.arctan2(v[..., 1], v[..., 0]), 2 * np.pi)
    return theta, phi


def half_diff(wi: Float[np.ndarray, "N 3"], wo: Float[np.ndarray, "N 3"]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rusinkiewicz (1998) coordinates (theta_h, theta_d, phi_d) of light/view pairs, radians:
    the half vector h = (wi + wo) / |wi + wo| in the local frame, and wi in the frame of h (wi
    turned by -phi_h about z, then by -theta_h about y), phi_d in (-pi, pi]. As MERL's reference
    code (``std_coords_to_half_diff_coords``); opposite directions (only at or below the horizon)
    have no half vector: the normal stands in, rather than 0/0 and NumPy's warnings."""
    wi = np.asarray(wi, np.float64).reshape(-1, 3)
    wo = np.asarray(wo, np.float64).reshape(-1, 3)
    h = wi + wo
    length = np.linalg.norm(h, axis=1, keepdims=True)
    h = np.where(length > 0, h / np.where(length > 0, length, 1.0), [0.0, 0.0, 1.0])
    theta_h = np.arccos(np.clip(h[:, 2], -1.0, 1.0))
    phi_h = np.arctan2(h[:, 1], h[:, 0])
    c, s = np.cos(phi_h), np.sin(phi_h)
    x = c * wi[:, 0] + s * wi[:, 1]
    y = -s * wi[:, 0] + c * wi[:, 1]
    ct, st = np.cos(theta_h), np.sin(theta_h)
    dx = ct * x - st * wi[:, 2]
    dz = st * x + ct * wi[:, 2]
    return theta_h, np.arccos(np.clip(dz, -1.0, 1.0)), np.arctan2(y, dx)


def ubo_directions() -> Float[np.ndarray, "81 3"]:
    """The 81 UBO directions as unit vectors in the local frame."""
    a = ubo_angles()
    d = spherical_to_cartesian(a[:, 0], a[:, 1])
    d[0] = (0.0, 0.0, 1.0)  # exact pole, no sin(0) round-off
    return d


def ubo_pairs() -> tuple[Float[np.ndarray, "6561 3"], Float[np.ndarray, "6561 3"]]:
    """All (light, view) pairs: ``wi[k], wo[k]`` with k = light * 81 + view."""
    d = ubo_directions()
    wi = np.repeat(d, UBO_SIZE, axis=0)
    wo = np.tile(d, (UBO_SIZE, 1))
    return wi, wo


def ubo_index(theta_deg: float, phi_deg: float) -> int:
    """Index 0..80 of the UBO direction with these integer-degree angles (KeyError if none)."""
    theta = int(round(theta_deg))
    phi = int(round(phi_deg)) % 360
    if theta == 0:
        phi = 0  # the pole has one direction whatever the file calls its azimuth
    table = _UBO_INDEX
    key = (theta, phi)
    if key not in table:
        raise KeyError(key)
    return table[key]


_UBO_INDEX = {(int(t), int(p)): i for i, (t, p) in enumerate(ubo_angles_deg())}
