"""Parameter maps of ``blender:principled`` as a .blend file: a textured square, written by Blender
itself in the worker process (:mod:`brdffit.cycles`; needs ``.venv-blender``, else one line).

Every parameter map is an image texture feeding the Principled BSDF input of that parameter (the
sockets of :data:`SOCKETS`; ``specular_tint``, one grey value, as the colour (t, t, t), as
``model.native`` writes it). The textures are 32-bit float OpenEXR files that brdffit writes into a
temporary folder and Blender packs into the .blend, so the file is self-contained. Base Color is read
as Linear Rec.709 (brdffit's colours are linear Rec.709), the other maps as Non-Color data (no
transform); a one-channel map reaches its input through a Separate Color node's red channel, which is
exact (a colour linked to a float input goes through the luminance). Interpolation ``Closest`` (one
texel per texel, as ``validate-btf`` renders the maps), extension Repeat. The distribution (GGX) and
the inputs that are no parameters (Specular IOR Level, the switched-off layers) are what
``model.native`` writes.

The file holds the square (the maps' aspect, the longer side 2 units, facing +z; texel (0, 0) at its
top left: Blender's texture v runs up the image), an orthographic camera looking down on it at one
pixel per texel, a sun and Cycles as the render engine; the material's custom property ``brdffit``
holds the maps' ``extras`` as JSON text.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .._files import scratch
from .formats import MapsFormat

#: Parameter of ``blender:principled`` -> the Principled BSDF input its map feeds.
SOCKETS = {"base_color": "Base Color", "metallic": "Metallic", "roughness": "Roughness", "ior": "IOR",
           "specular_tint": "Specular Tint"}
#: Inputs that take a colour (a one-channel map is repeated over R, G, B).
COLOUR_SOCKETS = ("Base Color", "Specular Tint")


def blend_bytes(model, arrays: dict[str, np.ndarray], name: str, extras: dict) -> bytes:
    """The contents of the .blend file of ``arrays`` (the maps of ``model``, blender:principled)."""
    from .. import cycles
    from .textures import write_exr

    if set(SOCKETS) != set(model.param_names):  # the table above follows the model's parameters
        raise RuntimeError(f"{model.name}: parameters {model.param_names} differ from the sockets table {list(SOCKETS)}")
    json.dumps(extras)  # what cannot be stored fails here, before Blender runs
    height, width = next(iter(arrays.values())).shape[:2]
    means = {p.name: np.clip(arrays[p.name].mean(axis=(0, 1)), p.lower, p.upper) for p in model.params}
    with scratch("brdffit-maps-") as tmp:
        textures = {}
        for param, socket in SOCKETS.items():
            a = arrays[param]
            colour = socket in COLOUR_SOCKETS
            file = Path(tmp) / f"{param}.exr"
            write_exr(file, np.repeat(a, 3, axis=-1) if colour and a.shape[-1] == 1 else a)
            textures[socket] = {"path": str(file), "name": f"{name}_{param}", "data": param != "base_color",
                                "scalar": not colour}
        return cycles.blend_maps_file(model.native(means), textures, str(name), extras, width, height)


#: The Principled BSDF: :data:`SOCKETS` names the inputs the maps feed.
MAPS_FORMAT = MapsFormat("Blender", (".blend",), lambda job: blend_bytes(job.model, job.arrays, job.bsdf_id, job.extras),
                         models=("blender:principled",), note="needs .venv-blender")
