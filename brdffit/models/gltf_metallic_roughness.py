"""The glTF 2.0 core metallic-roughness material, as a native model (docs/materials.md#native-materials-and-exports).

The Khronos Group, "glTF 2.0 Specification", Appendix B "BRDF Implementation" (2021): GGX
(Trowbridge & Reitz 1975) with the height-correlated Smith masking-shadowing (Heitz 2014) and
Schlick's Fresnel (Schlick 1994).

Parameters
----------
==========  ========  =================  ===========  =======  =========  ==================================================
name        channels  bounds             physical     default  role       meaning
==========  ========  =================  ===========  =======  =========  ==================================================
base_color  3         [0, 1]             [0, 1]       0.5      albedo     ``baseColorFactor`` (linear RGB; alpha 1)
metallic    1         [0, 1]             [0, 1]       0        fresnel    ``metallicFactor``
roughness   1         [0.01, 1] (log)    [0.01, 1]    0.5      roughness  ``roughnessFactor`` (perceptual: alpha = roughness^2)
==========  ========  =================  ===========  =======  =========  ==================================================

    w = (1 - |v.h|)^5,  alpha = roughness^2
    S = D V:  D = alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2),
              V = 1 / (2 (|n.v| sqrt(alpha^2 + (1 - alpha^2)(n.l)^2) + |n.l| sqrt(alpha^2 + (1 - alpha^2)(n.v)^2)))
              (V = G2 / (4 (n.l)(n.v)) with G2 the height-correlated Smith G: the kit, ``_microfacet``)
    dielectric = (1 - F_d) base_color / pi + F_d S,   F_d = 0.04 + 0.96 w
    metal      = F_m S,                               F_m = base_color + (1 - base_color) w
    f_r        = (1 - metallic) dielectric + metallic metal

The factors are the parameters themselves: ``native()`` returns the glTF material object
(``pbrMetallicRoughness`` with ``baseColorFactor``, ``metallicFactor``, ``roughnessFactor``), no
extension, so every viewer that implements the core material shows this BRDF. The tests hold it
equal to an independent implementation of the appendix's ``mix``/``fresnel_mix`` form
(tests/test_native_models.py). No parameter is linear (base_color enters both F_m and the
diffuse term). Bounds: the factors' ranges; roughness from 0.01 (alpha 1e-4: a mirror is a delta).
"""

from __future__ import annotations

import jax.numpy as jnp

from . import _math as m
from . import _microfacet as mf
from .base import Lobe, Model, Param, Proposal

PARAMS = (
    Param("base_color", 3, 0.0, 1.0, 0.5, "albedo", doc="baseColorFactor"),
    Param("metallic", 1, 0.0, 1.0, 0.0, "fresnel", doc="metallicFactor"),
    Param("roughness", 1, 0.01, 1.0, 0.5, "roughness", doc="roughnessFactor (alpha = roughness^2)"),
)


def formula(p, wi, wo):
    base, metallic = p["base_color"], p["metallic"]
    alpha = p["roughness"] * p["roughness"]
    h = m.half_vector(wi, wo)
    # D (= alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2)) and the height-correlated G2 from the kit:
    # D G2 / (4 (n.l)(n.v)) is the spec's D V
    s = mf.ggx_d(h, alpha) * mf.smith_g2(wi, wo, alpha) / (4.0 * m.cos_theta(wi) * m.cos_theta(wo))
    w = (1.0 - jnp.clip(jnp.abs(m.dot(wo, h)), 0.0, 1.0)) ** 5
    f_d = 0.04 + 0.96 * w
    f_m = base + (1.0 - base) * w
    dielectric = (1.0 - f_d) * base / jnp.pi + f_d * s
    return (1.0 - metallic) * dielectric + metallic * f_m * s


def halfwidth(p):
    """As ``ggx`` with alpha = roughness^2."""
    return mf.halfwidth(p["roughness"] ** 2)


def to_native(p) -> dict:
    return {
        "pbrMetallicRoughness": {
            "baseColorFactor": [float(x) for x in p["base_color"]] + [1.0],
            "metallicFactor": float(p["metallic"][0]),
            "roughnessFactor": float(p["roughness"][0]),
        },
    }


def sampling(p):
    """GGX of alpha = roughness^2; the diffuse share is what base_color adds."""
    a = p("roughness") ** 2
    return (Proposal("ggx", (a, a)), Proposal("cosine", scales=("base_color",), minus=0))


MODEL = Model(
    name="gltf:metallic_roughness",
    params=PARAMS,
    formula=formula,
    citation="The Khronos Group: glTF 2.0 Specification, Appendix B (BRDF Implementation), 2021",
    reciprocal=True,
    doc=__doc__,
    lobes=(Lobe("gltf:metallic_roughness", ("metallic", "roughness")),),
    halfwidth=halfwidth,
    to_native=to_native,
    sampling=sampling,
)
