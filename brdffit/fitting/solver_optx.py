"""optimistix's stock solvers (``optx_lm``, ``gauss_newton``, ``dogleg``, ``bfgs``; docs/fitting.md#fitting).

They know no bounds: they see an unconstrained variable, mapped onto the box element by element by
:func:`to_box` (a fold, on a log axis for parameters with a positive lower bound), and a Jacobi
scaling of its columns (see :func:`solve_stock`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from ..models.base import _fold
from .objective import Objective
from .solver_lm import status_code


def _log_axis(lo):
    """Parameters with a positive lower bound (roughness, exponents) move on a log axis."""
    return lo > 0


def to_box(x, lo, hi):
    """Unconstrained x -> a value in [lo, hi], element by element, slope +-1 on the solver's axis:
    a fold (triangle wave) for a finite box, a reflection lo + |x - lo| (or hi - |hi - x|) for a
    half-infinite one, the identity when unbounded. Positive lower bounds use a log axis."""
    log = _log_axis(lo)
    a = jnp.where(log, jnp.log(jnp.where(log, lo, 1.0)), lo)
    b = jnp.where(log, jnp.log(jnp.where(log, hi, 1.0)), hi)
    y = _fold(x, a, b)  # the models' own fold (one definition)
    return jnp.where(log, jnp.exp(y), y)


def from_box(v, lo, hi):
    """Inverse of :func:`to_box` on the box."""
    log = _log_axis(lo)
    v = jnp.clip(v, lo, hi)
    return jnp.where(log, jnp.log(jnp.where(log, v, 1.0)), v)


def stock_solver(name: str, rtol: float, atol: float):
    """optimistix's solver object behind a stock solver's name."""
    # optimistix stops when every |change| < atol + rtol |value|, per residual and per unknown:
    # with atol = 0, a residual or unknown that is exactly 0 and stays so (an excluded sample,
    # weight 0; a parameter held at 0) gives 0/0 = NaN, and the solve never stops (seen: any
    # weight-0 sample ran gauss_newton, dogleg and optx_lm to max_steps). The smallest normal
    # float is no tolerance at all otherwise.
    atol = max(float(atol), float(np.finfo(np.float64).tiny))
    # Held parameters have zero Jacobian columns: the undamped Gauss-Newton step needs a solver
    # for rank-deficient systems (SVD).
    if name == "optx_lm":
        return optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    if name == "gauss_newton":
        return optx.GaussNewton(rtol=rtol, atol=atol, linear_solver=lx.SVD())
    if name == "dogleg":
        return optx.Dogleg(rtol=rtol, atol=atol, linear_solver=lx.SVD())
    if name == "bfgs":
        return optx.BFGS(rtol=rtol, atol=atol)  # a minimiser of the sum of squares
    raise ValueError(name)


#: Column norm the stock solvers see at the start (Jacobi scaling, see :func:`solve_stock`).
COLUMN_NORM = 30.0


def solve_stock(objective: Objective, name: str, rtol: float, atol: float, max_steps: int):
    """run(v0 (P,), data, lo, hi, free, consts) -> (v, Resume, done, code, steps) with the stock solver
    ``name`` (``Resume``: the loss at v and at v0, J^T J at v; the damping entries 0: a stock solve does
    not continue)."""
    from .state import Resume

    fn, ne, loss_of = objective.residual, objective.normal_equations, objective.loss_at
    solver = stock_solver(name, rtol, atol)

    def run(v0, data, lo, hi, free, consts):
        """The stock solver works on z = x * s, x = from_box(v), s = |J_j(x0)| / COLUMN_NORM.

        Why: optimistix's Levenberg-Marquardt damps with lambda * I starting at 1, its dogleg
        starts with a unit trust radius and BFGS with an identity Hessian; our Jacobian columns
        span 1e-3..1e2, and unscaled they spent 60-160 steps reaching the Gauss-Newton regime.
        Jacobi scaling makes lambda * I act like Marquardt's damping. The residuals are divided by their
        norm at the start: the same objective up to a constant factor (the same optimum), and the solver
        sees numbers of order one whatever the table's unit (BFGS's first step is the gradient itself: at
        x1e-12 it stopped "converged" at 3x the optimum's loss)."""
        v0 = jnp.clip(v0, lo, hi)
        x0 = from_box(v0, lo, hi)
        r0 = fn(v0, data)
        size = jnp.sqrt(r0 @ r0)
        size = jnp.where(jnp.isfinite(size) & (size > 0), size, 1.0)

        def fn_x(x, data):
            # Held parameters stay at their start value; their columns are zero.
            return fn(to_box(jnp.where(free, x, x0), lo, hi), data) / size

        jac = jax.jacfwd(fn_x)(x0, data)
        norms = jnp.sqrt(jnp.sum(jac**2, axis=0))
        norms = jnp.where(jnp.isfinite(norms), norms, 0.0)
        # A floor for near-zero columns, on the effect of a *relative* change of each variable: a scale of a
        # table x1e12 is ~1e11 with a column ~1e-11, and an absolute floor took it for a dead column (BFGS
        # did not move in 200 steps).
        magnitude = jnp.where(x0 != 0, jnp.abs(x0), 1.0)
        effect = norms * magnitude
        norms = jnp.maximum(effect, 1e-3 * jnp.max(effect)) / magnitude / COLUMN_NORM
        scale = jnp.where(norms > 0, norms, 1.0)
        sol = optx.least_squares(lambda z, d: fn_x(z / scale, d), solver, x0 * scale, args=data,
                                 max_steps=max_steps, throw=False)
        v = to_box(jnp.where(free, sol.value / scale, x0), lo, hi)
        code = status_code(sol.result)
        zero = jnp.zeros((), v.dtype)
        state = Resume(loss_of(v, data, consts), loss_of(v0, data, consts), jnp.zeros_like(v), ne(v, data)[2], zero, zero)
        return v, state, code == 0, code, sol.stats["num_steps"]

    return run
