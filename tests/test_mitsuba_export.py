"""A fit in a user's own Mitsuba scene (docs/materials.md#a-fit-in-any-mitsuba-scene): ``to_mitsuba``, the ``brdffit`` plugin, ``brdffit
export``, and the Dr.Jit lifecycle of the Python BSDF (docs/DESIGN.md#where-users-meet-brdffit, 12, 13)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import drjit as dr
import numpy as np
import pytest

import brdffit
from brdffit._mitsuba import evaluated_calls, mitsuba
from brdffit.cli import main
from brdffit.fitting.result import FitResult
from brdffit.render import render_sphere

mi = mitsuba()
GGX = {"kd": [0.2, 0.3, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": 0.3, "f0": 0.1}


def ggx_fit(params=GGX) -> FitResult:
    return FitResult.from_dict({"model": "ggx", "params": {k: np.atleast_1d(v).tolist() for k, v in params.items()},
                                "converged": True, "data_name": "test"})


def user_scene(bsdf, light, size, spp=64, integrator="path") -> dict:
    """Written by hand the way a user would, not with brdffit's scene code: a plain (unrotated) unit
    sphere, an orthographic camera on +z, one directional light, Mitsuba's path tracer."""
    return {
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": 3},
        "sensor": {
            "type": "orthographic",
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}},
            "sampler": {"type": "stratified", "sample_count": spp},
        },
        "ball": {"type": "sphere", "bsdf": bsdf},
        "sun": {"type": "directional", "direction": [float(-x) for x in light], "irradiance": {"type": "rgb", "value": 1.0}},
    }


def disc(size, radius=0.9):
    c = (np.arange(size) + 0.5) * (2.0 / size) - 1.0
    x, y = np.meshgrid(c, -c)
    return x * x + y * y < radius * radius


def mean_relative_difference(a, b, mask):
    return float(np.abs(a - b)[mask].sum() / np.abs(b)[mask].sum())


def test_to_mitsuba_sphere_equals_render_sphere():
    fit = ggx_fit()
    light = np.array([0.4, 0.3, np.sqrt(1 - 0.25)])
    size = 40
    scene = mi.load_dict(user_scene(fit.to_mitsuba(), light, size))
    with brdffit.evaluated_calls():
        img = np.asarray(mi.render(scene, spp=64))[..., :3]
    ref = render_sphere(fit, [light], size=size, spp=64)[0]
    assert mean_relative_difference(img, ref, disc(size)) < 0.01
    assert fit.to_mitsuba()["type"] == "brdffit" and fit.to_mitsuba()["alpha"] == 0.3


def test_plugin_rejects_bad_properties():
    with pytest.raises(Exception, match="missing parameters"):
        mi.load_dict({"type": "brdffit", "model": "ggx", "kd": 0.3})
    with pytest.raises(Exception, match="unknown properties"):
        mi.load_dict({**brdffit.mitsuba_bsdf("lambert", {"kd": 0.5}), "alpha": 0.2})


def test_composite_names_use_underscores():
    d = brdffit.mitsuba_bsdf("lambert+ggx+ggx", brdffit.models.get("lambert+ggx+ggx").defaults())
    assert {"kd", "ggx1_ks", "ggx2_alpha"} <= set(d)
    assert "SymbolicBSDF[brdffit:lambert+ggx+ggx" in str(mi.load_dict(d))  # the formula run by Dr.Jit


def test_export_cli_xml_loads_in_a_scene(tmp_path, capsys):
    fit_path = tmp_path / "fit.json"
    ggx_fit().to_json(fit_path)
    xml = tmp_path / "bsdf.xml"
    assert main(["export", str(fit_path), "-o", str(xml), "--id", "paint"]) == 0
    light = np.array([0.0, 0.5, np.sqrt(0.75)])
    scene_xml = tmp_path / "scene.xml"
    scene_xml.write_text(textwrap.dedent(f"""\
        <scene version="3.0.0">
            <include filename="{xml.name}"/>
            <integrator type="direct"/>
            <sensor type="orthographic">
                <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
                <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/>
                    <rfilter type="box"/></film>
                <sampler type="stratified"><integer name="sample_count" value="16"/></sampler>
            </sensor>
            <shape type="sphere"><ref id="paint"/></shape>
            <emitter type="directional"><vector name="direction" value="{-light[0]}, {-light[1]}, {-light[2]}"/></emitter>
        </scene>"""))
    scene = mi.load_file(str(scene_xml))
    img = np.asarray(brdffit._mitsuba.render(scene, spp=16))[..., :3]
    ref = render_sphere(ggx_fit(), [light], size=24, spp=16)[0]
    assert mean_relative_difference(img, ref, disc(24)) < 0.01
    # standard output without -o; bad input: exit 2, one line naming the file, nothing written
    capsys.readouterr()
    assert main(["export", str(fit_path)]) == 0
    assert '<bsdf type="brdffit" id="' in capsys.readouterr().out
    assert main(["export", str(fit_path), "-o", str(xml)]) == 2  # exists, no --force
    assert "already exists" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text("{nope")
    assert main(["export", str(bad), "-o", str(tmp_path / "x.xml")]) == 2
    err = capsys.readouterr().err
    assert "bad.json" in err and len(err.strip().splitlines()) == 1
    unknown = tmp_path / "unknown.json"
    unknown.write_text(json.dumps({"model": "no_such", "params": {}}))
    assert main(["export", str(unknown), "-o", str(tmp_path / "x.xml")]) == 2
    assert not (tmp_path / "x.xml").exists()


# -- Dr.Jit lifecycle (docs/scene.md#scene-aware-fitting) ---------------------------------------------------------------------

def other_scene() -> dict:
    """A scene with Mitsuba's own BSDFs only: path tracer (symbolic loops and calls by default)."""
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4},
        "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16}, "sampler": {"type": "independent", "sample_count": 4}},
        "ball": {"type": "sphere", "bsdf": {"type": "roughconductor", "alpha": 0.2}},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, -1]).scale(3), "bsdf": {"type": "diffuse"}},
        "sky": {"type": "constant"},
    }


def test_other_scenes_render_in_either_order_while_a_brdffit_bsdf_lives():
    assert dr.flag(dr.JitFlag.SymbolicCalls) and dr.flag(dr.JitFlag.SymbolicLoops)
    before = np.asarray(mi.render(mi.load_dict(other_scene()), spp=4))
    ours = mi.load_dict(user_scene(ggx_fit().to_mitsuba(), [0, 0, 1], 16, spp=4))  # alive from here on
    with evaluated_calls():
        a = np.asarray(mi.render(ours, spp=4))
    assert np.all(np.isfinite(a)) and a.max() > 0
    # flags restored: the next scene renders symbolically, with the brdffit BSDF still registered
    assert dr.flag(dr.JitFlag.SymbolicCalls) and dr.flag(dr.JitFlag.SymbolicLoops)
    after = np.asarray(mi.render(mi.load_dict(other_scene()), spp=4))
    np.testing.assert_allclose(after, before, rtol=1e-5, atol=1e-6)
    # and brdffit's own renders, again, in between
    again = np.asarray(brdffit._mitsuba.render(ours, spp=4))
    np.testing.assert_allclose(again, a, rtol=1e-5, atol=1e-6)
    render_sphere(("lambert", {"kd": 0.5}), [[0, 0, 1]], size=8)
    np.testing.assert_allclose(np.asarray(mi.render(mi.load_dict(other_scene()), spp=4)), before, rtol=1e-5, atol=1e-6)


# -- teardown (docs/DESIGN.md#tests-that-fail-when-the-code-is-wrong) ------------------------------------------------------------------------------

EXIT_SNIPPET = """
import sys, time
from brdffit.render import as_source, render_sphere
render_sphere(("lambert", {"kd": 0.3}), [(0.3, 0.0)], size=8)
source = as_source(("ggx", {"kd": 0.3, "ks": 0.3, "alpha": 0.3, "f0": 0.05}))  # compiles in the background
time.sleep(float(sys.argv[1]))  # the interpreter starts its exit while that compilation runs
"""


@pytest.mark.parametrize("delay", [0.2, 0.4, 0.8])
def test_exit_while_the_model_compiles_is_clean(delay):
    proc = subprocess.run([sys.executable, "-c", EXIT_SNIPPET, str(delay)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-500:]
    assert "terminate called" not in proc.stderr


VARIANT_SNIPPET = """
import sys
import numpy as np
import mitsuba as mi
mi.set_variant("scalar_rgb")  # the user's choice, not brdffit's llvm_ad_rgb
import brdffit  # registers the plugin for it
scene = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 3},
    "sensor": {"type": "orthographic", "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
               "film": {"type": "hdrfilm", "width": 8, "height": 8}},
    "ball": {"type": "sphere", "bsdf": brdffit.mitsuba_bsdf("lambert", {"kd": 0.5})},
    "sky": {"type": "constant"}})
with brdffit.evaluated_calls():
    img = np.asarray(mi.render(scene, spp=16))
centre = img[2:6, 2:6, :3].mean()
print(mi.variant(), round(float(centre), 2))
"""


def test_plugin_keeps_the_users_variant():
    """A Lambertian sphere of albedo 0.5 under a unit white sky: radiance 0.5 facing the camera."""
    proc = subprocess.run([sys.executable, "-c", VARIANT_SNIPPET], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-1000:]
    variant, centre = proc.stdout.split()
    assert variant == "scalar_rgb" and abs(float(centre) - 0.5) < 0.03


def test_parameter_maps_follow_mitsubas_bitmap_layout():
    """lambert with a kd map renders like Mitsuba's diffuse BSDF with that map as a bitmap texture
    (nearest lookup): the same texel at every uv."""
    rng = np.random.default_rng(5)
    kd = rng.uniform(0.1, 0.9, (4, 6, 3))

    def scene(bsdf):
        return {
            "type": "scene",
            "integrator": {"type": "direct"},
            "sensor": {"type": "orthographic", "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 3], target=[0, 0, 0], up=[0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": 24, "height": 24, "rfilter": {"type": "box"}},
                       "sampler": {"type": "independent", "sample_count": 4}},
            "plane": {"type": "rectangle", "bsdf": bsdf},
            "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": {"type": "rgb", "value": np.pi}},
        }

    ours = brdffit.mitsuba_bsdf("lambert", {"kd": kd})
    with evaluated_calls():
        a = np.asarray(mi.render(mi.load_dict(scene(ours)), spp=4))[..., :3]
    texture = {"type": "bitmap", "bitmap": mi.Bitmap(kd.astype(np.float32)), "raw": True, "filter_type": "nearest"}
    b = np.asarray(mi.render(mi.load_dict(scene({"type": "diffuse", "reflectance": texture})), spp=4))[..., :3]
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    assert len(np.unique(np.round(a[..., 0], 5))) == 24  # every texel shows
