"""Fitted parameter maps (a per-texel BTF fit, docs/btf.md#btfs-per-texel-fitting) as a textured native material (docs/materials.md#native-materials-and-exports).

``ParameterMaps.export(path)`` and ``brdffit export PARAMS.exr -o FILE`` write the maps of a native
model as the renderer's own material, each parameter map a texture, so that the BTF renders in
that renderer without brdffit. The extension picks the format, as for a single fit: a module of
this package that declares ``MAPS_FORMAT`` (:class:`brdffit.materials.formats.MapsFormat`: its
extensions, the models whose maps it holds, its writer):

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
from . import formats
from ._names import check_id, default_id
from .textures import textures_folder


def outputs(path: str | os.PathLike) -> list[Path]:
    """What an export to ``path`` writes: the file, and before it the folder of its textures where
    its format writes texture files beside it."""
    path = Path(path)
    return [textures_folder(path), path] if formats.for_path(path, maps=True).textures else [path]


def checked_maps(maps, path: str | os.PathLike, source=None) -> tuple[formats.MapsFormat, object, dict[str, np.ndarray]]:
    """(format, model, {parameter: (H, W, size) float64}) when ``maps`` can be written as ``path``;
    else one line: ``UsageError`` for a format that does not hold the model, ``InputError`` naming
    ``source`` (the params.exr, if any) for maps the renderer would refuse. Called before any work."""
    from .. import models

    fmt = formats.for_path(path, maps=True)
    ext = Path(path).suffix.lower()
    model = models.get(maps.model)
    if not model.is_native:
        natives = ", ".join(dict.fromkeys(m for f in formats.formats(maps=True) for m in f.held()))
        raise UsageError(f"{path}: {model.name} is not a native model, so its maps have no material file: fit the "
                         f"BTF with a native model ({natives}); brdffit.mitsuba_bsdf(maps.model, maps.params) "
                         "renders these in Mitsuba, inside brdffit.evaluated_calls()")
    if not fmt.holds(model.name):
        usable = [e for f in formats.formats(maps=True) if f.holds(model.name) for e in f.extensions]
        raise UsageError(f"{path}: a textured {ext} file holds {' or '.join(fmt.held())} maps, and these are "
                         f"{model.name} maps: export them as {' or '.join(usable)} (maps are not converted)")
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
    return fmt, model, arrays


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
    paths written (the textures folder first where there is one, then the file). Everything is
    checked before any work; each output is written atomically, the file last, so that its presence
    means a complete result; an existing output is replaced only with ``force``."""
    from .._files import atomic_dir, atomic_file, reserve

    path = Path(path)
    fmt, model, arrays = checked_maps(maps, path, source)
    bsdf_id = check_id(default_id(path) if bsdf_id is None else bsdf_id)  # the single-fit export's rule
    plan = fmt.plan(model, arrays, path, source) if fmt.plan else None  # what the renderer refuses: here
    job = formats.MapsJob(model, arrays, path, bsdf_id, extras(maps, model), plan)
    targets = outputs(path)
    with contextlib.ExitStack() as held:
        for target in targets:  # checked and held, all, before any work
            held.enter_context(reserve(target, force=force, folder=target != path))
        if fmt.textures:
            with atomic_dir(textures_folder(path), force=force) as tmp:
                fmt.textures(job, Path(tmp))
        data = fmt.write(job)
        with atomic_file(path, force=force, suffix=path.suffix.lower()) as tmp:
            Path(tmp).write_bytes(data)
    return targets
