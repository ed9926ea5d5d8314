"""Mitsuba 3's ``roughconductor`` plugin (GGX), as a native model (docs/materials.md#native-materials-and-exports).

W. Jakob et al., Mitsuba 3 renderer, ``src/bsdfs/roughconductor.cpp`` (2022-); B. Walter,
S. R. Marschner, H. Li, K. E. Torrance, "Microfacet Models for Refraction through Rough Surfaces",
EGSR 2007; conductor Fresnel after K. D. Moeller, "Optics", 1988.

Parameters
----------
====================  ========  =================  ===========  =======  ==========  ============================================
name                  channels  bounds             physical     default  role        meaning
====================  ========  =================  ===========  =======  ==========  ============================================
alpha                 1         [1e-4, 1] (log)    [1e-4, 1]    0.1      roughness   GGX roughness (the plugin's ``alpha``)
eta                   3         [0.01, 10] (log)   [0.01, 10]   0.2      fresnel     real part of the complex IOR (``eta``)
k                     3         [0, 20]            [0, 20]      3        fresnel     imaginary part, extinction (``k``)
====================  ========  =================  ===========  =======  ==========  ============================================

f_r = F(h.l; eta + i k) D(h) G1(l, h) G1(v, h) / (4 (n.l)(n.v))

with Mitsuba's isotropic GGX D, its separable Smith G1 and its exact conductor Fresnel; no diffuse
term. Mitsuba's ``eval`` returns f_r (n.l) (with si.wi the view): this formula equals it
(tests/test_native_models.py). ``native()`` writes every setting the formula relies on: the plugin's
default distribution is Beckmann (9.6 % off GGX at alpha 0.3), so ``distribution`` is always
``ggx``; ``eta``/``k`` are written as spectra (so no ``material`` preset applies) that Mitsuba's RGB
variants integrate back to the fitted RGB values exactly and whose Fresnel reflectance, in its
spectral variants, has the fitted RGB colour at every angle (``brdffit.models._spectra``; RGB values
would be upsampled channel by channel and clipped to [0, 1] there: a purple fit rendered olive).
``specular_reflectance`` is not fitted and keeps the plugin's default, 1 (docs/materials.md#native-materials-and-exports): the complex IOR
alone spans every reflectance curve a scale would, and a scale beside it leaves the fit a flat
direction (s F(eta, k) = s' F(eta', k') along a curve; measured: no 2 % recovery of eta, k or s, and
a lm run that ended worse than its start).

Bounds: what Mitsuba accepts and the formula needs (alpha > 0; eta and k cover every metal of
Mitsuba's IOR list in RGB).
"""

from __future__ import annotations

import jax.numpy as jnp

from . import _math as m
from ._mitsuba_math import fresnel_conductor, ggx_d, ggx_halfwidth, rgb, smith_g1, spectrum
from ._spectra import WAVELENGTHS, conductor_spectra
from .base import Lobe, Model, Param, Proposal

PARAMS = (
    Param("alpha", 1, 1e-4, 1.0, 0.1, "roughness", doc="GGX roughness (Mitsuba alpha)"),
    Param("eta", 3, 0.01, 10.0, 0.2, "fresnel", doc="real part of the complex index of refraction"),
    Param("k", 3, 0.0, 20.0, 3.0, "fresnel", doc="imaginary part of the complex index of refraction"),
)


def formula(p, wi, wo):
    h = m.half_vector(wi, wo)
    alpha = p["alpha"]
    d = ggx_d(h, alpha)
    g = smith_g1(wi, h, alpha) * smith_g1(wo, h, alpha)
    f = fresnel_conductor(jnp.clip(m.dot(wo, h), 0.0, 1.0), p["eta"], p["k"])
    return f * d * g / (4.0 * m.cos_theta(wi) * m.cos_theta(wo))


def to_native(p) -> dict:
    eta, k = conductor_spectra(p["eta"], p["k"])
    return {
        "type": "roughconductor",
        "distribution": "ggx",
        "alpha": float(p["alpha"][0]),
        "eta": spectrum(WAVELENGTHS, eta),
        "k": spectrum(WAVELENGTHS, k),
        "specular_reflectance": rgb([1.0, 1.0, 1.0]),  # the plugin's default, written
    }


def sampling(p):
    a = p("alpha")
    return (Proposal("ggx", (a, a)),)


MODEL = Model(
    name="mitsuba:roughconductor",
    params=PARAMS,
    formula=formula,
    citation="Mitsuba 3 roughconductor (GGX); Walter, Marschner, Li, Torrance: Microfacet Models for "
             "Refraction through Rough Surfaces, EGSR 2007",
    reciprocal=True,
    doc=__doc__,
    lobes=(Lobe("mitsuba:roughconductor", ("alpha", "eta", "k")),),
    halfwidth=ggx_halfwidth,
    to_native=to_native,
    sampling=sampling,
)
