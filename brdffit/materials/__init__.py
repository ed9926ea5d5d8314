"""A fit as a material other programs load (docs/materials.md#a-fit-in-any-mitsuba-scene and docs/materials.md#native-materials-and-exports): conversion to a native model, export.

- :func:`convert` fits a target model (a native one: ``mitsuba:*``, ``gltf:*``, ``blender:*``) to a
  fit's own BRDF on the UBO-81 grid and records the conversion error.
- :func:`export` writes a fit as a file whose extension picks the format. The formats are modules
  of this package, each declaring its extensions, the models it holds and its writer
  (:mod:`.formats`, the registry): ``.xml`` a Mitsuba 3 scene-XML fragment (:mod:`.mitsuba_xml`: the
  renderer's own plugin for a ``mitsuba:*`` fit, the ``brdffit`` plugin of docs/materials.md#a-fit-in-any-mitsuba-scene otherwise),
  ``.glb`` / ``.gltf`` a UV sphere carrying a ``gltf:*`` material (:mod:`.gltf`), ``.blend`` a sphere
  with a ``blender:*`` material, written by Blender in the worker of :mod:`brdffit.cycles`
  (:mod:`.blender`; needs ``.venv-blender``), ``.mtlx`` a MaterialX 1.39 document (:mod:`.materialx`:
  ``gltf_pbr`` for a glTF fit, ``open_pbr_surface`` for a Blender fit). A BTF's parameter maps
  export as textured materials of the same formats (:mod:`.textured`).

``FitResult.convert`` / ``FitResult.export``, ``brdffit export FIT.json [--to MODEL] -o FILE`` and the
explorer's Export are thin surfaces over these two functions. A conversion runs the fit driver (the
engine, below this layer) rather than ``brdffit.fit``, which stands above it with FitResult.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from ..errors import UsageError
from . import formats
from ._names import check_id, default_id, safe_id
from ._record import conversion_line, converted_from, native_of

__all__ = ["check_format", "check_id", "conversion_line", "convert", "converted_from", "default_id", "describe",
           "export", "formats", "material_bytes", "native_of", "safe_id"]

#: Metrics relative to the reference (docs/fitting.md#fitting): not a number against a reference that is 0 everywhere.
RELATIVE_METRICS = ("rel_rmse", "mean_rel_error")


def convert(fit, model, *, loss: str | None = None, **fit_options):
    """``fit`` converted to ``model``: ``model`` fitted to the fit's own BRDF on the UBO-81 grid
    (every pair weighted 1, the fit's own loss unless ``loss`` is given), through the same
    ``brdffit.fit`` as any measurement. The returned FitResult's ``options["converted_from"]`` holds
    the source model and the conversion error: ``rel_rmse`` and ``log_rmse`` of the converted BRDF
    against the source fit's on that grid (docs/fitting.md#fitting's definitions)."""
    from .._fit_defaults import LOSSES
    from ..fitting.measurements import fit_measurements
    from ..fitting.options import FitOptions
    from ..grid import ubo_pairs
    from ..measurement import Measurement

    target = _target(model)
    if target.name == fit.model.name:
        return fit
    wi, wo = ubo_pairs()
    values = np.asarray(fit.eval(wi, wo), np.float64)
    source = f"{fit.data_name} ({fit.model.name} fit)" if fit.data_name else f"{fit.model.name} fit"
    table = Measurement(wi, wo, values, name=source, source=f"brdffit fit of {fit.model.name}", grid="ubo81")
    if loss is None:
        loss = fit.loss if fit.loss in LOSSES else "log"
    # The fit driver itself (the engine below this layer, like ``brdffit.fit``), making a result of
    # the source fit's own type: FitResult's ``convert`` and ``export`` call this module.
    try:
        options = FitOptions(loss=loss, **fit_options)
    except TypeError as exc:
        raise UsageError(f"convert: {' '.join(str(exc).split())}") from None
    converted, = fit_measurements([table], target, options, result_type=type(fit))
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


def _target(model):
    """The model a conversion asks for (``--to``), or one UsageError line naming it."""
    from .. import models

    try:
        return models.get(model)
    except KeyError as exc:
        raise UsageError(f"--to {model}: {exc.args[0] if exc.args else exc}") from None


def check_format(fit, path: str | os.PathLike, to: str | None = None, source=None) -> str:
    """The extension of ``path`` if its format (:mod:`.formats`) holds ``fit`` (converted to ``to``
    when given); else one ``UsageError`` line that says what would work. Called before any work.
    ``source`` (the fit file, if any) is the file an error about the fit's parameters names."""
    fmt = formats.for_path(path)
    # an unknown --to is named as such first (the format's refusal would call it the fit's model)
    name = _target(to).name if to is not None else fit.model.name
    if not fmt.holds("".join(str(name).split()).lower()):
        held = fmt.held()
        what = f"not {name} (--to)" if to is not None else f"and this fit is {name}"
        raise UsageError(f"{path}: a {fmt.name} file holds a {' or '.join(held)} material, {what}: convert it with "
                         f"--to {held[0]} (brdffit.materials.export(fit, path, to={held[0]!r}))")
    if to is None and fit.model.is_native:
        native_of(fit, source)  # parameters outside what the renderer accepts: refused before any work
    return Path(path).suffix.lower()


def material_bytes(fit, ext: str, bsdf_id: str) -> bytes:
    """The contents of a material file of format ``ext`` for ``fit`` (checked by :func:`check_format`),
    the material called ``bsdf_id`` (:func:`check_id`)."""
    return formats.of_extension(ext).write(fit, ext, check_id(bsdf_id))


def describe(fit, ext: str) -> str:
    """What a material file of format ``ext`` holds for ``fit``, for the line that says it was written."""
    return formats.of_extension(ext).describe(fit, ext)


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
