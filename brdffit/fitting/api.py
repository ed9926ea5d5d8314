"""`brdffit.fit`: one measurement, one model -> FitResult."""

from __future__ import annotations

import dataclasses

import functools
from collections.abc import Callable, Mapping

import jax.numpy as jnp
import numpy as np

from ..errors import UsageError
from ..measurement import Measurement
from ..models.base import Model
from . import init as _init
from .losses import check_loss
from .problem import data_unit, in_unit, loss_values, prepare, resolve_model
from .result import FitResult
from .._fit_defaults import DEFAULT_ATOL, DEFAULT_MAX_STEPS, DEFAULT_RTOL
from .program import STATUS_TEXT, check_solver, compiled, program_args, run_fit
from .space import ParameterSpace, fit_warnings, sample_spacing
from .structure import gauss_newton_matrix

from .._fit_defaults import COMPOSITE_STARTS, DEFAULT_LOSS, DEFAULT_SOLVER  # noqa: E402

#: Condition number of J'J above which standard errors are not reported.
STDERR_MAX_COND = 1e12


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


def _start_from(init, model: Model, lo, hi) -> np.ndarray:
    if isinstance(init, FitResult):
        init = init.params
    if isinstance(init, str):
        if init != "defaults":
            raise UsageError(f"init must be None, 'defaults', a params dict or a FitResult, not {init!r}")
        return np.clip(model.default_vector(), lo, hi)
    if not isinstance(init, Mapping):
        raise UsageError(f"init must be None, 'defaults', a params dict or a FitResult, not {type(init).__name__}")
    full = dict(model.defaults())
    full.update({k: v for k, v in init.items()})
    try:
        v = np.asarray(model.flatten(full))
    except ValueError as exc:
        raise UsageError(f"init: {exc}") from None
    return np.clip(v, lo, hi)


def default_starts(model: Model) -> int:
    """Starts solved at once (one vmapped solve) when the caller does not say: 1, or
    COMPOSITE_STARTS for a composite with several lobes of one kind. Measured (lambert+ggx+ggx,
    the 4 shared RGL files): the structure-aware grid (lobes at separated roughnesses, see
    ``init``) puts the best start in the best basin; 4 starts reached the same loss (to 1e-8) at
    3-5x the time, so COMPOSITE_STARTS is 1. ``multistart=k`` adds k starts."""
    kinds = [c.name for c in model.components]
    return COMPOSITE_STARTS if len(kinds) != len(set(kinds)) else 1


def parameter_space(model: Model, bounds=None, fixed=None, physical: bool = False) -> ParameterSpace:
    """Where a fit of ``model`` may move (``brdffit.fitting.space``): flat ``lo``/``hi`` (may be
    infinite) and ``free`` mask, the runtime arguments of the init and of every solver."""
    if not bounds and not fixed:
        return _default_space(model, bool(physical))
    return ParameterSpace.build(model, bounds, fixed, physical)


@functools.lru_cache(maxsize=64)
def _default_space(model: Model, physical: bool) -> ParameterSpace:
    """The space of a fit without overrides, built once per model (its arrays are read-only)."""
    space = ParameterSpace.build(model, None, None, physical)
    for a in (space.lo, space.hi, space.free, space.values):
        a.flags.writeable = False
    return space


def space_options(bounds, fixed, physical) -> dict:
    """The parameter-space arguments as JSON-ready options (only those given)."""
    out = {}
    if bounds:
        out["bounds"] = {k: [None if b is None else float(b) for b in v] for k, v in bounds.items()}
    if fixed:
        out["fixed"] = {k: np.asarray(v, dtype=np.float64).reshape(-1).tolist() for k, v in fixed.items()}
    if physical:
        out["physical"] = True
    return out


def _quiet(_message: str) -> None:
    pass


def fit(
    measurement: Measurement,
    model: str | Model,
    *,
    loss: str = DEFAULT_LOSS,
    solver: str = DEFAULT_SOLVER,
    init=None,
    multistart: int | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    rtol: float = DEFAULT_RTOL,
    atol: float = DEFAULT_ATOL,
    weights=None,
    scene=None,
    scipy_jac: str = "exact",
    progress: Callable[[str], None] | None = None,
    bounds: Mapping[str, tuple] | None = None,
    fixed: Mapping[str, object] | None = None,
    physical: bool = False,
) -> FitResult:
    """Fit ``model`` to ``measurement``.

    loss: l2 | cosine_l2 | log | cbrt | relative. solver: lm | optx_lm | gauss_newton | dogleg |
    bfgs | scipy. init: None (the variable-projection grid, see ``brdffit.fitting.init``),
    "defaults", a params dict (missing parameters take their defaults) or a FitResult.
    multistart: further grid starts solved beside the best one (all in one vmapped solve; the
    lowest loss wins); None (default) = ``default_starts(model) - 1``. rtol: relative tolerance
    (see ``solve.BoundedLevenbergMarquardt``); atol: absolute floor on the loss, 0 = none.
    progress: called with a short text at each phase (initialising, compiling, solving, solved).
    Non-convergence is reported in ``.status``, never raised; parameters are never NaN.

    Parameter space (``brdffit.fitting.space``): the model's bounds (only what its formula needs),
    ``physical=True`` for its plausible ranges, ``bounds={"name": (lo, hi)}`` to narrow a box
    (None on a side keeps it), ``fixed={"name": value}`` to hold a parameter. Lobes of one kind
    come out narrowest first. ``.at_bound`` and ``.warnings`` report what the constraints decided.

    scene: a ``brdffit.scene.Usage`` (``brdffit.scene_usage``, SPEC 12): the samples are weighted
    by where that scene looks (``usage.weights``), times ``weights``.
    """
    scene_note = None
    if scene is not None:  # SPEC 12
        weights = scene.weights(measurement) * (1.0 if weights is None else np.asarray(weights, np.float64))
        scene_note = _coverage_note(scene, measurement)
    note = progress or _quiet
    loss = check_loss(loss)
    solver = check_solver(solver)
    if max_steps < 1:
        raise UsageError("max_steps must be at least 1")
    if multistart is not None and int(multistart) < 0:
        raise UsageError("multistart must be >= 0")
    prep = prepare(measurement, weights)
    m = resolve_model(model, prep.channels)
    space = parameter_space(m, bounds, fixed, physical)
    # The solve works in the table's unit (problem.data_unit: 1, or a power of ten for a table far from
    # reflectance's range); the result is given back in the table's own unit.
    unit = data_unit(m, prep)
    unscale = np.where(space.linear_mask(), unit, 1.0)
    solve_space = space.in_unit(unit)
    data = in_unit(prep, unit).data
    lo, hi, free = solve_space.lo, solve_space.hi, solve_space.free
    anchor = solve_space.clip(_start_from("defaults" if init is None else init, m, space.lo, space.hi) / unscale)
    n_starts = 1 + (default_starts(m) - 1 if multistart is None else int(multistart))
    if solver == "scipy":
        n_starts = 1 if multistart is None else n_starts

    compile_s = run_s = init_s = 0.0
    note("initialising: grid of starts" if init is None else "initialising: the given start")
    note(f"solving: {solver}, {n_starts} start{'s' if n_starts > 1 else ''}")
    if solver == "scipy":
        from .solve import solve_scipy

        if init is None:
            starts, _, c_s, r_s = _init.best_starts(m, loss, data, lo, hi, free, anchor, k=n_starts, note=note)
            compile_s, run_s, init_s = c_s, r_s, c_s + r_s
        else:
            starts = anchor[None, :]
        best = None
        for i, v0 in enumerate(starts):
            v, value, code, steps, c_s, r_s = solve_scipy(
                m, loss, v0, data, lo, hi, free, rtol=rtol, atol=atol, max_steps=max_steps, jac=scipy_jac
            )
            compile_s += c_s
            run_s += r_s
            if best is None or value < best[1]:
                best = (v, value, code, steps, i)
        v, value, code, steps, i_best = best
        v0, metrics, jtj, n_given = starts[i_best], None, None, len(starts)
    else:
        # One compiled program: grid start (unless init is given), solve, metrics, J^T J.
        grid = init is None
        args = program_args(m, solve_space, data, anchor[None, :] if not grid else np.zeros((0, m.n_free)), grid=grid)
        n_given = min(n_starts, len(args[0]) if grid else 1)
        out, compile_s, run_s = run_fit(m, loss, solver, rtol, atol, max_steps, n_given, args, grid=grid, note=note)
        v, value, code, steps, v0 = out["v"], float(out["loss"]), int(out["code"]), int(out["steps"]), out["start"]
        metrics, jtj = {k: float(x) for k, x in out["metrics"].items()}, out["jtj"]
        for lobe in _init.switched_off_lobes(solve_space, np.asarray(v)):
            # A lobe the solve switched off: try it again at every roughness, scored on every sample
            # (linear parameters solved at each, the fit itself one more candidate), and keep what
            # lowers the loss.
            note(f"re-seeding the lobe of {lobe[0]}: the fit switched it off")
            pts = _init.reseed_points(solve_space, np.asarray(v), lobe)
            every_row = np.arange(np.asarray(data[0]).shape[0])  # a narrow peak the subset missed counts
            again = (pts, np.asarray(v, np.float64)[None, :]) + args[2:7] + (every_row,)
            out2, c_s, r_s = run_fit(m, loss, solver, rtol, atol, max_steps, 1, again, grid=True, note=note)
            compile_s, run_s = compile_s + c_s, run_s + r_s
            if float(out2["loss"]) < value:
                v, value, code, v0 = out2["v"], float(out2["loss"]), int(out2["code"]), out2["start"]
                steps += int(out2["steps"])
                metrics, jtj = {k: float(x) for k, x in out2["metrics"].items()}, out2["jtj"]
    note(f"solved: {steps} steps, loss {value:.6g}, {STATUS_TEXT[code]}")
    if unit != 1.0:  # back to the table's unit; metrics and J^T J are computed there afresh
        v, v0 = np.asarray(v) * unscale, np.asarray(v0) * unscale
        metrics = jtj = value = None  # the loss too: SPEC 5's value on the table as given
    # Fixed entries exactly at their values; lobes of one kind narrowest first (J^T J follows).
    perm = space.canonical_order(space.clip(v))
    v = space.clip(v)[perm]
    jtj = None if jtj is None else np.asarray(jtj)[np.ix_(perm, perm)]
    result = _result(space, loss, solver, measurement, prep, v, value, code, steps, v0,
                   seconds={"compile": compile_s, "run": run_s, "init": init_s},
                   metrics=metrics, jtj=jtj,
                   options={"max_steps": max_steps, "rtol": rtol, "atol": atol,
                            "multistart": None if multistart is None else int(multistart),
                            "starts": int(n_given), "init": "grid" if init is None else "given",
                            **({"data_unit": unit} if unit != 1.0 else {}),
                            **space_options(bounds, fixed, physical)})
    if scene_note is not None:
        result = dataclasses.replace(result, warnings=(*result.warnings, scene_note))
    return result


#: Below this fraction of a scene's weight covered by the data, a scene-weighted fit says so.
COVERAGE_WARN = 0.95


def _coverage_note(scene, measurement: Measurement) -> str | None:
    """One sentence when the data cover too little of where ``scene`` looks (issue 28: such a fit
    was the plain fit without a word), else None."""
    if not hasattr(scene, "coverage"):  # any object with weights(measurement) may weight a fit
        return None
    covered = scene.coverage(measurement)  # a brdffit.scene.Usage (duck-typed: no upward import)
    if covered >= COVERAGE_WARN:
        return None
    return (f"the data cover {covered:.0%} of where the scene looks ({scene.material!r} in {scene.scene}); "
            "the rest gets the floor weight, so the fit is closer to the plain fit than to the scene's: "
            "for a source that can be evaluated anywhere (RGL, MERL, UTIA), brdffit.scene.fit_data(source, usage) "
            "samples it where the scene looks")


def _result(space: ParameterSpace, loss, solver, measurement: Measurement, prep, v, value, code, steps, v0, *,
            seconds, options, metrics=None, jtj=None) -> FitResult:
    m, lo, hi, free, name = space.model, space.lo, space.hi, space.free, measurement.name
    params = {k: a.copy() for k, a in m.unflatten(np.asarray(v, dtype=np.float64)).items()}
    if metrics is None or jtj is None:
        # Through the disk cache, like the solve (a second process traces nothing).
        args = (jnp.asarray(v, dtype=jnp.float64), prep.data)
        metrics_fn, _ = compiled(("metrics", m, loss), lambda: lambda v, d: loss_values(m)(v, d, (loss,)), *args)
        jtj_fn, _ = compiled(("jtj", m, loss), lambda: gauss_newton_matrix(m, loss), *args)
        metrics = {k: float(x) for k, x in metrics_fn(*args).items()}
        jtj = np.asarray(jtj_fn(*args))
    if value is None:
        value = metrics[loss]
    stderr = standard_errors(m, params, jtj, value, prep.n_used * prep.channels, lo, hi, free)
    ref = np.asarray(prep.data[2])[prep.used]  # the data's unit (see ParameterSpace.at_bound)
    at_bound = space.at_bound(v, data_scale=float(np.mean(np.abs(ref))) if ref.size else None)
    wo = np.asarray(measurement.wo)[prep.used]
    warnings = fit_warnings(space, v, at_bound, stderr, sample_spacing(wo))
    status = STATUS_TEXT[code]
    if solver == "scipy" and code == 0:
        status = "converged (scipy least_squares)"
    return FitResult(
        model=m,
        params=params,
        loss=loss,
        loss_value=float(value),
        metrics=metrics,
        steps=int(steps),
        converged=code == 0,
        status=status,
        seconds=seconds,
        solver=solver,
        data_name=name,
        n_used=prep.n_used,
        n_excluded=prep.n_excluded,
        excluded=prep.excluded,
        stderr=stderr,
        start={k: a.copy() for k, a in m.unflatten(np.asarray(v0, dtype=np.float64)).items()},
        options=options,
        at_bound=at_bound,
        warnings=tuple(warnings),
    )
