"""Fitted parameter maps (a per-texel BTF fit, SPEC 7) as a textured native material (SPEC 13).

``ParameterMaps.export(path)`` and ``brdffit export PARAMS.exr -o FILE`` write the maps of a native
model as the renderer's own material, each parameter map a texture, so that the BTF renders in
that renderer without brdffit. The extension picks the format, as for a single fit:

- ``.xml``: Mitsuba 3's own plugin (``roughconductor``, ``roughplastic``, ``principled``) whose
  parameters are ``bitmap`` textures, 32-bit float OpenEXR files in the folder ``<stem>_textures``
  beside the XML (:mod:`.textured_mitsuba`; what Mitsuba cannot take as a texture is said there);
- ``.glb`` / ``.gltf``: a textured square carrying a ``gltf:metallic_roughness`` material with
  ``baseColorTexture`` and ``metallicRoughnessTexture`` PNGs inside the file (:mod:`.textured_gltf`);
- ``.blend``: a textured square with Blender's Principled BSDF fed by image textures (float
  OpenEXR, packed into the file), written by Blender in the worker of :mod:`brdffit.cycles`
  (:mod:`.textured_blender`; needs ``.venv-blender``).

Texel layout, one for every format: texel (row r, column c) of the maps -- row 0 is the top row of
the BTF's images -- is pixel (r, c) of every texture image (row 0 at the top of the image, as image
files store it), and covers u in [c/W, (c+1)/W) and v in [r/H, (r+1)/H) in the texture coordinates
of Mitsuba's ``bitmap`` and of glTF, whose v runs down the image; Blender's v runs up the image
(v_Blender = 1 - v). The squares of the glTF and Blender files show the texture upright, seen from
their front (+z), texel (0, 0) at the top left. Textures are sampled at the nearest texel (Mitsuba
``filter_type`` nearest, glTF magnification NEAREST, Blender ``Closest``), as ``validate-btf``
renders the maps, and repeat beyond [0, 1].

A model the format does not hold (a ``mitsuba:*`` map in a .glb, a ``ggx`` map anywhere) is one
line (:class:`brdffit.errors.UsageError`): maps are not converted to another model here (the per-
texel conversion is a fit of every texel: fit the BTF with the target model instead), and a non-
native model's maps render in Mitsuba through ``brdffit.mitsuba_bsdf(maps.model, maps.params)``
(brdffit's own plugin, inside ``brdffit.evaluated_calls()``), which has no file form.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np

from ..errors import InputError, UsageError
from ._names import check_id

#: Extension -> the native models a textured file of that format holds.
FORMAT_MODELS = {".xml": ("mitsuba:roughconductor", "mitsuba:roughplastic", "mitsuba:principled"),
                 ".glb": ("gltf:metallic_roughness",), ".gltf": ("gltf:metallic_roughness",),
                 ".blend": ("blender:principled",)}


def textures_folder(path: str | os.PathLike) -> Path:
    """The folder beside a Mitsuba XML that holds its texture files: ``<stem>_textures``."""
    path = Path(path)
    return path.with_name(path.stem + "_textures")


def outputs(path: str | os.PathLike) -> list[Path]:
    """What an export to ``path`` writes: the file, and for ``.xml`` its textures folder first."""
    path = Path(path)
    return [textures_folder(path), path] if path.suffix.lower() == ".xml" else [path]


def checked_maps(maps, path: str | os.PathLike, source=None) -> tuple[str, object, dict[str, np.ndarray]]:
    """(extension, model, {parameter: (H, W, size) float64}) when ``maps`` can be written as ``path``;
    else one line: ``UsageError`` for a format that does not hold the model, ``InputError`` naming
    ``source`` (the params.exr, if any) for maps the renderer would refuse. Called before any work."""
    from .. import models

    ext = Path(path).suffix.lower()
    if ext not in FORMAT_MODELS:
        raise UsageError(f"{path}: unknown textured material format {ext or '(no extension)'!r}; parameter maps "
                         f"export as {', '.join(sorted(FORMAT_MODELS))}")
    model = models.get(maps.model)
    if not model.is_native:
        natives = ", ".join(dict.fromkeys(m for held in FORMAT_MODELS.values() for m in held))
        raise UsageError(f"{path}: {model.name} is not a native model, so its maps have no material file: fit the "
                         f"BTF with a native model ({natives}); brdffit.mitsuba_bsdf(maps.model, maps.params) "
                         "renders these in Mitsuba, inside brdffit.evaluated_calls()")
    if model.name not in FORMAT_MODELS[ext]:
        formats = [e for e, held in FORMAT_MODELS.items() if model.name in held]
        raise UsageError(f"{path}: a textured {ext} file holds {' or '.join(FORMAT_MODELS[ext])} maps, and these are "
                         f"{model.name} maps: export them as {' or '.join(formats)} (maps are not converted)")
    shape = tuple(maps.shape)
    arrays = {}
    for p in model.params:
        if p.name not in maps.params:
            raise InputError(source, f"no map for parameter {p.name!r} of {model.name}")
        a = np.asarray(maps.params[p.name], np.float64)
        size = model.size(p)
        if a.shape == shape:
            a = a[..., None]
        if a.shape != (*shape, size):
            raise InputError(source, f"map {p.name!r} has shape {a.shape}, expected {(*shape, size)}")
        # compared in float32, the precision of params.exr and of the textures
        v, lo, hi = a.astype(np.float32), np.float32(p.lower), np.float32(p.upper)
        bad = ~np.isfinite(v) | (v < lo) | (v > hi)
        if bad.any():
            r, c, _ = np.argwhere(bad)[0]
            raise InputError(source, f"cannot export: map {p.name!r} at texel (row {r}, column {c}) is {a[r, c].tolist()}, "
                                     f"outside [{p.lower:g}, {p.upper:g}], the range the renderer accepts")
        arrays[p.name] = a
    return ext, model, arrays


def extras(maps, model) -> dict:
    """What the files record about the maps (XML comment, glTF ``extras``, a Blender custom property)."""
    from .._files import strict_json

    h, w = maps.shape
    return strict_json({"brdffit": {"model": model.name, "texels": [int(h), int(w)], "loss": maps.loss_name,
                                    "converged_share": float(np.mean(maps.converged)) if np.size(maps.converged) else 0.0,
                                    "source": str(maps.info.get("file", "")) if isinstance(maps.info, dict) else ""}})


def export_maps(maps, path: str | os.PathLike, *, bsdf_id: str | None = None, force: bool = False,
                source=None) -> list[Path]:
    """Write ``maps`` as the textured material file ``path`` (see the module docstring); returns the
    paths written (for ``.xml``: the textures folder, then the XML). Everything is checked before any
    work; each output is written atomically, the XML last, so that its presence means a complete
    result; an existing output is replaced only with ``force``."""
    from .._files import atomic_dir, atomic_file, reserve

    ext, model, arrays = checked_maps(maps, path, source)
    if bsdf_id is None:
        from . import default_id

        bsdf_id = default_id(path)
    bsdf_id = check_id(bsdf_id)  # the single-fit export's rule
    if ext == ".xml":
        from .textured_mitsuba import plan

        native = plan(model, arrays, textures_folder(path).name, source)  # what Mitsuba cannot take: refused here
    targets = outputs(path)
    about = extras(maps, model)
    with contextlib.ExitStack() as held:
        for target in targets:  # checked and held, both, before any work
            held.enter_context(reserve(target, force=force, folder=target != Path(path)))
        if ext == ".xml":
            from .textured_mitsuba import write_textures, xml_text

            with atomic_dir(textures_folder(path), force=force) as tmp:
                write_textures(native, arrays, Path(tmp))
            text = xml_text(native, bsdf_id, model, about)
            with atomic_file(path, force=force, suffix=".xml") as tmp:
                Path(tmp).write_text(text, encoding="utf-8")
        elif ext == ".blend":
            from .textured_blender import blend_bytes

            data = blend_bytes(model, arrays, bsdf_id, about)
            with atomic_file(path, force=force, suffix=".blend") as tmp:
                Path(tmp).write_bytes(data)
        else:
            from .textured_gltf import gltf_bytes

            data = gltf_bytes(arrays, bsdf_id, binary=ext == ".glb", extras=about)
            with atomic_file(path, force=force, suffix=ext) as tmp:
                Path(tmp).write_bytes(data)
    return targets
