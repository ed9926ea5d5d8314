"""f_r outside a render: an analytic model through its compiled JAX formula (the one evaluator,
``brdffit.fitting.model_eval``, which ``FitResult.eval`` uses too), any Mitsuba BSDF at given
directions (SPEC 1's order: wi towards the light, wo towards the viewer; 1/sr, the cosine removed).
The callback BSDF (``bsdf``), the sampler's lobe weights (``sampling``) and the RGL reader's
evaluator (``measured``) use them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._mitsuba import evaluated_calls, mitsuba

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


def eval_bsdf(bsdf, wi: Float[np.ndarray, "N 3"], wo: Float[np.ndarray, "N 3"]) -> Float[np.ndarray, "N 3"]:
    """f_r(wi = light, wo = view) of any Mitsuba BSDF at local directions, in 1/sr (cosine removed).

    This is how a ``measured`` RGL reference is evaluated outside a render (the 81x81 table panel,
    the closed-form agreement test), in the order Mitsuba renders it (SPEC 3).
    """
    mi = mitsuba()
    wi = np.asarray(wi, np.float64).reshape(-1, 3)
    wo = np.asarray(wo, np.float64).reshape(-1, 3)
    n = wi.shape[0]
    if mi.variant().startswith("scalar"):
        out = np.zeros((n, 3))
        ctx = mi.BSDFContext()
        for k in range(n):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*wo[k])
            si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
            v = bsdf.eval(ctx, si, mi.Vector3f(*wi[k]))
            out[k] = np.array([v[0], v[1], v[2]], np.float64)
    else:
        import drjit as dr

        si = dr.zeros(mi.SurfaceInteraction3f, n)  # every field defined, at the batch's width
        si.wi = mi.Vector3f(*(mi.Float(wo[:, c].astype(np.float32)) for c in range(3)))
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        with evaluated_calls():
            v = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*(mi.Float(wi[:, c].astype(np.float32)) for c in range(3))))
        out = np.stack([np.asarray(v[c], np.float64) for c in range(3)], -1).reshape(n, 3)
    cos_l = wi[:, 2:3]
    return np.where(cos_l > 0, out / np.where(cos_l > 0, cos_l, 1.0), 0.0)
