"""A fit.json is input like any other (docs/cli.md#the-command-line-and-set-up): checked completely before it is used.

:func:`parse_fit_text` turns the file's text into a document or one ``InputError`` line (a text
that is not Unicode, a lone surrogate in any string, included); :func:`check_fit_document`
verifies every field :class:`~brdffit.fitting.result.FitResult` reads (types, sizes, finite
parameters inside the model's own bounds, and inside the bounds the file records when it does:
a record can only narrow what is accepted, never widen it) and returns the model. Fields it does
not know are accepted (newer writers add some). A number that a fit may not have (a metric of a
diverged fit, its loss) may be null: strict JSON has no NaN (``FitResult.to_json`` writes null).
"""

from __future__ import annotations

import json
import math
from numbers import Real
from typing import Any

import numpy as np

from .._fit_defaults import STATUS_TEXT
from ..errors import InputError

#: optional fields and the type each must have when present (JSON types, bool is not an int here)
_SCALARS: dict[str, tuple[type, ...]] = {
    "format": (str,),
    "loss": (str,),
    "status": (str,),
    "solver": (str,),
    "data_name": (str,),
    "citation": (str,),
    "converged": (bool,),
    "loss_value": (int, float, type(None)),
}
_COUNTS = ("steps", "n_used", "n_excluded")
_FLOAT_MAPS = ("metrics", "seconds")
#: what a converted fit records (``options.converted_from``, ``brdffit.materials.convert``) and the
#: JSON type each field must have
_CONVERSION_TEXT = ("model", "data_name", "grid", "loss")
_CONVERSION_NUMBERS = ("rel_rmse", "log_rmse")
#: metric names read under today's name: the relative RMSE is ``rel_rmse`` everywhere (docs/fitting.md#fitting and docs/materials.md#native-materials-and-exports);
#: the image metrics called it ``relative_rmse`` before
METRIC_ALIASES = {"relative_rmse": "rel_rmse"}
#: relative slack on recorded bounds: values are written with full precision, this only absorbs
#: the float32 round trip of a bound that some writer stored
_SLACK = 1e-9


def parse_fit_text(text: str | bytes, path=None) -> dict[str, Any]:
    """The JSON object of a fit file, or ``InputError(path, "not a fit file (JSON): ...")``."""
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(path, "not a fit file (JSON): binary data, not UTF-8 text") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not a fit file (JSON): {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:
        raise InputError(path, "not a fit file (JSON): nested too deeply") from None
    if not isinstance(doc, dict):
        raise InputError(path, f"not a fit file: the JSON holds a {type(doc).__name__}, not an object")
    try:
        where = _lone_surrogate(doc, None)
    except RecursionError:
        raise InputError(path, "not a fit file (JSON): nested too deeply") from None
    if where is not None:
        raise InputError(path, f"{where} holds a lone surrogate (an escape such as \\ud800 that is not Unicode text)")
    return doc


def _encodable(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _lone_surrogate(value, where: str | None) -> str | None:
    """Where in a JSON document a string holds a lone surrogate (JSON's escapes allow one, UTF-8
    cannot encode it: every file written from it would fail); None if nowhere."""
    if isinstance(value, str):
        return None if _encodable(value) else where
    if isinstance(value, dict):
        for k, v in value.items():
            if not _encodable(k):
                return f"a key of {where or 'the file'}"
            found = _lone_surrogate(v, f"field {k!r}" if where is None else f"{where}.{k}")
            if found:
                return found
    elif isinstance(value, list):
        for i, v in enumerate(value):
            found = _lone_surrogate(v, f"{where}[{i}]")
            if found:
                return found
    return None


def _is_number(x) -> bool:
    return isinstance(x, Real) and not isinstance(x, bool)


def _number_or_null(x) -> bool:
    return x is None or _is_number(x)


def _check_at_bound(value, path, model) -> None:
    """``at_bound``: parameter name -> text ("lower", "upper in channel 0", as ``ParameterSpace.at_bound``
    writes it) or per-channel flags (a list of booleans, as files of earlier writers may hold)."""
    def entry_ok(v) -> bool:
        return isinstance(v, str) or (isinstance(v, list) and 0 < len(v) <= model.channels
                                      and all(isinstance(x, bool) for x in v))

    if not isinstance(value, dict) or not all(entry_ok(v) for v in value.values()):
        raise InputError(path, "field 'at_bound' must be an object parameter -> text (e.g. \"lower\")")
    unknown = [k for k in value if k not in model.param_names]
    if unknown:
        raise InputError(path, f"field 'at_bound' names {unknown[0]!r}, not a parameter of the model")


def _number_list(value, what: str, path, allow_null: bool = False) -> list[float]:
    items = value if isinstance(value, list) else [value]
    out = []
    for x in items:
        if x is None and allow_null:
            out.append(math.nan)
        elif _is_number(x):
            out.append(float(x))
        else:
            raise InputError(path, f"{what} must be a number or a list of numbers, got {json.dumps(x)[:60]}")
    if not out:
        raise InputError(path, f"{what} is an empty list")
    return out


def check_fit_document(d: dict[str, Any], path=None):
    """Verify a fit document; return its model (channels applied). Raises one ``InputError``."""
    from .. import models

    if not isinstance(d, dict):
        raise InputError(path, "not a fit file: expected a JSON object")
    for key in ("model", "params"):
        if key not in d:
            raise InputError(path, f"not a brdffit fit result: no {key!r} field")
    name, params = d["model"], d["params"]
    if not isinstance(name, str) or not name.strip():
        raise InputError(path, f"field 'model' must be a model name, got {json.dumps(name)[:60]}")
    channels = d.get("channels", 3)
    if not _is_number(channels) or channels not in (1, 3):
        raise InputError(path, f"field 'channels' must be 1 or 3, got {json.dumps(channels)[:60]}")
    try:
        model = models.get(name)
    except KeyError:
        raise InputError(path, f"unknown model {name!r}; known: {', '.join(models.names())}") from None
    except (ValueError, OverflowError, MemoryError) as exc:
        raise InputError(path, f"model {name!r} cannot be built: {' '.join(str(exc).split())}") from None
    if model.channels != int(channels):
        model = model.with_channels(int(channels))

    for key, types in _SCALARS.items():
        if key in d and (not isinstance(d[key], types) or (isinstance(d[key], bool) and bool not in types)):
            raise InputError(path, f"field {key!r} has the wrong type ({type(d[key]).__name__})")
    for key in _COUNTS:
        if key in d and not (isinstance(d[key], int) and not isinstance(d[key], bool) and d[key] >= 0):
            raise InputError(path, f"field {key!r} must be a count (an integer >= 0), got {json.dumps(d[key])[:60]}")
    code = d.get("status_code")  # absent or null: read from 'status'
    if code is not None and not (isinstance(code, int) and not isinstance(code, bool) and code in STATUS_TEXT):
        raise InputError(path, f"field 'status_code' must be one of {sorted(STATUS_TEXT)}, "
                               f"got {json.dumps(d['status_code'])[:60]}")
    for key in _FLOAT_MAPS:
        if key in d:
            m = d[key]
            if not isinstance(m, dict) or not all(_number_or_null(v) for v in m.values()):
                raise InputError(path, f"field {key!r} must be an object of numbers")
    if "at_bound" in d and d["at_bound"] is not None:
        _check_at_bound(d["at_bound"], path, model)
    if "warnings" in d and d["warnings"] is not None:
        if not (isinstance(d["warnings"], list) and all(isinstance(w, str) for w in d["warnings"])):
            raise InputError(path, "field 'warnings' must be a list of sentences (text)")
    if "excluded" in d:
        ex = d["excluded"]
        if not isinstance(ex, dict) or not all(isinstance(v, int) and not isinstance(v, bool) for v in ex.values()):
            raise InputError(path, "field 'excluded' must be an object of counts")
    if "options" in d:
        if not isinstance(d["options"], dict):
            raise InputError(path, "field 'options' must be an object")
        if "converted_from" in d["options"]:
            _check_conversion(d["options"]["converted_from"], path)
    for key, allow_null in (("stderr", True), ("start", False)):
        if key in d:
            m = d[key]
            if not isinstance(m, dict):
                raise InputError(path, f"field {key!r} must be an object")
            for k, v in m.items():
                if k not in model.param_names:
                    raise InputError(path, f"field {key!r} names {k!r}, not a parameter of the model")
                if v is not None or not allow_null:
                    _number_list(v, f"{key}.{k}", path, allow_null=allow_null)

    if not isinstance(params, dict):
        raise InputError(path, f"field 'params' must be an object name -> value(s), got a {type(params).__name__}")
    values = {k: np.asarray(_number_list(v, f"parameter {k!r}", path), dtype=np.float64) for k, v in params.items()}
    try:
        checked = model.check_params(values)
    except ValueError as exc:
        raise InputError(path, " ".join(str(exc).split())) from None
    recorded = _recorded_bounds(d.get("bounds"), path)
    for p in model.params:
        v = np.asarray(checked[p.name], dtype=np.float64)
        if not np.all(np.isfinite(v)):
            raise InputError(path, f"parameter {p.name!r} is not finite: {v.tolist()}")
        # the model's own bounds always (outside them the formula is not defined: a file cannot
        # widen them), and the bounds the file records where it records some (they may narrow them)
        boxes = [(p.lower, p.upper, f"bounds of {model.name}")]
        if p.name in recorded:
            boxes.append((*recorded[p.name], "recorded bounds"))
        for lo, hi, where in boxes:
            lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
            if lo.size not in (1, v.size) or hi.size not in (1, v.size):
                raise InputError(path, f"bounds.{p.name} has {lo.size}/{hi.size} entries, the parameter {v.size}")
            slack_lo = _SLACK * np.maximum(np.abs(lo), 1.0)
            slack_hi = _SLACK * np.maximum(np.abs(hi), 1.0)
            if np.any(v < lo - slack_lo) or np.any(v > hi + slack_hi):
                raise InputError(path, f"parameter {p.name!r} = {v.tolist()} lies outside its {where} "
                                       f"[{_fmt(lo)}, {_fmt(hi)}]")
    return model


def _check_conversion(c, path) -> None:
    """``options.converted_from`` as ``brdffit.materials.convert`` records it."""
    if not isinstance(c, dict):
        raise InputError(path, "field 'options.converted_from' must be an object (the conversion's record)")
    for key in _CONVERSION_TEXT:
        if key in c and not isinstance(c[key], str):
            raise InputError(path, f"field 'options.converted_from.{key}' must be text")
    for key in _CONVERSION_NUMBERS:
        if key in c and not _number_or_null(c[key]):
            raise InputError(path, f"field 'options.converted_from.{key}' must be a number")
    metrics = c.get("source_fit_metrics", {})
    if not isinstance(metrics, dict) or not all(_number_or_null(v) for v in metrics.values()):
        raise InputError(path, "field 'options.converted_from.source_fit_metrics' must be an object of numbers")


def _fmt(x: np.ndarray) -> str:
    return ", ".join(f"{float(v):g}" for v in np.atleast_1d(x))


def _recorded_bounds(bounds, path) -> dict[str, tuple[Any, Any]]:
    """``bounds`` as a file may record it: name -> [lower, upper] (numbers or per-channel lists)."""
    if bounds is None:
        return {}
    if not isinstance(bounds, dict):
        raise InputError(path, "field 'bounds' must be an object name -> [lower, upper]")
    out = {}
    for name, pair in bounds.items():
        if isinstance(pair, dict) and {"lower", "upper"} <= set(pair):
            pair = [pair["lower"], pair["upper"]]
        if not (isinstance(pair, list) and len(pair) == 2):
            raise InputError(path, f"bounds.{name} must be [lower, upper]")
        lo = _number_list(pair[0], f"bounds.{name} lower", path)
        hi = _number_list(pair[1], f"bounds.{name} upper", path)
        if len(lo) != len(hi) and 1 not in (len(lo), len(hi)):
            raise InputError(path, f"bounds.{name}: lower has {len(lo)} entries, upper {len(hi)}")
        if any(math.isnan(x) for x in lo + hi) or np.any(np.asarray(lo) > np.asarray(hi)):
            raise InputError(path, f"bounds.{name} is not an interval: {pair}")
        out[name] = (lo if len(lo) > 1 else lo[0], hi if len(hi) > 1 else hi[0])
    return out
