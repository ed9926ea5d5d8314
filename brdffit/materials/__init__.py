"""A fit as a material other programs load (SPEC 8, 13): conversion to a native model, export.

- :func:`convert` fits a target model (a native one: ``mitsuba:*``, ``gltf:*``) to a fit's own
  BRDF on the UBO-81 grid and records the conversion error.
- :func:`export` writes a fit as a file whose extension picks the format: ``.xml`` a Mitsuba 3
  scene-XML fragment (the renderer's own plugin for a ``mitsuba:*`` fit, the ``brdffit`` plugin of
  SPEC 8 otherwise), ``.glb`` / ``.gltf`` a UV sphere carrying a ``gltf:*`` material, ``.blend`` a
  sphere with a ``blender:principled`` material (written by Blender in the worker of
  :mod:`brdffit.cycles`; needs ``.venv-blender``), ``.mtlx`` a MaterialX 1.39 document (``gltf_pbr``
  for a glTF fit, ``open_pbr_surface`` for a Blender fit).

``FitResult.convert`` / ``FitResult.export`` and ``brdffit export FIT.json [--to MODEL] -o FILE`` are
thin surfaces over these two functions.
"""

from __future__ import annotations

import dataclasses
import os
import re
from pathlib import Path

import numpy as np

from ..errors import UsageError

#: File extension -> what it holds.
FORMATS = {".xml": "Mitsuba 3 scene XML", ".glb": "glTF 2.0 binary", ".gltf": "glTF 2.0",
           ".blend": "Blender", ".mtlx": "MaterialX 1.39"}
#: The native models a format that needs one holds (the first is the one to convert to).
FORMAT_MODELS = {".glb": ("gltf:metallic_roughness",), ".gltf": ("gltf:metallic_roughness",),
                 ".blend": ("blender:principled",),
                 ".mtlx": ("gltf:metallic_roughness", "blender:principled")}


def convert(fit, model, *, loss: str | None = None, **fit_options):
    """``fit`` converted to ``model``: ``model`` fitted to the fit's own BRDF on the UBO-81 grid
    (every pair weighted 1, the fit's own loss unless ``loss`` is given), through the same
    ``brdffit.fit`` as any measurement. The returned FitResult's ``options["converted_from"]`` holds
    the source model and the conversion error: ``rel_rmse`` and ``log_rmse`` of the converted BRDF
    against the source fit's on that grid (SPEC 5's definitions)."""
    from .. import models
    from ..fitting.api import fit as run_fit
    from .._fit_defaults import LOSSES
    from ..grid import ubo_pairs
    from ..measurement import Measurement

    try:
        target = models.get(model)
    except KeyError as exc:
        raise UsageError(f"--to {model}: {exc.args[0] if exc.args else exc}") from None
    if target.name == fit.model.name:
        return fit
    wi, wo = ubo_pairs()
    values = np.asarray(fit.eval(wi, wo), np.float64)
    source = f"{fit.data_name} ({fit.model.name} fit)" if fit.data_name else f"{fit.model.name} fit"
    table = Measurement(wi, wo, values, name=source, source=f"brdffit fit of {fit.model.name}", grid="ubo81")
    if loss is None:
        loss = fit.loss if fit.loss in LOSSES else "log"
    converted = run_fit(table, target, loss=loss, **fit_options)
    error = {
        "model": fit.model.name,
        "data_name": fit.data_name,
        "grid": "ubo81",
        "loss": loss,
        "rel_rmse": float(converted.metrics.get("rel_rmse", float("nan"))),
        "log_rmse": float(converted.metrics.get("log_rmse", float("nan"))),
    }
    return dataclasses.replace(converted, data_name=fit.data_name or source,
                               options={**converted.options, "converted_from": error})


def conversion_line(fit) -> str | None:
    """One line naming the conversion error of a converted fit, None for a fit that was not converted."""
    c = fit.options.get("converted_from") if isinstance(fit.options, dict) else None
    if not c:
        return None
    return (f"converted {c.get('model')} -> {fit.model.name}: rel_rmse {c.get('rel_rmse', float('nan')):.4g}, "
            f"log_rmse {c.get('log_rmse', float('nan')):.4g} against the {c.get('model')} fit on the UBO-81 grid")


def _about(fit) -> str:
    about = f"brdffit fit: {fit.model.name}"
    if fit.data_name:
        about += f" on {fit.data_name}"
    if fit.converged is False:
        about += " (the fit did not converge)"
    line = conversion_line(fit)
    return about + (f"; {line}" if line else "")


def check_format(fit, path: str | os.PathLike, to: str | None = None, source=None) -> str:
    """The extension of ``path`` if it can hold ``fit`` (converted to ``to`` when given); else one
    ``UsageError`` line that says what would work. Called before any work. ``source`` (the fit
    file, if any) is the file an error about the fit's parameters names."""
    ext = Path(path).suffix.lower()
    if ext not in FORMATS:
        raise UsageError(f"{path}: unknown material format {ext or '(no extension)'!r}; "
                         f"use one of {', '.join(sorted(FORMATS))}")
    needed = FORMAT_MODELS.get(ext)
    name = to if to is not None else fit.model.name
    if needed is not None and "".join(str(name).split()).lower() not in needed:
        held = " or ".join(needed)
        raise UsageError(f"{path}: a {FORMATS[ext]} file holds a {held} material, and this fit is "
                         f"{name}: convert it with --to {needed[0]} (FitResult.export(path, to={needed[0]!r}))")
    if to is None and fit.model.is_native:
        native_of(fit, source)  # parameters outside what the renderer accepts: refused before any work
    return ext


def native_of(fit, source=None) -> dict:
    """``fit.model.native(fit.params)``, or one ``InputError`` naming the parameter the renderer refuses."""
    from ..errors import InputError

    try:
        return fit.model.native(fit.params)
    except ValueError as exc:
        raise InputError(source, f"cannot export: {exc}") from None


def material_bytes(fit, ext: str, bsdf_id: str) -> bytes:
    """The contents of a material file of format ``ext`` for ``fit`` (checked by :func:`check_format`)."""
    if ext == ".xml":
        if fit.model.target == "mitsuba":
            from .mitsuba_xml import native_xml

            native = native_of(fit)
            comment = (_about(fit) + f". {fit.model.citation}. Mitsuba 3's own {native['type']}"
                       " plugin: loads in any Mitsuba 3 (no brdffit needed); include it with"
                       f' <include filename="THIS FILE"/> and refer to it with <ref id="{bsdf_id}"/>.')
            return native_xml(native, bsdf_id, comment).encode()
        from ..render.export import bsdf_xml

        text = bsdf_xml(fit, bsdf_id=bsdf_id)
        line = conversion_line(fit)
        if line:
            text = text.replace("<scene", f"<!-- {line.replace('--', '- -')} -->\n<scene", 1)
        return text.encode()
    extras = {"brdffit": {"model": fit.model.name, "data_name": fit.data_name, "loss": fit.loss,
                          "converged": bool(fit.converged), "metrics": dict(fit.metrics),
                          **({"converted_from": fit.options["converted_from"]}
                             if isinstance(fit.options, dict) and "converted_from" in fit.options else {})}}
    if ext == ".blend":
        from .blender import blend_bytes

        return blend_bytes(native_of(fit), bsdf_id, extras)
    if ext == ".mtlx":
        from .materialx import mtlx_text

        return mtlx_text(fit.model.name, native_of(fit), bsdf_id, extras).encode()
    from .gltf import gltf_bytes

    return gltf_bytes(native_of(fit), bsdf_id, binary=ext == ".glb", extras=extras)


def default_id(path: str | os.PathLike) -> str:
    """A Mitsuba-safe id from a file name (letters, digits, '_')."""
    return re.sub(r"[^A-Za-z0-9_]", "_", Path(path).stem) or "brdffit"


def export(fit, path: str | os.PathLike, *, to: str | None = None, bsdf_id: str | None = None,
           force: bool = False, **convert_options):
    """Write ``fit`` (converted to ``to`` first when given) as the material file ``path``, the
    extension choosing the format (see the module docstring); atomically, replacing an existing file
    only with ``force``. Returns the fit written (the converted one with ``to``)."""
    from .._files import atomic_file, check_target

    ext = check_format(fit, path, to)
    check_target(path, force, folder=False)  # before the work: nothing is written on bad usage
    if to is not None:
        fit = convert(fit, to, **convert_options)
    if bsdf_id is None:
        bsdf_id = default_id(path)
    data = material_bytes(fit, ext, bsdf_id)
    with atomic_file(path, force=force) as tmp:
        tmp.write_bytes(data)
    return fit
