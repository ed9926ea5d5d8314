"""brdffit.validate and `brdffit validate`: files, metrics, exit codes, atomic output."""

from __future__ import annotations

import json

import numpy as np
import OpenEXR
import pytest

import brdffit
from brdffit import Measurement, models
from brdffit.cli import main
from brdffit.grid import ubo_pairs
from brdffit.render import default_lights, validate
from conftest import NO_DATA, RGL_FILES

GGX = {"kd": [0.3, 0.25, 0.2], "ks": 0.3, "alpha": 0.3, "f0": 0.05}


def ggx_measurement() -> Measurement:
    wi, wo = ubo_pairs()
    model = models.get("ggx")
    return Measurement(wi, wo, np.asarray(model.eval(model.check_params(GGX), wi, wo)), name="ggx_table", grid="ubo81")


def read_exr(path) -> np.ndarray:
    with OpenEXR.File(str(path)) as f:
        return np.asarray(f.channels()["RGB"].pixels)


PHONG_CLASSIC = {"kd": [0.3, 0.25, 0.2], "ks": 0.4, "n": 3.0}


def phong_classic_measurement() -> Measurement:
    """A non-reciprocal reference (f(l, v) != f(v, l)): a light/view swap anywhere shows."""
    wi, wo = ubo_pairs()
    model = models.get("phong_classic")
    values = np.asarray(model.eval(model.check_params(PHONG_CLASSIC), wi, wo))
    return Measurement(wi, wo, values, name="phong_classic_table", grid="ubo81")


def test_validate_writes_everything(tmp_path):
    out = tmp_path / "val"
    lights = np.deg2rad([[0, 0], [50, 120]])
    ref = phong_classic_measurement()
    v = validate(ref, ("phong_classic", PHONG_CLASSIC), lights=lights, size=32, out=out, spp=2)
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        ["metrics.json", "table.png", "table_reference.exr", "table_fit.exr"]
        + [f"{k}_{t}.{e}" for t in ("t00_p000", "t50_p120") for k, e in (("reference", "exr"), ("fit", "exr"), ("panel", "png"))]
    )
    assert sorted(p.name for p in v.files) == names
    np.testing.assert_array_equal(read_exr(out / "fit_t50_p120.exr"), v.fit[1])
    np.testing.assert_array_equal(read_exr(out / "reference_t00_p000.exr"), v.reference[0])
    # the tables are [light, view]: the reference as measured, the fit as the model evaluated here
    # (phong_classic is not reciprocal, so a transposed table on either side fails)
    wi, wo = ubo_pairs()
    model = models.get("phong_classic")
    expect_fit = np.asarray(model.eval(model.check_params(PHONG_CLASSIC), wi, wo)).reshape(81, 81, 3)
    assert np.max(np.abs(expect_fit - expect_fit.transpose(1, 0, 2))) > 0.1 * expect_fit.max()
    np.testing.assert_allclose(read_exr(out / "table_fit.exr"), expect_fit, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(read_exr(out / "table_reference.exr"), ref.table(), rtol=1e-6, atol=1e-7)
    m = json.loads((out / "metrics.json").read_text())
    assert len(m["lights"]) == 2
    for block in [*m["lights"], m["overall"]]:
        for key in ("rmse", "rel_rmse", "psnr", "flip"):
            assert np.isfinite(block[key]), key
    # the table is the model sampled on the grid: the fitted table equals the measured one
    assert m["table"]["rmse"] < 1e-9
    # the same fit against its own table: interpolation error only, small
    assert m["overall"]["rel_rmse"] < 0.05 and m["overall"]["flip"] < 0.1


def test_table_metrics_of_a_different_fit_by_hand():
    """Table metrics of a Lambert fit against the phong_classic reference, computed here in numpy."""
    ref = phong_classic_measurement()
    kd = np.array([0.5, 0.4, 0.3])
    v = validate(ref, ("lambert", {"kd": kd}), lights=default_lights(1), size=16, spp=1)
    r = ref.table()
    f = np.broadcast_to(kd / np.pi, r.shape)
    d = f - r
    t = v.metrics["table"]
    assert t["rmse"] == pytest.approx(np.sqrt(np.mean(d**2)), rel=1e-6)
    assert t["rel_rmse"] == pytest.approx(np.sqrt(np.mean(d**2) / np.mean(r**2)), rel=1e-6)
    # docs/fitting.md#fitting's one log residual: ln(1 + f cos theta_light) - ln(1 + f_ref cos theta_light); the
    # UBO-81 rows' cosines written out from docs/conventions.md#conventions (rings of 1, 6, 12, 18, 20, 24 at 0..75 degrees)
    c = np.repeat(np.cos(np.radians([0, 15, 30, 45, 60, 75])), [1, 6, 12, 18, 20, 24])[:, None, None]
    assert t["log_rmse"] == pytest.approx(np.sqrt(np.mean((np.log1p(f * c) - np.log1p(r * c)) ** 2)), rel=1e-6)
    assert t["valid_pairs"] == 6561


def test_worse_fit_scores_worse(tmp_path):
    ref = ggx_measurement()
    lights = default_lights(2)
    good = validate(ref, ("ggx", GGX), lights=lights, size=24, spp=2)
    bad = validate(ref, ("lambert", {"kd": [0.3, 0.25, 0.2]}), lights=lights, size=24, spp=2)
    assert bad.metrics["overall"]["rmse"] > 2 * good.metrics["overall"]["rmse"]
    assert bad.metrics["overall"]["psnr"] < good.metrics["overall"]["psnr"]
    assert bad.metrics["overall"]["flip"] > good.metrics["overall"]["flip"]
    assert bad.metrics["table"]["rmse"] > good.metrics["table"]["rmse"]
    assert good.files == ()  # nothing written without out


def test_default_lights():
    d = np.rad2deg(default_lights())
    assert d.shape == (5, 2) and d[0, 0] == 0 and d[-1, 0] == 75
    assert np.rad2deg(default_lights(3))[:, 0].tolist() == [0, 38, 75]


def write_fit(path, model="ggx", params=GGX):
    path.write_text(json.dumps({"model": model, "channels": 3, "params": {k: np.atleast_1d(v).tolist() for k, v in params.items()}}))
    return path


@pytest.mark.skipif(not RGL_FILES, reason=NO_DATA)
def test_cli_validate_rgl(tmp_path, capsys):
    fit = write_fit(tmp_path / "fit.json")
    out = tmp_path / "v"
    rc = main(["validate", str(RGL_FILES[0]), str(fit), "-o", str(out), "--lights", "2", "--size", "24", "--spp", "1"])
    assert rc == 0
    assert (out / "metrics.json").is_file() and (out / "table.png").is_file()
    assert len(list(out.glob("panel_*.png"))) == 2
    err = capsys.readouterr()
    assert "psnr" in err.out and "time:" in err.err
    # an existing result is kept unless --force
    rc = main(["validate", str(RGL_FILES[0]), str(fit), "-o", str(out), "--lights", "1", "--size", "16"])
    assert rc == 2 and "already exists" in capsys.readouterr().err
    assert len(list(out.glob("panel_*.png"))) == 2
    rc = main(["validate", str(RGL_FILES[0]), str(fit), "-o", str(out), "--lights", "1", "--size", "16", "--force"])
    assert rc == 0 and len(list(out.glob("panel_*.png"))) == 1


def test_cli_bad_input(tmp_path, capsys):
    fit = write_fit(tmp_path / "fit.json")
    out = tmp_path / "v"
    rc = main(["validate", str(tmp_path / "missing.bsdf"), str(fit), "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "missing.bsdf" in err and len(err.strip().splitlines()) == 1
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    src = brdffit.save(ggx_measurement(), tmp_path / "table.npz")
    rc = main(["validate", str(src), str(bad), "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "bad.json" in err
    unknown = write_fit(tmp_path / "unknown.json", model="no_such_model")
    rc = main(["validate", str(src), str(unknown), "-o", str(out)])
    assert rc == 2 and "unknown.json" in capsys.readouterr().err
    rc = main(["validate", str(fit), str(fit), "-o", str(out)])  # a fit is no reference
    err = capsys.readouterr().err
    assert rc == 2 and "fit.json" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_invalid_table_entries_are_left_out(tmp_path):
    m = ggx_measurement()
    weights = np.ones(6561)
    weights[:81] = 0  # light at the pole: all invalid
    values = np.asarray(m.values).copy()
    values[:81] = 1e6  # garbage that must not count
    m = m.replace(weights=weights, values=values)
    v = validate(m, ("ggx", GGX), lights=default_lights(1), size=16, spp=1, out=tmp_path / "v")
    assert v.metrics["table"]["valid_pairs"] == 6561 - 81
    assert v.metrics["table"]["rmse"] < 1e-9
    assert np.all(np.isnan(v.table_reference[0])) and np.all(np.isfinite(v.table_reference[1:]))


def test_failure_leaves_nothing_behind(tmp_path, monkeypatch):
    import brdffit.plot as plot

    def broken(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(plot, "compare_table", broken)
    with pytest.raises(RuntimeError, match="disk full"):
        validate(ggx_measurement(), ("ggx", GGX), lights=default_lights(1), size=16, spp=1, out=tmp_path / "v")
    assert list(tmp_path.iterdir()) == []


def test_identical_images_give_strict_json(tmp_path):
    m = ggx_measurement()
    # a Lambertian table is reproduced exactly by the interpolator, and lambert with kd = pi is exactly
    # 1 in single precision too (kd / pi, both the same float32): identical images, PSNR = inf
    flat = m.replace(values=np.full((6561, 3), 1.0))
    v = validate(flat, ("lambert", {"kd": np.pi}), lights=default_lights(1), size=16, spp=1, out=tmp_path / "v")
    assert v.metrics["overall"]["psnr"] == float("inf")
    text = (tmp_path / "v" / "metrics.json").read_text()
    assert json.loads(text)["overall"]["psnr"] is None and "Infinity" not in text


def test_unconverged_fit_is_labelled():
    from brdffit.render import as_source

    class Fit:
        model = models.get("ggx")
        params = GGX
        converged = False

    assert as_source(Fit()).label == "ggx (fit not converged)"
    Fit.converged = True
    assert as_source(Fit()).label == "ggx"
