"""The fit driver: every fit of brdffit runs here.

``brdffit.fit`` (one measurement), ``brdffit.fit_batch`` (many) and ``brdffit.fit_btf`` (the texels
of a BTF, tile by tile) check their options into one :class:`~brdffit.fitting.options.FitOptions`
and call :func:`solve` (arrays in, a :class:`Solved` record out: one row per fit, each with its
status code) or :func:`fit_measurements` (measurements in, one ``FitResult`` per fit, built by one
function). What runs:

- ``scipy``: the start grid (``init.best_starts``) then scipy's least_squares per start, in Python;
- one fit (``fit``): one compiled program (``program.fit_program``: grid, solve, metrics, J^T J),
  then a lobe the solve switched off is tried again at every roughness (``init.reseed_points``);
- a batch (``fit_batch``, ``fit_btf``): the same program mapped over the fits
  (``batch.solve_batch``).

A table far from reflectance's range is solved in a unit of its own (``problem.data_unit``) and
given back in the table's.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..measurement import Measurement
from ..models.base import Model
from . import init as _init
from .options import FitOptions
from .problem import Data, Prepared, data_unit, in_unit, loss_values, prepare, resolve_model
from .._fit_defaults import STATUS_TEXT
from .program import compiled, program_args, run_fit
from .result import FitResult
from .space import ParameterSpace, fit_warnings, sample_spacing
from .structure import gauss_newton_matrix

#: Condition number of J'J above which standard errors are not reported.
STDERR_MAX_COND = 1e12


def _quiet(_message: str) -> None:
    pass


class Solved(NamedTuple):
    """What the solves found, one row per fit (NumPy, the fit axis first), in the solve's unit."""

    v: np.ndarray  # (n, P) canonical lobe order, fixed entries exact
    loss: np.ndarray  # (n,) the fit's loss at v
    code: np.ndarray  # (n,) int: status code (``_fit_defaults.STATUS_TEXT``), 0 converged
    steps: np.ndarray  # (n,) int
    start: np.ndarray  # (n, P) the start the best solve came from
    metrics: dict | None  # name -> (n,), or None (scipy: computed with the result)
    jtj: np.ndarray | None  # (n, P, P) in v's order, or None
    seconds: dict  # "compile", "run", "init": the whole call's
    starts: int  # candidates solved per fit


def _in_canonical_order(space: ParameterSpace, v: np.ndarray, jtj: np.ndarray | None):
    """Fixed entries exactly at their values, lobes of one kind narrowest first (a swap of whole
    interchangeable lobes: f_r and the loss are unchanged; J^T J follows the swap)."""
    v = np.stack([space.clip(row) for row in v])
    if not space.order:
        return v, jtj
    perms = np.stack([space.canonical_order(row) for row in v])
    v = np.take_along_axis(v, perms, axis=1)
    if jtj is not None:
        jtj = np.stack([h[np.ix_(p, p)] for h, p in zip(jtj, perms)])
    return v, jtj


def solve(space: ParameterSpace, options: FitOptions, data: Data, *, starts: np.ndarray | None = None,
          grid: bool = True, batch: bool = False, note: Callable[[str], None] = _quiet, on_chunk=None) -> Solved:
    """Fit every row of ``data`` (arrays with a leading fit axis (n, ...)) in ``space``. ``starts``:
    (n, P) given starts, ranked beside the grid's points (``grid``), or the only ones; ``batch``: run
    the batched program (``batch.solve_batch``; else n must be 1)."""
    model, n = space.model, int(np.asarray(data.ref).shape[0])
    k = options.starts(model)
    if options.solver == "scipy":
        return _solve_scipy(space, options, data, starts, grid, k, note)
    if batch:
        from .batch import solve_batch

        res = solve_batch(space, options, data, k=k, starts=starts, grid=grid, on_chunk=on_chunk)
        v, jtj = _in_canonical_order(space, res["v"], res["jtj"])
        return Solved(v, res["loss"], res["code"], res["steps"], res["start"], res["metrics"], jtj,
                      {"compile": res["compile_s"], "run": res["run_s"], "init": 0.0}, k)
    assert n == 1, "one fit at a time outside a batch"
    one = Data(*(np.asarray(a)[0] for a in data))
    given = np.zeros((0, model.n_free)) if starts is None else np.asarray(starts, np.float64).reshape(1, -1)
    args = program_args(model, space, one, given, grid=grid)
    k = min(k, len(args.grid_points) if grid else 1)
    out, compile_s, run_s = run_fit(model, options.loss, options.solver, options.rtol, options.atol,
                                    options.max_steps, k, args, grid=grid, note=note)
    steps = int(out["steps"])
    for lobe in _init.switched_off_lobes(space, np.asarray(out["v"])):
        # A lobe the solve switched off: try it again at every roughness, scored on every sample
        # (linear parameters solved at each, the fit itself one more candidate), and keep what
        # lowers the loss.
        note(f"re-seeding the lobe of {lobe[0]}: the fit switched it off")
        again = args._replace(grid_points=_init.reseed_points(space, np.asarray(out["v"]), lobe),
                              given=np.asarray(out["v"], np.float64)[None, :],
                              subset=np.arange(one.ref.shape[0]))  # a narrow peak the subset missed counts
        out2, c_s, r_s = run_fit(model, options.loss, options.solver, options.rtol, options.atol,
                                 options.max_steps, 1, again, grid=True, note=note)
        compile_s, run_s = compile_s + c_s, run_s + r_s
        if float(out2["loss"]) < float(out["loss"]):
            out, steps = out2, steps + int(out2["steps"])
    row = {key: np.asarray(a)[None] for key, a in out.items() if key != "metrics"}
    v, jtj = _in_canonical_order(space, row["v"], row["jtj"])
    return Solved(v, row["loss"], row["code"], np.array([steps]), row["start"],
                  {key: np.asarray(x)[None] for key, x in out["metrics"].items()}, jtj,
                  {"compile": compile_s, "run": run_s, "init": 0.0}, k)


def _solve_scipy(space: ParameterSpace, options: FitOptions, data: Data, starts, grid: bool, k: int, note) -> Solved:
    """scipy's least_squares from the k best grid points (or the given start) of each fit, in Python."""
    from . import solver_scipy  # scipy: imported only when a scipy fit runs

    model, n = space.model, int(np.asarray(data.ref).shape[0])
    lo, hi, free = space.lo, space.hi, space.free
    anchor = space.clip(model.default_vector())
    rows = {key: [] for key in ("v", "loss", "code", "steps", "start")}
    seconds = {"compile": 0.0, "run": 0.0, "init": 0.0}
    solved = 1
    for row in range(n):
        one = Data(*(np.asarray(a)[row] for a in data))
        if grid:
            candidates, _, c_s, r_s = _init.best_starts(model, options.loss, one, lo, hi, free, anchor, k=k, note=note)
            seconds["compile"] += c_s
            seconds["run"] += r_s
            seconds["init"] += c_s + r_s
        else:
            candidates = space.clip(starts[row])[None, :]
        solved = len(candidates)
        best = None
        for i, v0 in enumerate(candidates):
            v, value, code, steps, c_s, r_s = solver_scipy.solve_scipy(
                model, options.loss, v0, one, lo, hi, free, rtol=options.rtol, atol=options.atol,
                max_steps=options.max_steps, jac=options.scipy_jac)
            seconds["compile"] += c_s
            seconds["run"] += r_s
            if best is None or value < best[1]:
                best = (v, value, code, steps, v0)
        for key, x in zip(rows, best):
            rows[key].append(x)
    v, _ = _in_canonical_order(space, np.asarray(rows["v"], np.float64), None)
    return Solved(v, np.asarray(rows["loss"]), np.asarray(rows["code"]), np.asarray(rows["steps"]),
                  np.asarray(rows["start"]), None, None, seconds, solved)


def fit_measurements(measurements: Sequence[Measurement], model: str | Model, options: FitOptions, *,
                     weights=None, starts=None, grid: bool = True, batch: bool = False,
                     note: Callable[[str], None] = _quiet, on_chunk=None) -> list[FitResult]:
    """Fit ``model`` to each measurement (same samples and channels) with ``options``; one FitResult
    each. ``starts``: (n, P) flat vectors in the table's unit (already in the space), or None."""
    preps = [prepare(m, weights) for m in measurements]
    mdl = resolve_model(model, preps[0].channels)
    space = options.space(mdl)
    # The solve works in the table's unit (problem.data_unit: 1, or a power of ten for a table far from
    # reflectance's range; one for a batch, whose bounds are shared); results come back in the table's.
    unit = data_unit(mdl, *preps)
    unscale = np.where(space.linear_mask(), unit, 1.0)
    solved = [in_unit(p, unit).data for p in preps]
    data = Data(*(np.stack([np.asarray(d[i]) for d in solved]) for i in range(len(Data._fields))))
    given = None if starts is None else np.asarray(starts, np.float64) / unscale
    k = options.starts(mdl)
    note("initialising: grid of starts" if grid else "initialising: the given start")
    note(f"solving: {options.solver}, {k} start{'s' if k > 1 else ''}")
    res = solve(space.in_unit(unit), options, data, starts=given, grid=grid, batch=batch, note=note,
                on_chunk=on_chunk)
    if not batch:
        note(f"solved: {int(res.steps[0])} steps, loss {float(res.loss[0]):.6g}, {STATUS_TEXT[int(res.code[0])]}")
    n = len(measurements)
    seconds = res.seconds if not batch else {key: s / n for key, s in res.seconds.items()}
    record = {**options.record(), "starts": res.starts, "init": "grid" if grid else "given"}
    if batch:
        record.update(batch=True, chunk=min(options.chunk, n))
    if unit != 1.0:
        record["data_unit"] = unit
    given_back = unit == 1.0 and res.metrics is not None  # else metrics, J^T J and loss afresh, in the table's unit
    # space.clip: fixed entries exactly at their values after the unit's round trip
    return [fit_result(space, options, m, prep, space.clip(res.v[i] * unscale), int(res.code[i]), int(res.steps[i]),
                       res.start[i] * unscale, seconds=seconds, options_record=record,
                       value=float(res.loss[i]) if given_back else None,
                       metrics={key: float(x[i]) for key, x in res.metrics.items()} if given_back else None,
                       jtj=res.jtj[i] if given_back else None)
            for i, (m, prep) in enumerate(zip(measurements, preps))]


def fit_result(space: ParameterSpace, options: FitOptions, measurement: Measurement, prep: Prepared, v, code: int,
               steps: int, v0, *, seconds, options_record, value=None, metrics=None, jtj=None) -> FitResult:
    """The FitResult of one fit at ``v`` (the table's unit); metrics, J^T J and the loss computed here
    where the solve did not give them in that unit."""
    m, loss = space.model, options.loss
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
    stderr = standard_errors(m, params, jtj, value, prep.n_used * prep.channels, space.lo, space.hi, space.free)
    ref = np.asarray(prep.data.ref)[prep.used]  # the data's unit (see ParameterSpace.at_bound)
    at_bound = space.at_bound(v, data_scale=float(np.mean(np.abs(ref))) if ref.size else None)
    warnings = fit_warnings(space, v, at_bound, stderr, sample_spacing(np.asarray(measurement.wo)[prep.used]))
    status = STATUS_TEXT[code]
    if options.solver == "scipy" and code == 0:
        status = "converged (scipy least_squares)"
    return FitResult(
        model=m, params=params, loss=loss, loss_value=float(value), metrics=metrics, steps=int(steps),
        converged=code == 0, status=status, status_code=int(code), seconds=dict(seconds), solver=options.solver,
        data_name=measurement.name, n_used=prep.n_used, n_excluded=prep.n_excluded, excluded=prep.excluded,
        stderr=stderr, start={k: a.copy() for k, a in m.unflatten(np.asarray(v0, dtype=np.float64)).items()},
        options=dict(options_record), at_bound=at_bound, warnings=tuple(warnings))


def with_warning(result: FitResult, sentence: str | None) -> FitResult:
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
