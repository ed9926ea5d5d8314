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
from pathlib import Path

import numpy as np

from ..errors import UsageError
from ._names import check_id, safe_id

#: Metrics relative to the reference (SPEC 5): not a number against a reference that is 0 everywhere.
RELATIVE_METRICS = ("rel_rmse", "mean_rel_error")

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
    metrics = dict(converted.metrics)
    if not np.sum(values**2) > 1e-300:  # the fitting's floor of a relative metric's denominator
        # a source fit that is zero everywhere: an error relative to it is not a number (it was 1e150)
        metrics.update({k: float("nan") for k in RELATIVE_METRICS if k in metrics})
    error = {
        "model": fit.model.name,
        "data_name": fit.data_name,
        "grid": "ubo81",
        "loss": loss,
        "rel_rmse": float(metrics.get("rel_rmse", float("nan"))),
        "log_rmse": float(metrics.get("log_rmse", float("nan"))),
        "source_fit_metrics": dict(fit.metrics),  # how well the source fit met its data
    }
    return dataclasses.replace(converted, metrics=metrics, data_name=fit.data_name or source,
                               options={**converted.options, "converted_from": error})


def converted_from(fit) -> dict | None:
    """What a converted fit records of its conversion (``options["converted_from"]``), else None."""
    c = fit.options.get("converted_from") if isinstance(fit.options, dict) else None
    return c if isinstance(c, dict) and c else None


def _value(x) -> str:
    x = float("nan") if x is None else float(x)
    return f"{x:.4g}" if np.isfinite(x) else "undefined"


def conversion_line(fit) -> str | None:
    """One line naming the conversion error of a converted fit, None for a fit that was not converted."""
    c = converted_from(fit)
    if c is None:
        return None
    line = (f"converted {c.get('model')} -> {fit.model.name}: rel_rmse {_value(c.get('rel_rmse'))}, "
            f"log_rmse {_value(c.get('log_rmse'))} against the {c.get('model')} fit on the UBO-81 grid")
    if _value(c.get("rel_rmse")) == "undefined":
        line += f" (rel_rmse is relative to the {c.get('model')} fit, which is 0 everywhere)"
    return line


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


def _extras(fit) -> dict:
    """What a material file records of the fit (glTF ``extras``, a Blender custom property, a MaterialX
    attribute), as strict JSON: a converted fit's metrics are its error against the source fit, and
    are named so (``metrics_against_source_fit``; the source fit's own, against its data, are in
    ``converted_from.source_fit_metrics``)."""
    from .._files import strict_json

    about = {"model": fit.model.name, "data_name": fit.data_name, "loss": fit.loss, "converged": bool(fit.converged)}
    conversion = converted_from(fit)
    if conversion is None:
        about["metrics"] = dict(fit.metrics)
    else:
        about["metrics_against_source_fit"] = dict(fit.metrics)
        about["converted_from"] = conversion
    return {"brdffit": strict_json(about)}


def material_bytes(fit, ext: str, bsdf_id: str) -> bytes:
    """The contents of a material file of format ``ext`` for ``fit`` (checked by :func:`check_format`),
    the material called ``bsdf_id`` (:func:`check_id`)."""
    bsdf_id = check_id(bsdf_id)
    if ext == ".xml":
        from .mitsuba_xml import native_xml, plugin_dict

        if fit.model.target == "mitsuba":
            native = native_of(fit)
            how = (f"Mitsuba 3's own {native['type']} plugin: loads in any Mitsuba 3 (no brdffit needed); include"
                   f' it with <include filename="THIS FILE"/> and refer to it with <ref id="{bsdf_id}"/>.')
        else:
            native = plugin_dict(fit)
            how = ("Load it with `import brdffit; brdffit.register_mitsuba()` (after mi.set_variant), include it"
                   f' with <include filename="THIS FILE"/> and refer to it with <ref id="{bsdf_id}"/>;'
                   " render it like any scene.")
        return native_xml(native, bsdf_id, f"{_about(fit)}. {fit.model.citation}. {how}").encode()
    if ext == ".blend":
        from .blender import blend_bytes

        return blend_bytes(native_of(fit), bsdf_id, _extras(fit))
    if ext == ".mtlx":
        from .materialx import mtlx_text

        return mtlx_text(fit.model.name, native_of(fit), bsdf_id, _extras(fit)).encode()
    from .gltf import gltf_bytes

    return gltf_bytes(native_of(fit), bsdf_id, binary=ext == ".glb", extras=_extras(fit))


def describe(fit, ext: str) -> str:
    """What a material file of format ``ext`` holds for ``fit``, for the line that says it was written."""
    if ext == ".xml":
        return f"Mitsuba's own {fit.model.native(fit.params)['type']} plugin" if fit.model.target == "mitsuba" \
            else '<bsdf type="brdffit">'
    if ext == ".mtlx":
        from .materialx import SHADERS

        return f"a MaterialX 1.39 {SHADERS.get(fit.model.name, 'surface')} material"
    return f"a UV sphere with the material ({FORMATS[ext]})"


def default_id(path: str | os.PathLike) -> str:
    """The material id of an export to ``path`` when none is given: its file name made safe."""
    return safe_id(Path(path).stem)


def export(fit, path: str | os.PathLike, *, to: str | None = None, bsdf_id: str | None = None,
           force: bool = False, **convert_options):
    """Write ``fit`` (converted to ``to`` first when given) as the material file ``path``, the
    extension choosing the format (see the module docstring), the material called ``bsdf_id``
    (checked as the CLI's ``--id``; default: :func:`default_id`); atomically, replacing an existing
    file only with ``force``. The output is taken (checked, locked against other runs) before the
    conversion: of several runs writing it at once one proceeds, the others raise UsageError.
    Returns the fit written (the converted one with ``to``)."""
    from .._files import atomic_file, reserve

    ext = check_format(fit, path, to)
    bsdf_id = default_id(path) if bsdf_id is None else check_id(bsdf_id)
    with reserve(path, force, folder=False):  # before the work: nothing is written on bad usage
        if to is not None:
            fit = convert(fit, to, **convert_options)
        data = material_bytes(fit, ext, bsdf_id)
        with atomic_file(path, force=force) as tmp:
            tmp.write_bytes(data)
    return fit
