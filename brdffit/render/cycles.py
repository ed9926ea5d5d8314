"""The second renderer of a validation: Blender's Cycles (docs/materials.md#native-materials-and-exports), same framing as docs/validation.md#validation-rendering.

``render_sphere(..., renderer="cycles")`` (the registry: :mod:`brdffit.render.renderers`) renders a ``blender:principled`` fit with Blender's own
Principled BSDF (the fit's ``native()`` dict, distribution GGX) through the Blender worker
(:mod:`brdffit.cycles`): the unit sphere (an exact sphere, Cycles' point primitive), the orthographic
camera on +z, one sun of angle 0 per light, direct light only, a box pixel filter, linear radiance.
Only a native Blender fit renders there: a measurement, or a fit of another model, is one UsageError
line (the reference of a validation is always rendered by Mitsuba).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError, UsageError

CYCLES_MODEL = "blender:principled"


def cycles_material(src) -> dict:
    """The Principled BSDF settings of a source, or one line saying why Cycles cannot render it."""
    if src.kind != "model":
        raise UsageError(f"renderer 'cycles' renders {CYCLES_MODEL} fits; {src.label} is a measurement "
                         "(a validation renders its reference with Mitsuba)")
    if src.model.name != CYCLES_MODEL:
        raise UsageError(f"renderer 'cycles' renders {CYCLES_MODEL} fits, and this fit is {src.model.name}: "
                         f"convert it first (brdffit.materials.convert(fit, {CYCLES_MODEL!r}), or fit with --model {CYCLES_MODEL})")
    try:
        return src.model.native({k: np.asarray(v) for k, v in src.params.items()})
    except ValueError as exc:
        raise InputError(None, f"cannot render in Cycles: {exc}") from None


def render_sphere_cycles(src, dirs: np.ndarray, size: int, irradiance: float, spp: int, seed: int,
                         mask: np.ndarray, progress=None) -> np.ndarray:
    """(L, size, size, 3) float32 linear radiance, zero outside the disc (as the Mitsuba path)."""
    from .. import cycles

    material = cycles_material(src)
    out = np.zeros((len(dirs), size, size, 3), np.float32)
    for k, d in enumerate(dirs):  # one light a request: progress per image, as the Mitsuba path
        img = cycles.render_sphere(material, [d], size=size, irradiance=irradiance, spp=spp, seed=seed)[0]
        out[k] = np.where(mask[..., None], img, 0.0)
        if progress is not None:
            progress(k + 1, len(dirs))
    return out
