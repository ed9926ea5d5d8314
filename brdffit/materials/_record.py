"""What a material file records of the fit it holds, one rule for every format (docs/materials.md#native-materials-and-exports): the line
that says what the fit is (an XML comment, a MaterialX doc string), the ``brdffit`` record of its
metrics and conversion (glTF ``extras``, a Blender custom property, a MaterialX attribute), and the
native dictionary the renderer loads."""

from __future__ import annotations

import numpy as np


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


def about(fit) -> str:
    """What the fit is, in one sentence: model, data, whether it converged, its conversion."""
    text = f"brdffit fit: {fit.model.name}"
    if fit.data_name:
        text += f" on {fit.data_name}"
    if fit.converged is False:
        text += " (the fit did not converge)"
    line = conversion_line(fit)
    return text + (f"; {line}" if line else "")


def native_of(fit, source=None) -> dict:
    """``fit.model.native(fit.params)``, or one ``InputError`` naming the parameter the renderer refuses."""
    from ..errors import InputError

    try:
        return fit.model.native(fit.params)
    except ValueError as exc:
        raise InputError(source, f"cannot export: {exc}") from None


def fit_record(fit) -> dict:
    """What a material file records of the fit (glTF ``extras``, a Blender custom property, a MaterialX
    attribute), as strict JSON: a converted fit's metrics are its error against the source fit, and
    are named so (``metrics_against_source_fit``; the source fit's own, against its data, are in
    ``converted_from.source_fit_metrics``)."""
    from .._files import strict_json

    record = {"model": fit.model.name, "data_name": fit.data_name, "loss": fit.loss, "converged": bool(fit.converged)}
    conversion = converted_from(fit)
    if conversion is None:
        record["metrics"] = dict(fit.metrics)
    else:
        record["metrics_against_source_fit"] = dict(fit.metrics)
        record["converted_from"] = conversion
    return {"brdffit": strict_json(record)}
