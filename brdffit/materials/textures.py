"""Texture files of parameter maps: float OpenEXR images, and when a map is one number.

Shared by the textured exports (:mod:`brdffit.materials.textured`): Mitsuba's ``bitmap`` textures
and Blender's image textures are these files.
"""

from __future__ import annotations

import os

import numpy as np

#: A map whose texels all lie within this relative spread of its largest value is one number.
UNIFORM_RTOL = 1e-6


def uniform_value(a: np.ndarray) -> np.ndarray | None:
    """The value of a map (H, W, size) whose texels all hold one value (within float32
    precision, :data:`UNIFORM_RTOL`), else None."""
    a = np.asarray(a, np.float64)
    spread = a.max(axis=(0, 1)) - a.min(axis=(0, 1))
    if np.all(spread <= UNIFORM_RTOL * np.abs(a).max(axis=(0, 1))):
        return a.mean(axis=(0, 1))
    return None


def write_exr(path: str | os.PathLike, a: np.ndarray) -> None:
    """A texture as a 32-bit float OpenEXR: (H, W, 3) as ``R,G,B``, (H, W, 1) or (H, W) as ``Y``,
    row 0 the top row (increasing-Y line order, OpenEXR's default)."""
    import OpenEXR

    a = np.asarray(a, np.float32)
    channels = {"RGB": np.ascontiguousarray(a)} if a.ndim == 3 and a.shape[-1] == 3 else {
        "Y": np.ascontiguousarray(a.reshape(a.shape[:2]))}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, channels) as f:
        f.write(str(path))
