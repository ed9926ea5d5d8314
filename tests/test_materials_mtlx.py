"""MaterialX export (docs/materials.md#native-materials-and-exports): gltf_pbr for glTF fits, open_pbr_surface for Blender fits; the document
validates against MaterialX's own standard libraries (MaterialX's validate()), and carries the values."""

from __future__ import annotations

import json

import MaterialX as mx
import pytest

from brdffit import models
from brdffit.errors import UsageError
from brdffit.materials import materialx

GLTF = models.get("gltf:metallic_roughness").native({"base_color": [0.2, 0.4, 0.6], "metallic": 0.3, "roughness": 0.7})
BLENDER = models.get("blender:principled").native({"base_color": [0.9, 0.5, 0.1], "metallic": 0.8, "roughness": 0.25,
                                                   "ior": 1.7, "specular_tint": 0.6})
EXTRAS = {"brdffit": {"model": "ggx", "converted_from": {"rel_rmse": 0.012, "log_rmse": None}}}


def standard_libraries():
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    return lib


def read(text):
    doc = mx.createDocument()
    mx.readFromXmlString(doc, text)
    doc.importLibrary(standard_libraries())
    return doc


def values(doc):
    return {i.getName(): i.getValue() for i in doc.getNode("m_shader").getInputs()}


@pytest.mark.parametrize("model, native, shader", [("gltf:metallic_roughness", GLTF, "gltf_pbr"),
                                                   ("blender:principled", BLENDER, "open_pbr_surface")])
def test_document_validates_with_the_right_shading_node(model, native, shader):
    doc = read(materialx.mtlx_text(model, native, "my fit.1", EXTRAS))
    assert doc.getVersionString() == "1.39"
    ok, message = doc.validate()
    assert ok, message
    (material,) = doc.getMaterialNodes()
    assert material.getName() == "my_fit_1" and material.getCategory() == "surfacematerial"
    assert json.loads(material.getAttribute("brdffit")) == EXTRAS
    (node,) = [n for n in doc.getNodes() if n.getType() == "surfaceshader"]
    assert node.getCategory() == shader
    assert node.getNodeDef() is not None and node.getNodeDef().getName() == f"ND_{shader}_surfaceshader"


def test_values_are_the_fit():
    gltf = values(read(materialx.mtlx_text("gltf:metallic_roughness", GLTF, "m", {})))
    assert list(gltf["base_color"].asTuple()) == pytest.approx([0.2, 0.4, 0.6])
    assert (gltf["metallic"], gltf["roughness"]) == pytest.approx((0.3, 0.7))
    pbr = values(read(materialx.mtlx_text("blender:principled", BLENDER, "m", {})))
    assert list(pbr["base_color"].asTuple()) == pytest.approx([0.9, 0.5, 0.1])
    assert list(pbr["specular_color"].asTuple()) == pytest.approx([0.6] * 3)
    assert (pbr["base_metalness"], pbr["specular_roughness"], pbr["specular_ior"], pbr["specular_weight"]) == \
        pytest.approx((0.8, 0.25, 1.7, 1.0))  # Specular IOR Level 0.5 is OpenPBR's specular_weight 1


def test_validation_catches_a_wrong_input(monkeypatch):
    """The check is MaterialX's own: an input the node definition does not have fails it."""
    original = materialx._inputs
    monkeypatch.setattr(materialx, "_inputs", lambda m, n: {**original(m, n), "metalness": ("float", 0.5)})
    ok, message = read(materialx.mtlx_text("gltf:metallic_roughness", GLTF, "m", {})).validate()
    assert not ok and "metalness" in message


def test_other_models_are_one_line():
    with pytest.raises(UsageError, match="this fit is mitsuba:roughplastic: convert it"):
        materialx.mtlx_text("mitsuba:roughplastic", {"type": "roughplastic"}, "m", {})
