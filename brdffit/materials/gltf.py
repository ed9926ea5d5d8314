"""``.glb`` / ``.gltf`` (docs/materials.md#native-materials-and-exports): a ``gltf:*`` fit as a glTF 2.0 asset, a UV sphere carrying the material.

Written with pygltflib (the Khronos-listed Python library for glTF 2.0). The asset holds one scene,
one node, one mesh of one triangle primitive (POSITION, NORMAL, TEXCOORD_0, TANGENT, indices) and
one material: the object ``model.native(params)`` returns, i.e. the core metallic-roughness factors
and nothing else (no extension: every viewer shows the same BRDF). What brdffit knows about the fit
(model, data, loss, a conversion's error) goes into the material's ``extras``.

``.glb`` is the binary container (JSON chunk + one BIN chunk); ``.gltf`` is JSON with the buffer
embedded as a base64 data URI, so either is one self-contained file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from .._files import plain_text, strict_json
from ._record import fit_record, native_of
from .formats import Format

#: Rings and segments of the sphere: about 4k triangles, smooth in any viewer, 200 kB as .glb.
RINGS, SEGMENTS = 48, 96


def uv_sphere(rings: int = RINGS, segments: int = SEGMENTS) -> dict[str, np.ndarray]:
    """Unit sphere, +Y up (glTF's convention): float32 positions = normals (V, 3), texcoords (V, 2),
    tangents (V, 4) along increasing u, and uint32 triangle indices (T*3,), counter-clockwise seen
    from outside (glTF's front face). The seam column is doubled so u runs 0..1 without a wrap."""
    theta = np.linspace(0.0, math.pi, rings + 1)  # from +Y (north pole) down
    phi = np.linspace(0.0, 2.0 * math.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    normal = np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], -1).reshape(-1, 3)
    uv = np.stack([p / (2.0 * math.pi), t / math.pi], -1).reshape(-1, 2)
    tangent_xyz = np.stack([np.cos(p), np.zeros_like(p), -np.sin(p)], -1).reshape(-1, 3)
    tangent = np.concatenate([tangent_xyz, np.ones((tangent_xyz.shape[0], 1))], -1)
    cols = segments + 1
    tris = []
    for i in range(rings):
        for j in range(segments):
            a, b = i * cols + j, (i + 1) * cols + j
            c, d = a + 1, b + 1
            if i > 0:  # the pole rows' first triangle would be degenerate
                tris.append((a, b, c))
            if i < rings - 1:
                tris.append((c, b, d))
    return {
        "POSITION": normal.astype(np.float32),
        "NORMAL": normal.astype(np.float32),
        "TEXCOORD_0": uv.astype(np.float32),
        "TANGENT": tangent.astype(np.float32),
        "indices": np.asarray(tris, np.uint32).reshape(-1),
    }


def _pad4(b: bytes) -> bytes:
    return b + b"\0" * (-len(b) % 4)


def sphere_asset(material: Mapping, name: str, extras: Mapping | None = None):
    """The pygltflib ``GLTF2`` of a UV sphere carrying ``material`` (a glTF material object, as
    ``model.native`` returns it), its binary buffer set as the asset's blob."""
    import pygltflib as g

    name = plain_text(name)
    mesh = uv_sphere()
    blob, views, accessors = b"", [], []
    component = {np.float32: g.FLOAT, np.uint32: g.UNSIGNED_INT}
    kinds = {1: g.SCALAR, 2: g.VEC2, 3: g.VEC3, 4: g.VEC4}
    attributes = {}
    for key in ("indices", "POSITION", "NORMAL", "TEXCOORD_0", "TANGENT"):
        data = mesh[key]
        width = 1 if data.ndim == 1 else data.shape[1]
        raw = data.tobytes()
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(raw),
                                  target=g.ELEMENT_ARRAY_BUFFER if key == "indices" else g.ARRAY_BUFFER))
        accessor = g.Accessor(bufferView=len(views) - 1, componentType=component[data.dtype.type],
                              count=int(data.shape[0]), type=kinds[width])
        if key == "POSITION":  # required by the spec for positions
            accessor.min = [float(v) for v in data.min(axis=0)]
            accessor.max = [float(v) for v in data.max(axis=0)]
        accessors.append(accessor)
        attributes[key] = len(accessors) - 1
        blob += _pad4(raw)
    pbr = dict(material.get("pbrMetallicRoughness", {}))
    gltf_material = g.Material(
        name=name,
        pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=[float(v) for v in pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])],
            metallicFactor=float(pbr.get("metallicFactor", 1.0)),
            roughnessFactor=float(pbr.get("roughnessFactor", 1.0)),
        ),
        doubleSided=bool(material.get("doubleSided", False)),
        extras=strict_json(dict(extras or {})),  # strict JSON: a NaN metric is null, never a bare NaN
    )
    asset = g.GLTF2(
        asset=g.Asset(version="2.0", generator="brdffit"),
        scene=0,
        scenes=[g.Scene(nodes=[0])],
        nodes=[g.Node(mesh=0, name=name)],
        meshes=[g.Mesh(name=f"{name} sphere", primitives=[g.Primitive(
            attributes=g.Attributes(POSITION=attributes["POSITION"], NORMAL=attributes["NORMAL"],
                                    TEXCOORD_0=attributes["TEXCOORD_0"], TANGENT=attributes["TANGENT"]),
            indices=attributes["indices"], material=0, mode=g.TRIANGLES)])],
        materials=[gltf_material],
        accessors=accessors,
        bufferViews=views,
        buffers=[g.Buffer(byteLength=len(blob))],
    )
    asset.set_binary_blob(blob)
    return asset


def gltf_bytes(material: Mapping, name: str, binary: bool, extras: Mapping | None = None) -> bytes:
    """The whole file: ``.glb`` bytes (binary) or ``.gltf`` JSON with the buffer as a data URI."""
    import pygltflib as g

    asset = sphere_asset(material, name, extras)
    if binary:
        return b"".join(asset.save_to_bytes())
    asset.convert_buffers(g.BufferFormat.DATAURI)
    return asset.to_json(indent=2).encode()


def _describe(fit, ext: str) -> str:
    return f"a UV sphere with the material (glTF 2.0{' binary' if ext == '.glb' else ''})"


#: Every ``gltf:*`` model: ``model.native`` is a glTF material object.
FORMAT = Format("glTF 2.0", (".glb", ".gltf"),
                lambda fit, ext, bsdf_id: gltf_bytes(native_of(fit), bsdf_id, binary=ext == ".glb", extras=fit_record(fit)),
                _describe, target="gltf")
