"""A fit as a material other programs load (docs/materials.md#native-materials-and-exports): native Mitsuba XML that plain Mitsuba renders,
glTF files checked by an independent reader, conversion with its error, and refusals (docs/materials.md#native-materials-and-exports)."""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from brdffit.cli import main
from brdffit.errors import InputError, UsageError
from brdffit.fitting.result import FitResult
from brdffit.materials import convert, export

PLASTIC = {"diffuse_reflectance": [0.3, 0.2, 0.1], "alpha": 0.2, "int_ior": 1.5,
           "specular_reflectance": [1.0, 1.0, 1.0]}
GLTF = {"base_color": [0.8, 0.4, 0.2], "metallic": 0.3, "roughness": 0.45}
PRINCIPLED = {"base_color": [0.6, 0.3, 0.2], "roughness": 0.4, "metallic": 0.2, "specular": 0.6, "anisotropic": 0.3,
              "sheen": 0.4, "clearcoat": 0.5, "clearcoat_gloss": 0.6}
GGX = {"kd": [0.2, 0.3, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": 0.3, "f0": 0.1}


def a_fit(model, params, **extra) -> FitResult:
    doc = {"model": model, "params": {k: np.atleast_1d(v).tolist() for k, v in params.items()},
           "converged": True, "data_name": "test material", "loss": "log"}
    return FitResult.from_dict({**doc, **extra})


def write_fit(tmp_path, model, params) -> str:
    """A fit.json written as another tool (or a hand edit) would: not checked on the way out."""
    path = tmp_path / "fit.json"
    doc = {"format": "brdffit.fit/1", "model": model, "converged": True, "data_name": "test material",
           "loss": "log", "params": {k: np.atleast_1d(v).tolist() for k, v in params.items()}}
    path.write_text(json.dumps(doc))
    return str(path)


# -- Mitsuba: the renderer's own plugin, loaded by a process that never imports brdffit -------------

PLAIN_MITSUBA = textwrap.dedent("""
    import sys
    import numpy as np
    import mitsuba as mi
    mi.set_variant("scalar_rgb")            # no libLLVM needed: plain Mitsuba as shipped
    scene = mi.load_file(sys.argv[1])
    image = np.asarray(mi.render(scene, spp=16))
    assert "brdffit" not in sys.modules, "the export needed brdffit"
    np.save(sys.argv[2], image)
""")


def user_scene_xml(include: str, light, size: int) -> str:
    """A user's scene written by hand: a plain unit sphere, an orthographic camera on +z, one sun,
    Mitsuba's direct integrator, the exported material included and referenced by its id."""
    d = ", ".join(repr(float(-x)) for x in light)
    return f"""<scene version="3.0.0">
    <include filename="{include}"/>
    <integrator type="direct"><integer name="emitter_samples" value="1"/><integer name="bsdf_samples" value="0"/></integrator>
    <sensor type="orthographic">
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/>
            <rfilter type="box"/></film>
        <sampler type="stratified"><integer name="sample_count" value="16"/></sampler>
    </sensor>
    <shape type="sphere"><ref id="paint"/></shape>
    <emitter type="directional"><vector name="direction" value="{d}"/><rgb name="irradiance" value="1"/></emitter>
</scene>
"""


@pytest.mark.mitsuba
@pytest.mark.parametrize("model, params", [("mitsuba:roughplastic", PLASTIC), ("mitsuba:principled", PRINCIPLED)])
def test_native_xml_renders_in_plain_mitsuba_like_brdffit(tmp_path, model, params):
    from brdffit.render import render_sphere

    fit = a_fit(model, params)
    export(fit, tmp_path / "paint.xml")
    text = (tmp_path / "paint.xml").read_text()
    kind = model.split(":")[1]
    assert f'<bsdf type="{kind}" id="paint">' in text and "brdffit\"" not in text
    if kind == "roughplastic":
        assert '<string name="distribution" value="ggx"/>' in text  # never the plugin's Beckmann default
    else:
        assert '<float name="spec_trans" value="0.0"/>' in text or '<float name="spec_trans" value="0"/>' in text
    light = np.array([0.4, 0.3, np.sqrt(1 - 0.25)])
    size = 48
    (tmp_path / "scene.xml").write_text(user_scene_xml("paint.xml", light, size))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = subprocess.run([sys.executable, "-c", PLAIN_MITSUBA, str(tmp_path / "scene.xml"), str(tmp_path / "img.npy")],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    plain = np.load(tmp_path / "img.npy")[..., :3]
    ours = render_sphere(fit, lights=[light], size=size, spp=16)[0]
    c = (np.arange(size) + 0.5) * (2.0 / size) - 1.0
    x, y = np.meshgrid(c, -c)
    inside = x * x + y * y < 0.9**2
    for ch in range(3):  # mean within 2 % per channel (docs/materials.md#native-materials-and-exports's "Done when")
        assert plain[..., ch][inside].mean() == pytest.approx(ours[..., ch][inside].mean(), rel=0.02)
    assert plain[inside].mean() > 0.01  # not black


def test_native_fit_to_mitsuba_is_the_renderers_own_plugin():
    fit = a_fit("mitsuba:roughplastic", PLASTIC)
    d = fit.to_mitsuba()
    assert d["type"] == "roughplastic" and d["distribution"] == "ggx"
    assert a_fit("ggx", GGX).to_mitsuba()["type"] == "brdffit"  # a non-native fit keeps the plugin


# -- glTF: an independent reading of the file ------------------------------------------------------

def read_glb(data: bytes) -> tuple[dict, bytes]:
    """The GLB container by the spec (magic, version 2, total length, JSON chunk, BIN chunk), by hand."""
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A  # "JSON"
    doc = json.loads(data[20:20 + json_len])
    off = 20 + json_len
    bin_len, bin_type = struct.unpack_from("<II", data, off)
    assert bin_type == 0x004E4942  # "BIN\0"
    return doc, data[off + 8:off + 8 + bin_len]


def accessor(doc, blob, index, dtype, width):
    a = doc["accessors"][index]
    view = doc["bufferViews"][a["bufferView"]]
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    arr = np.frombuffer(blob, dtype=dtype, count=a["count"] * width, offset=start)
    return arr.reshape(a["count"], width) if width > 1 else arr


def test_glb_holds_the_factors_on_an_outward_sphere(tmp_path):
    fit = a_fit("gltf:metallic_roughness", GLTF)
    fit.export(tmp_path / "ball.glb")  # docs/materials.md#native-materials-and-exports's FitResult.export: brdffit.materials.export
    doc, blob = read_glb((tmp_path / "ball.glb").read_bytes())
    assert doc["asset"]["version"] == "2.0"
    (material,) = doc["materials"]
    pbr = material["pbrMetallicRoughness"]
    assert pbr["baseColorFactor"] == pytest.approx([0.8, 0.4, 0.2, 1.0])
    assert pbr["metallicFactor"] == pytest.approx(0.3) and pbr["roughnessFactor"] == pytest.approx(0.45)
    assert "extensionsUsed" not in doc and not material.get("extensions")  # core material only
    assert material["extras"]["brdffit"]["model"] == "gltf:metallic_roughness"
    node = doc["nodes"][doc["scenes"][doc["scene"]]["nodes"][0]]
    (prim,) = doc["meshes"][node["mesh"]]["primitives"]
    assert prim["material"] == 0 and prim.get("mode", 4) == 4
    pos = accessor(doc, blob, prim["attributes"]["POSITION"], np.float32, 3)
    nrm = accessor(doc, blob, prim["attributes"]["NORMAL"], np.float32, 3)
    idx = accessor(doc, blob, prim["indices"], np.uint32, 1).reshape(-1, 3)
    assert np.allclose(np.linalg.norm(pos, axis=1), 1.0, atol=1e-6) and np.allclose(nrm, pos)
    a, b, c = pos[idx[:, 0]], pos[idx[:, 1]], pos[idx[:, 2]]
    area = np.cross(b - a, c - a)
    # counter-clockwise seen from outside (glTF's front face), no degenerate triangle, closed surface
    assert np.all(np.einsum("ij,ij->i", area, (a + b + c) / 3) > 0)
    assert 0.5 * np.linalg.norm(area, axis=1).sum() == pytest.approx(4 * np.pi, rel=0.01)
    mins, maxs = doc["accessors"][prim["attributes"]["POSITION"]]["min"], doc["accessors"][prim["attributes"]["POSITION"]]["max"]
    assert np.allclose(mins, pos.min(axis=0)) and np.allclose(maxs, pos.max(axis=0))


def test_gltf_json_embeds_its_buffer(tmp_path):
    import pygltflib

    export(a_fit("gltf:metallic_roughness", GLTF), tmp_path / "ball.gltf")
    doc = json.loads((tmp_path / "ball.gltf").read_text())
    assert doc["buffers"][0]["uri"].startswith("data:application/octet-stream;base64,")
    back = pygltflib.GLTF2().load(str(tmp_path / "ball.gltf"))
    assert back.materials[0].pbrMetallicRoughness.roughnessFactor == pytest.approx(0.45)


# -- conversion ------------------------------------------------------------------------------------

@pytest.mark.parametrize("source,params", [("ggx", GGX), ("ward", {"kd": [0.2, 0.2, 0.2], "ks": [0.3, 0.3, 0.3],
                                                                  "alpha_x": 0.2, "alpha_y": 0.2})])
def test_convert_reports_its_error_against_the_source(source, params):
    from brdffit.grid import ubo_pairs

    fit = a_fit(source, params)
    out = fit.convert("gltf:metallic_roughness")  # docs/materials.md#native-materials-and-exports's FitResult.convert: brdffit.materials.convert
    assert type(out) is FitResult and out.model.name == "gltf:metallic_roughness"
    c = out.options["converted_from"]
    assert c["model"] == source and c["grid"] == "ubo81"
    # the stored error is the error of the converted BRDF against the source's, computed here by hand
    wi, wo = ubo_pairs()
    f, g = out.eval(wi, wo), fit.eval(wi, wo)
    rel = np.sqrt(np.mean((f - g) ** 2)) / np.sqrt(np.mean(g**2))
    log = np.sqrt(np.mean((np.log1p(f * wi[:, 2:3]) - np.log1p(g * wi[:, 2:3])) ** 2))
    assert c["log_rmse"] == pytest.approx(log, rel=1e-6)
    assert c["rel_rmse"] == pytest.approx(rel, rel=1e-6)
    assert convert(fit, source) is fit  # nothing to convert


def test_cli_export_to_prints_and_stores_the_conversion_error(tmp_path, capsys):
    src = write_fit(tmp_path, "ggx", GGX)
    assert main(["export", src, "--to", "gltf:metallic_roughness", "-o", str(tmp_path / "m.glb")]) == 0
    err = capsys.readouterr().err
    assert "converted ggx -> gltf:metallic_roughness: rel_rmse" in err
    doc, _ = read_glb((tmp_path / "m.glb").read_bytes())
    stored = doc["materials"][0]["extras"]["brdffit"]["converted_from"]
    assert stored["model"] == "ggx" and f"{stored['rel_rmse']:.4g}" in err
    assert main(["export", src, "--to", "mitsuba:roughplastic", "-o", str(tmp_path / "m.xml")]) == 0
    text = (tmp_path / "m.xml").read_text()
    assert "converted ggx -&gt; mitsuba:roughplastic" in text or "converted ggx -> mitsuba:roughplastic" in text
    assert '<bsdf type="roughplastic"' in text


# -- refusals: one line, exit 2, nothing written -----------------------------------------------------

@pytest.mark.parametrize("model,params,args,says", [
    ("ggx", GGX, ["-o", "x.glb"], "holds a gltf:metallic_roughness material, and this fit is ggx: convert it with --to"),
    ("mitsuba:roughplastic", PLASTIC, ["-o", "x.gltf"], "convert it with --to gltf:metallic_roughness"),
    ("ggx", GGX, ["-o", "x.obj"], "unknown material format '.obj'"),
    ("ggx", GGX, ["-o", "x.mtlx"], "holds a gltf:metallic_roughness or blender:principled material, and this "
                                   "fit is ggx: convert it with --to gltf:metallic_roughness"),
    ("mitsuba:roughplastic", PLASTIC, ["-o", "x.blend"], "holds a blender:principled material, and this fit is "
                                                         "mitsuba:roughplastic: convert it with --to blender:principled"),
    ("ggx", GGX, ["--to", "no_such_model", "-o", "x.xml"], "unknown model"),
    # an unknown --to is named as such whatever the format (it was "... and this fit is no_such_model")
    ("ggx", GGX, ["--to", "no_such_model", "-o", "x.mtlx"], "--to no_such_model: unknown model 'no_such_model'"),
    ("ggx", GGX, ["--to", "no_such_model", "-o", "x.glb"], "--to no_such_model: unknown model 'no_such_model'"),
    # a --to the format does not hold is the --to's model, not the fit's
    ("ggx", GGX, ["--to", "mitsuba:roughplastic", "-o", "x.glb"],
     "holds a gltf:metallic_roughness material, not mitsuba:roughplastic (--to): convert it with --to "
     "gltf:metallic_roughness"),
    ("gltf:metallic_roughness", {**GLTF, "metallic": 1.5}, ["-o", "x.glb"],
     "'metallic' = [1.5] lies outside its bounds of gltf:metallic_roughness [0, 1]"),
])
def test_export_refusals(tmp_path, capsys, model, params, args, says):
    src = write_fit(tmp_path, model, params)
    args = [a if not a.startswith("x.") else str(tmp_path / a) for a in args]
    assert main(["export", src, *args]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and "Traceback" not in err and len(err.splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.json"]


def test_export_writes_materialx_documents(tmp_path, capsys):
    """``.mtlx`` through the same export path: a glTF fit as gltf_pbr as it is; a ggx fit converted
    to gltf:metallic_roughness, its conversion error in the document's brdffit attribute."""
    import MaterialX as mx

    src = write_fit(tmp_path, "gltf:metallic_roughness", GLTF)
    assert main(["export", src, "-o", str(tmp_path / "m.mtlx")]) == 0
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(tmp_path / "m.mtlx"))
    (shader,) = doc.getNodes("gltf_pbr")
    assert shader.getInput("metallic").getValue() == pytest.approx(0.3)
    assert shader.getInput("roughness").getValue() == pytest.approx(0.45)
    assert list(shader.getInput("base_color").getValue().asTuple()) == pytest.approx([0.8, 0.4, 0.2])
    other = tmp_path / "ggx"
    other.mkdir()
    assert main(["export", write_fit(other, "ggx", GGX), "--to", "gltf:metallic_roughness",
                 "-o", str(other / "g.mtlx")]) == 0
    assert "converted ggx -> gltf:metallic_roughness" in capsys.readouterr().err
    assert '"converted_from"' in (other / "g.mtlx").read_text().replace("&quot;", '"')


def test_export_writes_a_blend_file(blender, tmp_path):
    """``.blend`` through the same export path (Blender writes it in the worker): the material, as
    Blender reads it back, carries the fitted inputs."""
    params = {"base_color": [0.7, 0.3, 0.1], "metallic": 0.2, "roughness": 0.35, "ior": 1.5, "specular_tint": 1.0}
    fit = a_fit("blender:principled", params)
    export(fit, tmp_path / "paint.blend")
    (name, mat), = blender.inspect(tmp_path / "paint.blend").items()
    assert name == "paint"
    for key, value in fit.model.native(fit.params)["inputs"].items():
        if key in mat["inputs"]:
            assert np.allclose(mat["inputs"][key], value, atol=1e-6), key


def test_python_export_refusals(tmp_path):
    with pytest.raises(UsageError, match="convert it with --to gltf:metallic_roughness"):
        export(a_fit("ggx", GGX), tmp_path / "x.glb")
    import dataclasses

    fit = a_fit("mitsuba:roughplastic", PLASTIC)  # a fit file with such values is refused on reading
    bad = dataclasses.replace(fit, params={**fit.params, "alpha": np.array([-1.0])})
    with pytest.raises(InputError, match="cannot export: .*'alpha' = \\[-1.0\\] outside \\[1e-4, 1\\]"):
        export(bad, tmp_path / "x.xml")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.mitsuba
@pytest.mark.parametrize("model,params", [("ggx", GGX), ("mitsuba:roughplastic", PLASTIC)])
def test_a_scene_including_an_export_loads_for_scene_tools(tmp_path, model, params):
    """validate-scene / scene_usage load the user's scene themselves: an included export, the brdffit
    plugin as well as a native one, is found by its id (it used to be 'Plugin "brdffit" not found')."""
    from brdffit.scene.load import load_scene

    export(a_fit(model, params), tmp_path / "paint.xml")
    (tmp_path / "scene.xml").write_text(user_scene_xml("paint.xml", [0.0, 0.0, 1.0], 8))
    loaded = load_scene(tmp_path / "scene.xml", "paint")
    assert len(loaded.shapes) == 1 and loaded.original.id() == "paint"
