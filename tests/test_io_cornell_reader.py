"""The Cornell / pbrt-v2 .brdf reader on small generated files: colours pinned against the published
sRGB matrix (IEC 61966-2-1) and the CIE 1931 table, the negative-RGB count, and the exact message of
each refusal (the file named, the problem in words)."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.errors import InputError
from brdffit.io import cornell

WL = np.arange(400.0, 701.0, 10.0)  # 31 wavelengths
# IEC 61966-2-1 (sRGB), XYZ -> linear RGB, as published (4 decimals)
SRGB_FROM_XYZ = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])


def cie1931_at(wl):
    import colour

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return np.stack([cmfs[w] for w in wl])  # the 1 nm table read at whole wavelengths, no interpolation


def expected_rgb(spectrum):
    """sum_k s_k xyz_bar(l_k), to RGB with the published matrix, divided by the RGB of a flat spectrum of 1."""
    cmf = cie1931_at(WL)
    return (SRGB_FROM_XYZ @ (spectrum @ cmf)) / (SRGB_FROM_XYZ @ cmf.sum(axis=0))


def write(path, rows, wl=WL, header="# generated\n"):
    text = header + f"{len(wl)}\n" + " ".join(f"{w:g}" for w in wl) + "\n"
    text += "".join(" ".join(repr(float(x)) for x in r) + "\n" for r in rows)
    path.write_text(text)
    return path


def test_colours_against_published_matrix(tmp_path):
    red_spd = (WL > 600).astype(float)
    blue_spd = (WL < 480).astype(float)
    ramp = np.linspace(0.0, 1.0, WL.size)
    rows = [[0.3, 0.0, 0.3, np.pi, *s] for s in (red_spd, blue_spd, ramp)]
    m = cornell.read(write(tmp_path / "c.brdf", rows), clip_negative=False)
    got = np.asarray(m.values)
    for k, s in enumerate((red_spd, blue_spd, ramp)):
        np.testing.assert_allclose(got[k], expected_rgb(s), atol=2e-3)
    # the figure for the red spectrum (a transposed matrix gives (0.40, -1.75, -0.27))
    np.testing.assert_allclose(got[0], [0.71, -0.05, -0.01], atol=0.01)
    assert dict(m.extra)["negative_rgb_clipped"] == 0  # nothing clipped when asked not to


def test_negative_rgb_clipped_and_counted(tmp_path):
    red_spd = (WL > 600).astype(float)
    rows = [[0.3, 0.0, 0.3, np.pi, *red_spd], [0.3, 0.0, 0.3, np.pi, *np.full(WL.size, 0.5)]]
    m = cornell.read(write(tmp_path / "c.brdf", rows))
    v = np.asarray(m.values)
    np.testing.assert_allclose(v[0], np.maximum(expected_rgb(red_spd), 0), atol=2e-3)
    assert v[0, 1] == 0.0 and v[0, 2] == 0.0
    np.testing.assert_allclose(v[1], [0.5, 0.5, 0.5], rtol=1e-12)
    extra = dict(m.extra)
    assert extra["negative_rgb_clipped"] == 1
    assert extra["format"] == "cornell" and extra["wavelengths_nm"] == (400.0, 700.0, 31)
    assert m.grid is None and m.name == "c" and m.source == str(tmp_path / "c.brdf")
    assert cornell.read(tmp_path / "c.brdf", name="x").name == "x"


def test_directions_light_first_phi_from_x(tmp_path):
    """pbrt-v2: (theta_i, phi_i) is the light, (s cos phi, s sin phi, cos theta)."""
    row = [np.pi / 3, np.pi / 2, np.pi / 4, np.pi, *np.ones(WL.size)]
    m = cornell.read(write(tmp_path / "d.brdf", [row]))
    s3, s4 = np.sin(np.pi / 3), np.sin(np.pi / 4)
    np.testing.assert_allclose(np.asarray(m.wi)[0], [0.0, s3, 0.5], atol=1e-15)
    np.testing.assert_allclose(np.asarray(m.wo)[0], [-s4, 0.0, s4], atol=1e-15)


def test_comments_and_line_layout_do_not_matter(tmp_path):
    p = tmp_path / "lay.brdf"
    p.write_text("# head\n2 # count\n500\n600 0.1 0 # mid-row comment\n 0.2 3 0.25 0.75\n")
    m = cornell.read(p)
    assert m.n_samples == 1
    np.testing.assert_allclose(np.asarray(m.values)[0], np.array([0.25, 0.75]) @ cornell.spectral_to_rgb_matrix((500.0, 600.0)))


def test_spectral_matrix_interpolates_the_cie_table():
    """At 405 nm (between table rows of the 1 nm table) the CMFs are interpolated linearly; the
    matrix rows are then normalised so that the columns sum to 1."""
    wl = (404.5, 550.0, 650.0)
    m = cornell.spectral_to_rgb_matrix(wl)
    cmf = np.vstack([(cie1931_at([404]) + cie1931_at([405])) / 2, cie1931_at([550, 650])])
    raw = cmf @ SRGB_FROM_XYZ.T
    np.testing.assert_allclose(m, raw / raw.sum(axis=0), atol=2e-3)
    np.testing.assert_allclose(m.sum(axis=0), [1, 1, 1], rtol=1e-12)
    with pytest.raises(ValueError, match="wavelengths 300..500 nm outside the CIE 1931 table 360..830 nm"):
        cornell.spectral_to_rgb_matrix((300.0, 500.0))
    with pytest.raises(ValueError, match="outside the CIE 1931 table"):
        cornell.spectral_to_rgb_matrix((500.0, 900.0))
    cornell.spectral_to_rgb_matrix((360.0, 830.0))  # the table's own ends are inside


GOOD = "2\n500 600\n"


@pytest.mark.parametrize(
    "text, expected",
    [
        ("# only a comment\n", "empty Cornell .brdf file (no numbers)"),
        (GOOD + "0.1 0 0.1 abc 1 1\n", "not a number: 'abc'"),
        (GOOD + "0.1 0 0.1 " + "y" * 60 + " 1 1\n", "not a number: '" + "y" * 40 + "'"),
        ("2.5\n500 600\n", "first number must be the wavelength count, got 2.5"),
        ("0\n", "first number must be the wavelength count, got 0"),
        ("10001\n", "first number must be the wavelength count, got 10001"),
        ("3\n500 600\n", "truncated: 2 numbers after the wavelength count 3"),
        ("2\n600 500\n0 0 0 0 1 1\n", "implausible wavelength list 500..600 nm"),
        ("2\n500 500\n0 0 0 0 1 1\n", "implausible wavelength list 500..500 nm"),
        ("2\n150 600\n0 0 0 0 1 1\n", "implausible wavelength list 150..600 nm"),
        ("2\n500 2100\n0 0 0 0 1 1\n", "implausible wavelength list 500..2100 nm"),
        (GOOD, "no samples after the wavelength list"),
        (GOOD + "0 0 0 0 1 1 0\n", "7 sample numbers are not a multiple of 6 (4 angles + 2 spectral values per sample)"),
        (GOOD + "0 0 0 0 nan 1\n0 0 0 0 1 inf\n0 0 0 0 1 1\n", "2 samples hold non-finite numbers"),
        (GOOD + "-0.1 0 0 0 1 1\n", "theta outside [0, pi/2]: angles must be radians of reflection directions"),
        (GOOD + "0 0 1.5717 0 1 1\n", "theta outside [0, pi/2]: angles must be radians of reflection directions"),
    ],
)
def test_refusals(tmp_path, text, expected):
    p = tmp_path / "bad.brdf"
    p.write_text(text)
    with pytest.raises(InputError) as info:
        cornell.read(p)
    assert info.value.path == str(p) and info.value.problem == expected


def test_boundaries_accepted(tmp_path):
    """One wavelength, 10000 of them, 200 and 2000 nm, theta = 0 and pi/2 are all valid."""
    p = tmp_path / "edge.brdf"
    p.write_text(f"1\n555\n0 0 {np.pi / 2!r} 0 2\n")
    assert np.asarray(cornell.read(p).values).tolist() == [[2.0, 2.0, 2.0]]
    p.write_text("2\n360 830\n0 0 0 0 1 1\n")
    np.testing.assert_allclose(np.asarray(cornell.read(p).values), [[1, 1, 1]], rtol=1e-12)
    many = 10000
    p.write_text(f"{many}\n" + " ".join(str(400 + 0.04 * k) for k in range(many)) + "\n0 0 0 0 " + "1 " * many + "\n")
    np.testing.assert_allclose(np.asarray(cornell.read(p).values), [[1, 1, 1]], rtol=1e-9)


def test_binary_content_refused(tmp_path):
    p = tmp_path / "bin.brdf"
    p.write_bytes(b"2\n500 600\n\xff\xfe\x00")
    with pytest.raises(InputError) as info:
        cornell.read(p)
    assert info.value.problem == "not a text Cornell .brdf file (binary content)"


def test_non_ascii_text_is_refused(tmp_path):
    """The reader decodes ASCII strictly: UTF-8 text (here an accented comment) is not taken."""
    p = tmp_path / "utf8.brdf"
    p.write_text("# mesur\u00e9\n1\n555\n0 0 0 0 2\n", encoding="utf-8")
    with pytest.raises(InputError) as info:
        cornell.read(p)
    assert info.value.problem == "not a text Cornell .brdf file (binary content)"


@pytest.mark.parametrize("wl, reader_says", [("200 600", False), ("200.5 600", False), ("500 2000", False),
                                             ("500 2000.5", True), ("199.5 600", True)])
def test_wavelength_plausibility_bounds(tmp_path, wl, reader_says):
    """200..2000 nm pass the reader's own check (then the CIE table, 360..830 nm, refuses them);
    beyond, the reader refuses the list itself."""
    p = tmp_path / "wl.brdf"
    p.write_text(f"2\n{wl}\n0 0 0 0 1 1\n")
    with pytest.raises(ValueError) as info:
        cornell.read(p)
    if reader_says:
        assert isinstance(info.value, InputError) and info.value.problem.startswith("implausible wavelength list")
    else:
        assert not isinstance(info.value, InputError) and "outside the CIE 1931 table" in str(info.value)


@pytest.mark.parametrize("row", ["0 0 -0.1 0", "1.6 0 0 0", "0 0 1.6 0"])
def test_theta_out_of_range_refused(tmp_path, row):
    p = tmp_path / "t.brdf"
    p.write_text(f"{GOOD}{row} 1 1\n")
    with pytest.raises(InputError, match=r"^.*: theta outside \[0, pi/2\]"):
        cornell.read(p)


def test_any_phi_and_theta_up_to_the_tolerance_accepted(tmp_path):
    """Only thetas are range-checked (pi/2 + 1e-6 still passes); azimuths may be negative or > pi/2;
    a black spectrum is not counted as negative RGB."""
    edge = repr(np.pi / 2 + 1e-6)
    p = tmp_path / "ok.brdf"
    p.write_text(f"{GOOD}0.1 3.0 {edge} -3.0 1 1\n{edge} -2.5 0.2 2.0 0 0\n")
    m = cornell.read(p)
    assert m.n_samples == 2 and dict(m.extra)["negative_rgb_clipped"] == 0
    np.testing.assert_allclose(np.asarray(m.values), [[1, 1, 1], [0, 0, 0]], rtol=1e-12, atol=0)


def test_provenance_written_into_the_metadata(tmp_path):
    """What a saved table tells its reader about the conversion (docs/formats.md#measurement: metadata travel with the data)."""
    m = cornell.read(write(tmp_path / "p.brdf", [[0.3, 0.0, 0.3, np.pi, *np.ones(WL.size)]]))
    extra = dict(m.extra)
    assert extra["colour"] == "CIE 1931 2deg -> linear Rec.709, white-balanced: constant spectrum 1 -> RGB (1,1,1)"
    assert extra["directions"] == "pbrt-v2: first pair = light (wi), second = view (wo), phi from +x"
