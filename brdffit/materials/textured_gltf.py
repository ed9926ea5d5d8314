"""Parameter maps of ``gltf:metallic_roughness`` as a glTF 2.0 asset: a textured square.

Written with pygltflib, as the single-fit export (:mod:`brdffit.materials.gltf`). The asset holds
one scene, one node, one mesh of one triangle primitive (a square in the z = 0 plane facing +z, its
sides in the maps' aspect, the longer one 2 units; POSITION, NORMAL, TEXCOORD_0, indices) and one
core metallic-roughness material, no extension, so every viewer shows the same BRDF:

- ``baseColorTexture``: the base_color map, an 8-bit RGB PNG, sRGB-encoded as the glTF
  specification says base colour textures are; ``baseColorFactor`` (1, 1, 1, 1).
- ``metallicRoughnessTexture``: an 8-bit RGB PNG, linear, packed as the specification reads it:
  G = roughness, B = metallic (R = 255, what an occlusion channel packed there would mean: none;
  no ``occlusionTexture`` refers to it); ``metallicFactor`` = ``roughnessFactor`` = 1.

Eight bits: a texel's value is read back within half a code (1/510 in the encoded value; for the
base colour in sRGB, up to 0.8 % of the linear value at 0.05 and less above). Texel layout (see
:mod:`brdffit.materials.textured`): image row 0 is maps row 0; the square's top-left corner has
texture coordinates (0, 0) (glTF's origin is the image's top-left), so texel (r, c) lies at
x = -a + (c + 1/2) 2a / W, y = b - (r + 1/2) 2b / H. Sampler: magnification NEAREST (one texel per
texel, as ``validate-btf`` renders the maps), minification LINEAR_MIPMAP_LINEAR, wrap REPEAT.
The maps' model, size and source go into the material's ``extras``.
"""

from __future__ import annotations

import io
from collections.abc import Mapping

import numpy as np

#: glTF sampler constants (the specification's WebGL enums).
NEAREST, LINEAR_MIPMAP_LINEAR, REPEAT = 9728, 9987, 10497
#: The red channel of the metallic-roughness texture (unused by the material; 255 = no occlusion).
UNUSED_RED = 255


def square(height: int, width: int) -> dict[str, np.ndarray]:
    """The square: float32 positions (4, 3), normals (4, 3) = +z, texcoords (4, 2), and uint32
    indices of two triangles counter-clockwise seen from +z (glTF's front face). Corners in the order
    top-left, top-right, bottom-left, bottom-right; the longer side spans [-1, 1]."""
    a, b = width / max(height, width), height / max(height, width)
    position = np.array([[-a, b, 0.0], [a, b, 0.0], [-a, -b, 0.0], [a, -b, 0.0]], np.float32)
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]], np.float32)
    normal = np.tile(np.array([0.0, 0.0, 1.0], np.float32), (4, 1))
    return {"POSITION": position, "NORMAL": normal, "TEXCOORD_0": uv,
            "indices": np.array([2, 3, 1, 2, 1, 0], np.uint32)}


def texture_images(arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The two textures as (H, W, 3) uint8 arrays: ``base_color`` sRGB-encoded, and
    ``metallic_roughness`` packed (R unused, G roughness, B metallic)."""
    from ..io.images import linear_to_srgb

    def code(x):
        return np.round(np.clip(np.asarray(x, np.float64), 0.0, 1.0) * 255.0).astype(np.uint8)

    base = code(linear_to_srgb(arrays["base_color"]))
    rough, metal = code(arrays["roughness"][..., 0]), code(arrays["metallic"][..., 0])
    packed = np.stack([np.full_like(rough, UNUSED_RED), rough, metal], -1)
    return {"base_color": base, "metallic_roughness": packed}


def png(image: np.ndarray) -> bytes:
    """An (H, W, 3) uint8 image as PNG bytes (no gamma or colour-profile chunk: glTF ignores them)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image), "RGB").save(buf, format="PNG")
    return buf.getvalue()


def _pad4(b: bytes) -> bytes:
    return b + b"\0" * (-len(b) % 4)


def square_asset(arrays: Mapping[str, np.ndarray], name: str, extras: Mapping | None = None):
    """The pygltflib ``GLTF2`` of the textured square, its binary buffer (geometry, then the two
    PNGs) set as the asset's blob."""
    import pygltflib as g

    height, width = np.shape(arrays["base_color"])[:2]
    mesh = square(height, width)
    blob, views, accessors, attributes = b"", [], [], {}
    kinds = {1: g.SCALAR, 2: g.VEC2, 3: g.VEC3}
    for key in ("indices", "POSITION", "NORMAL", "TEXCOORD_0"):
        data = mesh[key]
        components = 1 if data.ndim == 1 else data.shape[1]
        raw = data.tobytes()
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(raw),
                                  target=g.ELEMENT_ARRAY_BUFFER if key == "indices" else g.ARRAY_BUFFER))
        accessor = g.Accessor(bufferView=len(views) - 1, count=int(data.shape[0]), type=kinds[components],
                              componentType=g.UNSIGNED_INT if key == "indices" else g.FLOAT)
        if key == "POSITION":  # required by the spec for positions
            accessor.min = [float(v) for v in data.min(axis=0)]
            accessor.max = [float(v) for v in data.max(axis=0)]
        accessors.append(accessor)
        attributes[key] = len(accessors) - 1
        blob += _pad4(raw)
    images = []
    for image in texture_images(arrays).values():
        raw = png(image)
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(raw)))  # images: no target
        images.append(g.Image(bufferView=len(views) - 1, mimeType="image/png"))
        blob += _pad4(raw)
    material = g.Material(
        name=name,
        pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=[1.0, 1.0, 1.0, 1.0], baseColorTexture=g.TextureInfo(index=0),
            metallicFactor=1.0, roughnessFactor=1.0, metallicRoughnessTexture=g.TextureInfo(index=1)),
        doubleSided=False,
        extras=dict(extras or {}),
    )
    asset = g.GLTF2(
        asset=g.Asset(version="2.0", generator="brdffit"),
        scene=0,
        scenes=[g.Scene(nodes=[0])],
        nodes=[g.Node(mesh=0, name=name)],
        meshes=[g.Mesh(name=f"{name} square", primitives=[g.Primitive(
            attributes=g.Attributes(POSITION=attributes["POSITION"], NORMAL=attributes["NORMAL"],
                                    TEXCOORD_0=attributes["TEXCOORD_0"]),
            indices=attributes["indices"], material=0, mode=g.TRIANGLES)])],
        materials=[material],
        textures=[g.Texture(sampler=0, source=0, name="base_color"),
                  g.Texture(sampler=0, source=1, name="metallic_roughness")],
        samplers=[g.Sampler(magFilter=NEAREST, minFilter=LINEAR_MIPMAP_LINEAR, wrapS=REPEAT, wrapT=REPEAT)],
        images=images,
        accessors=accessors,
        bufferViews=views,
        buffers=[g.Buffer(byteLength=len(blob))],
    )
    asset.set_binary_blob(blob)
    return asset


def gltf_bytes(arrays: Mapping[str, np.ndarray], name: str, binary: bool, extras: Mapping | None = None) -> bytes:
    """The whole file: ``.glb`` bytes (binary) or ``.gltf`` JSON with the buffer as a data URI."""
    import pygltflib as g

    asset = square_asset(arrays, name, extras)
    if binary:
        return b"".join(asset.save_to_bytes())
    asset.convert_buffers(g.BufferFormat.DATAURI)
    return asset.to_json(indent=2).encode()
