"""Numerically safe building blocks shared by the model formulas.

Every helper keeps values *and gradients* finite on the closed upper hemisphere, in float32 and
float64. Branches use the double-``where`` pattern: the unsafe branch is fed a harmless input,
so no NaN or inf reaches the gradient through the branch that is not taken.
"""

from __future__ import annotations

import jax.numpy as jnp

#: Smallest cosine a formula divides by. Directions at the horizon (cos = 0) are evaluated as if
#: at 89.99999 degrees: the BRDF value there is a limit, not a number.
COS_EPS = 1e-7


def cos_theta(w):
    """n . w as (N, 1), clamped to [COS_EPS, 1]."""
    return jnp.clip(w[..., 2:3], COS_EPS, 1.0)


def safe_sqrt(x):
    """sqrt(max(x, 0)) with a finite gradient at 0."""
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), 0.0)


def safe_norm(v, axis=-1, keepdims=True):
    return safe_sqrt(jnp.sum(v * v, axis=axis, keepdims=keepdims))


def normalize(v, fallback=(0.0, 0.0, 1.0)):
    """v / |v|, or ``fallback`` where |v| == 0 (e.g. the half vector of opposite grazing rays)."""
    sq = jnp.sum(v * v, axis=-1, keepdims=True)
    ok = sq > 1e-30
    inv = jnp.where(ok, 1.0 / jnp.sqrt(jnp.where(ok, sq, 1.0)), 0.0)
    return jnp.where(ok, v * inv, jnp.asarray(fallback, dtype=v.dtype))


def half_vector(wi, wo):
    """h = (wi + wo) / |wi + wo| (the normal where wi = -wo)."""
    return normalize(wi + wo)


def sin2_cos2_theta(w):
    """(sin^2 theta, cos^2 theta) of unit vectors, both (N, 1), without 1 - cos^2 cancellation."""
    sin2 = w[..., 0:1] ** 2 + w[..., 1:2] ** 2
    cos2 = w[..., 2:3] ** 2
    total = sin2 + cos2
    return sin2 / total, cos2 / total


def tan2_theta(w):
    """tan^2 theta, (N, 1), finite at the horizon (cosine clamped to COS_EPS)."""
    sin2, cos2 = sin2_cos2_theta(w)
    return sin2 / jnp.maximum(cos2, COS_EPS**2)


def reflect(w):
    """Mirror direction about the normal: r = 2 (n.w) n - w."""
    return w * jnp.asarray([-1.0, -1.0, 1.0], dtype=w.dtype)


def safe_pow(base, exponent):
    """max(base, 0) ** exponent, finite with finite gradients for exponent up to 1e4 and base 0."""
    positive = base > 0
    safe_base = jnp.where(positive, base, 1.0)
    return jnp.where(positive, jnp.exp(exponent * jnp.log(safe_base)), 0.0)


def schlick_fresnel(f0, cos_theta_d):
    """Schlick's approximation F = f0 + (1 - f0) (1 - cos)^5."""
    c = jnp.clip(cos_theta_d, 0.0, 1.0)
    return f0 + (1.0 - f0) * (1.0 - c) ** 5


def dot(a, b):
    """Row-wise dot product, (N, 1)."""
    return jnp.sum(a * b, axis=-1, keepdims=True)


def hz_sq(h):
    """cos^2 theta of a unit vector, floored at COS_EPS^2 so that dividing by it stays finite."""
    return jnp.maximum(h[..., 2:3] ** 2, COS_EPS**2)


def log_cap(dtype) -> float:
    """Largest exponent ``capped_exp`` lets through: e^100 in float64, e^35 in float32.

    Far above any measured reflectance (1/sr), yet a squared residual of that size is still finite,
    so a model evaluated at a corner of its box (e.g. a Lafortune lobe with |C| > 1 and n = 1e4)
    never hands the solver an inf.
    """
    return 35.0 if jnp.finfo(dtype).bits <= 32 else 100.0


def capped_exp(x):
    """exp(min(x, log_cap)): overflow-free exponential (see ``log_cap``)."""
    return jnp.exp(jnp.minimum(x, log_cap(x.dtype)))


def capped_pow(base, exponent):
    """max(base, 0) ** exponent via ``capped_exp``; 0 (with zero gradient) where base <= 0."""
    positive = base > 0
    safe_base = jnp.where(positive, base, 1.0)
    return jnp.where(positive, capped_exp(exponent * jnp.log(safe_base)), 0.0)


def v_cavity_g(n_dot_h, n_dot_l, n_dot_v, v_dot_h):
    """Torrance-Sparrow / Cook-Torrance V-cavity masking-shadowing
    G = min(1, 2 (n.h)(n.v)/(v.h), 2 (n.h)(n.l)/(v.h)), (N, 1)."""
    vh = jnp.maximum(v_dot_h, COS_EPS)
    return jnp.minimum(1.0, jnp.minimum(2.0 * n_dot_h * n_dot_v / vh, 2.0 * n_dot_h * n_dot_l / vh))
