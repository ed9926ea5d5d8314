"""Oren-Nayar: rough diffuse reflection (the paper's qualitative model).

M. Oren, S. K. Nayar, "Generalization of Lambert's Reflectance Model", SIGGRAPH 1994, eq. 30
(the "qualitative model", without the interreflection term).

Parameters
----------
=====  ========  ========  =========  =======  =========  ============================================
name   channels  bounds    physical   default  role       meaning
=====  ========  ========  =========  =======  =========  ============================================
kd     3         [0, inf)  [0, 1]     0.5      albedo     albedo rho of the facets (linear)
sigma  1         [0, inf)  [0, pi/2]  0.3      roughness  standard deviation of the facet slope angle,
                                                          **in radians** (the paper's sigma)
=====  ========  ========  =========  =======  =========  ============================================

Bounds (what the formula needs): kd >= 0, no upper bound (arbitrary units); sigma >= 0, no upper
bound (A and B saturate). Physical range (``physical=True``): kd <= 1, sigma <= pi/2 (a slope-angle
standard deviation beyond 90 degrees describes no surface).

Formula::

    f_r = kd/pi (A + B max(0, cos(ph_i - ph_o)) sin a tan b)
    A = 1 - 0.5 sigma^2/(sigma^2 + 0.33),   B = 0.45 sigma^2/(sigma^2 + 0.09)
    a = max(th_i, th_o),                     b = min(th_i, th_o)

evaluated without angles: sin a sin b = sin th_i sin th_o, so
cos(ph_i - ph_o) sin a tan b = (l_x v_x + l_y v_y) / max(n.l, n.v), which has no singularity at
normal incidence or at the horizon. sigma = 0 is Lambert. Reciprocal (symmetric in l and v).
Lecture form: the diffuse term k_d (n.l) of the lecture's sum generalised to rough surfaces.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from . import _math as m
from .base import Model, Param, Proposal

INF = math.inf

PARAMS = (
    Param("kd", 3, 0.0, INF, 0.5, "albedo", linear=True, doc="facet albedo", physical=(0.0, 1.0)),
    Param("sigma", 1, 0.0, INF, 0.3, "roughness", doc="slope-angle standard deviation, radians", physical=(0.0, math.pi / 2)),
)


def formula(p, wi, wo):
    s2 = p["sigma"] ** 2
    a = 1.0 - 0.5 * s2 / (s2 + 0.33)
    b = 0.45 * s2 / (s2 + 0.09)
    cos_dphi_sin_tan = jnp.maximum(wi[..., 0:1] * wo[..., 0:1] + wi[..., 1:2] * wo[..., 1:2], 0.0) / jnp.maximum(
        m.cos_theta(wi), m.cos_theta(wo)
    )
    return p["kd"] / jnp.pi * (a + b * cos_dphi_sin_tan)


def sampling(p):
    return (Proposal("cosine", scales=("kd",)),)


MODEL = Model(
    name="oren_nayar",
    lobes=(),  # a diffuse term (a composite has at most one): no specular lobe to order
    params=PARAMS,
    formula=formula,
    citation="M. Oren, S. K. Nayar, Generalization of Lambert's Reflectance Model, SIGGRAPH 1994",
    reciprocal=True,
    float32_jacobian=True,  # measured: tests/test_structure.py, benchmarks/README.md
    doc=__doc__,
    sampling=sampling,
)
