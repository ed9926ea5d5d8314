"""Lambert: the ideal diffuse reflector.

J. H. Lambert, *Photometria*, 1760.

Parameters
----------
====  ========  ========  ========  =======  ======  =======================
name  channels  bounds    physical  default  role    meaning
====  ========  ========  ========  =======  ======  =======================
kd    3         [0, inf)  [0, 1]    0.5      albedo  diffuse albedo (linear)
====  ========  ========  ========  =======  ======  =======================

Bounds (what the formula needs): kd >= 0, no upper bound (data in arbitrary units). Physical
range (``physical=True``): kd <= 1 (the albedo is kd).

Lecture form: I_d = I_L k_d (n . l). As a BRDF the cosine belongs to the rendering equation, not to
f_r, and energy conservation fixes the 1/pi: f_r = k_d / pi, whose directional albedo is k_d
(so kd here is pi times a lecture k_d that was calibrated as "I_d / (I_L (n.l))"). The lecture's
ambient term I_a k_a is a constant light, not part of any f_r. Equals Mitsuba's ``diffuse``.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from .base import Model, Param, Proposal

INF = math.inf

PARAMS = (
    Param("kd", 3, 0.0, INF, 0.5, "albedo", linear=True, doc="diffuse albedo", physical=(0.0, 1.0)),
)


def formula(p, wi, wo):
    # (1, C): broadcasts against the (N, C) of other terms; Model.eval broadcasts to (N, C).
    return jnp.reshape(p["kd"], (1, -1)) / jnp.pi


def sampling(p):
    return (Proposal("cosine", scales=("kd",)),)


MODEL = Model(
    name="lambert",
    params=PARAMS,
    formula=formula,
    citation="J. H. Lambert, Photometria, 1760",
    reciprocal=True,
    float32_jacobian=True,  # measured: tests/test_structure.py, benchmarks/README.md
    doc=__doc__,
    sampling=sampling,
)
