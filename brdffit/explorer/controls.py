"""The explorer's parameter controls: a slider per parameter value within the model's bounds, and
the checks of values set from Python (``Explorer.set_params``).

A slider moves on a logarithmic axis for a roughness or an exponent (and any parameter whose own
axis is logarithmic: ``Param.scale``) when its lower bound is positive, on a linear axis otherwise
(a roughness that may be 0, Oren-Nayar's sigma). Its range is the parameter's bounds, the
physical range standing in on an infinite side (``Param.finite_range``), widened to hold the
current value: a fit may leave the physical range, and the slider must still show where it went.
A parameter with one value per channel has a slider per channel ("kd R", "kd G", "kd B").
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import UsageError
from ..models.base import Model, Param, format_range

#: Roles whose sliders are logarithmic (see the module docstring).
LOG_ROLES = ("roughness", "exponent")


@dataclasses.dataclass(frozen=True)
class Slider:
    """One slider: the value ``index`` of parameter ``param``."""

    param: str
    index: int
    label: str
    lo: float
    hi: float
    log: bool

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def is_log(p: Param) -> bool:
    return (p.role in LOG_ROLES or p.scale == "log") and p.lower > 0


def slider_range(p: Param, values: np.ndarray) -> tuple[float, float]:
    """The range of ``p``'s sliders (see the module docstring)."""
    lo, hi = p.finite_range
    v = np.asarray(values, np.float64)
    top, bottom = float(v.max()), float(v.min())
    if top > hi:  # above the physical range on an open side: room to move on
        hi = min(p.upper, top * 2.0 if is_log(p) else top * 1.5)
    if bottom < lo:
        lo = max(p.lower, bottom / 2.0 if is_log(p) else bottom - 0.5 * (hi - bottom))
    return float(lo), float(hi)


def sliders(model: Model, params: dict) -> list[Slider]:
    """The sliders of ``model`` at ``params``, in the order of its parameter table."""
    names = ("R", "G", "B") if model.channels == 3 else tuple(str(c) for c in range(model.channels))
    out = []
    for p in model.params:
        values = np.asarray(params[p.name], np.float64)
        lo, hi = slider_range(p, values)
        for i in range(model.size(p)):
            label = p.name if model.size(p) == 1 else f"{p.name} {names[i]}"
            out.append(Slider(p.name, i, label, lo, hi, is_log(p)))
    return out


def checked(model: Model, params: dict) -> dict[str, np.ndarray]:
    """``params`` as float64 arrays of the declared sizes, each inside its bounds; else one
    ``UsageError`` naming the parameter."""
    try:
        out = {k: np.asarray(v, np.float64).reshape(-1) for k, v in model.check_params(params).items()}
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    for p in model.params:
        v = out[p.name]
        if not np.all(np.isfinite(v)) or np.any(v < p.lower) or np.any(v > p.upper):
            raise UsageError(f"{model.name}: {p.name} = {v.tolist()} is outside its bounds "
                             f"{format_range(p.lower, p.upper)}")
    return out


def with_values(model: Model, params: dict, values: dict) -> dict[str, np.ndarray]:
    """``params`` with ``values`` (name -> a number, or one per channel) set; see :func:`checked`."""
    unknown = sorted(set(values) - set(model.param_names))
    if unknown:
        raise UsageError(f"{model.name} has no parameter {', '.join(map(repr, unknown))}; "
                         f"it has {', '.join(model.param_names)}")
    return checked(model, {**params, **values})


def clipped(model: Model, params: dict) -> dict[str, np.ndarray]:
    """``params`` from the front end: each value put inside its bounds (a slider's end may lie a
    rounding step outside)."""
    out = {}
    for p in model.params:
        v = np.asarray(params.get(p.name, p.default), np.float64).reshape(-1)
        v = np.broadcast_to(v, (model.size(p),)) if v.size == 1 else v[: model.size(p)]
        out[p.name] = np.clip(np.where(np.isfinite(v), v, p.default), p.lower, p.upper)
    return checked(model, out)


def carried(model: Model, params: dict) -> dict[str, np.ndarray]:
    """Parameters of ``model`` after a change of model: a parameter of the same name and size keeps
    its value (inside the new bounds), the others take their defaults."""
    out = {}
    for p in model.params:
        old = params.get(p.name)
        if old is not None and np.size(old) == model.size(p) and np.all(np.isfinite(old)):
            out[p.name] = np.clip(np.asarray(old, np.float64).reshape(-1), p.lower, p.upper)
        else:
            out[p.name] = np.full(model.size(p), p.default)
    return out


def as_lists(params: dict) -> dict[str, list[float]]:
    """Parameters as JSON lists (the front end's form, and ``Explorer.state``)."""
    return {k: [float(x) for x in np.asarray(v, np.float64).reshape(-1)] for k, v in params.items()}


def same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(np.asarray(a[k]), np.asarray(b[k])) for k in a)
