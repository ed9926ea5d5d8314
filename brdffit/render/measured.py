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


#: How far (radians) a direction is moved off a pole of the plugin's parametrisation, towards azimuth 0.
POLE_NUDGE = 1e-6


def _towards_azimuth_0(d: np.ndarray, rows: np.ndarray) -> None:
    """Turn ``d[rows]`` by POLE_NUDGE about the y axis, towards +x, in place: y is kept exactly, so a
    vector at the pole (or a half vector there) leaves it along azimuth 0 exactly, which is the way
    the plugin's interpolation is approached (its value at a pole depends on the way)."""
    x, z = d[rows, 0], d[rows, 2]
    c, s = np.cos(POLE_NUDGE), np.sin(POLE_NUDGE)
    d[rows, 0], d[rows, 2] = x * c + z * s, z * c - x * s


def off_the_poles(light: np.ndarray, view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(light, view) (N, 3) read at azimuth 0 where the plugin's parametrisation has a pole.

    The plugin reads the view's azimuth and the half vector's as atan2(y, x). Where that vector is at
    the pole (x = y = 0: a view along the normal; a light and view mirrored about it, whose half
    vector is the normal) atan2 gives 0 or pi by the sign of a zero, and Dr.Jit's fast-math kernels
    do not keep that sign the same from one compiled kernel to another: the UBO table came out with
    rows mirrored, or mirrored pairs swapped, after other renders in the same process. So such a view
    is turned POLE_NUDGE towards +x, and so is the light of a pair whose half vector is at the pole:
    the value read is the limit along azimuth 0, the same in every process (on the shared RGL files
    it differs from a fresh process's old exact-pole reading by up to 6 % at mirrored pairs, and by a
    mirrored light azimuth in the rows with the view at the pole). Elsewhere nothing moves."""
    # as the kernel sees them: in float32 (two directions that are not quite mirrored in float64 can
    # be, once rounded)
    light = np.asarray(light, np.float32).reshape(-1, 3).astype(np.float64)
    view = np.asarray(view, np.float32).reshape(-1, 3).astype(np.float64)
    at_pole = (view[:, 0] == 0) & (view[:, 1] == 0)
    view[at_pole, 1] = 0.0  # +0: its sign is what the kernels lose
    _towards_azimuth_0(view, at_pole)
    half = light + view
    _towards_azimuth_0(light, (half[:, 0] == 0) & (half[:, 1] == 0))
    return light, view


def eval_measured(path: Path, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """f_r(light, view), (N, 3): Mitsuba's ``measured`` plugin evaluated for all pairs at once by
    :func:`brdffit.render.evaluate.eval_bsdf`, the one way brdffit evaluates a Mitsuba BSDF outside a
    render (the validation's reference table is evaluated the same way), off the poles of its
    parametrisation (:func:`off_the_poles`)."""
    return eval_bsdf(load_measured(path), *off_the_poles(light, view))
