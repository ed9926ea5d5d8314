"""GGX (Trowbridge-Reitz) microfacet BRDF with a Lambertian base.

B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet Models for Refraction through Rough
Surfaces", EGSR 2007. T. S. Trowbridge, K. P. Reitz, JOSA 65(5), 1975. C. Schlick, "An Inexpensive
BRDF Model for Physically-based Rendering", CGF 13(3), 1994.

Parameters
----------
=====  ========  =================  =========  =======  =========  =======================================
name   channels  bounds             physical   default  role       meaning
=====  ========  =================  =========  =======  =========  =======================================
kd     3         [0, inf)           [0, 1]     0.1      albedo     diffuse albedo (linear)
ks     3         [0, inf)           [0, 1]     0.5      albedo     specular scale (linear)
alpha  1         [1e-4, inf) (log)  [1e-4, 1]  0.2      roughness  GGX roughness (= Mitsuba's alpha)
f0     1         [0, 1]             [0, 1]     0.04     fresnel    Schlick reflectance at normal incidence
=====  ========  =================  =========  =======  =========  =======================================

Bounds (what the formula needs): kd, ks >= 0 (a negative scale gives a negative BRDF), with no
upper bound, because measured tables are often in arbitrary units and glossy paints want ks > 1;
alpha > 0 (alpha = 0 is a mirror, a delta function), floored at 1e-4 where D is still exact in
float32, no upper bound (a very rough surface; D and G stay finite, see ``brdffit.testing``);
f0 in [0, 1] (Schlick's F leaves [0, 1] otherwise). Physical range (``physical=True``): kd <= 1 and
ks <= 1 (each term's albedo: D is normalised and F G <= 1, so the lobe reflects at most ks; the sum
kd + ks <= 1 is not enforced), alpha <= 1 (rms slope beyond 45 degrees).

f_r = kd/pi + ks F(h.l) G(l, v) D(h) / (4 (n.l)(n.v))

D(h) = alpha^2 / (pi (cos^2 th_h alpha^2 + sin^2 th_h)^2)    (the usual form, rearranged so that
                                                              it stays exact at alpha = 1e-4)
G    = G1(l) G1(v),  G1(w) = 2 / (1 + sqrt(1 + alpha^2 tan^2 th_w))    (separable Smith)
F    = f0 + (1 - f0)(1 - h.l)^5                                   (Schlick)

With kd = 0, ks = 1, f0 = 1 this is Mitsuba 3's ``roughconductor`` (distribution ggx, material
none, sample_visible irrelevant for eval) divided by cos(theta_o).

Lecture form: the specular term of the ambient + diffuse + specular sum, with the microfacet
BRDF in place of r_s (v.r)^h: I_s = I_L (n.l) ks F G D / (4 (n.l)(n.v)); D is normalised
(int D (n.h) dw = 1), so ks <= 1 is an energy-conserving reflectance scale. Reciprocal.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from . import _math as m
from . import _microfacet as mf
from .base import Model, Param, Proposal

INF = math.inf

PARAMS = (
    Param("kd", 3, 0.0, INF, 0.1, "albedo", linear=True, doc="diffuse albedo", physical=(0.0, 1.0)),
    Param("ks", 3, 0.0, INF, 0.5, "albedo", linear=True, doc="specular scale", physical=(0.0, 1.0)),
    Param("alpha", 1, 1e-4, INF, 0.2, "roughness", doc="GGX roughness (= Mitsuba alpha)", physical=(1e-4, 1.0)),
    Param("f0", 1, 0.0, 1.0, 0.04, "fresnel", doc="Schlick reflectance at normal incidence"),
)


def specular_lobe(p, wi, wo):
    """ks F G D / (4 (n.l)(n.v)) without the diffuse term, (N, C); D and G from the kit (``_microfacet``)."""
    h = m.half_vector(wi, wo)
    alpha = p["alpha"]
    d = mf.ggx_d(h, alpha)
    g = mf.smith_g1(wi, alpha) * mf.smith_g1(wo, alpha)
    f = m.schlick_fresnel(p["f0"], m.dot(wi, h))
    return p["ks"] * f * g * d / (4.0 * m.cos_theta(wi) * m.cos_theta(wo))


def formula(p, wi, wo):
    return p["kd"] / jnp.pi + specular_lobe(p, wi, wo)


def halfwidth(p):
    """D(th_h)/D(0) = 1/2 at tan th_h = alpha sqrt(sqrt(2) - 1); reflected directions: twice that."""
    return mf.halfwidth(p["alpha"])


def sampling(p):
    a = p("alpha")
    return (Proposal("cosine", scales=("kd",)), Proposal("ggx", (a, a), ("ks",)))


MODEL = Model(
    name="ggx",
    params=PARAMS,
    formula=formula,
    citation="Walter, Marschner, Li, Torrance: Microfacet Models for Refraction through Rough Surfaces, EGSR 2007",
    reciprocal=True,
    float32_jacobian=True,  # measured: tests/test_structure.py, benchmarks/README.md
    doc=__doc__,
    halfwidth=halfwidth,
    sampling=sampling,
)
