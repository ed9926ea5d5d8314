"""The GGX (Trowbridge-Reitz) microfacet kit, written once for every model that uses it (docs/models.md#models).

B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet Models for Refraction through Rough
Surfaces", EGSR 2007 (the distribution, eq. 33, and its Smith G1, eq. 34); E. Heitz,
"Understanding the Masking-Shadowing Function in Microfacet-Based BRDFs", JCGT 3(2), 2014 (Lambda,
the height-correlated G2, the anisotropic roughness seen along a direction, eq. 80).

With alpha the roughness (Mitsuba's alpha; glTF's and Blender's roughness^2), theta the angle from
the normal:

    D(h)     = alpha^2 / (pi (sin^2 th_h + alpha^2 cos^2 th_h)^2)     normalised: int D (n.h) dw = 1
    D(h)     = 1 / (pi ax ay ((hx/ax)^2 + (hy/ay)^2 + hz^2)^2)        anisotropic (tangent x)
    Lambda(w) = (sqrt(1 + alpha^2 tan^2 th_w) - 1) / 2
    G1(w)    = 1 / (1 + Lambda(w)) = 2 / (1 + sqrt(1 + alpha^2 tan^2 th_w))     (separable: G1(l) G1(v))
    G2(l, v) = 1 / (1 + Lambda(l) + Lambda(v))                                 (height-correlated)

D is written in the form that stays exact at small alpha (the usual (n.h)^2 (alpha^2 - 1) + 1
cancels there), tan^2 through :func:`brdffit.models._math.tan2_theta` (finite at the horizon).
Which models use which: ``ggx`` and Mitsuba's plugins the separable G (Mitsuba's also zero where a
direction sees the back of the microfacet: ``_mitsuba_math``), glTF and Blender's Cycles the
height-correlated one. ``tests/test_microfacet.py`` holds each form equal to an independent one and
every GGX model to this kit.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from . import _math as m


def ggx_d(h, alpha):
    """D(h) of an isotropic GGX of roughness ``alpha``, for a unit half vector h, (N, 1)."""
    sin2, cos2 = m.sin2_cos2_theta(h)
    a2 = alpha * alpha
    return a2 / (jnp.pi * (cos2 * a2 + sin2) ** 2)


def ggx_d_aniso(h, ax, ay):
    """D(h) of an anisotropic GGX, roughness ``ax`` along the tangent (x) and ``ay`` across, (N, 1)."""
    hx, hy, hz = h[..., 0:1], h[..., 1:2], h[..., 2:3]
    q = (hx / ax) ** 2 + (hy / ay) ** 2 + hz * hz
    return 1.0 / (jnp.pi * ax * ay * q * q)


def _root(w, alpha2):
    """sqrt(1 + alpha^2 tan^2 theta_w), (N, 1), finite at the horizon."""
    return jnp.sqrt(1.0 + alpha2 * m.tan2_theta(w))


def smith_lambda(w, alpha):
    """Smith's Lambda(w) of an isotropic GGX, (N, 1)."""
    return 0.5 * (_root(w, alpha * alpha) - 1.0)


def smith_g1(w, alpha):
    """Smith's masking G1(w) = 1 / (1 + Lambda(w)) of an isotropic GGX, (N, 1)."""
    return 2.0 / (1.0 + _root(w, alpha * alpha))


def aniso_alpha2(w, ax, ay):
    """The squared roughness an anisotropic GGX shows along the azimuth of the unit direction w."""
    sin2, _ = m.sin2_cos2_theta(w)
    cos_phi2 = jnp.where(sin2 > 0.0, w[..., 0:1] ** 2 / jnp.where(sin2 > 0.0, sin2, 1.0), 1.0)
    return ax * ax * cos_phi2 + ay * ay * (1.0 - cos_phi2)


def smith_g1_aniso(w, ax, ay):
    """Smith's G1(w) of an anisotropic GGX: the isotropic one at the roughness seen along w."""
    return 2.0 / (1.0 + _root(w, aniso_alpha2(w, ax, ay)))


def smith_g2(wi, wo, alpha):
    """The height-correlated masking-shadowing G2 = 1 / (1 + Lambda(wi) + Lambda(wo)), (N, 1)."""
    return 1.0 / (1.0 + smith_lambda(wi, alpha) + smith_lambda(wo, alpha))


def halfwidth(alpha) -> float:
    """The lobe's half width at half maximum in reflected directions: the distribution of slopes,
    D cos^4 th_h, falls to half its peak at tan th_h = alpha sqrt(sqrt(2) - 1) (D itself does for a
    narrow lobe), and a reflected direction turns twice the half vector."""
    return 2.0 * np.arctan(alpha * math.sqrt(math.sqrt(2.0) - 1.0))  # floats, or arrays: one width per fit
