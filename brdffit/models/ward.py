"""Ward: the anisotropic elliptical Gaussian lobe (isotropic when alpha_x == alpha_y).

G. J. Ward, "Measuring and Modeling Anisotropic Reflection", SIGGRAPH 1992, eq. 5a.

Parameters
----------
=======  ========  =================  =========  =======  =========  =======================================
name     channels  bounds             physical   default  role       meaning
=======  ========  =================  =========  =======  =========  =======================================
kd       3         [0, inf)           [0, 1]     0.1      albedo     diffuse albedo (Ward's rho_d; linear)
ks       3         [0, inf)           [0, 1]     0.3      albedo     specular albedo (Ward's rho_s; linear)
alpha_x  1         [1e-4, inf) (log)  [1e-4, 1]  0.2      roughness  rms slope along the tangent x (phi = 0)
alpha_y  1         [1e-4, inf) (log)  [1e-4, 1]  0.2      roughness  rms slope along the bitangent y
=======  ========  =================  =========  =======  =========  =======================================

Bounds (what the formula needs): kd, ks >= 0, no upper bound (arbitrary units); alpha_x, alpha_y
> 0 (the lobe divides by them), floored at 1e-4, no upper bound. Physical range
(``physical=True``): kd, ks <= 1 (Ward's rho_d, rho_s are albedos), alpha_x, alpha_y <= 1.

Formula (BRDF form, as in the paper)::

    f_r = kd/pi + ks exp(-tan^2 th_h (cos^2 ph_h / ax^2 + sin^2 ph_h / ay^2))
                     / (4 pi ax ay sqrt((n.l)(n.v)))

evaluated as exp(-(h_x^2/ax^2 + h_y^2/ay^2) / h_z^2), which is the same expression without the
angles (tan th_h cos ph_h = h_x/h_z). Reciprocal. Ward's normalisation is exact only for small
alpha and is known to exceed energy conservation near grazing view (the 1/sqrt((n.l)(n.v))).
Cosines are clamped at 1e-7 at the horizon. Anisotropy axes follow the local frame: x is the
tangent at phi = 0.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from . import _math as m
from .base import Model, Param, Proposal

INF = math.inf

PARAMS = (
    Param("kd", 3, 0.0, INF, 0.1, "albedo", linear=True, doc="diffuse albedo", physical=(0.0, 1.0)),
    Param("ks", 3, 0.0, INF, 0.3, "albedo", linear=True, doc="specular albedo", physical=(0.0, 1.0)),
    Param("alpha_x", 1, 1e-4, INF, 0.2, "roughness", doc="rms slope along x", physical=(1e-4, 1.0)),
    Param("alpha_y", 1, 1e-4, INF, 0.2, "roughness", doc="rms slope along y", physical=(1e-4, 1.0)),
)


def formula(p, wi, wo):
    ax, ay = p["alpha_x"], p["alpha_y"]
    h = m.half_vector(wi, wo)
    # -tan^2 th_h (cos^2 ph_h/ax^2 + sin^2 ph_h/ay^2) without angles; h_z^2 floored at the horizon.
    e = -((h[..., 0:1] / ax) ** 2 + (h[..., 1:2] / ay) ** 2) / m.hz_sq(h)
    norm = 4.0 * jnp.pi * ax * ay * jnp.sqrt(m.cos_theta(wi) * m.cos_theta(wo))
    return p["kd"] / jnp.pi + p["ks"] * jnp.exp(e) / norm


def halfwidth(p):
    """exp(-tan^2 th_h/alpha^2) = 1/2 at tan th_h = alpha sqrt(ln 2), along the narrower axis;
    twice that in reflected directions."""
    return 2.0 * np.arctan(np.minimum(p["alpha_x"], p["alpha_y"]) * math.sqrt(math.log(2.0)))


def sampling(p):
    """Ward's exponent is the anisotropic Beckmann one."""
    return (Proposal("cosine", scales=("kd",)), Proposal("beckmann", (p("alpha_x"), p("alpha_y")), ("ks",)))


MODEL = Model(
    name="ward",
    params=PARAMS,
    formula=formula,
    citation="G. J. Ward, Measuring and Modeling Anisotropic Reflection, SIGGRAPH 1992",
    reciprocal=True,
    float32_jacobian=True,  # measured: tests/test_structure.py, benchmarks/README.md
    doc=__doc__,
    halfwidth=halfwidth,
    sampling=sampling,
)
