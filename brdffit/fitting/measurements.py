"""Measurements in, FitResults out: the layer between ``brdffit.fit`` / ``fit_batch`` (and a material's
conversion by fitting, ``materials``) and the fit driver (``driver.solve``: arrays in, one row per fit out).

:func:`fit_measurements` prepares the measurements (``problem.prepare``: one stack of values for 1 or n), resolves the
model, the data's unit, the number of starts and the parameter space once, runs the driver once for every fit, and
makes each fit's result (:func:`fit_result`: its parameters, standard errors, bounds reached and warnings) of the type
its caller names: this module is engine, below the renderers, figures and material files that a FitResult's methods
call, so it does not import that class.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from .._fit_defaults import STATUS_TEXT
from ..errors import UsageError
from ..measurement import Measurement
from ..models.base import Model
from .driver import quiet, solve
from .options import FitOptions
from .problem import Prepared, data_unit, prepare, resolve_model, stack_data
from .space import ParameterSpace, fit_warnings, sample_spacing

#: Condition number of J'J above which standard errors are not reported.
STDERR_MAX_COND = 1e12


def fit_measurements(measurements: Sequence[Measurement], model: str | Model, options: FitOptions, *,
                     result_type: type, weights=None, starts=None, grid: bool = True, check_given: bool = False,
                     note: Callable[[str], None] = quiet, progress=None, who: str = "fit") -> list:
    """Fit ``model`` to each measurement (same samples and channels) with ``options``; one
    ``result_type`` (:class:`brdffit.FitResult`) each. ``starts``: one start per measurement, each
    "defaults", a params dict or a flat vector (P,) in the table's unit (``ParameterSpace.start``), or None;
    ``check_given``: see :func:`solve`. ``progress(fraction)``: called as the solves finish. ``who``: the
    caller named in the messages of bad starts."""
    preps = [prepare(m, weights) for m in measurements]
    mdl = resolve_model(model, preps[0].channels)
    data = stack_data([p.data for p in preps])
    # problem.data_unit: 1, or a power of ten for a table far from reflectance's range under a loss a unit
    # only rescales (one for a batch, whose bounds are shared); results come back in the table's unit.
    unit = data_unit(mdl, options.loss, data)
    k = options.starts(mdl)
    space = options.space(mdl)
    try:
        given = None if starts is None else np.stack([space.start(s) for s in starts])
    except UsageError as exc:
        raise UsageError(f"{who}: {exc}") from None
    note("initialising: grid of starts" if grid else "initialising: the given start")
    note(f"solving: {options.solver}, {k if grid else 1} start(s)")
    res = solve(space, options, data, k=k, unit=unit, starts=given, grid=grid, results=True, check_given=check_given,
                note=note, progress=progress)
    n = len(measurements)
    if n == 1:
        note(f"solved: {int(res.steps[0])} steps, loss {float(res.loss[0]):.6g}, {STATUS_TEXT[int(res.code[0])]}")
    seconds = {key: s / n for key, s in res.seconds.items()}
    record = {**options.record(), "starts": res.starts, "init": "grid" if grid else "given"}
    if n > 1:
        record.update(batch=True)
    if unit != 1.0:
        record["data_unit"] = unit
    results = [fit_result(result_type, space, options, m, prep, res.v[i], int(res.code[i]), int(res.steps[i]),
                          res.start[i], seconds=seconds, options_record=record, value=float(res.loss[i]),
                          metrics={key: float(x[i]) for key, x in res.metrics.items()}, jtj=res.jtj[i])
               for i, (m, prep) in enumerate(zip(measurements, preps))]
    return [with_warning(r, res.notes.get(i)) for i, r in enumerate(results)]


def fit_result(result_type: type, space: ParameterSpace, options: FitOptions, measurement: Measurement, prep: Prepared,
               v, code: int, steps: int, v0, *, seconds, options_record, value: float, metrics: dict, jtj):
    """The ``result_type`` (FitResult) of one fit at ``v``, with its loss ``value``, ``metrics`` and ``jtj``
    (all in the table's unit: :func:`solve`'s)."""
    m, loss = space.model, options.loss
    params = {k: a.copy() for k, a in m.unflatten(np.asarray(v, dtype=np.float64)).items()}
    stderr = standard_errors(m, params, jtj, value, prep.n_used * prep.channels, space.lo, space.hi, space.free)
    ref = np.asarray(prep.data.ref)[prep.used]  # the data's unit (see ParameterSpace.at_bound)
    at_bound = space.at_bound(v, data_scale=float(np.mean(np.abs(ref))) if ref.size else None)
    warnings = fit_warnings(space, v, at_bound, stderr, sample_spacing(np.asarray(measurement.wo)[prep.used]))
    status = STATUS_TEXT[code]
    if options.solver == "scipy" and code == 0:
        status = "converged (scipy least_squares)"
    return result_type(
        model=m, params=params, loss=loss, loss_value=float(value), metrics=metrics, steps=int(steps),
        converged=code == 0, status=status, status_code=int(code), seconds=dict(seconds), solver=options.solver,
        data_name=measurement.name, n_used=prep.n_used, n_excluded=prep.n_excluded, excluded=prep.excluded,
        stderr=stderr, start={k: a.copy() for k, a in m.unflatten(np.asarray(v0, dtype=np.float64)).items()},
        options=dict(options_record), at_bound=at_bound, warnings=tuple(warnings))


def with_warning(result, sentence: str | None):
    """``result`` with one more warning (None: as it is)."""
    return result if sentence is None else dataclasses.replace(result, warnings=(*result.warnings, sentence))


def standard_errors(model: Model, params, jtj, loss_value: float, n_residuals: int, lo, hi, free=None):
    """Per parameter: standard errors from J'J at the solution (sigma^2 (J'J)^-1), or None.
    ``jtj``: the Gauss-Newton matrix of the fit's residuals at ``params``; ``loss_value``: their sum
    of squares; ``n_residuals``: their number.

    None for a parameter at one of its bounds (the active constraint makes the Gaussian
    approximation meaningless there), and for a parameter with a share in a (near) null direction
    of the column-scaled J'J (condition > STDERR_MAX_COND): a combination the data do not
    determine, e.g. ks and alpha of a lobe narrower than the sample spacing (only ks/alpha^2 is
    seen), or Lafortune's rho and |C| (only rho |C|^n is seen).
    """
    v = np.concatenate([np.broadcast_to(np.asarray(params[p.name], np.float64).reshape(-1), (model.size(p),))
                        for p in model.params])
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    tol = 1e-9 * np.maximum(np.abs(v), 1e-300)
    at_bound = (np.abs(v - lo) <= tol) | (np.abs(v - hi) <= tol)
    free = ~at_bound if free is None else (np.asarray(free, bool) & ~at_bound)
    out: dict[str, np.ndarray | None] = {p.name: None for p in model.params}
    jtj = np.asarray(jtj, dtype=np.float64)
    if not free.any() or not np.all(np.isfinite(jtj)):
        return out
    Hf = jtj[np.ix_(free, free)]
    # Column scaling, so that the conditioning test does not depend on parameter units.
    scale = np.sqrt(np.maximum(np.diag(Hf), 0.0))
    if np.any(scale == 0):
        scale = np.where(scale == 0, 1.0, scale)
    jtj = Hf / scale[:, None] / scale[None, :]
    w, V = np.linalg.eigh(jtj)
    small = w <= w[-1] / STDERR_MAX_COND
    dof = max(n_residuals - int(free.sum()), 1)
    # Residuals are normalised by 1/sqrt(n): sigma^2 (J'J)^-1 of the unnormalised problem equals
    # (sum r^2 / dof) (J'J)^-1 in these units. A parameter with a share in a (near) null
    # direction of J'J is not identifiable from these data: no standard error for it.
    s2 = loss_value / dof
    in_null = (V[:, small] ** 2).sum(axis=1) > 1e-6
    var = (V[:, ~small] ** 2 / w[~small]).sum(axis=1) * s2 / scale**2
    se_free = np.where(in_null, np.nan, np.sqrt(np.maximum(var, 0.0)))
    se = np.full(v.shape, np.nan)
    se[free] = se_free
    i = 0
    for p in model.params:
        n = model.size(p)
        block = se[i : i + n]
        out[p.name] = None if np.any(np.isnan(block)) else block.copy()
        i += n
    return out
