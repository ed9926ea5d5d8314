"""BTF reading (docs/btf.md#btfs-per-texel-fitting): folders and zip archives, space-separated names, JPEG / Radiance HDR,
region / step / includes_cos / scale, the tile-major cache. (The RGBE reader and writer themselves:
test_io_hdr.py.)"""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

import brdffit
from brdffit.btf import generate as gen
from brdffit.errors import InputError
from brdffit.grid import UBO_SIZE, ubo_pairs
from brdffit.io.hdr import encode_hdr
from brdffit.io.images import direction_name, srgb_to_linear


def _truth(h=5, w=7, seed=0):
    m = brdffit.models.get("lambert")
    return m, gen.smooth_maps(m, h, w, seed=seed)


# -- folders and archives ---------------------------------------------------------------------------
def _expected(maps, model):
    """(H, W, 6561, C) f_r of the generating maps (the model's formula, evaluated here)."""
    return np.concatenate([block for _, block in gen.model_tables(model, maps)], axis=2)


def test_space_named_zip_of_jpegs_matches_its_folder(tmp_path):
    model, maps = _truth()
    zpath = gen.write_model_btf(tmp_path / "ubo.zip", model, maps, format="jpg", spaces=True, archive=True,
                                exposure=2.0)
    with zipfile.ZipFile(zpath) as z:
        names = z.namelist()
    assert "tl015 pl060 tv000 pv000.jpg" in names and len(names) == UBO_SIZE * UBO_SIZE
    btf = brdffit.load_btf(zpath, scale=0.5, tile=4)
    assert btf.shape == (5, 7) and btf.channels == 3 and btf.n_tiles == 4
    truth = _expected(maps, model)
    # 8-bit sRGB JPEG (quality 95): a few codes of error, relative to the brightest value
    got = np.stack([btf.texel(r, c).values for r in range(5) for c in range(7)]).reshape(truth.shape)
    assert np.max(np.abs(got - truth)) < 0.03 * truth.max()
    # the same archive unpacked to a folder (names with spaces) reads identically, also with load()
    folder = tmp_path / "unpacked"
    with zipfile.ZipFile(zpath) as z:
        z.extractall(folder)
    again = brdffit.load_btf(folder, scale=0.5, tile=4)
    np.testing.assert_array_equal(again.tile_values(3), btf.tile_values(3))
    m = brdffit.load(folder, scale=0.5)
    np.testing.assert_allclose(m.values, got.reshape(-1, UBO_SIZE * UBO_SIZE, 3).mean(axis=0), rtol=1e-5)


def test_zip_of_exrs_reads_as_its_folder_and_leaves_nothing_in_tmpdir(tmp_path, monkeypatch):
    """The OpenEXR binding reads files only: a zip's EXR members go through a scratch folder of the run (which the
    executable's Ctrl-C removes), emptied as they are read and removed when the archive is closed."""
    import tempfile

    model, maps = _truth(3, 4, seed=3)
    zpath = gen.write_model_btf(tmp_path / "ubo.zip", model, maps, archive=True)
    folder = tmp_path / "unpacked"
    with zipfile.ZipFile(zpath) as z:
        assert all(n.endswith(".exr") for n in z.namelist())
        z.extractall(folder)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    btf = brdffit.load_btf(zpath, tile=2, cache_dir=tmp_path / "cache")
    assert list(tmp.iterdir()) == []
    again = brdffit.load_btf(folder, tile=2, cache_dir=tmp_path / "cache2")
    for t in range(btf.n_tiles):
        np.testing.assert_array_equal(btf.tile_values(t), again.tile_values(t))


def test_hdr_zip_with_per_view_folders(tmp_path):
    model, maps = _truth(4, 3, seed=2)
    zpath = gen.write_model_btf(tmp_path / "atrium.zip", model, maps, format="hdr", spaces=True, per_view=True,
                                archive=True)
    with zipfile.ZipFile(zpath) as z:
        assert "tv015 pv060/tl000 pl000 tv015 pv060.hdr" in z.namelist()
        # inside a view's folder the short name (light only) is accepted too
        short = tmp_path / "short.zip"
        with zipfile.ZipFile(short, "w") as out:
            for name in z.namelist():
                folder, file = name.split("/")
                out.writestr(f"{folder}/{file[:11]}.hdr", z.read(name))
    btf = brdffit.load_btf(short)
    truth = _expected(maps, model)
    got = np.stack([btf.texel(r, c).values for r in range(4) for c in range(3)]).reshape(truth.shape)
    np.testing.assert_allclose(got, truth, rtol=1 / 128)


def test_exr_folder_exact_and_options(tmp_path):
    model, maps = _truth(6, 6, seed=4)
    folder = gen.write_model_btf(tmp_path / "f", model, maps)
    # bounded read buffer: 0.05 MB holds 144 images of 6x6x3 float32 at a time; same content
    small = brdffit.load_btf(folder, buffer_mb=0.05, tile=4)
    assert small.memory()["read_buffer"] <= 0.05 * 2**20
    truth = _expected(maps, model)
    btf = brdffit.load_btf(folder, tile=4)
    np.testing.assert_array_equal(small.tile_values(1), btf.tile_values(1))
    np.testing.assert_allclose(btf.tile_values(0), truth[:4, :4], rtol=1e-6)
    np.testing.assert_allclose(btf.tile_values(3), truth[4:, 4:], rtol=1e-6)
    k = 22 * UBO_SIZE + 5
    np.testing.assert_allclose(btf.image(22, 5), truth[:, :, k], rtol=1e-6)
    # region + step select texels of the photographs; includes_cos divides by cos(theta_light); scale multiplies
    sub = brdffit.load_btf(folder, region=(1, 6, 0, 5), step=2, includes_cos=True, scale=3.0, cache_dir=tmp_path / "c")
    assert sub.shape == (3, 3)
    cos_l = ubo_pairs()[0][:, 2]
    np.testing.assert_allclose(sub.texel(2, 1).values, 3.0 * truth[5, 2] / cos_l[:, None], rtol=1e-6)
    # memory report: cache file of tiles, one tile while fitting
    mem = sub.memory()
    assert mem["cache_file"] == sub.cache.stat().st_size == 1 * UBO_SIZE**2 * 16 * 16 * 3 * 4
    # the cache is reused when loaded again with the same options into the same folder
    again = brdffit.load_btf(folder, region=(1, 6, 0, 5), step=2, includes_cos=True, scale=3.0, cache_dir=tmp_path / "c")
    assert again.cache == sub.cache
    np.testing.assert_array_equal(again.texel(0, 0).values, sub.texel(0, 0).values)


def test_srgb_png_decoding(tmp_path):
    model, maps = _truth(3, 3, seed=6)
    folder = gen.write_model_btf(tmp_path / "p", model, maps, format="png", exposure=1.5)
    btf = brdffit.load_btf(folder, scale=1 / 1.5)
    truth = _expected(maps, model)
    # decoded = sRGB EOTF of the 8-bit code / 1.5; the code is within half a step of the encoded truth
    got = btf.texel(1, 2).values
    enc = 1.055 * np.clip(truth[1, 2] * 1.5, 0, 1) ** (1 / 2.4) - 0.055
    enc = np.where(truth[1, 2] * 1.5 <= 0.0031308, 12.92 * truth[1, 2] * 1.5, enc)
    lo = srgb_to_linear(np.clip(enc - 0.5 / 255, 0, 1)) / 1.5
    hi = srgb_to_linear(np.clip(enc + 0.5 / 255, 0, 1)) / 1.5
    assert np.all((got >= lo - 1e-7) & (got <= hi + 1e-7))


def test_bad_btf_sources(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        brdffit.load_btf(tmp_path / "missing")
    (tmp_path / "x.zip").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="zip"):
        brdffit.load_btf(tmp_path / "x.zip")
    with zipfile.ZipFile(tmp_path / "few.zip", "w") as z:
        z.writestr(f"{direction_name(0, 0).replace('_', ' ')}.hdr", encode_hdr(np.ones((2, 2, 3))))
    with pytest.raises(InputError, match="incomplete image set: 6560 of 6561"):
        brdffit.load_btf(tmp_path / "few.zip")
    with zipfile.ZipFile(tmp_path / "odd.zip", "w") as z:
        z.writestr("tl015 pl061 tv000 pv000.hdr", b"")
    with pytest.raises(InputError, match="not on the UBO-81 grid"):
        brdffit.load_btf(tmp_path / "odd.zip")


def test_a_broken_exr_in_a_zip_is_named_by_its_member(tmp_path):
    """The OpenEXR binding's message named the scratch copy it was given (gone by the time it is read); the line
    names the archive's member instead."""
    model, maps = _truth(2, 2, seed=6)
    zpath = gen.write_model_btf(tmp_path / "ubo.zip", model, maps, archive=True)
    broken = tmp_path / "broken.zip"
    with zipfile.ZipFile(zpath) as z, zipfile.ZipFile(broken, "w") as out:
        names = z.namelist()
        for name in names:
            out.writestr(name, b"not an exr" if name == names[7] else z.read(name))
    with pytest.raises(InputError) as info:
        brdffit.load_btf(broken, cache_dir=tmp_path / "cache")
    said = str(info.value)
    assert said.startswith(f"{broken}:{names[7]}: unreadable image: ") and "brdffit-zip-" not in said, said
    assert names[7] in said.split("unreadable image: ", 1)[1], said
    assert sorted(p.name for p in (tmp_path / "cache").iterdir()) == []  # the cache half written is removed
