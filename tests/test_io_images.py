"""Image folders: known per-direction colours come back (flat and per-view, PNG and EXR)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

import brdffit
from brdffit.errors import InputError
from brdffit.io.images import direction_name, linear_to_srgb, srgb_to_linear

N = 81


def codes(seed=0):
    """A distinct 8-bit sRGB colour per (light, view) pair."""
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, size=(N, N, 3), dtype=np.uint8)


def write_folder(root, kind="png", layout="flat", table=None, prefix="", skip=(), size=2):
    root.mkdir(parents=True, exist_ok=True)
    for i in range(N):
        for j in range(N):
            if (i, j) in skip:
                continue
            stem = prefix + direction_name(i, j)
            folder = root
            if layout in ("views", "views-short"):
                folder = root / stem[-11:]  # tvTTT_pvPPP
                folder.mkdir(exist_ok=True)
            if layout == "views-short":
                stem = stem[:-12]  # [prefix_]tlTTT_plPPP: the view is the folder's
            if kind == "png":
                Image.fromarray(np.tile(table[i, j], (size, size, 1))).save(folder / f"{stem}.png")
            else:
                import OpenEXR

                px = {c: np.full((size, size), table[i, j, k], np.float32) for k, c in enumerate("RGB")}
                OpenEXR.File({"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}, px).write(
                    str(folder / f"{stem}.exr")
                )
    return root


def eotf(c):
    """Expected linear values from colour-science's own sRGB EOTF (IEC 61966-2-1), not the product's."""
    import colour

    return colour.models.eotf_sRGB(np.asarray(c, np.float64))


def test_srgb_eotf_computes_in_float64():
    codes32 = np.array([0.5, 0.9], np.float32)
    got = srgb_to_linear(codes32)
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, ((codes32.astype(np.float64) + 0.055) / 1.055) ** 2.4)


def test_srgb_eotf_exact():
    c = np.array([0.0, 0.04045, 0.5, 1.0])
    np.testing.assert_allclose(srgb_to_linear(c), [0, 0.04045 / 12.92, ((0.555) / 1.055) ** 2.4, 1.0], rtol=1e-15)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(c)), c, atol=1e-12)
    every_code = np.arange(256) / 255.0
    np.testing.assert_allclose(srgb_to_linear(every_code), eotf(every_code), rtol=1e-12, atol=1e-15)
    # by hand from the IEC 61966-2-1 formula: code 128 -> 0.2158605, code 188 -> 0.5028865 (8-bit, /255)
    np.testing.assert_allclose(srgb_to_linear(np.array([128, 188]) / 255), [0.2158605, 0.5028865], rtol=1e-6)


def test_linear_to_srgb_clips_to_code_range_and_encodes_in_float64():
    """Writers (sample images, BTF maps, render previews) rely on codes in [0, 1]: linear values below
    0 encode as 0, above 1 as 1; in between, colour-science's sRGB encoding (IEC 61966-2-1)."""
    import colour

    def oetf(x):
        return colour.cctf_encoding(np.asarray(x, np.float64), function="sRGB")

    x = np.array([-2.0, -1e-3, 0.0, 0.002, 0.18, 0.5, 1.0, 1.5, 7.0])
    expected = np.concatenate([[0.0, 0.0], oetf(x[2:7]), [1.0, 1.0]])
    np.testing.assert_allclose(linear_to_srgb(x), expected, rtol=1e-12, atol=0)
    # float32 input (e.g. an EXR image) is encoded in float64, not rounded to float32 on the way
    x32 = np.array([0.002, 0.18, 0.5, 0.9], np.float32)
    out = linear_to_srgb(x32)
    assert out.dtype == np.float64
    np.testing.assert_allclose(out, oetf(x32.astype(np.float64)), rtol=1e-12, atol=0)


@pytest.mark.parametrize("layout", ["flat", "views", "views-short"])
def test_png_folder_colours(tmp_path, layout):
    table = codes(1)
    root = write_folder(tmp_path / "btf", "png", layout, table, prefix="mat_")
    m = brdffit.load(root)
    assert m.grid == "ubo81" and m.meta["layout"] == ("flat" if layout == "flat" else "per-view folders")
    np.testing.assert_allclose(m.table(), eotf(table / 255.0), rtol=1e-12, atol=1e-15)
    wi, wo = brdffit.ubo_pairs()
    np.testing.assert_array_equal(np.asarray(m.wi), wi)
    np.testing.assert_array_equal(np.asarray(m.wo), wo)


def test_exr_folder_colours_and_cos_option(tmp_path):
    rng = np.random.default_rng(2)
    table = rng.uniform(0, 4, size=(N, N, 3)).astype(np.float32)
    root = write_folder(tmp_path / "exr", "exr", "views", table)
    m = brdffit.load(root)
    np.testing.assert_array_equal(m.table(), table.astype(np.float64))
    m2 = brdffit.load(root, includes_cos=True, scale=2.0)
    cos_l = brdffit.ubo_directions()[:, 2]
    np.testing.assert_allclose(m2.table(), 2.0 * table / cos_l[:, None, None], rtol=1e-12)
    assert m2.meta["includes_cos"] is True and m2.meta["scale"] == 2.0


def test_region_mean(tmp_path):
    # one image with a bright corner: the region picks it, the full mean averages it in
    table = np.zeros((N, N, 3), np.uint8)
    root = write_folder(tmp_path / "r", "png", "flat", table, size=4)
    img = np.zeros((4, 4, 3), np.uint8)
    img[:2, :2] = 255
    Image.fromarray(img).save(root / f"{direction_name(5, 7)}.png")
    full = brdffit.load(root).table()[5, 7]
    part = brdffit.load(root, region=(0, 2, 0, 2)).table()[5, 7]
    np.testing.assert_allclose(full, [0.25] * 3)
    np.testing.assert_allclose(part, [1.0] * 3)


def test_true_light_directions_recorded(tmp_path):
    root = write_folder(tmp_path / "t", "png", "flat", codes(3))
    wi, _ = brdffit.ubo_pairs()
    shifted = wi + np.array([0.01, 0.0, 0.0])
    m = brdffit.load(root, true_wi=shifted)
    np.testing.assert_allclose(np.asarray(m.wi), shifted / np.linalg.norm(shifted, axis=1, keepdims=True))
    assert m.meta["light_directions"] == "true (given)"
    assert brdffit.load(root).meta["light_directions"].startswith("nominal")


def test_missing_duplicate_offgrid_named(tmp_path):
    table = codes(4)
    root = write_folder(tmp_path / "m", "png", "flat", table, skip={(3, 4)})
    with pytest.raises(InputError, match=direction_name(3, 4)):
        brdffit.load(root)
    Image.fromarray(table[3, 4][None, None]).save(root / f"{direction_name(3, 4)}.png")
    brdffit.load(root)  # complete now
    Image.fromarray(table[3, 4][None, None]).save(root / f"x_{direction_name(3, 4)}.png")
    with pytest.raises(InputError, match="duplicated direction " + direction_name(3, 4)):
        brdffit.load(root)
    (root / f"x_{direction_name(3, 4)}.png").unlink()
    Image.fromarray(table[3, 4][None, None]).save(root / "tl015_pl010_tv000_pv000.png")
    with pytest.raises(InputError) as err:
        brdffit.load(root)
    assert str(err.value) == f"{root / 'tl015_pl010_tv000_pv000.png'}: light direction tl015_pl010 is not on the UBO-81 grid"
    (root / "tl015_pl010_tv000_pv000.png").unlink()
    (root / "notes.txt").write_text("ignored")
    Image.fromarray(table[0, 0][None, None]).save(root / "photo.png")
    with pytest.raises(InputError, match="photo.png: unparsable image name"):
        brdffit.load(root)


def test_read_image_kinds(tmp_path):
    from brdffit.io.images import read_image

    grey = np.array([[0, 128], [255, 64]], np.uint8)
    Image.fromarray(grey, "L").save(tmp_path / "g.png")
    np.testing.assert_allclose(read_image(tmp_path / "g.png")[..., 0], eotf(grey / 255.0))
    sixteen = np.array([[0, 30000], [65535, 1000]], np.uint16)
    Image.fromarray(sixteen).save(tmp_path / "s.png")
    np.testing.assert_allclose(read_image(tmp_path / "s.png")[..., 0], eotf(sixteen / 65535.0))
    np.testing.assert_allclose(read_image(tmp_path / "s.png", srgb=False)[..., 0], sixteen / 65535.0)
    rgb = np.full((8, 8, 3), (200, 100, 50), np.uint8)
    Image.fromarray(rgb).save(tmp_path / "c.jpg", quality=95)
    np.testing.assert_allclose(read_image(tmp_path / "c.jpg").mean(axis=(0, 1)), eotf(np.array([200, 100, 50]) / 255), atol=0.01)


def test_option_errors(tmp_path):
    from brdffit.errors import UsageError

    root = tmp_path / "o"
    root.mkdir()
    with pytest.raises(UsageError, match="region"):
        brdffit.load(root, region=(0, 1))
    p = tmp_path / "x.npz"
    brdffit.save(brdffit.Measurement(wi=[[0, 0, 1.0]], wo=[[0, 0, 1.0]], values=[[1.0]]), p)
    with pytest.raises(UsageError, match="unexpected keyword"):
        brdffit.load(p, region=(0, 1, 0, 1))


def test_short_name_off_the_grid_is_named(tmp_path):
    root = write_folder(tmp_path / "s", "png", "views-short", codes(5))
    bad = root / "tv000_pv000" / "tl015_pl010.png"
    Image.fromarray(codes(5)[0, 0][None, None]).save(bad)
    with pytest.raises(InputError) as err:
        brdffit.load(root)
    assert str(err.value) == f"{bad}: light direction tl015_pl010 is not on the UBO-81 grid"


def test_incomplete_set_names_the_count_and_the_first_three_missing(tmp_path):
    skip = {(0, 3), (2, 0), (2, 1), (40, 80), (80, 80)}
    root = write_folder(tmp_path / "i", "png", "flat", codes(6), skip=skip)
    with pytest.raises(InputError) as err:
        brdffit.load(root)
    first = ", ".join(direction_name(*k) for k in [(0, 3), (2, 0), (2, 1)])
    assert str(err.value) == f"{root}: incomplete image set: 5 of 6561 UBO pairs missing, e.g. {first}"


def test_region_selecting_no_texels_is_named(tmp_path):
    root = write_folder(tmp_path / "e", "png", "flat", codes(7), size=4)
    with pytest.raises(InputError) as err:
        brdffit.load(root, region=(2, 2, 0, 4))
    assert str(err.value).endswith(".png: region (2, 2, 0, 4) selects no texels of this image"), str(err.value)


@pytest.mark.parametrize("names", [("R", "G", "B", "A"), ("Y",), ("Y", "A")])
def test_read_image_exr_channels(tmp_path, names):
    """An EXR photograph: R, G, B when all three are there (alpha is not colour), else Y; linear."""
    import OpenEXR

    from brdffit.io.images import read_image

    rng = np.random.default_rng(8)
    px = {n: rng.uniform(0, 2, (3, 5)).astype(np.float32) for n in names}
    OpenEXR.File({"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}, dict(px)).write(str(tmp_path / "p.exr"))
    colour = ["R", "G", "B"] if "R" in names else ["Y"]
    got = read_image(tmp_path / "p.exr")
    assert got.dtype == np.float64  # (a float32 mean over an image's texels would round)
    np.testing.assert_array_equal(got, np.stack([px[n] for n in colour], -1).astype(np.float64))
    OpenEXR.File({"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}, {"A": px[names[0]]}).write(
        str(tmp_path / "a.exr"))
    with pytest.raises(ValueError, match=r"^no R,G,B or Y channels \(has A\)$"):
        read_image(tmp_path / "a.exr")


def test_metadata_in_full(tmp_path):
    """What a folder's Measurement records of how it was read (the meta of docs/formats.md#measurement; ``brdffit info``)."""
    table = codes(9)
    root = write_folder(tmp_path / "meta", "png", "flat", table)
    m = brdffit.load(root)
    assert (m.name, m.source, m.grid) == ("meta", str(root), "ubo81")
    assert m.meta == {"name": "meta", "source": str(root), "grid": "ubo81", "colour_space": "linear_rec709",
                      "units": "1/sr", "format": "images", "layout": "flat", "image_types": (".png",),
                      "decoding": "sRGB EOTF (IEC 61966-2-1) for 8/16-bit, EXR linear", "region": None,
                      "includes_cos": False, "scale": 1.0, "light_directions": "nominal (file names)"}
    raw = brdffit.load(root, srgb=False, region=[0, 1, 0, 1], scale=3, name="codes")
    extra = {k: raw.meta[k] for k in ("decoding", "region", "scale", "name")}
    assert extra == {"decoding": "codes taken as linear", "region": (0, 1, 0, 1), "scale": 3.0, "name": "codes"}
    np.testing.assert_allclose(raw.table(), 3.0 * table / 255.0, rtol=1e-12)


def test_a_view_folder_at_pv360_is_the_view_at_pv000(tmp_path):
    """Azimuths agree modulo 360: a view folder written tvTTT_pv360 holds the images named
    ..._tvTTT_pv000 (the same direction), and the table reads as if the folder said pv000."""
    table = codes(7)
    root = write_folder(tmp_path / "v", "png", "views", table)
    want = np.asarray(brdffit.load(root).values)
    (root / "tv000_pv000").rename(root / "tv000_pv360")
    np.testing.assert_array_equal(np.asarray(brdffit.load(root).values), want)
