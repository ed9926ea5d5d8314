"""The .blend export (docs/materials.md#native-materials-and-exports) and Blender reading brdffit's files: a .blend made by Blender holds a
sphere with the fit's Principled BSDF, which renders like blender:principled (Cycles measured as a
gonioreflectometer on the material taken from the file); a glTF export imports into Blender, through
Blender's own glTF importer, with the fitted factors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from brdffit import models
from brdffit.errors import UsageError
from brdffit.materials.blender import blend_bytes
from brdffit.materials.gltf import gltf_bytes

MODEL = models.get("blender:principled")
PARAMS = [{"base_color": [0.7, 0.3, 0.1], "metallic": 0.0, "roughness": 0.3, "ior": 1.45, "specular_tint": 1.0},
          {"base_color": [0.95, 0.8, 0.5], "metallic": 0.9, "roughness": 0.2, "ior": 1.5, "specular_tint": 0.7},
          {"base_color": [0.2, 0.5, 0.3], "metallic": 0.4, "roughness": 0.6, "ior": 2.2, "specular_tint": 0.4}]
EXTRAS = {"brdffit": {"model": "blender:principled", "converted_from": {"model": "ggx", "rel_rmse": 0.02}}}


def test_blend_file_holds_the_sphere_and_the_material(blender, tmp_path):
    native = MODEL.native(PARAMS[1])
    path = tmp_path / "fit.blend"
    path.write_bytes(blend_bytes(native, "my_fit", EXTRAS))
    assert path.read_bytes()[:7] == b"BLENDER"
    (name, mat), = blender.inspect(path).items()
    assert name == "my_fit" and mat["users"] == ["my_fit"] and mat["distribution"] == "GGX"
    for key, value in native["inputs"].items():
        if key in mat["inputs"]:
            assert np.allclose(mat["inputs"][key], value, atol=1e-6), key
    assert json.loads(mat["properties"]["brdffit"]) == EXTRAS


def test_blend_material_renders_like_the_model(blender, tmp_path):
    """The material as a user of the file gets it: appended from the .blend, measured in Cycles."""
    rng = np.random.default_rng(7)
    for k, params in enumerate(PARAMS):
        path = tmp_path / f"fit{k}.blend"
        path.write_bytes(blend_bytes(MODEL.native(params), "fit", {}))
        theta = np.radians(rng.uniform(0, 85, (10, 2)))
        phi = rng.uniform(0, 2 * np.pi, (10, 2))
        d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
        got = blender.gonio((path, "fit"), d[:, 0], d[:, 1])
        want = np.asarray(MODEL.eval(params, d[:, 0], d[:, 1])) * d[:, 0, 2:3]
        assert np.all(np.abs(got - want) <= 0.02 * np.abs(want) + 1e-4), (k, np.abs(got / want - 1).max())
    with pytest.raises(blender.BlenderError, match="no material 'other'"):
        blender.gonio((path, "other"), d[:1, 0], d[:1, 1])


def test_gltf_export_imports_into_blender_with_its_factors(blender, tmp_path):
    native = models.get("gltf:metallic_roughness").native({"base_color": [0.25, 0.5, 0.75], "metallic": 0.35,
                                                           "roughness": 0.65})
    for ext in (".glb", ".gltf"):
        path = tmp_path / f"sphere{ext}"
        path.write_bytes(gltf_bytes(native, "painted", binary=ext == ".glb", extras={"brdffit": {"model": "x"}}))
        mats = blender.inspect(path)
        assert list(mats) == ["painted"], mats
        inputs = mats["painted"]["inputs"]
        assert inputs["Base Color"] == pytest.approx([0.25, 0.5, 0.75], abs=1e-6)
        assert (inputs["Metallic"], inputs["Roughness"]) == pytest.approx((0.35, 0.65), abs=1e-6)
        assert mats["painted"]["users"], "the imported mesh carries the material"


def test_a_non_blender_material_is_one_line():
    with pytest.raises(UsageError, match="convert the fit with --to blender:principled"):
        blend_bytes({"pbrMetallicRoughness": {}}, "m", {})
