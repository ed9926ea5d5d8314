"""Scene-aware fitting (docs/scene.md#scene-aware-fitting): scene_usage, Usage.weights, fit(scene=), render/validate_scene, CLI."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import brdffit
from brdffit import Measurement, models
from brdffit.cli import main
from brdffit._mitsuba import mitsuba
from brdffit.grid import ubo_pairs
from brdffit.render.scene import _look_at
from brdffit.scene import rusinkiewicz, scene_usage, validate_scene
from conftest import REPO

SCENES = REPO / "scenes"
GGX = {"kd": [0.3, 0.25, 0.2], "ks": 0.3, "alpha": 0.3, "f0": 0.05}
LUM = np.array([0.2126, 0.7152, 0.0722])


def _dir(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


LIGHT = _dir(40.0, 30.0)  # towards the light, world = the plate's local frame


def plate_scene(material=None) -> dict:
    """An orthographic camera straight down on a plate (z = 0, local frame = world), one directional light."""
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sensor": {
            "type": "orthographic",
            "to_world": _look_at(mitsuba(), (0, 0, 3), (0, 0, 0), (0, 1, 0)),
            "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}},
        },
        "plate": {"type": "diffuse", "id": "plate"} if material is None else material,
        "shape": {"type": "rectangle", "to_world": mitsuba().ScalarTransform4f().scale(2.0),
                  "bsdf": {"type": "ref", "id": "plate"}},
        "light": {"type": "directional", "direction": list(map(float, -LIGHT)), "irradiance": {"type": "rgb", "value": 1.0}},
    }


def ggx_measurement() -> Measurement:
    wi, wo = ubo_pairs()
    model = models.get("ggx")
    return Measurement(wi, wo, np.asarray(model.eval(model.check_params(GGX), wi, wo)), name="ggx_table", grid="ubo81")


def test_camera_straight_down_records_the_single_pair():
    u = scene_usage(plate_scene(), "plate", spp=4)
    assert len(u) == 16 * 16 * 4  # every path: one emitter sample each (BSDF samples escape: no contribution)
    assert u.emitter_sampled.all()
    np.testing.assert_allclose(u.wi, np.broadcast_to(LIGHT, u.wi.shape), atol=1e-3)
    np.testing.assert_allclose(u.wo, np.broadcast_to([0.0, 0.0, 1.0], u.wo.shape), atol=1e-3)
    # each pixel gets albedo/pi * cos(theta_light) * E (diffuse 0.5, irradiance 1): known, not computed
    pixel = 0.5 / np.pi * LIGHT[2]
    np.testing.assert_allclose(u.weight, pixel / 4, rtol=1e-4)


@pytest.mark.parametrize("name,material", [("grazing_floor.xml", "floor"), ("front_sphere.xml", "object")])
def test_recorded_contributions_add_up_to_mitsubas_image(name, material):
    """Depth-2 scenes where only the material is seen: the recorded weights sum to the luminance
    of the image Mitsuba's own ``path`` integrator renders (an independent estimator)."""
    mi = mitsuba()
    u = scene_usage(SCENES / name, material, spp=16)
    img = np.asarray(mi.render(mi.load_file(str(SCENES / name)), spp=64))[..., :3]
    assert u.weight.sum() == pytest.approx(float((img @ LUM).sum()), rel=0.01)


def test_recorded_contributions_under_an_area_light_add_up_to_mitsubas_image():
    """Emitter samples and BSDF samples combined by MIS (an environment light, a glossy plate
    filling the view): the sum still matches Mitsuba's own render."""
    material = {"type": "roughconductor", "id": "plate", "alpha": 0.2}
    scene = plate_scene(material)
    del scene["light"]
    scene["env"] = {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}}
    scene["shape"]["to_world"] = mitsuba().ScalarTransform4f().scale(4.0)
    mi = mitsuba()
    u = scene_usage(scene, "plate", spp=16)
    assert u.emitter_sampled.any() and (~u.emitter_sampled).any()
    img = np.asarray(mi.render(mi.load_dict(scene), spp=256))[..., :3]
    assert u.weight.sum() == pytest.approx(float((img @ LUM).sum()), rel=0.01)


def test_ring_of_lights_sees_every_azimuth_and_bounces():
    u = scene_usage(SCENES / "ring_lights.xml", "object", spp=4)
    assert u.max_depth == 3
    assert (~u.emitter_sampled).any()  # light bounced off the ground onto the object counts too
    h = u.wi + u.wo
    azimuth = np.degrees(np.arctan2(h[:, 1], h[:, 0])) % 360
    assert np.histogram(azimuth, bins=8, range=(0, 360))[0].min() > 0


def test_rusinkiewicz_known_values():
    # a (theta_h, theta_d, phi_d) pair built by hand: d in the half-vector frame, turned by theta_h about y
    th, td, pd = np.radians([30.0, 40.0, 120.0])
    d = np.array([np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)])
    wi = np.array([d[0] * np.cos(th) + d[2] * np.sin(th), d[1], -d[0] * np.sin(th) + d[2] * np.cos(th)])
    h = np.array([np.sin(th), 0.0, np.cos(th)])
    wo = 2 * (wi @ h) * h - wi
    # phi_d 120 degrees is folded to 60 (mirror symmetry about the plane of incidence)
    np.testing.assert_allclose(rusinkiewicz(wi, wo)[0], [th, td, np.pi - pd], atol=1e-12)
    # swapping light and view is the same pair (reciprocity fold)
    np.testing.assert_allclose(rusinkiewicz(wo, wi)[0], [th, td, np.pi - pd], atol=1e-12)
    # mirror direction: theta_h 0, theta_d = theta; retro-reflection: theta_h = theta, theta_d 0
    a = _dir(50.0, 10.0)
    np.testing.assert_allclose(rusinkiewicz(a, a * [-1, -1, 1])[0, :2], np.radians([0.0, 50.0]), atol=1e-7)
    np.testing.assert_allclose(rusinkiewicz(a, a)[0, :2], np.radians([50.0, 0.0]), atol=1e-7)


def test_weights_peak_where_the_scene_looks_and_keep_a_floor():
    u = scene_usage(plate_scene(), "plate", spp=1)
    m = ggx_measurement()
    w = u.weights(m)
    # isotropic: every sample with the recorded pair's (theta_h, theta_d, phi_d) counts as that pair
    c0 = np.degrees(rusinkiewicz(LIGHT, [0.0, 0.0, 1.0]))[0]
    dist = np.abs(np.degrees(rusinkiewicz(m.wi, m.wo)) - c0).max(axis=1)
    assert (dist < 3).sum() >= 2 and w[dist < 3].min() > 0.6
    assert np.all(w[dist > 20] == 0.3)  # far from it: the default floor
    assert w.max() <= 1.0
    w0 = u.weights(m, floor=0.0)
    assert (w0 == 0).sum() > 3000  # asked for: the unused part of the table is dropped
    with pytest.raises(brdffit.UsageError):
        u.weights(m, floor=2.0)


def test_fit_with_scene_uses_its_weights():
    u = scene_usage(plate_scene(), "plate", spp=1)
    m = ggx_measurement()
    noisy = m.replace(values=np.asarray(m.values) * (1 + 0.3 * np.sin(np.arange(m.n_samples)))[:, None])
    a = brdffit.fit(noisy, "ggx", scene=u, init=GGX)
    b = brdffit.fit(noisy, "ggx", weights=u.weights(noisy), init=GGX)
    c = brdffit.fit(noisy, "ggx", init=GGX)
    np.testing.assert_allclose(a.params["alpha"], b.params["alpha"], rtol=1e-9)
    assert abs(float(a.params["alpha"][0]) - float(c.params["alpha"][0])) > 1e-6


_ORDER = """
import sys, numpy as np, brdffit
from brdffit._mitsuba import mitsuba
mi = mitsuba()
other = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 3},
    "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 16, "height": 16}},
    "s": {"type": "sphere", "center": [0, 0, 4], "bsdf": {"type": "roughconductor"}}, "e": {"type": "constant"}})
for step in sys.argv[1]:
    if step == "o":
        assert np.asarray(mi.render(other, spp=2)).mean() > 0
    else:
        img = brdffit.render_scene(sys.argv[2], "floor", ("ggx", {"kd": 0.3, "ks": 0.2, "alpha": 0.2, "f0": 0.04}), spp=2)
        assert img.shape == (64, 96, 3) and np.isfinite(img).all() and img.max() > 0
print("ok")
"""


@pytest.mark.parametrize("order", ["bo", "obo"])
def test_python_bsdf_render_then_any_scene_without_touching_flags(order):
    """A fit rendered in a scene (a Python BSDF: symbolic calls off) and another scene rendered with
    Dr.Jit's default (symbolic) flags, in either order, in a fresh process."""
    r = subprocess.run([sys.executable, "-c", _ORDER, order, str(SCENES / "grazing_floor.xml")], capture_output=True,
                       text=True, cwd=REPO, timeout=300)
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stderr[-2000:]


def test_validate_scene_writes_files_and_identical_sources_score_zero(tmp_path):
    out = tmp_path / "vs"
    scene = plate_scene()
    v = validate_scene(scene, "plate", ("ggx", GGX), ("ggx", GGX), spp=2, out=out)
    assert sorted(p.name for p in out.iterdir()) == ["fit.exr", "metrics.json", "panel.png", "reference.exr"]
    assert v.metrics["image"]["flip"] == 0.0 and v.metrics["image"]["rmse"] == 0.0
    m = json.loads((out / "metrics.json").read_text())
    assert m["image"]["psnr"] is None  # identical images: infinite PSNR, written as null
    worse = validate_scene(scene, "plate", ("lambert", {"kd": [0.3, 0.25, 0.2]}), ("ggx", GGX), spp=2)
    assert worse.metrics["image"]["flip"] > 0.01 and worse.metrics["image"]["rmse"] > 0


def test_cli_validate_scene_and_bad_input(tmp_path, capsys):
    fit_json = tmp_path / "fit.json"
    r = brdffit.fit(ggx_measurement(), "ggx")
    r.to_json(fit_json)
    ref = tmp_path / "ref.npz"
    brdffit.save(ggx_measurement(), ref)
    scene = str(SCENES / "front_sphere.xml")
    out = tmp_path / "out"
    assert main(["validate-scene", scene, "object", str(fit_json), "--reference", str(ref), "-o", str(out), "--spp", "2"]) == 0
    assert (out / "metrics.json").is_file() and (out / "panel.png").is_file()
    capsys.readouterr()
    bad = tmp_path / "bad"
    assert main(["validate-scene", scene, "nope", str(fit_json), "--reference", str(ref), "-o", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "front_sphere.xml" in err[0] and "'nope'" in err[0] and not bad.exists()
    broken = tmp_path / "broken.xml"
    broken.write_text("<scene version='3.0.0'><shape type=")
    assert main(["validate-scene", str(broken), "object", str(fit_json), "--reference", str(ref), "-o", str(bad)]) == 2
    assert "broken.xml" in capsys.readouterr().err and not bad.exists()
    assert main(["fit", str(ref), "--model", "ggx", "--material", "object", "-o", str(bad)]) == 2
    assert not bad.exists()


def test_cli_fit_with_scene(tmp_path):
    ref = tmp_path / "ref.npz"
    brdffit.save(ggx_measurement(), ref)
    out = tmp_path / "f"
    code = main(["fit", str(ref), "--model", "ggx", "--scene", str(SCENES / "front_sphere.xml"), "--material", "object",
                 "-o", str(out)])
    assert code == 0
    assert json.loads((out / "fit.json").read_text())["model"] == "ggx"


def test_plot_usage_returns_a_figure():
    from matplotlib.figure import Figure

    from brdffit.plot import usage as plot_usage

    fig = plot_usage(scene_usage(plate_scene(), "plate", spp=1))
    assert isinstance(fig, Figure) and len(fig.axes) >= 3
