"""Torrance-Sparrow: Gaussian distribution of V-groove facets in the half-angle, V-cavity
shadowing, Schlick Fresnel.

K. E. Torrance, E. M. Sparrow, "Theory for Off-Specular Reflection from Roughened Surfaces",
JOSA 57(9), 1967. C. Schlick, CGF 13(3), 1994 (Fresnel approximation).

Parameters
----------
====  ========  =================  ==========  =======  =========  ==========================================
name  channels  bounds             physical    default  role       meaning
====  ========  =================  ==========  =======  =========  ==========================================
kd    3         [0, inf)           [0, 1]      0.1      albedo     diffuse albedo (linear)
ks    3         [0, inf)           [0, 1e5]    1        albedo     specular scale, the paper's constant b
                                                                   (linear; not normalised, see below)
m     1         [1e-4, inf) (log)  [1e-4, 1]   0.2      roughness  width of the facet-angle Gaussian, radians
f0    1         [0, 1]             [0, 1]      0.04     fresnel    Schlick reflectance at normal incidence
====  ========  =================  ==========  =======  =========  ==========================================

Bounds (what the formula needs): kd, ks >= 0, no upper bound; m > 0, floored at 1e-4, no upper
bound (a wide Gaussian is finite); f0 in [0, 1]. Physical range (``physical=True``): kd <= 1;
m <= 1 radian; ks <= 1e5: energy conservation asks ks F pi m^2 <= 1 (see below), which couples
ks with m and is no box; 1e5 is that limit at m = 1.8e-3 (a lobe 0.3 degrees wide at half
maximum, far below what any sample spacing resolves: ``fit`` warns about such lobes), so a
larger ks is not plausible.

Formula (docs/models.md#models, the paper's form)::

    f_r = kd/pi + ks F(h.l) G D / (4 (n.l)(n.v))
    D = exp(-(th_h / m)^2)            th_h = angle between h and n (the paper's alpha), radians
    G = min(1, 2(n.h)(n.v)/(v.h), 2(n.h)(n.l)/(v.h))       (the paper's V-groove shadowing)
    F = f0 + (1 - f0)(1 - h.l)^5

The paper's distribution is P(alpha) = b exp(-c^2 alpha^2) with an arbitrary constant b; here
c = 1/m and b is folded into ks, so D is *not* normalised: D(n) = 1 whatever m. The specular
albedo is therefore about ks F pi m^2, and a sharp highlight needs ks ~ 1/(pi m^2) -- hence the
wide physical range of ks. (A modern normalisation would divide D by pi m^2; Cook-Torrance and GGX here are
normalised, with ks <= 1 physical.) th_h is computed as atan2(|h_xy|, h_z), whose gradient is finite at
h = n (acos' is not). Paper form vs lecture: the specular term of the ambient + diffuse +
specular sum. Reciprocal.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from . import _math as m
from .base import Model, Param, Proposal

INF = math.inf
from .cook_torrance import microfacet_lobe

PARAMS = (
    Param("kd", 3, 0.0, INF, 0.1, "albedo", linear=True, doc="diffuse albedo", physical=(0.0, 1.0)),
    Param("ks", 3, 0.0, INF, 1.0, "albedo", linear=True, scale="linear", doc="specular scale (paper's b)", physical=(0.0, 1e5)),
    Param("m", 1, 1e-4, INF, 0.2, "roughness", doc="Gaussian width of facet angles, radians", physical=(1e-4, 1.0)),
    Param("f0", 1, 0.0, 1.0, 0.04, "fresnel", doc="Schlick reflectance at normal incidence"),
)


def gaussian_facets(h, width):
    """exp(-(th_h/width)^2), (N, 1)."""
    th = jnp.arctan2(m.safe_norm(h[..., 0:2]), jnp.maximum(h[..., 2:3], 0.0))
    return jnp.exp(-((th / width) ** 2))


def formula(p, wi, wo):
    h = m.half_vector(wi, wo)
    return p["kd"] / jnp.pi + microfacet_lobe(p, wi, wo, h, gaussian_facets(h, p["m"]))


def halfwidth(p):
    """exp(-(th_h/m)^2) = 1/2 at th_h = m sqrt(ln 2); twice that in reflected directions."""
    return 2.0 * p["m"] * math.sqrt(math.log(2.0))


def sampling(p):
    """The Gaussian in the half angle is sampled as Beckmann of alpha = m (the same lobe for small
    angles, tan th ~ th)."""
    a = p("m")
    return (Proposal("cosine", scales=("kd",)), Proposal("beckmann", (a, a), ("ks",)))


MODEL = Model(
    name="torrance_sparrow",
    params=PARAMS,
    formula=formula,
    citation="K. E. Torrance, E. M. Sparrow, Theory for Off-Specular Reflection from Roughened Surfaces, "
    "JOSA 57(9), 1967",
    reciprocal=True,
    float32_jacobian=True,  # measured: tests/test_structure.py, benchmarks/README.md
    doc=__doc__,
    halfwidth=halfwidth,
    sampling=sampling,
)
