"""Blinn-Phong: the half-vector form of Phong's lobe, energy-normalised.

J. F. Blinn, "Models of Light Reflection for Computer Synthesized Pictures", SIGGRAPH 1977.
Normalisation (n+8)/(8 pi): T. Akenine-Moeller, E. Haines, N. Hoffman, *Real-Time Rendering*,
3rd ed., 2008, sec. 7.6 (an approximation of the exact factor, within a few percent).

Parameters
----------
====  ========  ==============  ========  =======  ========  =======================================
name  channels  bounds          physical  default  role      meaning
====  ========  ==============  ========  =======  ========  =======================================
kd    3         [0, inf)        [0, 1]    0.1      albedo    diffuse albedo (linear)
ks    3         [0, inf)        [0, 1]    0.5      albedo    specular albedo, approximately (linear)
n     1         [1, inf) (log)  [1, 1e4]  20       exponent  Blinn exponent
====  ========  ==============  ========  =======  ========  =======================================

Bounds (what the formula needs): kd, ks >= 0, no upper bound (arbitrary units); n >= 1 (as for
``phong``), no upper bound. Physical range (``physical=True``): kd <= 1, ks <= 1 (ks is about the
specular albedo), n <= 1e4.

BRDF form implemented::

    f_r = kd/pi + ks (n+8)/(8 pi) (n.h)^n,      h = (l + v)/|l + v|

Lecture form (Blinn 1977)::

    I = I_a k_a + I_L [ k_d (n.l) + k_s (n.h)^n ]

Blinn replaced Phong's (v.r) with (n.h): cheaper for a distant light and viewer, and the lobe
stretches correctly at grazing angles. Taken literally as a BRDF, the lecture's specular term is
k_s (n.h)^n / (n.l) (not reciprocal). The modern form drops the 1/(n.l) and multiplies by
(n+8)/(8 pi), so that ks is roughly the specular albedo whatever the exponent, and f_r is
reciprocal (h is symmetric in l and v). kd = pi k_d as for Lambert; the ambient term is not part
of f_r. Note that a Blinn-Phong exponent is about 4x the Phong exponent of the same highlight.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from . import _math as m
from .base import Model, Param, Proposal

INF = math.inf

PARAMS = (
    Param("kd", 3, 0.0, INF, 0.1, "albedo", linear=True, doc="diffuse albedo", physical=(0.0, 1.0)),
    Param("ks", 3, 0.0, INF, 0.5, "albedo", linear=True, doc="specular albedo (approximately)", physical=(0.0, 1.0)),
    Param("n", 1, 1.0, INF, 20.0, "exponent", doc="Blinn exponent", physical=(1.0, 1e4)),
)


def formula(p, wi, wo):
    n = p["n"]
    h = m.half_vector(wi, wo)
    return p["kd"] / jnp.pi + p["ks"] * (n + 8.0) / (8.0 * jnp.pi) * m.safe_pow(h[..., 2:3], n)


def halfwidth(p):
    """(n.h)^n = 1/2 at th_h = acos(2^(-1/n)); twice that in reflected directions."""
    return 2.0 * np.arccos(2.0 ** (-1.0 / np.asarray(p["n"], np.float64)))


def sampling(p):
    n = p("n")
    return (Proposal("cosine", scales=("kd",)), Proposal("half_power", (n, n), ("ks",)))


MODEL = Model(
    name="blinn_phong",
    params=PARAMS,
    formula=formula,
    citation="J. F. Blinn, Models of Light Reflection for Computer Synthesized Pictures, SIGGRAPH 1977",
    reciprocal=True,
    float32_jacobian=True,  # measured: tests/test_structure.py, benchmarks/README.md
    doc=__doc__,
    halfwidth=halfwidth,
    sampling=sampling,
)
