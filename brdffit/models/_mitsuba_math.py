"""Mitsuba 3's own building blocks, in JAX, for the ``mitsuba:*`` native models (docs/materials.md#native-materials-and-exports).

Each function reproduces a named piece of Mitsuba 3 (``include/mitsuba/render/fresnel.h``,
``microfacet.h``, ``src/bsdfs/roughplastic.cpp``) term for term, so that a native model equals the
plugin the user renders with; the tests hold every model equal to Mitsuba's ``bsdf.eval``
(tests/test_native_models.py). Written for the isotropic GGX distribution with visible-normal
sampling, the only setting the native models write.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from . import _math as m
from . import _microfacet as mf

#: Entries of roughplastic's precomputed external transmittance table over cos theta in [0, 1]
#: (Mitsuba's MI_ROUGH_TRANSMITTANCE_RES).
TRANSMITTANCE_RES = 64
#: The grids over which roughplastic's two precomputed terms are tabulated (:func:`rough_tables`):
#: (first node, last node, intervals) of ln(alpha) and of ln(eta - 1), spanning the model's bounds
#: (alpha in [1e-4, 1], int_ior in [1.05, 3]; the transmittance at grazing angles changes fastest
#: near eta = 1), one more node beyond each end; intervals of each direction's u axis.
TABLE_LOG_ALPHA = (math.log(1e-4), 0.0, 48)
TABLE_LOG_ETA1 = (math.log(0.05), math.log(2.0), 64)
TABLE_U = 64
TABLE_FILE = Path(__file__).with_name("_roughplastic_tables.npz")


def fresnel_conductor(cos_theta_i, eta, k):
    """Unpolarised Fresnel reflectance of a conductor with complex IOR eta + i k (Mitsuba's
    ``fresnel_conductor``, after Moeller's "Optics"), cos_theta_i in [0, 1]."""
    c2 = cos_theta_i * cos_theta_i
    s2 = 1.0 - c2
    s4 = s2 * s2
    temp1 = eta * eta - k * k - s2
    four_k2_eta2 = 4.0 * k * k * eta * eta
    a2pb2 = m.safe_sqrt(temp1 * temp1 + four_k2_eta2)
    # a^2 = (a2pb2 + temp1) / 2 as Mitsuba writes it cancels where temp1 < 0 (total internal
    # reflection of a small eta, k ~ 0); there it is 4 k^2 eta^2 / (2 (a2pb2 - temp1)), the same
    # number without the cancellation (found by the reciprocity property test: jitted, one order of
    # the directions gave F = 0 instead of 1).
    negative = temp1 < 0.0
    denominator = jnp.where(negative, a2pb2 - temp1, 1.0)
    a = m.safe_sqrt(jnp.where(negative, 0.5 * four_k2_eta2 / denominator, 0.5 * (a2pb2 + temp1)))
    term1 = a2pb2 + c2
    term2 = 2.0 * cos_theta_i * a
    r_s = (term1 - term2) / (term1 + term2)
    term3 = a2pb2 * c2 + s4
    term4 = term2 * s2
    r_p = r_s * (term3 - term4) / (term3 + term4)
    # at a matched index (eta 1, k 0) the differences above cancel to round-off, e.g. -7.7e-18:
    # a reflectance is never negative (Mitsuba's float32 result there is 0 to its precision)
    return jnp.maximum(0.5 * (r_s + r_p), 0.0)


def fresnel_dielectric(cos_theta_i, eta):
    """Mitsuba's ``fresnel(cos_theta_i, eta)`` for a real relative IOR ``eta`` (eta != 1): the
    unpolarised reflectance, the signed cosine of the refracted ray and eta_ti; total internal
    reflection gives r = 1."""
    outside = cos_theta_i >= 0.0
    eta_it = jnp.where(outside, eta, 1.0 / eta)
    eta_ti = jnp.where(outside, 1.0 / eta, eta)
    cos_t_sqr = 1.0 - (1.0 - cos_theta_i * cos_theta_i) * eta_ti * eta_ti
    ci = jnp.abs(cos_theta_i)
    ct = m.safe_sqrt(cos_t_sqr)
    a_s = (ci - eta_it * ct) / (ci + eta_it * ct)
    a_p = (ct - eta_it * ci) / (ct + eta_it * ci)
    r = 0.5 * (a_s * a_s + a_p * a_p)
    r = jnp.where(ci == 0.0, 1.0, r)
    cos_t = jnp.where(cos_theta_i >= 0.0, -ct, ct)
    return r, cos_t, eta_ti


def ggx_d(h, alpha):
    """Mitsuba's GGX ``eval(m)`` (isotropic): the kit's D (``_microfacet.ggx_d``)."""
    return mf.ggx_d(h, alpha)


def smith_g1(v, h, alpha):
    """Mitsuba's GGX ``smith_g1(v, m)``: the kit's G1, 0 where v sees the back of the microfacet m."""
    back = m.dot(v, h) * v[..., 2:3] <= 0.0
    return jnp.where(back, 0.0, mf.smith_g1(v, alpha))


def rgb(values) -> dict:
    """An RGB property of a ``mi.load_dict`` dictionary."""
    return {"type": "rgb", "value": [float(x) for x in values]}


def spectrum(wavelengths, values) -> dict:
    """A spectrum property of a ``mi.load_dict`` dictionary (``<spectrum value="400:0.1, ..."/>``):
    kept as it is in spectral variants, integrated to RGB (CIE 1931, D65) in the others."""
    return {"type": "spectrum", "value": [(float(w), float(v)) for w, v in zip(wavelengths, values)]}


def ggx_halfwidth(p) -> float:
    """Half width at half maximum of a GGX lobe of roughness ``p["alpha"]`` (``_microfacet.halfwidth``)."""
    return mf.halfwidth(p["alpha"])


# -- roughplastic's precomputed tables ----------------------------------------------------------

def _concentric_disk(u):
    """Mitsuba's ``square_to_uniform_disk_concentric`` of points u in [0, 1]^2 (..., 2)."""
    x = 2.0 * u[..., 0] - 1.0
    y = 2.0 * u[..., 1] - 1.0
    q13 = np.abs(x) < np.abs(y)
    r = np.where(q13, y, x)
    rp = np.where(q13, x, y)
    safe_r = np.where(r == 0.0, 1.0, r)
    phi = 0.25 * np.pi * rp / safe_r
    phi = np.where(q13, 0.5 * np.pi - phi, phi)
    phi = np.where((x == 0.0) & (y == 0.0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


@functools.lru_cache(maxsize=None)
def _quadrature(res: int):
    """Mitsuba's quadrature of ``eval_reflectance`` / ``eval_transmittance``: a res x res
    Gauss-Legendre grid on [0, 1]^2, its points through the concentric disk map (the first step of
    visible-normal sampling, independent of the parameters), and weights w_x w_y / 4."""
    nodes, weights = np.polynomial.legendre.leggauss(res)
    nx, ny = np.meshgrid(nodes, nodes)
    wx, wy = np.meshgrid(weights, weights)
    u = np.stack([0.5 * nx.ravel() + 0.5, 0.5 * ny.ravel() + 0.5], -1)
    px, py = _concentric_disk(u)
    return px, py, (wx * wy).ravel() * 0.25


def _vndf_normals(mu, alpha, px, py):
    """Microfacet normals (T, Q, 3) that Mitsuba's GGX visible-normal sampling (``sample``, the
    Heitz-d'Eon 2014 method) draws for the directions wi = (sqrt(1 - mu^2), 0, mu) (T,) at the disk
    points (px, py) (Q,); wi lies in the x-z plane, so phi = 0 after stretching."""
    cos_i = mu[:, None]
    sin_i = jnp.sqrt(jnp.maximum(1.0 - mu * mu, 0.0))[:, None]
    # step 1: stretch wi; it stays in the x-z plane (phi = 0 where sin theta > 0)
    sx, sz = alpha * sin_i, cos_i
    norm = jnp.sqrt(sx * sx + sz * sz)
    cos_t, sin_t = sz / norm, sx / norm
    # step 2: sample_visible_11
    s = 0.5 * (1.0 + cos_t)
    ppy = (1.0 - s) * jnp.sqrt(jnp.maximum(1.0 - px * px, 0.0)) + s * py
    z = jnp.sqrt(jnp.maximum(1.0 - (px * px + ppy * ppy), 0.0))
    inv = 1.0 / (sin_t * ppy + cos_t * z)
    slope_x = (cos_t * ppy - sin_t * z) * inv
    slope_y = px * inv
    # step 3: rotate (phi = 0: identity) and unstretch; step 4: the normal
    nx, ny = -slope_x * alpha, -slope_y * alpha
    nn = jnp.sqrt(nx * nx + ny * ny + 1.0)
    return jnp.stack([nx / nn, ny / nn, jnp.broadcast_to(1.0 / nn, nx.shape)], -1)


def _table_directions(n: int = TRANSMITTANCE_RES):
    mu = np.maximum(1e-6, np.linspace(0.0, 1.0, n))
    wi = np.stack([np.sqrt(1.0 - mu * mu), np.zeros(n), mu], -1)
    return mu, wi


def _constants(res: int, dtype):
    """The table directions and the quadrature, in the parameters' dtype (float32 stays float32)."""
    mu, wi = _table_directions()
    px, py, w = _quadrature(res)
    return tuple(jnp.asarray(a, dtype) for a in (mu, wi, px, py, w))


def external_transmittance(alpha, eta):
    """roughplastic's ``m_external_transmittance`` (TRANSMITTANCE_RES,): the fraction of light
    from each table direction transmitted through the rough dielectric interface of relative IOR
    ``eta`` > 1 (Mitsuba's ``eval_transmittance``, 32 x 32 nodes for eta > 1)."""
    mu, wi, px, py, w = _constants(32, alpha.dtype)
    mvec = _vndf_normals(mu, alpha, px, py)  # (T, Q, 3)
    wi_b = wi[:, None, :]
    cos_im = jnp.sum(wi_b * mvec, axis=-1, keepdims=True)
    f, cos_t, eta_ti = fresnel_dielectric(cos_im, eta)
    wo = mvec * (cos_im * eta_ti + cos_t) - wi_b * eta_ti  # Mitsuba's refract
    g = smith_g1(wo, mvec, alpha) * (1.0 - f)
    g = jnp.where(wo[..., 2:3] * wi_b[..., 2:3] >= 0.0, 0.0, g)
    return jnp.sum(g[..., 0] * w, axis=-1)


def directional_reflectance(alpha, eta, mu):
    """The rough interface's reflectance seen from inside the layer (relative IOR 1/eta) for the
    directions of cosines ``mu`` (D,): Mitsuba's ``eval_reflectance`` (128 x 128 nodes for 1/eta < 1)."""
    _, _, px, py, w = _constants(128, alpha.dtype)
    mu = jnp.asarray(mu, alpha.dtype)
    wi = jnp.stack([jnp.sqrt(1.0 - mu * mu), jnp.zeros_like(mu), mu], -1)
    mvec = _vndf_normals(mu, alpha, px, py)
    wi_b = wi[:, None, :]
    cos_im = jnp.sum(wi_b * mvec, axis=-1, keepdims=True)
    f, _, _ = fresnel_dielectric(cos_im, 1.0 / eta)
    wo = 2.0 * cos_im * mvec - wi_b  # Mitsuba's reflect(wi, m)
    g = smith_g1(wo, mvec, alpha) * f
    g = jnp.where(wo[..., 2:3] <= 0.0, 0.0, g)
    return jnp.sum(g[..., 0] * w, axis=-1)


def internal_reflectance(alpha, eta):
    """roughplastic's ``m_internal_reflectance``: the hemispherical reflectance seen from inside
    the layer, 2 mean(R(wi, 1/eta) cos theta_i) over the table directions."""
    mu, _ = _table_directions()
    return 2.0 * jnp.mean(directional_reflectance(alpha, eta, mu) * jnp.asarray(mu, alpha.dtype))


def lerp_table(table, x):
    """Mitsuba's ``lerp_gather``: linear interpolation of a table over [0, 1] at x (..., 1)."""
    n = table.shape[0]
    t = x * (n - 1)
    index = jnp.clip(jnp.floor(t), 0, n - 2).astype(jnp.int32)
    v0 = table[index]
    v1 = table[index + 1]
    return v0 + (v1 - v0) * (t - index)


def _table_nodes(spec) -> np.ndarray:
    first, last, n = spec
    h = (last - first) / n
    return first + h * np.arange(-1, n + 2)


def _critical_cos(eta):
    """Cosine of the critical angle inside a layer of relative IOR eta: total reflection below it."""
    return jnp.sqrt(1.0 - 1.0 / (eta * eta))


@functools.lru_cache(maxsize=None)
def _u_axes() -> tuple[np.ndarray, np.ndarray]:
    """(start, step) (alpha nodes, directions) of each direction's u axis (see :func:`rough_tables`):
    TABLE_U intervals over the critical cosines of TABLE_LOG_ETA1's range, one node beyond each end."""
    mu, _ = _table_directions()
    scale = np.exp(_table_nodes(TABLE_LOG_ALPHA))[:, None]
    etas = 1.0 + np.exp(_table_nodes(TABLE_LOG_ETA1))
    c_lo, c_hi = (math.sqrt(1.0 - 1.0 / (e * e)) for e in (etas[0], etas[-1]))  # _critical_cos, in NumPy
    u_lo, u_hi = np.arcsinh((c_lo - mu) / scale), np.arcsinh((c_hi - mu) / scale)
    return u_lo, (u_hi - u_lo) / TABLE_U


def build_rough_tables(path: Path = TABLE_FILE) -> None:
    """Tabulate roughplastic's terms with Mitsuba's own quadratures (above), in float64, and write
    them to ``path`` (what :func:`rough_tables` reads; run ``python -m brdffit.models._mitsuba_math``
    after changing the grids or the quadratures; about 10 minutes on two cores):
    ``transmittance[a, e, :]``, ``external_transmittance`` at the nodes of TABLE_LOG_ALPHA x
    TABLE_LOG_ETA1; ``reflectance[a, k, j]``, ``directional_reflectance`` of table direction k at node j
    of its u axis (:func:`_u_axes`)."""
    trans = jax.jit(jax.vmap(external_transmittance, in_axes=(None, 0)))
    refl = jax.jit(jax.vmap(lambda a, e, mu: directional_reflectance(a, e, mu[None])[0], in_axes=(None, 0, None)))
    mu, _ = _table_directions()
    u_lo, u_step = _u_axes()
    alphas, etas = np.exp(_table_nodes(TABLE_LOG_ALPHA)), 1.0 + np.exp(_table_nodes(TABLE_LOG_ETA1))
    transmittance = np.array([np.asarray(trans(jnp.float64(a), jnp.asarray(etas))) for a in alphas])
    reflectance = np.zeros((len(alphas), len(mu), TABLE_U + 3))
    for i, a in enumerate(alphas):
        for k, mu_k in enumerate(mu):  # not ``m``: that is the module ``_math`` here
            c = mu_k + a * np.sinh(u_lo[i, k] + u_step[i, k] * np.arange(0, TABLE_U + 1))
            inner = np.asarray(refl(jnp.float64(a), jnp.asarray(1.0 / np.sqrt(1.0 - c * c)), jnp.float64(mu_k)))
            # the node beyond each end, for the cubic's first and last interval: extrapolated (in
            # u, one step may leave the cosines' range at small alpha)
            reflectance[i, k] = np.concatenate([[2 * inner[0] - inner[1]], inner, [2 * inner[-1] - inner[-2]]])
    np.savez_compressed(path, transmittance=transmittance.astype(np.float32), reflectance=reflectance.astype(np.float32),
                        spec=np.asarray([*TABLE_LOG_ALPHA, *TABLE_LOG_ETA1, TABLE_U]))


@functools.lru_cache(maxsize=None)
def _rough_table() -> tuple[np.ndarray, np.ndarray]:
    with np.load(TABLE_FILE) as f:
        if not np.allclose(f["spec"], [*TABLE_LOG_ALPHA, *TABLE_LOG_ETA1, TABLE_U]):
            raise RuntimeError(f"{TABLE_FILE}: made for other grids; run python -m brdffit.models._mitsuba_math")
        return np.asarray(f["transmittance"], np.float64), np.asarray(f["reflectance"], np.float64)


def _cubic_weights(t):
    """The 4 weights of the cubic (Catmull-Rom) interpolant at t in [0, 1) between the middle two of
    4 nodes: continuous with its first derivative (what a solver needs)."""
    t2, t3 = t * t, t * t * t
    return jnp.stack([0.5 * (-t3 + 2 * t2 - t), 0.5 * (3 * t3 - 5 * t2 + 2), 0.5 * (-3 * t3 + 4 * t2 + t), 0.5 * (t3 - t2)])


def _cubic_index(x, first, step, n):
    """Index of the first of the 4 nodes around x on an axis of n intervals from ``first`` (node 0
    lies one step before it), and their weights."""
    u = (x - first) / step + 1.0
    i = jnp.clip(jnp.floor(u), 1, n)
    return (i - 1).astype(jnp.int32), _cubic_weights(u - i)


def rough_tables(alpha, eta):
    """roughplastic's two precomputed terms at (alpha, eta), ``external_transmittance`` (64,) and
    ``internal_reflectance`` (), from tables of Mitsuba's own quadratures (:func:`build_rough_tables`),
    cubic between nodes: the transmittance over (ln alpha, ln(eta - 1)); the internal reflectance as its 64
    directional terms, each over (ln alpha, u) with u = asinh((c - mu) / alpha), c the critical cosine
    of eta: a term changes fast where c crosses its direction's cosine mu, within about alpha (total
    reflection begins there), and u spreads that crossing over many nodes. The quadratures themselves
    (1.1 M nodes) made a fit 450x slower than a ggx fit and 2.5 GB large."""
    transmittance, reflectance = (jnp.asarray(t, alpha.dtype) for t in _rough_table())
    first, last, n = TABLE_LOG_ALPHA
    ia, wa = _cubic_index(jnp.log(alpha), first, (last - first) / n, n)
    first_e, last_e, n_e = TABLE_LOG_ETA1
    ie, we = _cubic_index(jnp.log(eta - 1.0), first_e, (last_e - first_e) / n_e, n_e)
    block = jax.lax.dynamic_slice(transmittance, (ia, ie, jnp.int32(0)), (4, 4, transmittance.shape[2]))
    t = jnp.einsum("a,e,aek->k", wa, we, block)
    # the internal reflectance: each of the 4 alpha nodes' tables at that node's u of every direction
    mu = jnp.asarray(_table_directions()[0], alpha.dtype)
    u_lo, u_step = (jax.lax.dynamic_slice(jnp.asarray(x, alpha.dtype), (ia, jnp.int32(0)), (4, mu.shape[0])) for x in _u_axes())
    scale = jnp.exp(first + (last - first) / n * (ia - 1 + jnp.arange(4)))[:, None]
    u = jnp.arcsinh((_critical_cos(eta) - mu[None, :]) / scale)
    x = (u - u_lo) / u_step + 1.0
    j = jnp.clip(jnp.floor(x), 1, TABLE_U)
    wj = _cubic_weights(x - j)  # (4 nodes along u, 4 alpha nodes, directions)
    rows = jax.lax.dynamic_slice(reflectance, (ia, jnp.int32(0), jnp.int32(0)), (4,) + reflectance.shape[1:])
    values = jnp.take_along_axis(rows, (j.astype(jnp.int32) - 1)[..., None] + jnp.arange(4), axis=-1)  # (4, D, 4)
    r = jnp.einsum("a,ak->k", wa, jnp.sum(values * jnp.moveaxis(wj, 0, -1), axis=-1))
    return t, 2.0 * jnp.mean(r * mu)


if __name__ == "__main__":
    from .. import _x64  # noqa: F401 - float64

    build_rough_tables()
