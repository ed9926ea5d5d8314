"""Mitsuba 3's ``roughplastic`` plugin (GGX), as a native model (docs/materials.md#native-materials-and-exports).

W. Jakob et al., Mitsuba 3 renderer, ``src/bsdfs/roughplastic.cpp`` (2022-); B. Walter,
S. R. Marschner, H. Li, K. E. Torrance, "Microfacet Models for Refraction through Rough Surfaces",
EGSR 2007; the diffuse base under a rough dielectric coating after C. Kelemen, L. Szirmay-Kalos,
"A Microfacet Based Coupled Specular-Matte BRDF Model with Importance Sampling", Eurographics 2001.

Parameters
----------
====================  ========  ==================  ============  =======  ==========  ===========================================
name                  channels  bounds              physical      default  role        meaning
====================  ========  ==================  ============  =======  ==========  ===========================================
diffuse_reflectance   3         [0, 1]              [0, 1]        0.5      albedo      the plugin's ``diffuse_reflectance`` (linear)
alpha                 1         [1e-4, 1] (log)     [1e-4, 1]     0.1      roughness   GGX roughness of the coating (``alpha``)
int_ior               1         [1.05, 3]           [1.05, 3]     1.49     fresnel     interior IOR (``int_ior``; ``ext_ior`` is 1)
specular_reflectance  3         [0, 1]              [0, 1]        1        albedo      the plugin's ``specular_reflectance`` (linear)
====================  ========  ==================  ============  =======  ==========  ===========================================

f_r = specular_reflectance F(v.h; eta) D(h) G1(l, h) G1(v, h) / (4 (n.l)(n.v))
    + diffuse_reflectance / (1 - R_int) T(n.l) T(n.v) / (pi eta^2)

with eta = int_ior / ext_ior, Mitsuba's isotropic GGX D and separable Smith G1, the exact
dielectric Fresnel F, and the plugin's two precomputed terms: T, the rough interface's external
transmittance tabulated at 64 cosines and interpolated linearly, and R_int, its hemispherical
internal reflectance (both integrated over visible normals with Gauss-Legendre nodes, as Mitsuba
does; ``brdffit.models._mitsuba_math``). ``nonlinear`` is the plugin's default, false: the diffuse
term is linear in diffuse_reflectance. Mitsuba's ``eval`` returns f_r (n.l): the tests hold this
formula equal to it (tests/test_native_models.py).

``native()`` writes every setting the formula relies on: ``distribution`` ggx (the plugin default
is Beckmann), ``ext_ior`` 1 (its default is air, 1.000277), ``nonlinear`` false and the
reflectances as RGB. Bounds: what Mitsuba accepts (reflectances in [0, 1], int_ior != ext_ior).
"""

from __future__ import annotations

import jax.numpy as jnp

from . import _math as m
from ._mitsuba_math import fresnel_dielectric, ggx_d, ggx_halfwidth, lerp_table, rgb, rough_tables, smith_g1
from .base import Lobe, Model, Param, Proposal

#: The exterior medium's IOR written into every export (vacuum): eta = int_ior.
EXT_IOR = 1.0

PARAMS = (
    Param("diffuse_reflectance", 3, 0.0, 1.0, 0.5, "albedo", linear=True, doc="diffuse reflectance"),
    Param("alpha", 1, 1e-4, 1.0, 0.1, "roughness", doc="GGX roughness (Mitsuba alpha)"),
    Param("int_ior", 1, 1.05, 3.0, 1.49, "fresnel", doc="interior index of refraction"),
    Param("specular_reflectance", 3, 0.0, 1.0, 1.0, "albedo", linear=True, doc="specular reflectance scale"),
)


def formula(p, wi, wo):
    alpha, eta = p["alpha"], p["int_ior"] / EXT_IOR
    h = m.half_vector(wi, wo)
    d = ggx_d(h, alpha)
    g = smith_g1(wi, h, alpha) * smith_g1(wo, h, alpha)
    f, _, _ = fresnel_dielectric(jnp.clip(m.dot(wo, h), 0.0, 1.0), eta)
    cos_i, cos_o = m.cos_theta(wi), m.cos_theta(wo)
    specular = p["specular_reflectance"] * f * d * g / (4.0 * cos_i * cos_o)
    table, r_int = rough_tables(alpha[0], eta[0])
    t_i, t_o = lerp_table(table, cos_i), lerp_table(table, cos_o)
    diffuse = p["diffuse_reflectance"] / (1.0 - r_int) * t_i * t_o / (jnp.pi * eta * eta)
    return specular + diffuse


def to_native(p) -> dict:
    return {
        "type": "roughplastic",
        "distribution": "ggx",
        "alpha": float(p["alpha"][0]),
        "int_ior": float(p["int_ior"][0]),
        "ext_ior": EXT_IOR,
        "nonlinear": False,
        "diffuse_reflectance": rgb(p["diffuse_reflectance"]),
        "specular_reflectance": rgb(p["specular_reflectance"]),
    }


def sampling(p):
    a = p("alpha")
    return (Proposal("cosine", scales=("diffuse_reflectance",)), Proposal("ggx", (a, a), ("specular_reflectance",)))


MODEL = Model(
    name="mitsuba:roughplastic",
    params=PARAMS,
    formula=formula,
    citation="Mitsuba 3 roughplastic (GGX); Walter, Marschner, Li, Torrance: Microfacet Models for "
             "Refraction through Rough Surfaces, EGSR 2007",
    reciprocal=True,
    doc=__doc__,
    lobes=(Lobe("mitsuba:roughplastic", ("alpha", "int_ior", "specular_reflectance")),),
    halfwidth=ggx_halfwidth,
    to_native=to_native,
    sampling=sampling,
)
