"""`brdffit.fit`: one measurement, one model -> FitResult."""

from __future__ import annotations

import functools
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import UsageError
from ..measurement import Measurement
from ..models.base import Model
from . import init as _init
from .losses import check_loss
from .problem import Data, evaluate, flat_residual, prepare, resolve_model
from .result import FitResult
from .solve import (
    DEFAULT_ATOL,
    DEFAULT_MAX_STEPS,
    DEFAULT_RTOL,
    STATUS_TEXT,
    check_solver,
    solve_lmb,
    solve_optx,
    solve_scipy,
)

#: Further grid starts tried by default when the first solve does not converge.
AUTO_RETRIES = 2

#: Condition number of J'J above which standard errors are not reported.
STDERR_MAX_COND = 1e12


@functools.lru_cache(maxsize=None)
def _jacobian_fn(model: Model, loss: str):
    return jax.jit(jax.jacfwd(flat_residual(model, loss)))


def standard_errors(model: Model, loss: str, params, data: Data, loss_value: float, n_residuals: int):
    """Per parameter: standard errors from J'J at the solution (sigma^2 (J'J)^-1), or None.

    None for a parameter at one of its bounds (the active constraint makes the Gaussian
    approximation meaningless there), and for a parameter with a share in a (near) null direction
    of the column-scaled J'J (condition > STDERR_MAX_COND): a combination the data do not
    determine, e.g. ks and alpha of a lobe narrower than the sample spacing (only ks/alpha^2 is
    seen), or Lafortune's rho and |C| (only rho |C|^n is seen).
    """
    v = np.asarray(model.flatten(params))
    J = np.asarray(_jacobian_fn(model, loss)(jnp.asarray(v), data))
    lo, hi = model.bounds()
    span = hi - lo
    at_bound = (np.abs(v - lo) <= 1e-9 * span + 1e-300) | (np.abs(v - hi) <= 1e-9 * span)
    free = ~at_bound
    out: dict[str, np.ndarray | None] = {p.name: None for p in model.params}
    if not free.any() or not np.all(np.isfinite(J)):
        return out
    Jf = J[:, free]
    # Column scaling, so that the conditioning test does not depend on parameter units.
    scale = np.linalg.norm(Jf, axis=0)
    if np.any(scale == 0):
        scale = np.where(scale == 0, 1.0, scale)
    jtj = (Jf / scale).T @ (Jf / scale)
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


#: Steps per solve of the active-set loop (the solver restarts after each, keeping its iterate).
ROUND_STEPS = 20  # measured: 50 let the first round crawl along a bound for ~50 steps
#: A parameter within this fraction of its axis from a bound, with the gradient pointing out of
#: the box, is snapped onto the bound and held there.
NEAR_BOUND = 1e-3


def _axis_distance(model: Model, v: np.ndarray):
    """Distance of each flat parameter to its lower / upper bound, in fractions of its axis."""
    lo_all, hi_all = [], []
    i = 0
    for p in model.params:
        n = model.size(p)
        x = v[i : i + n]
        if p.scale == "log":
            a, b, y = np.log(p.lower), np.log(p.upper), np.log(np.maximum(x, p.lower))
        else:
            a, b, y = p.lower, p.upper, x
        w = max(b - a, 1e-300)
        lo_all.append((y - a) / w)
        hi_all.append((b - y) / w)
        i += n
    return np.concatenate(lo_all), np.concatenate(hi_all)


def _active_set_solve(m: Model, loss: str, solver: str, v0, data: Data, *, rtol, atol, max_steps):
    """Solve with an active set of parameters held at their bounds.

    The fold transform (models.base) keeps iterates in the box, but when the optimum lies *on* a
    bound (ks = 1, kd = 0 ...) the loss seen by the solver has a kink there (a reflection), and a
    Gauss-Newton method zig-zags across it, or stops early beside it. So the solve runs in rounds
    of at most ROUND_STEPS steps: after each, parameters within NEAR_BOUND of a bound whose
    gradient points out of the box are snapped onto the bound and held (zero Jacobian column),
    and held parameters whose gradient points back into the box are released (KKT check). It
    ends when a round converges with an unchanged active set, or after ``max_steps`` in total.
    """
    v = np.asarray(v0, dtype=np.float64).copy()
    lo, hi = m.bounds()
    held = np.zeros(v.shape, bool)
    total_steps = 0
    compile_s = run_s = 0.0
    value, code = None, 1
    jac = _jacobian_fn(m, loss)
    res = flat_residual(m, loss)
    # BFGS builds its Hessian estimate over the iterations: a restart would throw it away.
    round_steps = max_steps if solver == "bfgs" else min(ROUND_STEPS, max_steps)
    while True:
        g = np.asarray(jac(jnp.asarray(v), data)).T @ np.asarray(res(jnp.asarray(v), data))
        d_lo, d_hi = _axis_distance(m, v)
        out_lo = (d_lo <= NEAR_BOUND) & (g > 0)
        out_hi = (d_hi <= NEAR_BOUND) & (g < 0)
        new_held = out_lo | out_hi
        if value is None:
            # First round: everything free. (Holding parameters that the start puts on a bound
            # can trap the solve in a corner that is a constrained local minimum only.)
            new_held = np.zeros(v.shape, bool)
            out_lo = out_hi = new_held
        elif code == 0 and np.array_equal(new_held, held):
            break
        if total_steps >= max_steps:
            code = code if code != 0 else 1
            break
        held = new_held
        v = np.where(out_lo, lo, np.where(out_hi, hi, v))
        x0 = jnp.asarray(m.to_unconstrained(m.unflatten(jnp.asarray(v))))
        x, value, code, steps, c_s, r_s = solve_optx(
            m, loss, solver, x0, data, ~held, rtol=rtol, atol=atol, max_steps=round_steps
        )
        total_steps += max(steps, 1)
        compile_s += c_s
        run_s += r_s
        v = np.asarray(m.flatten(m.from_unconstrained(jnp.asarray(x))))
    return v, value, code, total_steps, compile_s, run_s


def _start_from(init, model: Model) -> np.ndarray:
    if isinstance(init, FitResult):
        init = init.params
    if isinstance(init, str):
        if init != "defaults":
            raise UsageError(f"init must be None, 'defaults', a params dict or a FitResult, not {init!r}")
        init = model.defaults()
    if not isinstance(init, Mapping):
        raise UsageError(f"init must be None, 'defaults', a params dict or a FitResult, not {type(init).__name__}")
    full = dict(model.defaults())
    full.update({k: v for k, v in init.items()})
    try:
        v = np.asarray(model.flatten(full))
    except ValueError as exc:
        raise UsageError(f"init: {exc}") from None
    lo, hi = model.bounds()
    return np.clip(v, lo, hi)


def fit(
    measurement: Measurement,
    model: str | Model,
    *,
    loss: str = "log",
    solver: str = "lm",
    init=None,
    multistart: int | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    rtol: float = DEFAULT_RTOL,
    atol: float = DEFAULT_ATOL,
    weights=None,
    scene=None,
    grid_budget: int = _init.GRID_BUDGET,
    scipy_jac: str = "exact",
) -> FitResult:
    """Fit ``model`` to ``measurement``.

    loss: l2 | cosine_l2 | log | cbrt | relative. solver: lm | gauss_newton | dogleg | bfgs | scipy.
    init: None (variable-projection grid search, see ``brdffit.fitting.init``), "defaults", a
    params dict (missing parameters take their defaults) or a FitResult. multistart: polish this
    many further grid starts and keep the best; None (default) polishes AUTO_RETRIES further
    starts only when the first solve does not converge. Non-convergence is reported in ``.status``, never
    raised; parameters are never NaN. scene: a ``brdffit.scene.Usage`` (``brdffit.scene_usage``):
    the samples are weighted by where that scene looks (``usage.weights``), times ``weights``.
    """
    if scene is not None:  # SPEC 12
        weights = scene.weights(measurement) * (1.0 if weights is None else np.asarray(weights, np.float64))
    loss = check_loss(loss)
    solver = check_solver(solver)
    if max_steps < 1:
        raise UsageError("max_steps must be at least 1")
    prep = prepare(measurement, weights)
    m = resolve_model(model, prep.channels)
    data = prep.data

    compile_s = run_s = init_s = 0.0
    auto = multistart is None
    extra = AUTO_RETRIES if auto else max(0, int(multistart))
    if init is None:
        starts, _, c_s, r_s = _init.best_starts(m, loss, data, k=1 + extra, budget=grid_budget)
        compile_s += c_s
        run_s += r_s
        init_s = c_s + r_s
    else:
        starts = _start_from(init, m)[None, :]

    best = None
    for v0 in starts:
        if solver == "scipy":
            v, value, code, steps, c_s, r_s = solve_scipy(
                m, loss, v0, data, rtol=rtol, atol=atol, max_steps=max_steps, jac=scipy_jac
            )
        elif solver == "lmb":
            v, value, code, steps, c_s, r_s = solve_lmb(m, loss, v0, data, rtol=rtol, atol=atol, max_steps=max_steps)
        else:
            v, value, code, steps, c_s, r_s = _active_set_solve(
                m, loss, solver, v0, data, rtol=rtol, atol=atol, max_steps=max_steps
            )
        compile_s += c_s
        run_s += r_s
        # Prefer a converged solve; among equals, the lower loss.
        if best is None or (code == 0, -value) > (best[2] == 0, -best[1]):
            best = (v, value, code, steps, v0)
        if auto and code == 0:
            break
    v, value, code, steps, v0 = best

    params = {k: np.asarray(a) for k, a in m.unflatten(jnp.asarray(v)).items()}
    metrics = evaluate(m, params, data)
    stderr = standard_errors(m, loss, params, data, value, prep.n_used * prep.channels)
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
        seconds={"compile": compile_s, "run": run_s, "init": init_s},
        solver=solver,
        data_name=measurement.name,
        n_used=prep.n_used,
        n_excluded=prep.n_excluded,
        excluded=prep.excluded,
        stderr=stderr,
        start={k: np.asarray(a) for k, a in m.unflatten(jnp.asarray(v0)).items()},
        options={"max_steps": max_steps, "rtol": rtol, "atol": atol, "multistart": None if multistart is None else int(multistart),
                 "init": "grid" if init is None else "given"},
    )
