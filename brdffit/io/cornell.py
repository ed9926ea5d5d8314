"""Cornell Program of Computer Graphics gonioreflectometer data, as distributed with pbrt-v2
(``scenes/brdfs/*.brdf``).

Format (pbrt-v2 ``src/materials/measured.cpp``, "Irregularly Sampled Isotropic BRDF"): ``#``
starts a comment to the end of the line; then numbers only: the number of wavelengths n, the n
wavelengths in nm, then per sample ``theta_i phi_i theta_o phi_o`` (radians) and n spectral values.

Direction convention: pbrt-v2 builds ``wi = SphericalDirection(theta_i, phi_i)`` for "the incident
illumination direction" and ``wo`` for "the measured reflection direction" with
``SphericalDirection(s, c, phi) = (s cos phi, s sin phi, c)``, i.e. the first pair is the light
and phi is measured from +x in the same frame for both — docs/conventions.md#conventions's convention, taken as is. (The
shared files have phi_i = 0 and the mirror peak at phi_o = +-180 deg.)

Colour: each spectrum is integrated against the CIE 1931 2-degree observer (colour-science's
tabulated CMFs, sampled at the file's wavelengths) to XYZ, converted to linear Rec. 709 / sRGB
primaries with colour-science's XYZ -> RGB matrix, and white-balanced with one diagonal scale so
that a constant spectral value of 1 maps to exactly RGB (1, 1, 1) (equal-energy illuminant E as
the white; the data are reflectance-like BRDF values, so no other illuminant is implied). The
conversion is linear: a spectrum 0.5 everywhere gives RGB (0.5, 0.5, 0.5). Negative RGB can arise
for saturated spectra outside the Rec. 709 gamut; they are clipped to 0 and counted in
``extra["negative_rgb_clipped"]``.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..grid import spherical_to_cartesian
from ..measurement import Measurement


@functools.lru_cache(maxsize=8)
def spectral_to_rgb_matrix(wavelengths: tuple[float, ...]) -> np.ndarray:
    """(n, 3) matrix M with rgb = spectrum @ M (CIE 1931 2-degree, Rec. 709, constant 1 -> (1,1,1))."""
    from .._colour import import_colour

    colour = import_colour()
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    wl = np.asarray(wavelengths, dtype=np.float64)
    lo, hi = cmfs.wavelengths.min(), cmfs.wavelengths.max()
    if wl.min() < lo or wl.max() > hi:
        raise ValueError(f"wavelengths {wl.min():g}..{wl.max():g} nm outside the CIE 1931 table {lo:g}..{hi:g} nm")
    xyz_bar = np.stack([np.interp(wl, cmfs.wavelengths, cmfs.values[:, k]) for k in range(3)], axis=1)  # (n, 3)
    xyz_to_rgb = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, dtype=np.float64)
    m = xyz_bar @ xyz_to_rgb.T  # (n, 3): spectrum -> un-balanced RGB
    white = m.sum(axis=0)  # RGB of a constant spectrum of 1
    return m / white


def _numbers(path: Path) -> np.ndarray:
    text = path.read_text(encoding="ascii", errors="strict")
    tokens = " ".join(line.split("#", 1)[0] for line in text.splitlines()).split()
    if not tokens:
        raise InputError(path, "empty Cornell .brdf file (no numbers)")
    try:
        return np.asarray([float(t) for t in tokens], dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise InputError(path, f"not a number: {bad[:40]!r}") from None


def _is_float(t: str) -> bool:
    try:
        float(t)
        return True
    except ValueError:
        return False


def read(path, *, name: str | None = None, clip_negative: bool = True) -> Measurement:
    """Read a Cornell / pbrt-v2 ``.brdf`` as scattered RGB samples (grid None)."""
    path = Path(path)
    try:
        v = _numbers(path)
    except UnicodeDecodeError:
        raise InputError(path, "not a text Cornell .brdf file (binary content)") from None
    n_wl = v[0]
    if not (n_wl == int(n_wl) and 1 <= n_wl <= 10000):
        raise InputError(path, f"first number must be the wavelength count, got {v[0]:g}")
    n_wl = int(n_wl)
    if v.size < 1 + n_wl:
        raise InputError(path, f"truncated: {v.size - 1} numbers after the wavelength count {n_wl}")
    wl = v[1 : 1 + n_wl]
    if np.any(np.diff(wl) <= 0) or wl.min() < 200 or wl.max() > 2000:
        raise InputError(path, f"implausible wavelength list {wl.min():g}..{wl.max():g} nm")
    rest = v[1 + n_wl :]
    row = 4 + n_wl
    if rest.size == 0:
        raise InputError(path, "no samples after the wavelength list")
    if rest.size % row:
        raise InputError(
            path, f"{rest.size} sample numbers are not a multiple of {row} (4 angles + {n_wl} spectral values per sample)"
        )
    s = rest.reshape(-1, row)
    angles, spectra = s[:, :4], s[:, 4:]
    if not np.all(np.isfinite(s)):
        raise InputError(path, f"{int(np.sum(~np.all(np.isfinite(s), axis=1)))} samples hold non-finite numbers")
    if np.any(angles[:, [0, 2]] < 0) or np.any(angles[:, [0, 2]] > np.pi / 2 + 1e-6):
        raise InputError(path, "theta outside [0, pi/2]: angles must be radians of reflection directions")
    rgb = spectra @ spectral_to_rgb_matrix(tuple(float(x) for x in wl))
    negative = int(np.sum(np.any(rgb < 0, axis=1)))
    if clip_negative:
        rgb = np.maximum(rgb, 0.0)
    wi = spherical_to_cartesian(angles[:, 0], angles[:, 1])
    wo = spherical_to_cartesian(angles[:, 2], angles[:, 3])
    return Measurement(
        wi=wi,
        wo=wo,
        values=rgb,
        name=name or path.stem,
        source=str(path),
        grid=None,
        extra={
            "format": "cornell",
            "wavelengths_nm": (float(wl[0]), float(wl[-1]), n_wl),
            "colour": "CIE 1931 2deg -> linear Rec.709, white-balanced: constant spectrum 1 -> RGB (1,1,1)",
            "negative_rgb_clipped": negative if clip_negative else 0,
            "directions": "pbrt-v2: first pair = light (wi), second = view (wo), phi from +x",
        },
    )
