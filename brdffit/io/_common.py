"""Helpers shared by the readers."""

from __future__ import annotations

import numpy as np

from ..errors import UsageError
from ..grid import ubo_pairs


def query_directions(wi=None, wo=None) -> tuple[np.ndarray, np.ndarray, str | None]:
    """The (light, view) pairs a reader that can evaluate anywhere should sample.

    Default: the UBO-81 pairs (grid "ubo81"); else the given unit vectors (grid None).
    """
    if wi is None and wo is None:
        wi, wo = ubo_pairs()
        return wi, wo, "ubo81"
    if wi is None or wo is None:
        raise UsageError("give both wi and wo (light and view directions), or neither for the UBO-81 grid")
    wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
    wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
    if wi.shape != wo.shape or wi.ndim != 2 or wi.shape[1] != 3:
        raise UsageError(f"wi {wi.shape} and wo {wo.shape} must both be (N, 3)")
    return wi, wo, None


def file_size(path) -> int:
    import os

    return os.path.getsize(path)
