"""Cornell / pbrt-v2 .brdf reader: 1439 samples, finite non-negative RGB, peak at grazing mirror."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.errors import InputError
from brdffit.grid import cartesian_to_spherical
from brdffit.io.cornell import spectral_to_rgb_matrix
from conftest import cornell_params

WL = tuple(float(w) for w in range(400, 701, 10))


@pytest.mark.parametrize("path", cornell_params())
def test_cornell_real_files(path):
    m = brdffit.load(path)
    v = np.asarray(m.values)
    assert m.n_samples == 1439 and v.shape == (1439, 3) and m.grid is None
    assert np.all(np.isfinite(v)) and np.all(v >= 0)
    ti, pi_ = cartesian_to_spherical(np.asarray(m.wi))
    to, po = cartesian_to_spherical(np.asarray(m.wo))
    assert np.degrees(ti).min() > 9.9 and np.degrees(ti).max() < 80.1
    # peak of the luminance: grazing incidence (80 deg), view near the mirror direction
    k = int(np.argmax(v @ np.array([0.2126, 0.7152, 0.0722])))
    assert np.degrees(ti[k]) == pytest.approx(80.0, abs=0.5)
    assert abs(np.degrees(to[k]) - np.degrees(ti[k])) < 3.0
    dphi = np.degrees(np.abs(np.angle(np.exp(1j * (po[k] - pi_[k])))))
    assert dphi == pytest.approx(180.0, abs=3.0)


def test_spectral_white_and_linearity():
    M = spectral_to_rgb_matrix(WL)
    np.testing.assert_allclose(np.ones(31) @ M, [1, 1, 1], rtol=1e-12)
    np.testing.assert_allclose(0.25 * np.ones(31) @ M, [0.25, 0.25, 0.25], rtol=1e-12)
    # a long-wavelength spectrum is red, a short-wavelength one blue
    red = (np.asarray(WL) > 600).astype(float) @ M
    blue = (np.asarray(WL) < 480).astype(float) @ M
    assert red[0] > red[1] and red[0] > red[2]
    assert blue[2] > blue[0] and blue[2] > blue[1]


def write_cornell(path, rows, n_wl=31):
    lines = ["# synthetic", str(n_wl), " ".join(str(int(w)) for w in WL[:n_wl])]
    lines += [" ".join(f"{x:.6f}" for x in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")


def test_cornell_synthetic_grey(tmp_path):
    rows = [[0.5, 0.0, 0.3, np.pi] + [0.2] * 31, [0.2, 0.0, 0.2, 1.0] + [0.7] * 31]
    p = tmp_path / "grey.brdf"
    write_cornell(p, rows)
    m = brdffit.load(p)
    np.testing.assert_allclose(np.asarray(m.values), [[0.2] * 3, [0.7] * 3], rtol=1e-6)
    # light = first pair (theta_i, phi_i), view = second
    ti, _ = cartesian_to_spherical(np.asarray(m.wi))
    to, po = cartesian_to_spherical(np.asarray(m.wo))
    np.testing.assert_allclose(ti, [0.5, 0.2], atol=1e-12)
    np.testing.assert_allclose(to, [0.3, 0.2], atol=1e-12)
    np.testing.assert_allclose(po, [np.pi, 1.0], atol=1e-6)  # file holds 6 decimals


def test_cornell_wrong_column_count(tmp_path):
    p = tmp_path / "cols.brdf"
    write_cornell(p, [[0.5, 0.0, 0.3, np.pi] + [0.2] * 30])
    with pytest.raises(InputError, match="not a multiple of 35"):
        brdffit.load(p)


def test_format_override(tmp_path):
    p = tmp_path / "cornell.txt"
    write_cornell(p, [[0.5, 0.0, 0.3, np.pi] + [0.2] * 31])
    m = brdffit.load(p, format="cornell")
    assert m.n_samples == 1 and m.meta["format"] == "cornell"
    with pytest.raises(InputError, match="unknown format"):
        brdffit.load(p)


def _colour_science_rgb(spectra):
    """Independent path: colour-science's tabulated CIE 1931 2-degree CMFs at the file's wavelengths,
    its XYZ_to_RGB (sRGB primaries, no adaptation), white-balanced so a constant 1 gives (1, 1, 1)."""
    import colour

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"][np.asarray(WL)]  # (31, 3)

    def rgb(s):
        return colour.XYZ_to_RGB(np.asarray(s) @ cmfs, "sRGB", illuminant=None, chromatic_adaptation_transform=None)

    return rgb(spectra) / rgb(np.ones(len(WL)))


def test_spectral_colours_pinned_against_colour_science():
    M = spectral_to_rgb_matrix(WL)
    rng = np.random.default_rng(0)
    spectra = rng.uniform(0, 1, (20, len(WL)))
    np.testing.assert_allclose(spectra @ M, _colour_science_rgb(spectra), rtol=1e-10, atol=1e-12)
    # a spectrum of 1 above 600 nm: red with small negative green/blue (outside the Rec. 709 gamut)
    red = (np.asarray(WL) > 600).astype(float)
    np.testing.assert_allclose(red @ M, [0.7137, -0.0532, -0.0122], atol=5e-4)


def test_spectral_line_pinned_against_published_cie_and_iec_values():
    """A line at 600 nm: published CIE 1931 2-degree x,y,z-bar(600) = (1.0622, 0.6310, 0.0008) and the
    IEC 61966-2-1 XYZ -> sRGB matrix; the white is the sum of the CMFs over the 31 wavelengths."""
    import colour

    iec = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])
    white_xyz = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"][np.asarray(WL)].sum(axis=0)
    expect = (iec @ [1.0622, 0.6310, 0.0008]) / (iec @ white_xyz)
    line = (np.asarray(WL) == 600).astype(float)
    np.testing.assert_allclose(line @ spectral_to_rgb_matrix(WL), expect, rtol=2e-3, atol=1e-5)


def test_cornell_reader_colours(tmp_path):
    # the reader applies that conversion per sample, light = first angle pair; negatives clipped and counted
    from brdffit.io.cornell import read

    red = [1.0 if w > 600 else 0.0 for w in WL]
    blue = [1.0 if w < 480 else 0.0 for w in WL]
    p = tmp_path / "rb.brdf"
    write_cornell(p, [[0.5, 0.0, 0.3, np.pi] + red, [0.2, 0.0, 0.2, 1.0] + blue])
    expect = _colour_science_rgb(np.array([red, blue]))
    np.testing.assert_allclose(read(p, clip_negative=False).values, expect, rtol=1e-5, atol=1e-6)
    m = brdffit.load(p)
    np.testing.assert_allclose(np.asarray(m.values), np.maximum(expect, 0), rtol=1e-5, atol=1e-6)
    assert m.meta["negative_rgb_clipped"] == 2


def test_cornell_comments_and_bad_content_named(tmp_path):
    # '#' comments run to the end of the line, also after numbers, and may hold '#' themselves
    p = tmp_path / "c.brdf"
    write_cornell(p, [[0.5, 0.0, 0.3, np.pi] + [0.2] * 31])
    text = p.read_text().splitlines()
    text[1] += "  # 31 wavelengths # of 10 nm"
    p.write_text("\n".join(text) + "\n")
    np.testing.assert_allclose(np.asarray(brdffit.load(p, format="cornell").values), [[0.2] * 3], rtol=1e-6)
    bad = tmp_path / "bad.brdf"
    bad.write_text(p.read_text().replace("0.200000", "0.2x0", 1))
    with pytest.raises(InputError, match=r"bad\.brdf.*not a number: '0\.2x0'"):
        brdffit.load(bad)
    empty = tmp_path / "empty.brdf"
    empty.write_text("# only a comment\n")
    with pytest.raises(InputError, match=r"empty\.brdf.*no numbers"):
        brdffit.load(empty)
    binary = tmp_path / "bin.brdf"
    binary.write_bytes(b"31 400 \xff\xfe\x00 500")
    with pytest.raises(InputError, match=r"bin\.brdf.*binary"):
        brdffit.load(binary)
