"""Blender 5's Principled BSDF as Cycles renders it (opaque, distribution GGX), as a native model (docs/materials.md#native-materials-and-exports).

Blender Foundation, Cycles (Blender 5.0), ``intern/cycles/kernel/svm/closure.h`` (the Principled
BSDF's closures), ``kernel/closure/bsdf_microfacet.h`` and ``bsdf_util.h``; B. Walter et al.,
"Microfacet Models for Refraction through Rough Surfaces", EGSR 2007 (GGX with the height-correlated
Smith G); E. Heitz, "Understanding the Masking-Shadowing Function", JCGT 2014; M. Kutz et al.,
"Novel aspects of the Adobe Standard Material", 2021 (F82-tint).

Parameters
----------
==================  ========  =================  ===========  =======  =========  ===================================================
name                channels  bounds             physical     default  role       meaning
==================  ========  =================  ===========  =======  =========  ===================================================
base_color          3         [0, 1]             [0, 1]       0.8      albedo     ``Base Color`` (linear RGB)
metallic            1         [0, 1]             [0, 1]       0        fresnel    ``Metallic``
roughness           1         [0.01, 1] (log)    [0.01, 1]    0.5      roughness  ``Roughness`` (alpha = roughness^2)
ior                 1         [1.05, 3]          [1.05, 3]    1.5      fresnel    ``IOR`` of the dielectric
specular_tint       1         [0, 1]             [0, 1]       1        fresnel    ``Specular Tint``, grey (written as (t, t, t))
==================  ========  =================  ===========  =======  =========  ===================================================

Cycles' closures for these inputs (Coat, Sheen, Subsurface, Transmission, Alpha, Emission 0), with
alpha = roughness^2, h the half vector, c = h.v, S = D G / (4 (n.l)(n.v)) the GGX lobe without
Fresnel (D = alpha^2 / (pi (sin^2 + alpha^2 cos^2)^2) of h, G = 1 / (1 + L(l) + L(v)),
L(w) = (sqrt(1 + alpha^2 tan^2 w) - 1) / 2):

    metal      = F82(c; F0 = base_color, tint) S                            (weight metallic)
    specular   = (F0s + (1 - F0s) s(c)) S                                   (weight 1 - metallic)
    diffuse    = (1 - max(F0s + (1 - F0s) E(roughness, n.v, eta))) base_color / pi   (weight 1 - metallic)
    f_r        = metallic metal + (1 - metallic) (specular + diffuse)

with F0 = F0(ior) 2 level, eta = ior_from_F0(F0), F0s = min(F0 tint, 1),
s(c) = clamp((F(c; eta) - F0(eta)) / (1 - F0(eta)), 0, 1) the exact dielectric Fresnel remapped, and E
Cycles' precomputed ``ggx_gen_schlick_ior_s`` table (``_cycles_math``): the diffuse lies under the
specular layer, weighted by what the specular leaves at this view. The model is not reciprocal
(E depends on the view). No specular layer where F0 = 0 (ior 1, which the bounds leave out: dF0/dior
is 0 there, and fits that reached it stayed, measured in the recovery test).

``native()`` returns ``{"distribution": "GGX", "inputs": {socket: value}}``, pinning the distribution:
Blender's default, ``MULTI_GGX``, adds a multiple-scattering energy term this formula does not hold.
``specular_tint`` is one grey value: Cycles layers the diffuse by the largest channel of the specular
albedo, so a coloured tint would make each colour channel depend on the others (the solver's Jacobian
structure needs channel c to depend on channel c only). The metal's F82 tint uses it too.
Equality with Cycles, measured as a gonioreflectometer, is tested in tests/test_blender_principled.py.
"""

from __future__ import annotations

import jax.numpy as jnp

from . import _cycles_math as cy
from . import _math as m
from . import _microfacet as mf
from .base import Lobe, Model, Param
# the metal-roughness conventions it shares with glTF (GGX of alpha = roughness^2, base_color the
# diffuse share): one lobe width and one sampling declaration for both
from .gltf_metallic_roughness import halfwidth, sampling

PARAMS = (
    Param("base_color", 3, 0.0, 1.0, 0.8, "albedo", doc="Base Color"),
    Param("metallic", 1, 0.0, 1.0, 0.0, "fresnel", doc="Metallic"),
    Param("roughness", 1, 0.01, 1.0, 0.5, "roughness", doc="Roughness (alpha = roughness^2)"),
    Param("ior", 1, 1.05, 3.0, 1.5, "fresnel", doc="IOR of the dielectric layer"),
    Param("specular_tint", 1, 0.0, 1.0, 1.0, "fresnel", doc="Specular Tint (grey)"),
)

#: Specular IOR Level, not fitted (see the module docstring): Blender's default, F0 = F0(ior).
SPECULAR_IOR_LEVEL = 0.5
#: The inputs ``native()`` writes besides the fitted ones: what the formula assumes (opaque, no layers).
FIXED_INPUTS = {"Diffuse Roughness": 0.0, "Subsurface Weight": 0.0, "Transmission Weight": 0.0,
                "Coat Weight": 0.0, "Sheen Weight": 0.0, "Anisotropic": 0.0, "Alpha": 1.0,
                "Emission Strength": 0.0}


def formula(p, wi, wo):
    base, metallic, rough = p["base_color"], p["metallic"], p["roughness"]
    tint = p["specular_tint"]
    alpha = rough * rough
    h = m.half_vector(wi, wo)
    lobe = mf.ggx_d(h, alpha) * mf.smith_g2(wi, wo, alpha) / (4.0 * m.cos_theta(wi) * m.cos_theta(wo))
    c = jnp.clip(m.dot(wo, h), m.COS_EPS, 1.0)
    metal = cy.f82_tint(c, base, tint) * lobe
    # the dielectric layer: Specular IOR Level scales F0 (0.5 leaves it), Specular Tint tints it
    f0 = cy.f0_from_ior(p["ior"]) * (2.0 * SPECULAR_IOR_LEVEL)
    eta = cy.ior_from_f0(f0)
    f0s = jnp.clip(f0 * tint, 0.0, 1.0)
    f0_eta = cy.f0_from_ior(eta)
    s = jnp.clip((cy.fresnel_dielectric(c, eta) - f0_eta) / (1.0 - f0_eta), 0.0, 1.0)
    table = jnp.asarray(cy.gen_schlick_ior_s(), dtype=lobe.dtype)
    e = cy.lookup_3d(table, rough, m.cos_theta(wo), m.safe_sqrt((eta - 1.0) / (eta + 1.0)))
    layered = f0 > 0.0  # Cycles makes no specular closure where eta is 1
    specular = jnp.where(layered, f0s + (1.0 - f0s) * s, 0.0) * lobe
    under = jnp.where(layered, jnp.clip(1.0 - (f0s + (1.0 - f0s) * e), 0.0, 1.0), 1.0)
    return metallic * metal + (1.0 - metallic) * (specular + under * base / jnp.pi)


def to_native(p) -> dict:
    t = float(p["specular_tint"][0])
    return {
        "distribution": "GGX",
        "inputs": {
            "Base Color": [float(x) for x in p["base_color"]],
            "Metallic": float(p["metallic"][0]),
            "Roughness": float(p["roughness"][0]),
            "IOR": float(p["ior"][0]),
            "Specular IOR Level": SPECULAR_IOR_LEVEL,
            "Specular Tint": [t, t, t],
            **FIXED_INPUTS,
        },
    }


MODEL = Model(
    name="blender:principled",
    params=PARAMS,
    formula=formula,
    citation="Blender 5 Cycles Principled BSDF (GGX); Walter, Marschner, Li, Torrance: Microfacet Models "
             "for Refraction through Rough Surfaces, EGSR 2007; Kutz et al.: Novel aspects of the Adobe "
             "Standard Material, 2021",
    reciprocal=False,
    doc=__doc__,
    lobes=(Lobe("blender:principled", ("metallic", "roughness", "ior", "specular_tint")),),
    halfwidth=halfwidth,
    to_native=to_native,
    sampling=sampling,
)
