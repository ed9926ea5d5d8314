"""Phong, energy-normalised (the modern BRDF form of Phong's lobe).

B. T. Phong, "Illumination for Computer Generated Pictures", CACM 18(6), 1975 (the lobe).
R. R. Lewis, "Making Shaders More Physically Plausible", CGF 13(2), 1994 (the normalisation).

Parameters
----------
====  ========  ==============  ========  =======  ========  ============================================
name  channels  bounds          physical  default  role      meaning
====  ========  ==============  ========  =======  ========  ============================================
kd    3         [0, inf)        [0, 1]    0.1      albedo    diffuse albedo (linear)
ks    3         [0, inf)        [0, 1]    0.5      albedo    specular albedo at normal incidence (linear)
n     1         [1, inf) (log)  [1, 1e4]  20       exponent  Phong exponent (shininess)
====  ========  ==============  ========  =======  ========  ============================================

Bounds (what the formula needs): kd, ks >= 0, no upper bound (arbitrary units); n >= 1 (below 1 the
lobe's gradient with respect to the directions is infinite at its edge r.v = 0), no upper bound.
Physical range (``physical=True``): kd <= 1, ks <= 1 (the normalisation makes ks the lobe's albedo
at normal incidence), n <= 1e4 (a lobe about 1 degree wide, the sharpest a measurement resolves).

BRDF form implemented::

    f_r = kd/pi + ks (n+2)/(2 pi) max(0, r.v)^n,     r = 2(n.l)n - l  (mirror of the light)

Lecture form (Phong 1975)::

    I = I_a k_a + I_L [ k_d (n.l) + r_s (v.r)^h ]

The lecture's specular term I_s = I_L r_s (v.r)^h is *radiance for a given light*, so its BRDF is
I_s / (I_L (n.l)) = r_s (v.r)^h / (n.l) -- that is ``phong_classic``, which is not reciprocal and
not energy-conserving. This model instead takes the lobe (v.r)^h itself as the BRDF shape (h = n)
and scales it with Lewis' factor (n+2)/(2 pi), which makes ks the lobe's albedo at normal
incidence: ks <= 1 conserves energy, and f_r is reciprocal because r(l).v = r(v).l. The
diffuse term k_d (n.l) becomes the BRDF kd/pi (the cosine belongs to the rendering equation; the
1/pi makes kd the diffuse albedo). The ambient term I_a k_a is a constant light, not part of f_r.
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
    Param("ks", 3, 0.0, INF, 0.5, "albedo", linear=True, doc="specular albedo at normal incidence", physical=(0.0, 1.0)),
    Param("n", 1, 1.0, INF, 20.0, "exponent", doc="Phong exponent", physical=(1.0, 1e4)),
)


def lobe(wi, wo, n):
    """max(0, r.v)^n with r the mirror of wi, (N, 1)."""
    return m.safe_pow(m.dot(m.reflect(wi), wo), n)


def formula(p, wi, wo):
    n = p["n"]
    return p["kd"] / jnp.pi + p["ks"] * (n + 2.0) / (2.0 * jnp.pi) * lobe(wi, wo, n)


def halfwidth(p):
    """(r.v)^n = 1/2 at the angle acos(2^(-1/n)) from the mirror direction."""
    return np.arccos(2.0 ** (-1.0 / np.asarray(p["n"], np.float64)))


def sampling(p):
    return (Proposal("cosine", scales=("kd",)), Proposal("power", (p("n"), -1.0, 1.0), ("ks",)))


MODEL = Model(
    name="phong",
    params=PARAMS,
    formula=formula,
    citation="B. T. Phong, Illumination for Computer Generated Pictures, CACM 18(6), 1975; "
    "normalisation: R. R. Lewis, Making Shaders More Physically Plausible, CGF 13(2), 1994",
    reciprocal=True,
    float32_jacobian=True,  # measured: tests/test_structure.py, benchmarks/README.md
    doc=__doc__,
    halfwidth=halfwidth,
    sampling=sampling,
)
