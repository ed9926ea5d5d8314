"""Cook-Torrance: Beckmann microfacet distribution, V-cavity shadowing, Schlick Fresnel.

R. L. Cook, K. E. Torrance, "A Reflectance Model for Computer Graphics", ACM TOG 1(1), 1982.
P. Beckmann, A. Spizzichino, *The Scattering of Electromagnetic Waves from Rough Surfaces*, 1963.
C. Schlick, "An Inexpensive BRDF Model for Physically-based Rendering", CGF 13(3), 1994.

Parameters
----------
=====  ========  =================  =========  =======  =========  =======================================
name   channels  bounds             physical   default  role       meaning
=====  ========  =================  =========  =======  =========  =======================================
kd     3         [0, inf)           [0, 1]     0.1      albedo     diffuse albedo (linear)
ks     3         [0, inf)           [0, 1]     0.5      albedo     specular scale (linear)
alpha  1         [1e-4, inf) (log)  [1e-4, 1]  0.2      roughness  Beckmann rms slope (the paper's m)
f0     1         [0, 1]             [0, 1]     0.04     fresnel    Schlick reflectance at normal incidence
=====  ========  =================  =========  =======  =========  =======================================

Bounds (what the formula needs): kd, ks >= 0, no upper bound (arbitrary units, ks > 1 for
measured gloss); alpha > 0, floored at 1e-4 (Beckmann D evaluated in log space is exact there), no
upper bound; f0 in [0, 1]. Physical range (``physical=True``): kd, ks <= 1 (normalised D, F G <= 1:
each term's albedo is at most its scale), alpha <= 1.

BRDF form implemented (the modern normalisation)::

    f_r = kd/pi + ks F(h.l) G D(h) / (4 (n.l)(n.v))
    D = exp(-tan^2 th_h / alpha^2) / (pi alpha^2 cos^4 th_h)                 (Beckmann, normalised:
                                                                              int D (n.h) dw = 1)
    G = min(1, 2(n.h)(n.v)/(v.h), 2(n.h)(n.l)/(v.h))                          (V-cavity)
    F = f0 + (1 - f0)(1 - h.l)^5                                              (Schlick)

The 1982 paper writes R_s = F D G / (pi (n.l)(n.v)) with D_1982 = exp(-tan^2/m^2) / (m^2 cos^4)
= pi D: the same shape, 4 times larger (the modern 1/4 is the Jacobian of the half-vector map,
Walter et al. 2007), so ks_1982 = ks / 4 with alpha = m. Cook and Torrance used the full Fresnel
equations; Schlick's approximation (docs/models.md#models) replaces them. Lecture form: the specular term of the
lecture's ambient + diffuse + specular sum, I_s = I_L (n.l) ks F G D / (4 (n.l)(n.v)).
D is evaluated in log space so that alpha = 1e-4 and grazing half vectors stay finite in float32;
cosines are clamped at 1e-7 at the horizon. Reciprocal.
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
    Param("ks", 3, 0.0, INF, 0.5, "albedo", linear=True, doc="specular scale", physical=(0.0, 1.0)),
    Param("alpha", 1, 1e-4, INF, 0.2, "roughness", doc="Beckmann rms slope m", physical=(1e-4, 1.0)),
    Param("f0", 1, 0.0, 1.0, 0.04, "fresnel", doc="Schlick reflectance at normal incidence"),
)


def beckmann_ndf(h, alpha):
    """exp(-tan^2 th_h/alpha^2) / (pi alpha^2 cos^4 th_h), (N, 1), computed as exp(log D)."""
    c2 = m.hz_sq(h)
    tan2 = (h[..., 0:1] ** 2 + h[..., 1:2] ** 2) / c2
    log_d = -tan2 / alpha**2 - jnp.log(jnp.pi * alpha**2) - 2.0 * jnp.log(c2)
    return jnp.exp(log_d)


def microfacet_lobe(p, wi, wo, h, d):
    """ks F G D / (4 (n.l)(n.v)) with V-cavity G and Schlick F, given the half vector h and D (N, 1)."""
    cl, cv = m.cos_theta(wi), m.cos_theta(wo)
    vh = m.dot(wo, h)
    g = m.v_cavity_g(jnp.maximum(h[..., 2:3], 0.0), cl, cv, vh)
    f = m.schlick_fresnel(p["f0"], m.dot(wi, h))
    return p["ks"] * f * g * d / (4.0 * cl * cv)


def formula(p, wi, wo):
    h = m.half_vector(wi, wo)
    return p["kd"] / jnp.pi + microfacet_lobe(p, wi, wo, h, beckmann_ndf(h, p["alpha"]))


def halfwidth(p):
    """Beckmann D(th_h)/D(0) ~ exp(-tan^2 th_h/alpha^2) = 1/2 at tan th_h = alpha sqrt(ln 2); twice
    that in reflected directions."""
    return 2.0 * np.arctan(p["alpha"] * math.sqrt(math.log(2.0)))


def sampling(p):
    a = p("alpha")
    return (Proposal("cosine", scales=("kd",)), Proposal("beckmann", (a, a), ("ks",)))


MODEL = Model(
    name="cook_torrance",
    params=PARAMS,
    formula=formula,
    citation="R. L. Cook, K. E. Torrance, A Reflectance Model for Computer Graphics, ACM TOG 1(1), 1982",
    reciprocal=True,
    float32_jacobian=True,  # measured: tests/test_structure.py, benchmarks/README.md
    doc=__doc__,
    halfwidth=halfwidth,
    sampling=sampling,
)
