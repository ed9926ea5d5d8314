"""Cycles' own building blocks, in JAX, for ``blender:principled`` (docs/materials.md#native-materials-and-exports).

Each function reproduces a named piece of Blender 5's Cycles kernel (``intern/cycles/kernel/closure/
bsdf_util.h``, ``bsdf_microfacet.h``, ``util/lookup_table.h``, ``app/cycles_precompute.cpp``), written
from its definitions; the test holds the model equal to Cycles itself measured as a
gonioreflectometer (tests/test_blender_principled.py).

The one precomputed quantity is Cycles' ``ggx_gen_schlick_ior_s`` table: for GGX roughness r (alpha
= r^2), view cosine mu and z = ((eta - 1)/(eta + 1))^(1/2), the mean over GGX visible normals h
(Heitz 2018 sampling from the view) of s(h.v) = clamp((F(h.v, eta) - F0) / (1 - F0), 0, 1), counting 0
where the mirrored direction falls below the surface; 16 x 16 x 16 points, r and mu at i/15, z at
i/15 clamped to [1e-4, 0.99], eta = (1 + z^2)/(1 - z^2). Cycles estimates it by Monte Carlo (2^20
samples a point); here it is a quadrature over the sampling's unit disk (64 Gauss-Legendre radii x 128
angles: 1e-3 from a 128 x 512 one), computed once per process (about a second).
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from . import _math as m

TABLE_SIZE = 16


def f0_from_ior(ior):
    """Cycles' ``F0_from_ior``: ((ior - 1)/(ior + 1))^2."""
    return ((ior - 1.0) / (ior + 1.0)) ** 2


def ior_from_f0(f0):
    """Cycles' ``ior_from_F0``: (1 + sqrt f0)/(1 - sqrt f0), f0 clamped to [0, 0.99]."""
    s = m.safe_sqrt(jnp.clip(f0, 0.0, 0.99))
    return (1.0 + s) / (1.0 - s)


def fresnel_dielectric(c, eta):
    """Cycles' ``fresnel_dielectric`` (unpolarised, from outside) at cosine c in (0, 1], eta >= 1.
    c > 0 keeps every denominator positive (callers clamp c to COS_EPS)."""
    ect2 = eta * eta - (1.0 - c * c)  # >= c^2 > 0 for eta >= 1: no total internal reflection
    ct = m.safe_sqrt(ect2) / eta
    r_s = (c - eta * ct) / (c + eta * ct)
    r_p = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (r_s * r_s + r_p * r_p)


def _np_fresnel(c, eta):
    c = np.abs(c)
    ect2 = eta * eta - (1.0 - c * c)
    ct = np.sqrt(np.maximum(ect2, 0.0)) / eta
    with np.errstate(invalid="ignore", divide="ignore"):
        r_s = (c - eta * ct) / (c + eta * ct)
        r_p = (eta * c - ct) / (eta * c + ct)
    return np.where((ect2 > 0) & (c > 0), 0.5 * (r_s * r_s + r_p * r_p), 1.0)


def f82_tint(cos, f0, tint):
    """Cycles' F82-tint metal Fresnel (``fresnel_f82`` with ``fresnel_f82tint_B``, Kutz et al.,
    "Novel aspects of the Adobe Standard Material"): Schlick's curve darkened near 82 degrees so that
    there it is Schlick's value times ``tint``; clamped to [0, 1]."""
    f = 6.0 / 7.0
    f5 = f**5
    b = (f0 + (1.0 - f0) * f5) * (7.0 / (f5 * f)) * (1.0 - tint)
    s = jnp.clip(1.0 - cos, 0.0, 1.0)
    s5 = s**5
    return jnp.clip(f0 + (1.0 - f0) * s5 - b * cos * s5 * s, 0.0, 1.0)


@functools.lru_cache(maxsize=None)
def gen_schlick_ior_s(n_radius: int = 64, n_angle: int = 128) -> np.ndarray:
    """Cycles' ``ggx_gen_schlick_ior_s`` table, (z, mu, rough) = (16, 16, 16) (module docstring)."""
    x, w = np.polynomial.legendre.leggauss(n_radius)
    r = 0.5 * (x + 1.0)
    weight_r = w * r  # uniform disk: density 2 r dr (on [0, 1], Gauss-Legendre weights halved)
    phi = (np.arange(n_angle) + 0.5) * (2.0 * np.pi / n_angle)
    rr, pp = np.meshgrid(r, phi, indexing="ij")
    weight = np.broadcast_to(weight_r[:, None] / n_angle, rr.shape)
    t1, t2 = rr * np.cos(pp), rr * np.sin(pp)
    grid = np.arange(TABLE_SIZE) / (TABLE_SIZE - 1.0)
    rough, mus = np.clip(grid, 1e-4, 1.0), np.clip(grid, 1e-4, 1.0)
    z = np.clip(grid, 1e-4, 0.99)
    iors = (1.0 + z * z) / (1.0 - z * z)  # ior_from_F0(z^4)
    f0s = ((iors - 1.0) / (iors + 1.0)) ** 2
    out = np.zeros((TABLE_SIZE,) * 3)
    for j, mu in enumerate(mus):
        wi = np.array([np.sqrt(1.0 - mu * mu), 0.0, mu])
        for i, ro in enumerate(rough):
            a = ro * ro
            # Heitz 2018, "Sampling the GGX Distribution of Visible Normals": stretch, sample the
            # projected hemisphere, unstretch (the disk points are the parameters' nodes)
            vh = np.array([a * wi[0], 0.0, wi[2]])
            vh /= np.linalg.norm(vh)
            if vh[0] ** 2 > 1e-7:
                b1 = np.array([0.0, 1.0, 0.0]) * np.sign(vh[0])
                b2 = np.cross(vh, b1)
            else:
                b1, b2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
            s = 0.5 * (1.0 + vh[2])
            u2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - t1 * t1, 0.0)) + s * t2
            h = (t1[..., None] * b1 + u2[..., None] * b2
                 + np.sqrt(np.maximum(0.0, 1.0 - t1 * t1 - u2 * u2))[..., None] * vh)
            h = np.stack([a * h[..., 0], a * h[..., 1], np.maximum(h[..., 2], 0.0)], -1)
            h /= np.linalg.norm(h, axis=-1, keepdims=True)
            cos_hv = h @ wi
            above = 2.0 * cos_hv * h[..., 2] - wi[2] > 0.0  # the mirrored direction's z
            for k, (eta, f0) in enumerate(zip(iors, f0s)):
                s_f = np.clip((_np_fresnel(cos_hv, eta) - f0) / (1.0 - f0), 0.0, 1.0)
                out[k, j, i] = np.sum(weight * s_f * above)
    return np.clip(out, 0.0, 1.0)


def lookup_3d(table, x, y, z):
    """Cycles' ``lookup_table_read_3D``: trilinear interpolation over points at i/(n - 1) of a table
    indexed [z, y, x], the coordinates clamped to [0, 1]; x, y, z broadcast together."""
    n = table.shape[0]
    x, y, z = jnp.broadcast_arrays(x, y, z)

    def split(v):
        t = jnp.clip(v, 0.0, 1.0) * (n - 1)
        i = jnp.clip(jnp.floor(t), 0, n - 2).astype(jnp.int32)
        return i, t - i

    (ix, fx), (iy, fy), (iz, fz) = split(x), split(y), split(z)
    out = 0.0
    for dz, wz in ((0, 1.0 - fz), (1, fz)):
        for dy, wy in ((0, 1.0 - fy), (1, fy)):
            for dx, wx in ((0, 1.0 - fx), (1, fx)):
                out = out + wz * wy * wx * table[iz + dz, iy + dy, ix + dx]
    return out
