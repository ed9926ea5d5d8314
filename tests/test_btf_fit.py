"""Per-texel fitting and validation of BTFs (docs/btf.md#btfs-per-texel-fitting): known truth, measured mosaic, resuming,
two processes under jax.distributed, validate_btf against the photographs, the CLI."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import brdffit
from brdffit.btf import fit as btf_fit
from brdffit.btf import tile as btf_tile
from brdffit.btf import generate as gen
from brdffit.btf.maps import ParameterMaps
from brdffit.cli import main

from conftest import NO_DATA, RGL_FILES

HELPERS = Path(__file__).parent / "btf_helpers"


@pytest.fixture(scope="module")
def known_truth(tmp_path_factory):
    """16x16 texels of lambert+ggx, smooth maps, 1% multiplicative noise, EXR images."""
    model = brdffit.models.get("lambert+ggx")
    maps = gen.smooth_maps(model, 16, 16, seed=1)
    folder = gen.write_model_btf(tmp_path_factory.mktemp("kt") / "btf", model, maps, noise=0.01, seed=2)
    return folder, maps


@pytest.fixture(scope="module")
def small_lambert(tmp_path_factory):
    """4x4 texels of lambert (smoothly varying kd), 1% noise: a cheap BTF for the mechanics."""
    model = brdffit.models.get("lambert")
    maps = gen.smooth_maps(model, 4, 4, seed=3)
    return gen.write_model_btf(tmp_path_factory.mktemp("sl") / "btf", model, maps, noise=0.01, seed=4)


def _truth_maps(model_name, maps) -> ParameterMaps:
    h, w = next(iter(maps.values())).shape[:2]
    return ParameterMaps(model=model_name, params=maps, loss=np.zeros((h, w)), converged=np.ones((h, w), bool),
                         steps=np.zeros((h, w), int))


# -- validate_btf -----------------------------------------------------------------------------------
def test_validate_truth_maps_against_noisy_photographs(known_truth, tmp_path):
    folder, maps = known_truth
    btf = brdffit.load_btf(folder)
    v = brdffit.validate_btf(btf, _truth_maps("lambert+ggx", maps), out=tmp_path / "v")
    assert len(v.pairs) == 5
    psnr = [p["psnr"] for p in v.metrics["pairs"]]
    # the generator's 1% noise is what separates render and photograph: >= 40 dB, but not exact
    assert min(psnr) >= 40 and max(psnr) < 80, psnr
    rel = [p["rel_rmse"] for p in v.metrics["pairs"]]
    assert all(0.003 < r < 0.03 for r in rel), rel  # ~1% noise, relative
    names = {f.name for f in v.files}
    assert {"metrics.json", "panel_tl030_pl000_tv030_pv180.png", "render_tl000_pl000_tv000_pv000.exr"} <= names
    # a texture rendered the wrong way round (transposed) is far from the photographs
    flipped = {k: np.ascontiguousarray(np.swapaxes(a, 0, 1)) for k, a in maps.items()}
    bad = brdffit.validate_btf(btf, _truth_maps("lambert+ggx", flipped), pairs=[((45, 60), (15, 240))])
    assert bad.metrics["overall"]["psnr"] < 35


# -- resuming ---------------------------------------------------------------------------------------
def test_resume_after_interrupt(small_lambert, tmp_path, monkeypatch):
    btf = brdffit.load_btf(small_lambert, tile=2)
    assert btf.n_tiles == 4
    fresh = brdffit.fit_btf(btf, "lambert", progress=False)
    monkeypatch.setitem(btf_tile.GROUP_TEXELS, "cpu", 4)  # a group of one tile: the unit of a resume
    real = btf_tile.fit_tiles
    calls = []

    def interrupted(b, tiles, *args, **kwargs):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.extend(tiles)
        return real(b, tiles, *args, **kwargs)

    monkeypatch.setattr(btf_tile, "fit_tiles", interrupted)
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        brdffit.fit_btf(btf, "lambert", out=out, progress=False)
    assert sorted(p.name for p in (out / "tiles").glob("tile_*.npz")) == ["tile_00000.npz", "tile_00001.npz"]
    assert not (out / "params.exr").exists()
    calls.clear()

    def counted(b, tiles, *args, **kwargs):
        calls.extend(tiles)
        return real(b, tiles, *args, **kwargs)

    monkeypatch.setattr(btf_tile, "fit_tiles", counted)
    maps = brdffit.fit_btf(btf, "lambert", out=out, progress=False)
    assert calls == [2, 3]  # only the missing tiles
    assert maps.info["resumed_tiles"] == 2
    for k in fresh.params:
        np.testing.assert_array_equal(maps.params[k], fresh.params[k])
    np.testing.assert_array_equal(maps.loss, fresh.loss)
    assert (out / "params.exr").is_file() and not (out / "tiles").exists()
    assert maps._repr_png_().startswith(b"\x89PNG") and "<table>" in maps._repr_html_()
    back = ParameterMaps.load(out / "params.exr")
    np.testing.assert_allclose(back.params["kd"], fresh.params["kd"], rtol=1e-6)  # float32 file
    # a finished result is not replaced without force; another run's tiles are refused
    with pytest.raises(brdffit.UsageError, match="already holds a fit"):
        brdffit.fit_btf(btf, "lambert", out=out, progress=False)


# -- several processes ------------------------------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_processes_give_the_single_process_maps(small_lambert, tmp_path):
    port = _free_port()
    procs = [subprocess.Popen([sys.executable, str(HELPERS / "distributed_fit.py"), str(port), str(i), str(small_lambert),
                               "lambert", str(tmp_path / f"p{i}.npz"), str(tmp_path / f"cache{i}")],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) for i in range(2)]
    logs = [p.communicate(timeout=300)[0] for p in procs]
    assert all(p.returncode == 0 for p in procs), logs
    single = brdffit.fit_btf(brdffit.load_btf(small_lambert, tile=2), "lambert", progress=False)
    for i in range(2):
        with np.load(tmp_path / f"p{i}.npz") as z:
            assert int(z["processes"]) == 2
            np.testing.assert_array_equal(z["param:kd"], single.params["kd"])
            np.testing.assert_array_equal(z["loss"], single.loss)
            np.testing.assert_array_equal(z["steps"], single.steps)


# -- command line -----------------------------------------------------------------------------------
def test_cli_fit_btf_and_validate_btf(small_lambert, tmp_path, capsys):
    out = tmp_path / "fit"
    assert main(["fit-btf", str(small_lambert), "--model", "lambert", "-o", str(out), "--tile", "2"]) == 0
    assert (out / "params.exr").is_file() and (out / "summary.json").is_file() and (out / "preview_kd.png").is_file()
    assert main(["fit-btf", str(small_lambert), "--model", "lambert", "-o", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["validate-btf", str(small_lambert), str(out / "params.exr"), "-o", str(tmp_path / "v")]) == 0
    assert (tmp_path / "v" / "metrics.json").is_file()
    assert main(["validate-btf", str(small_lambert), str(out / "params.exr"), "-o", str(tmp_path / "v2"),
                 "--pairs", "15,61,0,0"]) == 2
    assert "not a direction pair" in capsys.readouterr().err and not (tmp_path / "v2").exists()
    assert main(["fit-btf", str(tmp_path / "missing"), "--model", "lambert", "-o", str(tmp_path / "x")]) == 2
    assert main(["fit-btf", str(small_lambert), "--model", "nope", "-o", str(tmp_path / "y")]) == 2
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


# -- the contract's figures (slow: hundreds of fits) ------------------------------------------------
@pytest.mark.slow
def test_known_truth_every_texel_as_good_as_a_single_fit(known_truth):
    folder, truth = known_truth
    btf = brdffit.load_btf(folder)
    maps = brdffit.fit_btf(btf, "lambert+ggx", progress=False)
    assert maps.converged.all()
    worst = 0.0
    for r in range(16):
        for c in range(16):
            single = brdffit.fit(btf.texel(r, c), "lambert+ggx")
            worst = max(worst, abs(maps.loss[r, c] - single.loss_value) / single.loss_value)
    assert worst <= 1e-3, worst
    # and the truth is recovered (1% noise on 6561 x 3 samples per texel)
    rel = np.abs(maps.params["ggx1.alpha"] - truth["ggx1.alpha"]) / truth["ggx1.alpha"]
    assert rel.max() < 0.03, rel.max()
    v = brdffit.validate_btf(btf, maps)
    assert min(p["psnr"] for p in v.metrics["pairs"]) >= 40


@pytest.mark.parametrize("loss", ["cbrt", "relative"])
def test_a_loss_that_reads_the_floors_fits_every_texel_as_fit_does(small_lambert, loss):
    """The texels' loss floors are computed where the loss reads them (``losses.READS_FLOOR``; the log loss's fit_btf
    leaves them out): under those losses each texel's loss equals ``fit``'s of the texel."""
    btf = brdffit.load_btf(small_lambert, tile=2)
    maps = brdffit.fit_btf(btf, "lambert", loss=loss, progress=False)
    assert maps.converged.all()
    for r in range(4):
        for c in range(4):
            single = brdffit.fit(btf.texel(r, c), "lambert", loss=loss)
            assert abs(maps.loss[r, c] - single.loss_value) <= 1e-6 * single.loss_value, (r, c)


@pytest.mark.slow
@pytest.mark.skipif(len(RGL_FILES) < 2, reason=NO_DATA)
def test_mosaic_of_measured_materials(tmp_path):
    folder, labels, ms = gen.write_mosaic_btf(tmp_path / "mosaic", RGL_FILES, height=16, width=16)
    btf = brdffit.load_btf(folder)
    maps = brdffit.fit_btf(btf, "ggx", out=tmp_path / "fit", progress=False)
    singles = [brdffit.fit(m, "ggx") for m in ms]  # a region's texels all hold that material's table
    for r in range(16):
        for c in range(16):
            ref = singles[labels[r, c]].loss_value
            assert abs(maps.loss[r, c] - ref) <= 0.01 * ref, (r, c, maps.loss[r, c], ref)
    # the maps (and their PNG previews) show the regions: constant inside, different between
    from PIL import Image

    for key in ("alpha", "ks"):
        png = np.asarray(Image.open(tmp_path / "fit" / f"preview_{key}.png").convert("RGB"), np.float64)
        means = [png[labels == k].mean(axis=0) for k in range(len(ms))]
        assert all(png[labels == k].std(axis=0).max() < 1.0 for k in range(len(ms)))
        assert min(np.abs(a - b).max() for i, a in enumerate(means) for b in means[i + 1:]) > 5
