"""renderer="cycles" (docs/materials.md#native-materials-and-exports): a blender:principled fit rendered by Blender's Cycles in the docs/validation.md#validation-rendering
framing agrees with the same fit rendered by Mitsuba; validate / CLI `validate --renderer cycles`;
fits and sources Cycles cannot render are one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

import brdffit
from brdffit import Measurement, models
from brdffit.cli import main
from brdffit.errors import UsageError
from brdffit.grid import ubo_pairs
from brdffit.render import default_lights, render_sphere, validate
from brdffit.render.scene import disc_mask, light_directions

MODEL = models.get("blender:principled")
FITS = {
    "plastic": {"base_color": [0.6, 0.3, 0.15], "metallic": 0.0, "roughness": 0.35, "ior": 1.5, "specular_tint": 1.0},
    "metal": {"base_color": [0.9, 0.7, 0.4], "metallic": 0.85, "roughness": 0.25, "ior": 1.6, "specular_tint": 0.6},
}


def per_light_means(images, size):
    mask = disc_mask(size)
    return np.stack([img[mask].mean(0) for img in images])  # (L, 3)


def block_errors(a, b, k=8):
    """Per light, the RMS difference of k x k block means relative to the mean: where the light
    falls on the sphere (a mean alone does not see a mirrored image), without the pixel noise of a
    narrow highlight sampled differently by the two renderers."""
    L, n = a.shape[0], a.shape[1] // k
    blocks = lambda x: x.reshape(L, n, k, n, k, 3).mean((2, 4))
    A, B = blocks(a), blocks(b)
    return np.sqrt(((A - B) ** 2).mean((1, 2, 3))) / B.mean((1, 2, 3))


@pytest.mark.parametrize("name", sorted(FITS))
def test_cycles_and_mitsuba_render_one_fit_alike(blender, name):
    """Mean per light and channel within 3 % (docs/materials.md#native-materials-and-exports; measured: 0.01-0.5 %), and where the light
    falls: 8 x 8 block means within 10 % RMS (measured: plastic 0.05-0.3 %, metal 1.1-3.8 %)."""
    params, size = FITS[name], 64
    lights = default_lights()
    cycles = render_sphere(("blender:principled", params), lights, size=size, spp=16, renderer="cycles")
    mitsuba = render_sphere(("blender:principled", params), lights, size=size, spp=16)
    assert cycles.shape == mitsuba.shape == (5, size, size, 3)
    assert np.all(cycles[:, ~disc_mask(size)] == 0)
    ratio = per_light_means(cycles, size) / per_light_means(mitsuba, size)
    assert np.all(np.abs(ratio - 1) < 0.03), ratio
    assert np.all(block_errors(cycles, mitsuba) < 0.1), block_errors(cycles, mitsuba)
    # the same checks see a wrong material (Cycles given sqrt(roughness)) and a mirrored image
    wrong = MODEL.native(params)
    wrong["inputs"]["Roughness"] = params["roughness"] ** 0.5
    broken = blender.render_sphere(wrong, light_directions(lights), size=size, spp=16)
    broken = np.where(disc_mask(size)[..., None], broken, 0.0)
    assert np.any(block_errors(broken, mitsuba) > 0.1)
    assert np.any(block_errors(cycles[:, :, ::-1], mitsuba) > 0.1)


def table_of(params) -> Measurement:
    wi, wo = ubo_pairs()
    return Measurement(wi, wo, np.asarray(MODEL.eval(MODEL.check_params(params), wi, wo)), name="principled_table",
                       grid="ubo81")


def test_validate_with_cycles(blender, tmp_path):
    params = FITS["plastic"]
    out = tmp_path / "v"
    v = validate(table_of(params), ("blender:principled", params), lights=np.deg2rad([[0, 0], [45, 90]]), size=48,
                 out=out, renderer="cycles")
    assert v.metrics["renderer"] == "cycles"
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["renderer"] == "cycles" and saved["fit"] == "blender:principled"
    assert len(list(out.glob("panel_*.png"))) == 2 and len(list(out.glob("fit_*.exr"))) == 2
    # the reference is the model's own table rendered by Mitsuba: the two renderers differ by little
    assert v.metrics["overall"]["rel_rmse"] < 0.1


def fit_file(path, model, params):
    path.write_text(json.dumps({"model": model, "channels": 3,
                                "params": {k: np.atleast_1d(v).tolist() for k, v in params.items()}}))
    return path


def test_what_cycles_cannot_render_is_one_line(tmp_path, capsys):
    ggx = ("ggx", {"kd": 0.2, "ks": 0.3, "alpha": 0.2, "f0": 0.04})
    with pytest.raises(UsageError, match=r"renders blender:principled fits, and this fit is ggx: convert it first"):
        render_sphere(ggx, [[0, 0, 1]], size=8, renderer="cycles")
    with pytest.raises(UsageError, match="is a measurement"):
        render_sphere(table_of(FITS["plastic"]), [[0, 0, 1]], size=8, renderer="cycles")
    with pytest.raises(UsageError, match="renderer 'povray'"):
        render_sphere(ggx, [[0, 0, 1]], size=8, renderer="povray")
    src = brdffit.save(table_of(FITS["plastic"]), tmp_path / "table.npz")
    fit = fit_file(tmp_path / "ggx.json", *ggx)
    out = tmp_path / "v"
    rc = main(["validate", str(src), str(fit), "-o", str(out), "--renderer", "cycles", "--size", "16"])
    err = capsys.readouterr().err
    assert rc == 2 and "convert it first" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_without_blender_the_cli_says_so_in_one_line(tmp_path, capsys, monkeypatch):
    from brdffit import cycles

    monkeypatch.setenv(cycles.ENV_VAR, str(tmp_path / "no-blender" / "python"))
    monkeypatch.setattr(cycles, "_SHARED", None)
    src = brdffit.save(table_of(FITS["plastic"]), tmp_path / "table.npz")
    fit = fit_file(tmp_path / "fit.json", "blender:principled", FITS["plastic"])
    out = tmp_path / "v"
    rc = main(["validate", str(src), str(fit), "-o", str(out), "--renderer", "cycles", "--size", "16"])
    err = capsys.readouterr().err
    assert rc == 2 and "no-blender" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
