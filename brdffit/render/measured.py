"""RGL-EPFL measured data (Dupuy & Jakob 2018) in Mitsuba's own ``measured`` plugin (SPEC 3).

The reader (:mod:`brdffit.io.rgl`) checks a file and builds the Measurement; it imports no
renderer. Evaluating the data is Mitsuba's part, here: :func:`load_measured` (the one door to the
plugin) and :func:`eval_measured`, which ``import brdffit`` provides to the reader as ``rgl_eval``
(brdffit/_wiring.py).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._mitsuba import mitsuba
from ..errors import InputError
from ..io import rgl
from .evaluate import eval_bsdf


def load_measured(path: str | Path):
    """Mitsuba's ``measured`` BSDF for an RGL file, verified first (the one door to the plugin)."""
    path = Path(path)
    rgl.check_tensor_file(path)
    mi = mitsuba()
    try:
        return mi.load_dict({"type": "measured", "filename": str(path)})
    except Exception as exc:  # noqa: BLE001 - Mitsuba's own parse errors become one line
        raise InputError(path, f"Mitsuba's measured plugin cannot read it: {' '.join(str(exc).split())[:300]}") from None


def eval_measured(path: Path, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """f_r(light, view), (N, 3): Mitsuba's ``measured`` plugin evaluated for all pairs at once by
    :func:`brdffit.render.evaluate.eval_bsdf`, the one way brdffit evaluates a Mitsuba BSDF outside a
    render (the validation's reference table is evaluated the same way)."""
    return eval_bsdf(load_measured(path), light, view)
