"""Ashikhmin-Shirley: anisotropic Phong lobe with Fresnel and a matching energy-coupled diffuse term.

M. Ashikhmin, P. Shirley, "An Anisotropic Phong BRDF Model", Journal of Graphics Tools 5(2), 2000.

Parameters
----------
====  ========  ==============  ========  =======  ========  ============================================
name  channels  bounds          physical  default  role      meaning
====  ========  ==============  ========  =======  ========  ============================================
rd    3         [0, inf)        [0, 1]    0.1      albedo    diffuse reflectance R_d (linear)
rs    3         [0, 1]          [0, 1]    0.3      fresnel   specular reflectance R_s at normal incidence
                                                             (enters the diffuse term too: not linear)
nu    1         [1, inf) (log)  [1, 1e4]  100      exponent  Phong exponent along the tangent x
nv    1         [1, inf) (log)  [1, 1e4]  100      exponent  Phong exponent along the bitangent y
====  ========  ==============  ========  =======  ========  ============================================

Bounds (what the formula needs): rd >= 0, no upper bound (arbitrary units); rs in [0, 1] (the
diffuse term carries 1 - rs, negative beyond 1); nu, nv >= 1 (as for ``phong``), no upper bound.
Physical range (``physical=True``): rd <= 1 (with rs <= 1 the model conserves energy by
construction, the paper's coupling of the two terms); nu, nv <= 1e4.

Formula (paper eqs. 4, 5)::

    f_r = rho_s + rho_d
    rho_s = sqrt((nu+1)(nv+1)) / (8 pi)
            (n.h)^((nu h_x^2 + nv h_y^2) / (1 - (n.h)^2)) / ((h.l) max(n.l, n.v)) F(h.l)
    F     = rs + (1 - rs)(1 - h.l)^5
    rho_d = 28 rd / (23 pi) (1 - rs) (1 - (1 - (n.l)/2)^5) (1 - (1 - (n.v)/2)^5)

(h_x = h.u, h_y = h.v of the paper, with u = x, v = y of the local frame.) f_r is affine, not
linear, in rd (rho_s does not depend on it). Lecture form: the specular term is Phong's
r_s (n.h)^n made anisotropic and normalised, with Fresnel; the diffuse term is the lecture's k_d
(n.l) corrected for the energy the specular layer takes. The exponent's 0/0 at h = n is replaced
by (nu + nv)/2, any value being exact there since (n.h)^e = 1. Reciprocal.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from . import _math as m
from .base import Model, Param, Proposal

INF = math.inf

PARAMS = (
    Param("rd", 3, 0.0, INF, 0.1, "albedo", linear=True, doc="diffuse reflectance", physical=(0.0, 1.0)),
    Param("rs", 3, 0.0, 1.0, 0.3, "fresnel", doc="specular reflectance at normal incidence"),
    Param("nu", 1, 1.0, INF, 100.0, "exponent", doc="exponent along x", physical=(1.0, 1e4)),
    Param("nv", 1, 1.0, INF, 100.0, "exponent", doc="exponent along y", physical=(1.0, 1e4)),
)


def formula(p, wi, wo):
    nu, nv, rs, rd = p["nu"], p["nv"], p["rs"], p["rd"]
    h = m.half_vector(wi, wo)
    cl, cv = m.cos_theta(wi), m.cos_theta(wo)
    hx2, hy2 = h[..., 0:1] ** 2, h[..., 1:2] ** 2
    sxy = hx2 + hy2  # = 1 - (n.h)^2, without the cancellation
    ok = sxy > 1e-30
    expo = jnp.where(ok, (nu * hx2 + nv * hy2) / jnp.where(ok, sxy, 1.0), 0.5 * (nu + nv))
    hl = jnp.maximum(m.dot(h, wi), m.COS_EPS)
    fres = m.schlick_fresnel(rs, hl)
    spec = jnp.sqrt((nu + 1.0) * (nv + 1.0)) / (8.0 * jnp.pi) * m.safe_pow(h[..., 2:3], expo)
    spec = spec / (hl * jnp.maximum(cl, cv)) * fres
    diff = 28.0 * rd / (23.0 * jnp.pi) * (1.0 - rs) * (1.0 - (1.0 - cl / 2.0) ** 5) * (1.0 - (1.0 - cv / 2.0) ** 5)
    return spec + diff


def halfwidth(p):
    """(n.h)^e = 1/2 at th_h = acos(2^(-1/e)) along the narrower axis (e = max(nu, nv)); twice
    that in reflected directions."""
    return 2.0 * np.arccos(2.0 ** (-1.0 / np.maximum(p["nu"], p["nv"])))


def sampling(p):
    """The specular term has no scale of its own: isolated by rd = 0; the diffuse one is what the
    rd-only albedo holds beyond it."""
    return (Proposal("half_power", (p("nu"), p("nv"))), Proposal("cosine", scales=("rd",), minus=0))


MODEL = Model(
    name="ashikhmin_shirley",
    params=PARAMS,
    formula=formula,
    citation="M. Ashikhmin, P. Shirley, An Anisotropic Phong BRDF Model, Journal of Graphics Tools 5(2), 2000",
    reciprocal=True,
    doc=__doc__,
    halfwidth=halfwidth,
    sampling=sampling,
)
