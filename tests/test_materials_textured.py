"""Fitted parameter maps as textured native materials (docs/btf.md#btfs-per-texel-fitting and docs/materials.md#native-materials-and-exports): the Mitsuba XML loaded and rendered
by plain Mitsuba in a process that never imports brdffit, texel by texel against the model's own JAX
formula; the glTF file checked by the Khronos validator and read back by hand (structure, textures,
channel packing, texel layout); the .blend rendered by Cycles through the worker; bad input refused
in one line."""

from __future__ import annotations

import io
import json
import os
import shutil
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from brdffit import models
from brdffit.btf.maps import ParameterMaps
from brdffit.cli import main
from brdffit.errors import InputError, UsageError

#: Not square, so that a transposed or mirrored texture cannot pass.
H, W = 5, 7
REPO = Path(__file__).resolve().parents[1]


def random_maps(model_name: str, seed: int = 0, uniform=()) -> ParameterMaps:
    """Maps of independent random texels inside each parameter's range (roughness kept moderate, so
    that every texel reflects light at the test's directions); the parameters in ``uniform`` hold one
    value everywhere."""
    model = models.get(model_name)
    rng = np.random.default_rng(seed)
    params = {}
    for p in model.params:
        lo, hi = p.finite_range
        if p.role == "roughness":
            lo, hi = max(lo, 0.15), min(hi, 0.7)
        lo, hi = lo + 0.05 * (hi - lo), hi - 0.05 * (hi - lo)
        shape = (H, W, model.size(p))
        params[p.name] = np.full(shape, (lo + hi) / 2) if p.name in uniform else rng.uniform(lo, hi, shape)
    return ParameterMaps(model.name, params, loss=rng.uniform(0, 1, (H, W)), converged=np.ones((H, W), bool),
                         steps=np.full((H, W), 7), loss_name="log", solver="lm")


def unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def per_texel(maps: ParameterMaps, light, view) -> np.ndarray:
    """f_r(light, view) (n.light) of every texel by the model's JAX formula: (H, W, 3)."""
    model = models.get(maps.model)
    out = np.zeros((H, W, 3))
    for r in range(H):
        for c in range(W):
            out[r, c] = np.asarray(model.eval(maps.texel_params(r, c), light[None], view[None]))[0]
    return out * light[2]


# -- Mitsuba: plain Mitsuba, no brdffit ----------------------------------------------------------------

PLAIN_MITSUBA = textwrap.dedent("""
    import sys
    import numpy as np
    import mitsuba as mi
    mi.set_variant("scalar_rgb")            # plain Mitsuba as shipped, no libLLVM needed
    for scene, out in zip(sys.argv[1::2], sys.argv[2::2]):
        np.save(out, np.asarray(mi.render(mi.load_file(scene), spp=1)))
    assert "brdffit" not in sys.modules, "the export needed brdffit"
""")


def square_scene(include: str, light, view) -> str:
    """A user's scene: Mitsuba's rectangle ([-1, 1]^2 scaled to the maps' aspect, normal +z) with the
    exported material, a directional light of irradiance 1 towards ``light``, and an orthographic
    camera whose rays run along -``view`` but whose film is sheared onto the square, so that pixel
    (i, j) sees the centre of texel (i, j) whatever the view (one sample per pixel, at its centre)."""
    to_world = np.array([[-1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 3], [0, 0, 0, 1]])  # lookat from +z, +y up
    to_world[:3, 2], to_world[:3, 3] = -view, 3.0 * view
    matrix = " ".join(repr(float(x)) for x in to_world.ravel())
    d = ", ".join(repr(float(-x)) for x in light)
    return f"""<scene version="3.0.0">
    <include filename="{include}"/>
    <integrator type="direct"><integer name="emitter_samples" value="1"/><integer name="bsdf_samples" value="0"/></integrator>
    <sensor type="orthographic">
        <transform name="to_world"><matrix value="{matrix}"/></transform>
        <film type="hdrfilm"><integer name="width" value="{W}"/><integer name="height" value="{H}"/>
            <rfilter type="box"/></film>
        <sampler type="stratified"><integer name="sample_count" value="1"/><boolean name="jitter" value="false"/></sampler>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><scale x="1" y="{H / W!r}" z="1"/></transform>
        <ref id="paint"/>
    </shape>
    <emitter type="directional"><vector name="direction" value="{d}"/><rgb name="irradiance" value="1"/></emitter>
</scene>
"""


#: (light, view) pairs: head-on view, and an oblique view off the mirror direction.
PAIRS = [(unit([0.5, 0.2, 0.84]), np.array([0.0, 0.0, 1.0])), (unit([-0.3, 0.45, 0.8]), unit([0.35, -0.2, 0.9]))]
CASES = [("mitsuba:roughconductor", ()), ("mitsuba:principled", ("specular",)),
         ("mitsuba:roughplastic", ("alpha", "int_ior"))]


@pytest.mark.mitsuba
def test_mitsuba_textured_xml_renders_each_texel_in_plain_mitsuba(tmp_path):
    """Each model's XML written through the CLI from a params.exr (the file fit-btf writes); one
    child process renders every scene. Mitsuba's rectangle has v = (y + 1)/2 and its bitmap v = 0 at
    the image's top row, so seen from +z with +y up, image row i shows texel row H - 1 - i."""
    scenes, expected = [], []
    for k, (name, uniform) in enumerate(CASES):
        maps = random_maps(name, seed=k, uniform=uniform)
        folder = tmp_path / f"case{k}"
        maps.save_exr(folder / "params.exr")
        assert main(["export", str(folder / "params.exr"), "-o", str(folder / "paint.xml"), "--id", "paint"]) == 0
        text = (folder / "paint.xml").read_text()
        kind = name.split(":")[1]
        assert f'<bsdf type="{kind}" id="paint">' in text and 'type="brdffit"' not in text
        textured = sorted(p.name for p in (folder / "paint_textures").iterdir())
        assert textured == sorted(f"{p.name}.exr" for p in models.get(name).params if p.name not in uniform)
        for u in uniform:  # the plugin's numbers: written as the map's one value
            assert f'<float name="{u}" value="' in text
        for j, (light, view) in enumerate(PAIRS):
            scene = folder / f"scene{j}.xml"  # the user's scene beside the material (see the README)
            scene.write_text(square_scene("paint.xml", light, view))
            scenes += [str(scene), str(folder / f"img{j}.npy")]
            loaded = ParameterMaps.load(folder / "params.exr")  # float32, as the textures hold them
            expected.append((name, folder / f"img{j}.npy", per_texel(loaded, light, view)))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = subprocess.run([sys.executable, "-c", PLAIN_MITSUBA, *scenes], capture_output=True, text=True, env=env,
                         cwd=tmp_path, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    for name, image, want in expected:
        got = np.load(image)[..., :3][::-1]  # image row i is texel row H - 1 - i (see the docstring)
        assert want.min() > 1e-4, name  # every texel lit and seen
        err = np.abs(got / want - 1.0)
        # float32 rendering against float64 JAX: ~1e-6; roughplastic's formula reads its precomputed terms
        # from smooth tables of Mitsuba's quadratures, within 2.5e-3 of Mitsuba (tests/test_native_models.py)
        tolerance = 2.5e-3 if name == "mitsuba:roughplastic" else 2e-5
        assert err.max() < tolerance, (name, float(err.max()))


def test_roughplastic_with_a_varying_alpha_is_refused_naming_it(tmp_path, capsys):
    """Mitsuba 3's roughplastic takes alpha and int_ior as numbers: a varying map is one line, exit 2,
    nothing written; the same maps with alpha and int_ior uniform export."""
    maps = random_maps("mitsuba:roughplastic", uniform=("int_ior",))
    maps.save_exr(tmp_path / "params.exr")
    assert main(["export", str(tmp_path / "params.exr"), "-o", str(tmp_path / "p.xml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "params.exr" in err and "alpha varies" in err and "int_ior" not in err
    assert sorted(os.listdir(tmp_path)) == ["params.exr"]
    with pytest.raises(InputError, match="int_ior varies"):
        random_maps("mitsuba:roughplastic", uniform=("alpha",)).export(tmp_path / "q.xml")
    random_maps("mitsuba:roughplastic", uniform=("alpha", "int_ior")).export(tmp_path / "p.xml")
    assert (tmp_path / "p_textures" / "diffuse_reflectance.exr").is_file()


# -- glTF: the Khronos validator, and the file read back by hand ------------------------------------------

def read_glb(data: bytes) -> tuple[dict, bytes]:
    """The GLB container by the spec (magic, version 2, total length, JSON chunk, BIN chunk), by hand."""
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A
    doc = json.loads(data[20:20 + json_len])
    bin_len, bin_type = struct.unpack_from("<II", data, 20 + json_len)
    assert bin_type == 0x004E4942
    return doc, data[28 + json_len:28 + json_len + bin_len]


def view_bytes(doc, blob, index) -> bytes:
    view = doc["bufferViews"][index]
    return blob[view.get("byteOffset", 0):view.get("byteOffset", 0) + view["byteLength"]]


def accessor(doc, blob, index, dtype):
    a = doc["accessors"][index]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[a["type"]]
    arr = np.frombuffer(view_bytes(doc, blob, a["bufferView"]), dtype=dtype, count=a["count"] * width)
    return arr.reshape(a["count"], width) if width > 1 else arr


def khronos_validate(path: Path) -> dict:
    """The report of the Khronos glTF-Validator (``make test`` installs it into .node-tools)."""
    node = shutil.which("node")
    module = REPO / ".node-tools" / "node_modules" / "gltf-validator"
    if node is None or not module.is_dir():
        pytest.skip("needs node and the Khronos glTF-Validator in .node-tools (make setup-gltf-validator)")
    script = ("const v = require(process.argv[1]); const fs = require('fs');"
              "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])))"
              ".then(r => console.log(JSON.stringify(r))).catch(e => { console.error(String(e)); process.exit(1); });")
    run = subprocess.run([node, "-e", script, str(module), str(path)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


def test_glb_is_valid_and_its_textures_hold_the_maps_texel_by_texel(tmp_path):
    from colour.models import eotf_inverse_sRGB  # the sRGB encoding, from outside brdffit
    from PIL import Image

    maps = random_maps("gltf:metallic_roughness", seed=3)
    maps.save_exr(tmp_path / "params.exr")
    assert main(["export", str(tmp_path / "params.exr"), "-o", str(tmp_path / "tile.glb"), "--id", "tile"]) == 0
    report = khronos_validate(tmp_path / "tile.glb")
    assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0, report["issues"]
    assert report["info"]["hasTextures"] and report["info"]["materialCount"] == 1
    doc, blob = read_glb((tmp_path / "tile.glb").read_bytes())
    (material,) = doc["materials"]
    pbr = material["pbrMetallicRoughness"]
    assert pbr.get("baseColorFactor", [1, 1, 1, 1]) == [1, 1, 1, 1]
    assert pbr.get("metallicFactor", 1) == 1 and pbr.get("roughnessFactor", 1) == 1
    assert "extensionsUsed" not in doc and material["extras"]["brdffit"]["texels"] == [H, W]

    def image(info):
        texture = doc["textures"][info["index"]]
        sampler = doc["samplers"][texture["sampler"]]
        assert sampler["magFilter"] == 9728  # NEAREST: one texel per texel
        img = doc["images"][texture["source"]]
        assert img["mimeType"] == "image/png"
        return np.asarray(Image.open(io.BytesIO(view_bytes(doc, blob, img["bufferView"]))).convert("RGB"), np.float64) / 255

    loaded = ParameterMaps.load(tmp_path / "params.exr")
    base, packed = image(pbr["baseColorTexture"]), image(pbr["metallicRoughnessTexture"])
    assert base.shape == packed.shape == (H, W, 3)
    half_code = 0.5 / 255 + 1e-9
    assert np.abs(base - eotf_inverse_sRGB(loaded.params["base_color"])).max() <= half_code  # sRGB-encoded
    assert np.abs(packed[..., 1] - loaded.params["roughness"][..., 0]).max() <= half_code  # G: roughness
    assert np.abs(packed[..., 2] - loaded.params["metallic"][..., 0]).max() <= half_code  # B: metallic

    node = doc["nodes"][doc["scenes"][doc["scene"]]["nodes"][0]]
    (prim,) = doc["meshes"][node["mesh"]]["primitives"]
    pos = accessor(doc, blob, prim["attributes"]["POSITION"], np.float32)
    uv = accessor(doc, blob, prim["attributes"]["TEXCOORD_0"], np.float32)
    tris = accessor(doc, blob, prim["indices"], np.uint32).reshape(-1, 3)
    assert np.allclose(accessor(doc, blob, prim["attributes"]["NORMAL"], np.float32), [0, 0, 1])
    for t in tris:  # counter-clockwise seen from +z: the front face looks at +z
        assert np.cross(pos[t[1]] - pos[t[0]], pos[t[2]] - pos[t[0]])[2] > 0
    # the texel layout: the centre of texel (r, c), as seen on the square (row 0 at the top), has the
    # texture coordinates of that texel's centre (glTF: (0, 0) is the image's top-left corner)
    x0, x1, y0, y1 = pos[:, 0].min(), pos[:, 0].max(), pos[:, 1].min(), pos[:, 1].max()
    assert (x1 - x0) / (y1 - y0) == pytest.approx(W / H)
    for r in range(H):
        for c in range(W):
            p = np.array([x0 + (c + 0.5) / W * (x1 - x0), y1 - (r + 0.5) / H * (y1 - y0)])
            for t in tris:  # barycentric interpolation in the triangle that holds p
                a, b, cc = pos[t, :2]
                lam = np.linalg.solve(np.stack([b - a, cc - a], 1), p - a)
                w3 = np.array([1 - lam.sum(), *lam])
                if np.all(w3 >= -1e-6):
                    assert w3 @ uv[t] == pytest.approx([(c + 0.5) / W, (r + 0.5) / H], abs=1e-6)
                    break
            else:
                raise AssertionError(f"texel ({r}, {c}) is not on the square")


def test_gltf_json_holds_the_same_asset(tmp_path):
    maps = random_maps("gltf:metallic_roughness", seed=4)
    maps.export(tmp_path / "tile.gltf", bsdf_id="tile")
    maps.export(tmp_path / "tile.glb", bsdf_id="tile")
    report = khronos_validate(tmp_path / "tile.gltf")
    assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0, report["issues"]
    doc = json.loads((tmp_path / "tile.gltf").read_text())
    glb, _ = read_glb((tmp_path / "tile.glb").read_bytes())
    assert doc["buffers"][0]["uri"].startswith("data:application/octet-stream;base64,")
    assert doc["materials"] == glb["materials"] and doc["images"] == glb["images"]


# -- Blender: the .blend rendered by Cycles ------------------------------------------------------------

def test_blend_renders_each_texel_in_cycles(blender, tmp_path):
    """The .blend as a user opens it (its textures packed: the EXRs brdffit wrote are gone), rendered
    through its own camera (one pixel per texel, looking down) under a sun of angle 0: pixel = f (n.l) E
    of its texel, image row 0 = texel row 0. docs/materials.md#native-materials-and-exports allows Cycles 2 %; measured 4e-5 here."""
    maps = random_maps("blender:principled", seed=5)
    path = maps.export(tmp_path / "tile.blend", bsdf_id="tile")[0]
    (name, mat), = blender.inspect(path).items()
    assert name == "tile" and mat["users"] == ["tile"] and mat["distribution"] == "GGX"
    assert json.loads(mat["properties"]["brdffit"])["brdffit"]["model"] == "blender:principled"
    view = np.array([0.0, 0.0, 1.0])
    for light in (unit([0.5, 0.2, 0.84]), unit([-0.4, -0.3, 0.7])):
        got = blender.render_file(path, light, irradiance=1.0, spp=4)
        want = per_texel(maps, light, view)
        assert got.shape == want.shape == (H, W, 3)
        err = np.abs(got / want - 1.0)
        assert err.max() < 1e-3, float(err.max())


# -- bad input: one line, exit 2, nothing written ------------------------------------------------------

def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, monkeypatch):
    ok = random_maps("mitsuba:roughconductor")
    ok.save_exr(tmp_path / "params.exr")
    ggx = random_maps("ggx")
    ggx.save_exr(tmp_path / "ggx.exr")
    lacking = ParameterMaps(ok.model, {k: v for k, v in ok.params.items() if k != "k"}, ok.loss, ok.converged, ok.steps)
    lacking.save_exr(tmp_path / "lacking.exr")
    (tmp_path / "taken.xml").write_text("mine")
    cases = [
        (["ggx.exr", "-o", "g.xml"], "ggx is not a native model"),
        (["params.exr", "-o", "c.glb"], "export them as .xml"),
        (["lacking.exr", "-o", "l.xml"], "no part for parameter 'k'"),
        (["params.exr", "-o", "taken.xml"], "already exists (use --force"),
        (["params.exr", "-o", "c.mtlx"], "unknown textured material format"),
        (["params.exr"], "give -o FILE"),
        (["params.exr", "-o", "c.xml", "--to", "gltf:metallic_roughness"], "not converted"),
        (["nothing.exr", "-o", "n.xml"], "no such file"),
    ]
    before = sorted(os.listdir(tmp_path))
    monkeypatch.chdir(tmp_path)
    for args, message in cases:
        assert main(["export", *args]) == 2, args
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err and "Traceback" not in err, (args, err)
    assert sorted(os.listdir(tmp_path)) == before and (tmp_path / "taken.xml").read_text() == "mine"
    (tmp_path / "taken_textures").mkdir()  # a textures folder of another export: also kept without --force
    (tmp_path / "taken.xml").unlink()
    assert main(["export", "params.exr", "-o", "taken.xml"]) == 2
    assert "taken_textures: already exists" in capsys.readouterr().err
    assert main(["export", "params.exr", "-o", "taken.xml", "--force"]) == 0
    assert sorted(p.name for p in (tmp_path / "taken_textures").iterdir()) == ["alpha.exr", "eta.exr", "k.exr"]
    with pytest.raises(UsageError, match="not a native model"):
        ggx.export(tmp_path / "g.glb")
