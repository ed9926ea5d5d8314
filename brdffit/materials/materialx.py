"""``.mtlx`` (docs/materials.md#native-materials-and-exports): a fit as a MaterialX 1.39 document, through the ``materialx`` package.

- ``gltf:metallic_roughness`` -> a ``gltf_pbr`` node (base_color, metallic, roughness: the glTF
  factors; the node's other inputs keep their defaults, the glTF core material's values).
- ``blender:principled`` -> an ``open_pbr_surface`` node with the settings that correspond to
  Blender's Principled BSDF (Blender 4's Principled follows OpenPBR): base_color, base_metalness =
  Metallic, specular_roughness = Roughness, specular_ior = IOR, specular_weight = 2 x Specular IOR
  Level, specular_color = Specular Tint (OpenPBR's metal uses it as the F82 tint, as Cycles does),
  base_diffuse_roughness = Diffuse Roughness. This is the corresponding material, not a proof of
  equality: how a MaterialX renderer evaluates OpenPBR is its own.

The shader feeds a ``surfacematerial`` named after the material; the fit and its conversion error
(``extras``) are the material's ``brdffit`` attribute (strict JSON text) and its ``doc`` string. The
document validates against MaterialX's standard libraries (tests/test_materials_mtlx.py).
"""

from __future__ import annotations

from .._files import json_text
from ..errors import UsageError
from ._names import safe_id
from ._record import fit_record, native_of
from .formats import Format


def _gltf_pbr(native: dict) -> dict:
    """{input: (type, value)} of ``gltf_pbr`` from a glTF material object."""
    pbr = native["pbrMetallicRoughness"]
    return {"base_color": ("color3", [float(x) for x in pbr["baseColorFactor"][:3]]),
            "metallic": ("float", float(pbr["metallicFactor"])),
            "roughness": ("float", float(pbr["roughnessFactor"]))}


def _open_pbr(native: dict) -> dict:
    """{input: (type, value)} of ``open_pbr_surface`` from Blender's Principled BSDF settings."""
    inputs = native["inputs"]
    return {"base_color": ("color3", [float(x) for x in inputs["Base Color"][:3]]),
            "base_metalness": ("float", float(inputs.get("Metallic", 0.0))),
            "base_diffuse_roughness": ("float", float(inputs.get("Diffuse Roughness", 0.0))),
            "specular_weight": ("float", 2.0 * float(inputs.get("Specular IOR Level", 0.5))),
            "specular_color": ("color3", [float(x) for x in inputs.get("Specular Tint", [1.0, 1.0, 1.0])[:3]]),
            "specular_roughness": ("float", float(inputs.get("Roughness", 0.5))),
            "specular_ior": ("float", float(inputs.get("IOR", 1.5)))}


#: Native model -> the MaterialX shading node that holds it and that node's inputs from ``model.native``:
#: the models a MaterialX file holds, in the order a message proposes them.
NODES = {"gltf:metallic_roughness": ("gltf_pbr", _gltf_pbr), "blender:principled": ("open_pbr_surface", _open_pbr)}
SHADERS = {model: node for model, (node, _) in NODES.items()}


def _inputs(model_name: str, native: dict) -> dict:
    """{input: (type, value)} of the shading node."""
    return NODES[model_name][1](native)


def mtlx_text(model_name: str, native: dict, name: str, extras: dict) -> str:
    """The MaterialX 1.39 document (XML text) of a native fit of ``model_name``."""
    import MaterialX as mx

    if model_name not in SHADERS:
        raise UsageError(f"a MaterialX file holds a {' or '.join(SHADERS)} material, and this fit is {model_name}: "
                         f"convert it with {' or '.join(f'--to {m}' for m in SHADERS)}")
    doc = mx.createDocument()
    material_name = safe_id(name)
    shader = doc.addNode(SHADERS[model_name], material_name + "_shader", "surfaceshader")
    for key, (kind, value) in _inputs(model_name, native).items():
        port = shader.addInput(key, kind)
        port.setValue(mx.Color3(*value) if kind == "color3" else value, kind)
    material = doc.addMaterialNode(material_name, shader)
    # MaterialX's writer leaves '<' unescaped in an attribute (not well-formed XML): JSON's own
    # escapes keep the markup characters out of the text (they occur only inside JSON strings)
    text = json_text(extras, sort_keys=True)
    material.setAttribute("brdffit", text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026"))
    about = extras.get("brdffit", extras) if isinstance(extras, dict) else {}
    material.setDocString(f"brdffit fit of {about.get('model', model_name)} as {SHADERS[model_name]}")
    return mx.writeToXmlString(doc)


FORMAT = Format("MaterialX 1.39", (".mtlx",),
                lambda fit, ext, bsdf_id: mtlx_text(fit.model.name, native_of(fit), bsdf_id, fit_record(fit)).encode(),
                lambda fit, ext: f"a MaterialX 1.39 {SHADERS[fit.model.name]} material", models=tuple(NODES))
