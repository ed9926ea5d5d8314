"""`FitOptions`: a fit's options, checked once, in one record.

``brdffit.fit``, ``brdffit.fit_batch`` and ``brdffit.fit_btf`` take their options as keyword
arguments (the public signatures) and turn them into one ``FitOptions`` before anything runs: the
checks, the number of starts and the parameter space are written here once, and the fit driver
(``driver``) reads nothing else.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from .._fit_defaults import (COMPOSITE_STARTS, DEFAULT_ATOL, DEFAULT_LOSS, DEFAULT_MAX_STEPS, DEFAULT_RTOL,
                             DEFAULT_SOLVER)
from ..errors import UsageError
from ..models.base import Model
from .losses import check_loss
from .objective import JACOBIANS
from .space import ParameterSpace, parameter_space
from .stages import check_solver


def default_starts(model: Model) -> int:
    """Starts solved at once (one vmapped solve) when the caller does not say: 1, or
    COMPOSITE_STARTS for a composite with several lobes of one kind. Measured (lambert+ggx+ggx,
    the 4 shared RGL files): the structure-aware grid (lobes at separated roughnesses, see
    ``init``) puts the best start in the best basin; 4 starts reached the same loss (to 1e-8) at
    3-5x the time, so COMPOSITE_STARTS is 1. ``multistart=k`` adds k starts."""
    kinds = [c.name for c in model.components]
    return COMPOSITE_STARTS if len(kinds) != len(set(kinds)) else 1


@dataclasses.dataclass(frozen=True, eq=False)
class FitOptions:
    """How to fit (not what): loss, solver, its tolerances and step budget, extra starts, the
    parameter space's overrides, and a batch's chunking. Built checked: an instance holds only
    valid values (the loss and solver under their canonical names)."""

    loss: str = DEFAULT_LOSS
    solver: str = DEFAULT_SOLVER
    max_steps: int = DEFAULT_MAX_STEPS
    rtol: float = DEFAULT_RTOL
    atol: float = DEFAULT_ATOL
    #: Starts solved beside the best grid point; None: ``default_starts(model) - 1``.
    multistart: int | None = None
    #: scipy's Jacobian: "exact" (JAX's, compiled), "2-point" or "3-point" (finite differences).
    scipy_jac: str = "exact"
    bounds: Mapping[str, tuple] | None = None
    fixed: Mapping[str, object] | None = None
    physical: bool = False
    #: Solves per compiled call, and solves vectorised together inside one; None: chosen for the backend
    #: (``lanes.plan``).
    chunk: int | None = None
    lanes: int | None = None
    #: The precision of a step's Jacobian (``objective.JACOBIANS``): "float64", or "float32" (a separable
    #: model's rows and sums; the loss stays exact), which ``fit_btf`` chooses.
    jacobian: str = "float64"

    def __post_init__(self):
        set_ = object.__setattr__  # frozen: the checked values replace the given ones once, here
        set_(self, "loss", check_loss(self.loss))
        set_(self, "solver", check_solver(self.solver))
        if int(self.max_steps) < 1:
            raise UsageError("max_steps must be at least 1")
        set_(self, "max_steps", int(self.max_steps))
        if self.multistart is not None:
            if int(self.multistart) < 0:
                raise UsageError("multistart must be >= 0")
            set_(self, "multistart", int(self.multistart))
        set_(self, "rtol", float(self.rtol))
        set_(self, "atol", float(self.atol))
        if self.scipy_jac not in ("exact", "2-point", "3-point"):
            raise UsageError(f"scipy_jac must be 'exact', '2-point' or '3-point', not {self.scipy_jac!r}")
        for name in ("chunk", "lanes"):
            value = getattr(self, name)
            if value is not None:
                if int(value) < 1:
                    raise UsageError("fit_batch: chunk and lanes must be at least 1")
                set_(self, name, int(value))
        set_(self, "physical", bool(self.physical))
        if self.jacobian not in JACOBIANS:
            raise UsageError(f"jacobian must be one of {', '.join(JACOBIANS)}, not {self.jacobian!r}")

    def batched(self, who: str) -> "FitOptions":
        """These options for a batch of fits (``who`` names the caller in the refusal): scipy runs
        one fit at a time in Python, it has no batched program."""
        if self.solver == "scipy":
            raise UsageError(f"{who}: solver 'scipy' is not batched; "
                             + ("use fit() per measurement" if who == "fit_batch" else "choose a compiled solver"))
        return self

    def starts(self, model: Model) -> int:
        """How many starts one fit of ``model`` solves (the best grid point, plus ``multistart``;
        scipy, which solves its starts one after another in Python: one unless ``multistart`` asks)."""
        if self.solver == "scipy" and self.multistart is None:
            return 1
        return 1 + (default_starts(model) - 1 if self.multistart is None else self.multistart)

    def space(self, model: Model) -> ParameterSpace:
        """Where a fit of ``model`` may move (``space.parameter_space``)."""
        return parameter_space(model, self.bounds, self.fixed, self.physical)

    def record(self) -> dict:
        """The options a FitResult records (JSON-ready; the space's overrides only where given)."""
        out = {"max_steps": self.max_steps, "rtol": self.rtol, "atol": self.atol, "multistart": self.multistart}
        if self.bounds:
            out["bounds"] = {k: [None if b is None else float(b) for b in v] for k, v in self.bounds.items()}
        if self.fixed:
            out["fixed"] = {k: np.asarray(v, dtype=np.float64).reshape(-1).tolist() for k, v in self.fixed.items()}
        if self.physical:
            out["physical"] = True
        return out
