"""A BRDF that interpolates a UBO-81 table (docs/conventions.md#conventions grid), for rendering measured references.

Interpolation scheme (4-D multilinear on the rings)
---------------------------------------------------
Each of the two directions (light ``wi``, view ``wo``) is written as (theta, phi) in the local
frame and spread over at most four UBO directions:

- theta: linear between the two rings that bracket it (0, 15, ..., 75 degrees). Above 75 degrees
  the 75-degree ring is used as is (constant extrapolation: the grid holds nothing lower).
- phi: within each of those rings, linear between the two neighbouring azimuths of that ring,
  wrapping around 360 degrees. The pole (theta = 0) is a single direction, whatever phi.

The weights of light and view multiply (16 table entries at most per pair). At a grid pair the
weights are 1 on that entry and 0 elsewhere, so the table is reproduced exactly (up to the
round-off of converting directions to angles). Invalid entries (weight 0 or not finite) are left
out and the remaining weights renormalised; a pair with no valid neighbour evaluates to 0.
Absolute azimuths are interpolated (no isotropy assumed), so anisotropic tables stay so.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..grid import UBO_PHI_STEP_DEG, UBO_SIZE, UBO_THETA_DEG

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


_THETA = np.deg2rad(np.asarray(UBO_THETA_DEG, np.float64))
_STEP = np.deg2rad(np.asarray(UBO_PHI_STEP_DEG, np.float64))
_COUNT = np.array([1] + [360 // s for s in UBO_PHI_STEP_DEG[1:]])
_OFFSET = np.concatenate([[0], np.cumsum(_COUNT)[:-1]])
_RING_GAP = _THETA[1] - _THETA[0]


def direction_weights(w: Float[np.ndarray, "N 3"]) -> tuple[np.ndarray, np.ndarray]:
    """UBO indices (N, 4) and weights (N, 4) of unit directions ``w`` (see the module docstring)."""
    w = np.asarray(w, np.float64).reshape(-1, 3)
    theta = np.arccos(np.clip(w[:, 2] / np.linalg.norm(w, axis=1), -1.0, 1.0))
    phi = np.mod(np.arctan2(w[:, 1], w[:, 0]), 2 * np.pi)
    last = len(_THETA) - 1
    pos = np.clip(theta / _RING_GAP, 0.0, float(last))
    r0 = np.minimum(np.floor(pos).astype(int), last - 1)
    t = pos - r0  # 0..1 between ring r0 and r0 + 1
    idx = np.empty((w.shape[0], 4), np.int64)
    wt = np.empty((w.shape[0], 4))
    for j, (ring, ring_w) in enumerate(((r0, 1.0 - t), (r0 + 1, t))):
        count = _COUNT[ring]
        k = phi / _STEP[ring]
        k0 = np.floor(k)
        u = np.where(count > 1, k - k0, 0.0)
        k0 = np.mod(k0.astype(np.int64), count)
        k1 = np.mod(k0 + 1, count)
        idx[:, 2 * j] = _OFFSET[ring] + k0
        idx[:, 2 * j + 1] = _OFFSET[ring] + k1
        wt[:, 2 * j] = ring_w * (1.0 - u)
        wt[:, 2 * j + 1] = ring_w * u
    return idx, wt


class UboInterpolator:
    """f_r(wi, wo) of a UBO-81 table, interpolated as in the module docstring."""

    def __init__(self, table: Float[np.ndarray, "81 81 C"], valid: np.ndarray | None = None):
        table = np.asarray(table, np.float64)
        if table.ndim != 3 or table.shape[:2] != (UBO_SIZE, UBO_SIZE):
            raise ValueError(f"a UBO table has shape (81, 81, C), not {table.shape}")
        ok = np.all(np.isfinite(table), axis=2)
        if valid is not None:
            ok &= np.asarray(valid, bool).reshape(UBO_SIZE, UBO_SIZE)
        self.table = np.where(ok[..., None], table, 0.0)
        self.valid = ok.astype(np.float64)

    @classmethod
    def from_measurement(cls, m) -> "UboInterpolator":
        if m.grid != "ubo81":
            raise ValueError(f"{m.name}: a tabulated BSDF needs a ubo81 measurement, this one has grid={m.grid!r}")
        return cls(m.table(), np.asarray(m.weights).reshape(UBO_SIZE, UBO_SIZE) > 0)

    def __call__(self, wi: Float[np.ndarray, "N 3"], wo: Float[np.ndarray, "N 3"]) -> Float[np.ndarray, "N C"]:
        li, lw = direction_weights(wi)
        vi, vw = direction_weights(wo)
        n = li.shape[0]
        acc = np.zeros((n, self.table.shape[2]))
        norm = np.zeros(n)
        for a in range(4):
            for b in range(4):
                w = lw[:, a] * vw[:, b]
                w = w * self.valid[li[:, a], vi[:, b]]
                acc += w[:, None] * self.table[li[:, a], vi[:, b]]
                norm += w
        return np.where(norm[:, None] > 0, acc / np.where(norm > 0, norm, 1.0)[:, None], 0.0)
