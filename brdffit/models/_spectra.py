"""Spectra of a conductor's complex IOR that look, in Mitsuba's spectral variants, like its RGB fit.

A ``mitsuba:roughconductor`` fit has RGB ``eta`` and ``k``. Mitsuba's spectral variants upsample an
RGB property channel by channel into a smooth reflectance-like spectrum, clipped to [0, 1]
(``srgb``), and then evaluate the Fresnel term per wavelength: an eta or k above 1 is lost, and even
below 1 the Fresnel reflectance of upsampled (eta, k) is not the upsampled reflectance -- a purple
fit renders olive. So the export writes eta and k as spectra (a ``<spectrum>`` property: Mitsuba
keeps a spectrum as it is in spectral variants and integrates it to RGB in the others), chosen so
that

1. in RGB variants, Mitsuba's integration (``spectrum_list_to_srgb`` of an unbounded property:
   CIE 1931 under D65, then sRGB) gives back exactly the fitted RGB eta and k, so RGB renders
   are unchanged (the native models' equality, tests/test_native_models.py);
2. in spectral variants, the Fresnel reflectance per wavelength, seen by the same CIE/D65 projection
   (what a spectral render of a white light shows), is the fitted RGB reflectance at every angle.

(1) is linear in the spectra (:func:`srgb_projection`); (2) is a small least-squares problem over
the spectra's values at :data:`WAVELENGTHS` (linear between them), solved with (1) as a hard
constraint, positivity bounds and a little smoothness (:func:`conductor_spectra`).
"""

from __future__ import annotations

import functools

import numpy as np

#: Where the spectra are given (nm): Mitsuba's CIE range, every 20.4 nm (linear in between).
WAVELENGTHS = np.linspace(360.0, 830.0, 24)
#: Mitsuba's constants (``include/mitsuba/core/spectrum.h``): the CIE range, the Y normalisation of its
#: integrals, D65's normalisation and the XYZ -> linear sRGB matrix.
CIE_MIN, CIE_MAX, STEPS = 360.0, 830.0, 1000
Y_NORMALIZATION = 1.0 / 106.7502593994140625
D65_NORMALIZATION = 1.0 / 98.99741751876255
XYZ_TO_SRGB = np.array([[3.240479, -1.537150, -0.498535], [-0.969256, 1.875991, 0.041556],
                        [0.055648, -0.204043, 1.057311]])
#: Angles (cosines) at which the spectral reflectance must look like the RGB one.
COSINES = np.array([1.0, 0.95, 0.85, 0.7, 0.55, 0.4, 0.28, 0.18, 0.1, 0.05, 0.02])


@functools.lru_cache(maxsize=None)
def srgb_projection() -> np.ndarray:
    """M (3, len(WAVELENGTHS)): the linear RGB Mitsuba integrates a spectrum given at WAVELENGTHS to
    (``spectrum_list_to_srgb(..., bounded=False, d65=True)``): CIE 1931 2-degree colour matching
    functions and D65 (colour-science's tables, 5 nm, linear between samples as Mitsuba's), a
    Riemann sum of 1000 steps over [360, 830] nm. rgb = M @ values."""
    from .._colour import import_colour

    colour = import_colour()
    w = CIE_MIN + np.arange(STEPS) / (STEPS - 1) * (CIE_MAX - CIE_MIN)
    grid = np.arange(CIE_MIN, CIE_MAX + 1.0, 5.0)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz_tab = np.stack([np.asarray(cmfs[grid])[:, i] for i in range(3)])
    # D65 as colour-science tabulates it (to 780 nm), held constant beyond: the matching functions are
    # below 1e-4 there
    d65_tab = np.asarray(colour.SDS_ILLUMINANTS["D65"].copy().align(colour.SpectralShape(CIE_MIN, CIE_MAX, 5.0))[grid])
    xyz = np.stack([np.interp(w, grid, xyz_tab[i]) for i in range(3)]) * np.interp(w, grid, d65_tab) * D65_NORMALIZATION
    # the spectrum's value at each step, linear between the nodes: a hat function per node
    hats = np.stack([np.interp(w, WAVELENGTHS, np.eye(len(WAVELENGTHS))[j]) for j in range(len(WAVELENGTHS))], -1)
    return XYZ_TO_SRGB @ (xyz @ hats) * ((CIE_MAX - CIE_MIN) * Y_NORMALIZATION / STEPS)


def _fresnel(cos, eta, k):
    from ._mitsuba_math import fresnel_conductor

    return fresnel_conductor(cos, eta, k)


@functools.lru_cache(maxsize=None)
def _solver():
    """(eta_rgb, k_rgb) -> the log-spectra minimising :func:`_residual`: optimistix's
    Levenberg-Marquardt, compiled once per process (a solve then takes milliseconds)."""
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    n = len(WAVELENGTHS)
    M = jnp.asarray(srgb_projection())
    cos = jnp.asarray(COSINES)[:, None]
    # start: each wavelength takes the channel whose primary dominates there
    band = jnp.asarray(np.select([WAVELENGTHS < 490.0, WAVELENGTHS < 590.0], [2, 1], 0))

    def residual(x, args):
        eta_rgb, k_rgb, target = args
        eta, k = jnp.exp(x[:n]), jnp.exp(x[n:])  # positive
        colour = (M @ _fresnel(cos, eta[None, :], k[None, :]).T).T  # (angles, 3)
        fit = ((colour - target) / jnp.maximum(target, 0.02)).ravel()
        keep = jnp.concatenate([(M @ eta - eta_rgb) / jnp.max(eta_rgb), (M @ k - k_rgb) / jnp.maximum(jnp.max(k_rgb), 0.1)])
        smooth = jnp.concatenate([jnp.diff(eta, 2) / jnp.max(eta_rgb), jnp.diff(k, 2) / jnp.maximum(jnp.max(k_rgb), 0.1)])
        return jnp.concatenate([fit, 100.0 * keep, 0.05 * smooth])

    @jax.jit
    def solve(eta_rgb, k_rgb):
        target = _fresnel(cos, eta_rgb[None, :], k_rgb[None, :])
        x0 = jnp.log(jnp.maximum(jnp.concatenate([eta_rgb[band], k_rgb[band]]), 1e-3))
        sol = optx.least_squares(residual, optx.LevenbergMarquardt(rtol=1e-10, atol=1e-12), x0,
                                 args=(eta_rgb, k_rgb, target), max_steps=500, throw=False)
        return jnp.exp(sol.value[:n]), jnp.exp(sol.value[n:])

    return solve


@functools.lru_cache(maxsize=256)
def _spectra(eta_rgb: tuple, k_rgb: tuple) -> tuple[tuple, tuple]:
    M = srgb_projection()
    eta_rgb, k_rgb = np.asarray(eta_rgb), np.asarray(k_rgb)
    eta, k = (np.asarray(v, np.float64) for v in _solver()(eta_rgb, k_rgb))
    # condition 1 exactly: the smallest change of each spectrum that makes M @ spectrum the RGB value
    # (alternated with positivity, which that change may break where a spectrum nears 0)
    correct = M.T @ np.linalg.solve(M @ M.T, np.eye(3))
    for _ in range(8):
        eta = np.maximum(eta + correct @ (eta_rgb - M @ eta), 1e-4)
        k = np.maximum(k + correct @ (k_rgb - M @ k), 0.0)
    return tuple(float(v) for v in eta), tuple(float(v) for v in k)


def conductor_spectra(eta_rgb, k_rgb) -> tuple[np.ndarray, np.ndarray]:
    """eta(lambda) and k(lambda) at :data:`WAVELENGTHS` for an RGB complex IOR (see the module
    docstring): M @ eta = eta_rgb and M @ k = k_rgb, and the Fresnel reflectance of (eta, k) per
    wavelength, projected to RGB, is the RGB reflectance of (eta_rgb, k_rgb) at every angle."""
    eta, k = _spectra(tuple(float(v) for v in np.reshape(eta_rgb, 3)), tuple(float(v) for v in np.reshape(k_rgb, 3)))
    return np.asarray(eta), np.asarray(k)


def colour_error(eta_rgb, k_rgb, eta, k) -> float:
    """Largest relative difference, over angles and channels, between the RGB reflectance of
    (eta_rgb, k_rgb) and the projected reflectance of the spectra (eta, k)."""
    M = srgb_projection()
    target = np.asarray(_fresnel(COSINES[:, None], np.asarray(eta_rgb)[None, :], np.asarray(k_rgb)[None, :]))
    colour = (M @ np.asarray(_fresnel(COSINES[:, None], np.asarray(eta)[None, :], np.asarray(k)[None, :])).T).T
    return float(np.max(np.abs(colour - target) / np.maximum(target, 0.02)))
