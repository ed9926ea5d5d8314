"""Phong, the lecture's form taken literally as a BRDF (not reciprocal, not energy-normalised).

B. T. Phong, "Illumination for Computer Generated Pictures", CACM 18(6), 1975.

Parameters
----------
====  ========  ==============  =========  =======  ========  =============================================
name  channels  bounds          physical   default  role      meaning
====  ========  ==============  =========  =======  ========  =============================================
kd    3         [0, inf)        [0, 1]     0.1      albedo    diffuse albedo (linear)
ks    3         [0, inf)        [0, 1600]  0.5      albedo    the lecture's r_s (linear); no normalisation,
                                                              so sharp lobes need large values
n     1         [1, inf) (log)  [1, 1e4]   20       exponent  the lecture's h (shininess)
====  ========  ==============  =========  =======  ========  =============================================

Bounds (what the formula needs): kd, ks >= 0, no upper bound; n >= 1, no upper bound. Physical
range (``physical=True``): kd <= 1; n <= 1e4; ks <= 1.6e3: the lobe's albedo at normal incidence is
about ks 2 pi/(n + 1), so ks <= (n + 1)/(2 pi) couples ks with n; the physical box holds every ks
that allows for n <= 1e4 (1592).

Lecture form::

    I = I_a k_a + I_L [ k_d (n.l) + r_s (v.r)^h ],      r = 2(n.l)n - l

BRDF form implemented: divide the light-dependent part by the irradiance I_L (n.l)::

    f_r = kd/pi + ks max(0, r.v)^n / (n.l)

with kd = pi k_d (the lecture's diffuse coefficient times pi is the diffuse albedo), ks = r_s,
n = h. The ambient term is a constant light, not part of f_r. Because of the 1/(n.l), this f_r is
**not reciprocal** (f(l, v) != f(v, l)) and its albedo is not bounded by ks; the energy-normalised,
reciprocal variant is ``phong``. (n.l) is clamped at 1e-7 at the horizon.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from . import _math as m
from .base import Model, Param, Proposal

INF = math.inf

PARAMS = (
    Param("kd", 3, 0.0, INF, 0.1, "albedo", linear=True, doc="diffuse albedo (pi times the lecture's k_d)", physical=(0.0, 1.0)),
    Param("ks", 3, 0.0, INF, 0.5, "albedo", linear=True, scale="linear", doc="the lecture's r_s", physical=(0.0, 1.6e3)),
    Param("n", 1, 1.0, INF, 20.0, "exponent", doc="the lecture's exponent h", physical=(1.0, 1e4)),
)


def formula(p, wi, wo):
    spec = m.safe_pow(m.dot(m.reflect(wi), wo), p["n"]) / m.cos_theta(wi)
    return p["kd"] / jnp.pi + p["ks"] * spec


def halfwidth(p):
    """(r.v)^n = 1/2 at the angle acos(2^(-1/n)) from the mirror direction."""
    return np.arccos(2.0 ** (-1.0 / np.asarray(p["n"], np.float64)))


def sampling(p):
    return (Proposal("cosine", scales=("kd",)), Proposal("power", (p("n"), -1.0, 1.0), ("ks",)))


MODEL = Model(
    name="phong_classic",
    params=PARAMS,
    formula=formula,
    citation="B. T. Phong, Illumination for Computer Generated Pictures, CACM 18(6), 1975",
    reciprocal=False,
    float32_jacobian=True,  # measured: tests/test_structure.py, benchmarks/README.md
    doc=__doc__,
    halfwidth=halfwidth,
    sampling=sampling,
)
