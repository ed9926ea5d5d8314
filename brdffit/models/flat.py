"""The model as the fitting core reads it: one flat vector of parameter values (docs/fitting.md#solvers).

A model declares its parameters as a table of named entries (``brdffit.models.base.Model``); a solver
moves one flat vector. ``FlatView`` is that table read once into the flat layout -- where each
parameter's values sit, its bounds and physical range, its default, whether it is linear -- and the
formula as a function of the flat vector. ``Model.flat`` holds it, built when the model is made, so
every part of a fit (the parameter space, the start grid, the objective, the losses) reads the same
arrays instead of re-deriving them from the table, and the formula of a flat vector has one
definition. Its arrays are read-only: they are shared by every fit of the model.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from jaxtyping import Array, Float


@dataclasses.dataclass(frozen=True, eq=False)
class FlatView:
    """The flat layout of a model's parameter table (float64, read-only), and its formula of a flat vector."""

    #: (parameter name, its slice of the flat vector), in the order of the table.
    slices: tuple[tuple[str, slice], ...]
    #: The declared bounds (may be infinite).
    lo: np.ndarray
    hi: np.ndarray
    #: The physical ranges (finite; ``fit(..., physical=True)``).
    physical_lo: np.ndarray
    physical_hi: np.ndarray
    defaults: np.ndarray
    #: True at the entries of the parameters declared ``linear`` (those a table's unit scales).
    linear: np.ndarray
    #: ``f_r(v, wi, wo) -> (N, channels)``: the model's formula at the flat vector ``v`` (pure JAX).
    f_r: Callable[[Any, Any, Any], Any]

    def bounds(self, physical: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The declared bounds, or the physical ranges with ``physical=True``."""
        return (self.physical_lo, self.physical_hi) if physical else (self.lo, self.hi)


def _f_r(model, v: Float[Array, " P"], wi: Float[Array, "N 3"], wo: Float[Array, "N 3"]) -> Float[Array, "N C"]:
    return model.eval(model.unflatten(v), wi, wo)


def flat_view(model) -> FlatView:
    """``model``'s table read into the flat layout (``Model.__post_init__`` calls it once)."""
    sizes = [model.size(p) for p in model.params]

    def column(value_of, dtype=np.float64) -> np.ndarray:
        out = np.concatenate([np.full(n, value_of(p), dtype=dtype) for p, n in zip(model.params, sizes)]) \
            if sizes else np.zeros(0, dtype)
        out.flags.writeable = False
        return out

    ends = np.cumsum([0, *sizes])
    return FlatView(
        slices=tuple((p.name, slice(int(a), int(b))) for p, a, b in zip(model.params, ends[:-1], ends[1:])),
        lo=column(lambda p: p.lower), hi=column(lambda p: p.upper),
        physical_lo=column(lambda p: p.physical[0]), physical_hi=column(lambda p: p.physical[1]),
        defaults=column(lambda p: p.default), linear=column(lambda p: p.linear, bool),
        f_r=functools.partial(_f_r, model),
    )
