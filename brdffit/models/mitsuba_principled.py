"""Mitsuba 3's ``principled`` plugin (the Disney BSDF), reflection only, as a native model (docs/materials.md#native-materials-and-exports).

W. Jakob et al., Mitsuba 3 renderer, ``src/bsdfs/principled.cpp`` and ``principledhelpers.h``
(2022-); B. Burley, "Physically Based Shading at Disney", SIGGRAPH 2012 course notes; B. Burley,
"Extending the Disney BRDF to a BSDF with Integrated Subsurface Scattering", SIGGRAPH 2015.

Parameters
----------
===============  ========  ===============  ==========  =======  ==========  ===============================================================
name             channels  bounds           physical    default  role        meaning
===============  ========  ===============  ==========  =======  ==========  ===============================================================
base_color       3         [0, 1]           [0, 1]      0.5      albedo      diffuse albedo and the metal's F0
roughness        1         [0.032, 1]       [0.032, 1]  0.5      roughness   GGX alpha = roughness^2 (floor 0.001)
metallic         1         [0, 1]           [0, 1]      0.1      fresnel     dielectric (0) to conductor (1)
specular         1         [1e-3, 1] (log)  [1e-3, 1]   0.5      fresnel     dielectric F0 / 0.08: eta = 2 / (1 - sqrt(0.08 s)) - 1
anisotropic      1         [0, 0.9]         [0, 0.9]    0.1      anisotropy  alpha_x,y = roughness^2 / a, roughness^2 a; a = sqrt(1 - 0.9 x)
sheen            1         [0, 1]           [0, 1]      0.1      albedo      the grazing sheen lobe's weight
clearcoat        1         [0, 1]           [0, 1]      0.1      albedo      the secondary (GTR1) lobe's weight
clearcoat_gloss  1         [0, 1]           [0, 1]      0.5      roughness   GTR1 alpha = lerp(0.1, 0.001, gloss)
===============  ========  ===============  ==========  =======  ==========  ===============================================================

f_r = F_p D G / (4 (n.l)(n.v))                               main GGX lobe
    + (1 - metallic) base_color / pi (f_diff + f_retro)        Burley's diffuse and retro-reflection
    + sheen (1 - metallic) F_S(h.v)                               the sheen lobe
    + clearcoat / 4 Schlick(0.04; h.v) D_GTR1(h) G1(l; 0.25) G1(v; 0.25)

term for term as Mitsuba's ``eval`` (which returns f_r (n.l)): alpha_x,y with the floor 0.001
(``calc_dist_params``); D and G Mitsuba's anisotropic GGX with the separable Smith G1;
F_p = (1 - metallic) F_dielectric(h.v; eta) + metallic Schlick(base_color) (``principled_fresnel``);
F_S(x) = (1 - x)^5 (``schlick_weight``),
f_diff = (1 - F_S(n.l)/2)(1 - F_S(n.v)/2), R_r = 2 roughness (h.v)^2,
f_retro = R_r (F_S(n.l) + F_S(n.v) + F_S(n.l) F_S(n.v) (R_r - 1)). The clearcoat lobe has no
(n.l)(n.v) below it, as Mitsuba writes it. tests/test_native_models.py holds this formula equal to
Mitsuba's ``bsdf.eval``. The formula is affine in base_color, sheen and clearcoat (declared
linear: the default start solves them at every grid point).

``native()`` writes every setting the formula relies on: ``spec_trans`` and ``flatness`` 0 (opaque,
no fake subsurface), ``specular`` (not ``eta``), and every parameter, including those at 0 (a
property written as 0 switches its lobe off, as the plugin's ``get_flag`` does; the formula is 0
there too). The tangent (x) axis is the surface's first tangent, as in Mitsuba.

Not fitted, written as the plugin's default 0: ``spec_tint`` and ``sheen_tint``. A tint divides
base_color by its luminance, so one channel of base_color would change the others: brdffit's models
work channel by channel (the structured solver relies on it, ``brdffit.testing`` checks it), and a
tinted dielectric F0 is what ``metallic`` between 0 and 1 already mixes in.

Bounds: roughness below sqrt(0.001) = 0.0316 is clamped by the plugin (a flat direction), hence
0.032; specular from 1e-3 (d eta / d specular is infinite at 0; the plugin's own floor for
transmission); anisotropic 0.9 stretches the lobe 3.2 : 1 (aspect^2 = 0.19); the weights are Disney's [0, 1].
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from . import _math as m
from . import _microfacet as mf
from ._mitsuba_math import fresnel_dielectric, ggx_halfwidth, rgb, smith_g1
from .base import Lobe, Model, Param, Proposal

#: The clearcoat lobe's fixed shadowing roughness and its Fresnel F0 (Mitsuba, after Burley 2012).
CLEARCOAT_G_ALPHA, CLEARCOAT_F0 = 0.25, 0.04

PARAMS = (
    Param("base_color", 3, 0.0, 1.0, 0.5, "albedo", linear=True, doc="base colour: diffuse albedo and the metal's F0"),
    Param("roughness", 1, 0.032, 1.0, 0.5, "roughness", doc="roughness (GGX alpha = roughness^2)"),
    Param("metallic", 1, 0.0, 1.0, 0.1, "fresnel", doc="dielectric (0) to conductor (1)"),
    Param("specular", 1, 1e-3, 1.0, 0.5, "fresnel", doc="dielectric F0 / 0.08 (sets eta)"),
    Param("anisotropic", 1, 0.0, 0.9, 0.1, "anisotropy", doc="anisotropy of the main lobe (tangent x)"),
    Param("sheen", 1, 0.0, 1.0, 0.1, "albedo", linear=True, doc="sheen lobe weight"),
    Param("clearcoat", 1, 0.0, 1.0, 0.1, "albedo", linear=True, doc="clearcoat lobe weight"),
    Param("clearcoat_gloss", 1, 0.0, 1.0, 0.5, "roughness", doc="clearcoat gloss (GTR1 alpha 0.1 to 0.001)"),
)


def eta_of_specular(specular):
    """The plugin's index of refraction for a ``specular`` value (F0 = 0.08 specular)."""
    return 2.0 / (1.0 - jnp.sqrt(0.08 * specular)) - 1.0


def schlick_weight(cos):
    """Mitsuba's ``schlick_weight``: (1 - cos)^5, cos clipped to [0, 1]."""
    x = jnp.clip(1.0 - cos, 0.0, 1.0)
    return x * x * x * x * x


def dist_params(roughness, anisotropic):
    """Mitsuba's ``calc_dist_params``: GGX (alpha_x, alpha_y) of roughness and anisotropy."""
    aspect = jnp.sqrt(1.0 - 0.9 * anisotropic)
    r2 = roughness * roughness
    return jnp.maximum(0.001, r2 / aspect), jnp.maximum(0.001, r2 * aspect)


def smith_g1_aniso(v, h, ax, ay):
    """Mitsuba's GGX ``smith_g1`` with the roughness projected on v's azimuth (the kit's
    ``smith_g1_aniso``); 0 where v sees the back of the microfacet h."""
    return jnp.where(m.dot(v, h) * v[..., 2:3] <= 0.0, 0.0, mf.smith_g1_aniso(v, ax, ay))


def schlick(f0, cos):
    """Mitsuba's ``calc_schlick`` outside a denser medium: lerp((1 - cos)^5, 1, f0)."""
    w = schlick_weight(cos)
    return w + f0 * (1.0 - w)


def gtr1_d(h, alpha):
    """Mitsuba's ``GTR1Isotropic::eval`` (Burley's clearcoat distribution, normalised in D cos)."""
    _, cos2 = m.sin2_cos2_theta(h)
    a2 = alpha * alpha
    return (a2 - 1.0) / (jnp.pi * jnp.log(a2) * (1.0 + (a2 - 1.0) * cos2))


def formula(p, wi, wo):
    base, metallic, roughness = p["base_color"], p["metallic"], p["roughness"]
    h = m.half_vector(wi, wo)
    cos_i, cos_o = m.cos_theta(wi), m.cos_theta(wo)
    cos_d = jnp.clip(m.dot(wo, h), 0.0, 1.0)
    eta = eta_of_specular(p["specular"])

    ax, ay = dist_params(roughness, p["anisotropic"])
    d = mf.ggx_d_aniso(h, ax, ay)
    g = smith_g1_aniso(wi, h, ax, ay) * smith_g1_aniso(wo, h, ax, ay)
    f_dielectric, _, _ = fresnel_dielectric(cos_d, eta)
    fresnel = (1.0 - metallic) * f_dielectric + metallic * schlick(base, cos_d)
    specular = fresnel * d * g / (4.0 * cos_i * cos_o)

    w_i, w_o, w_d = schlick_weight(cos_i), schlick_weight(cos_o), schlick_weight(cos_d)
    f_diff = (1.0 - 0.5 * w_i) * (1.0 - 0.5 * w_o)
    r_r = 2.0 * roughness * cos_d * cos_d
    f_retro = r_r * (w_o + w_i + w_o * w_i * (r_r - 1.0))
    diffuse = (1.0 - metallic) * base / jnp.pi * (f_diff + f_retro)

    sheen = p["sheen"] * (1.0 - metallic) * w_d

    alpha_c = 0.1 + (0.001 - 0.1) * p["clearcoat_gloss"]
    g_c = smith_g1(wi, h, CLEARCOAT_G_ALPHA) * smith_g1(wo, h, CLEARCOAT_G_ALPHA)
    clearcoat = 0.25 * p["clearcoat"] * schlick(CLEARCOAT_F0, cos_d) * gtr1_d(h, alpha_c) * g_c
    return specular + diffuse + sheen + clearcoat


def to_native(p) -> dict:
    scalars = ("roughness", "metallic", "specular", "anisotropic", "sheen", "clearcoat", "clearcoat_gloss")
    return {
        "type": "principled",
        "base_color": rgb(p["base_color"]),
        **{name: float(p[name][0]) for name in scalars},
        "spec_tint": 0.0, "sheen_tint": 0.0,  # untinted (see the module docstring)
        "spec_trans": 0.0,  # opaque (reflection only)
        "flatness": 0.0,  # no fake subsurface
    }


def halfwidth(p):
    """As ``ggx`` with alpha = roughness^2 (the main lobe)."""
    return ggx_halfwidth({"alpha": np.maximum(0.001, np.asarray(p["roughness"], np.float64) ** 2)})  # the isotropic width


def sampling(p):
    """The main GGX lobe; the diffuse, sheen and clearcoat shares are what their scales add (the
    GTR1 clearcoat sampled as a GGX lobe of its alpha)."""
    a = max(0.001, p("roughness") ** 2)
    a_c = 0.1 + (0.001 - 0.1) * p("clearcoat_gloss")
    return (Proposal("ggx", (a, a)), Proposal("cosine", scales=("base_color",), minus=0),
            Proposal("cosine", scales=("sheen",), minus=0), Proposal("ggx", (a_c, a_c), ("clearcoat",), minus=0))


MODEL = Model(
    name="mitsuba:principled",
    params=PARAMS,
    formula=formula,
    citation="Mitsuba 3 principled; Burley: Physically Based Shading at Disney, SIGGRAPH 2012 course notes",
    reciprocal=True,
    float32_jacobian=True,  # measured: tests/test_structure.py, benchmarks/README.md
    doc=__doc__,
    lobes=(Lobe("mitsuba:principled", tuple(p.name for p in PARAMS if p.name != "base_color")),),
    halfwidth=halfwidth,
    to_native=to_native,
    sampling=sampling,
)
