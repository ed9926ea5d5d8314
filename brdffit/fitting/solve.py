"""Solvers (SPEC 5).

``lm`` (the default) is :class:`BoundedLevenbergMarquardt`, brdffit's projected Levenberg-Marquardt
written as an optimistix least-squares solver and run by ``optx.least_squares(..., throw=False)``:
bounds are handled inside every iteration (the step is projected onto the box, and parameters on a
bound whose gradient points out of it are held for that iteration: an active set recomputed at
every step), so a fit is one compiled call with no Python rounds around it, and it vmaps (several
starts of one fit, the texels of a BTF).

The bounds ``lower``/``upper`` (may be -inf/+inf) and the mask ``free`` (False: held at the start
value) are *runtime* arrays (optimistix ``options``), so one compiled solver serves any bounds.

optimistix's stock solvers stay selectable (``optx_lm``, ``gauss_newton``, ``dogleg``, ``bfgs``);
they see an unconstrained variable, mapped onto the box element by element by :func:`to_box`.
``scipy`` (``scipy.optimize.least_squares``, TRF) is the reference baseline.

Tolerances are relative, so that a table multiplied by 1e-12 converges exactly as the original
(see :class:`BoundedLevenbergMarquardt`); ``atol`` is an optional absolute floor on the loss
(0 by default). Every solve returns a status code (``STATUS_TEXT``); its result is never NaN.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from .._fit_defaults import DEFAULT_ATOL, DEFAULT_MAX_STEPS, DEFAULT_RTOL, SOLVERS  # noqa: F401
from ..models.base import Model, _fold
from . import losses as L
from .linalg import inverse_quadratic_form, spd_solve
from .problem import Data, flat_residual
from .cache import compiled

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Array, Bool, Float, Int


def _status_code(result) -> jax.Array:
    """optimistix RESULTS -> int: 0 ok, 1 max steps, 2 diverged, 3 non-finite, 4 other."""
    R = optx.RESULTS
    return jnp.select(
        [result == R.successful, result == R.nonlinear_max_steps_reached, result == R.nonlinear_divergence,
         result == R.nonfinite],
        [0, 1, 2, 3],
        4,
    )


# -- brdffit's bounded Levenberg-Marquardt as an optimistix solver ------------------------------
class _LMState(eqx.Module):
    # The normal equations at the current point, not the Jacobian: a small loop carry (the
    # (M, P) Jacobian would be copied through the loop at every step).
    c: Float[Array, ""]
    c0: Float[Array, ""]  # the loss at the start (what a result must not exceed)
    g: Float[Array, " P"]
    H: Float[Array, "P P"]
    lam: Float[Array, ""]
    nu: Float[Array, ""]
    done: Bool[Array, ""]
    result: optx.RESULTS


def _normal_equations(fn, y, args):
    """Loss r.r, gradient J^T r and Gauss-Newton matrix J^T J at y for any residual ``fn``, with
    the Jacobian by forward mode (the generic route; a fit passes the structured
    ``structure.normal_equations`` of its model instead)."""
    def f(u):
        r = fn(u, args)[0]
        return r, r

    J, r = jax.jacfwd(f, has_aux=True)(y)
    return r @ r, J.T @ r, J.T @ J


#: Largest factor by which a parameter with a positive lower bound changes in one step.
STEP_FACTOR = 4.0


class BoundedLevenbergMarquardt(optx.AbstractLeastSquaresSolver):
    """Projected Levenberg-Marquardt with an active set per iteration, for a flat parameter vector.

    options: ``lower``, ``upper`` (P,) bounds (may be infinite), ``free`` (P,) bool (False: held at
    the start value). The start must lie in the box.

    One iteration: with r and J the residual and Jacobian at the current point (forward mode),
    g = J^T r, H = J^T J. Held: parameters not free, and those on a bound whose gradient points
    out of the box. The free ones solve (H + lam diag H) d = -g (Marquardt's scaling, so lam is
    unitless; Cholesky on the Jacobi-scaled system), the trial point is v + d clipped to the box;
    it is accepted when the loss decreases, and lam follows Nielsen's update (gain ratio of actual
    to predicted decrease).

    Convergence (all relative, so invariant under scaling the data or a parameter's units):
    the actual and the predicted relative decrease of the loss are both <= rtol (MINPACK's ftol
    test); or first-order optimality: for every free parameter, the cosine between r and J_i is
    <= rtol; or an exact fit: a loss <= options["loss_floor"] (``fit_constants`` gives 1e-26 x the
    loss of the zero model, i.e. residuals at roundoff level relative to the data), or <= atol^2; or no damping (lam up to 1e16) finds a decrease
    (a minimum to machine precision). Otherwise the solve ends after max_steps with
    ``nonlinear_max_steps_reached``.
    """

    rtol: float
    atol: float = 0.0
    norm: Callable = optx.max_norm
    #: (y, args) -> (r.r, J^T r, J^T J) of the residual; None: forward mode over every entry of y.
    #: ``structure.normal_equations`` gives a model's exact, cheaper form.
    normal_equations: Callable | None = eqx.field(static=True, default=None)

    def _normal(self, fn, y, args):
        if self.normal_equations is None:
            return _normal_equations(fn, y, args)
        return self.normal_equations(y, args)

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        c, g, H = self._normal(fn, y, args)
        dtype = y.dtype
        return _LMState(c=c, c0=c, g=g, H=H, lam=jnp.asarray(1e-3, dtype), nu=jnp.asarray(2.0, dtype),
                        done=jnp.asarray(False), result=optx.RESULTS.successful)

    def step(self, fn, y, args, options, state: _LMState, tags):
        lo, hi, free = options["lower"], options["upper"], options["free"]
        c, g, H, lam, nu = state.c, state.g, state.H, state.lam, state.nu
        eye = jnp.eye(y.shape[0], dtype=y.dtype)
        held = (~free) | ((y <= lo) & (g > 0)) | ((y >= hi) & (g < 0))
        gf = jnp.where(held, 0.0, g)
        # Jacobi scaling (columns to unit norm; a zero column keeps scale 1): Marquardt's damping
        # lam diag(H) becomes lam I, and the solve does not depend on the parameters' units (no
        # floor relative to the largest column: kd and alpha columns of a table scaled by 1e-12
        # differ by 1e12).
        D = jnp.sqrt(jnp.diag(H))
        D = jnp.where((D > 0) & jnp.isfinite(D), D, 1.0)
        Hs = H / D[:, None] / D[None, :]
        mask2 = (~held)[:, None] & (~held)[None, :]
        A = jnp.where(mask2, Hs + lam * eye, eye)  # held: identity rows, zero gradient
        d = -spd_solve(A, gf / D) / D
        d = jnp.where(jnp.all(jnp.isfinite(d)), d, 0.0)
        # Parameters with a positive lower bound (roughness, exponents) move by at most a factor
        # STEP_FACTOR per step (a trust region on their log axis, scale-free): the roughness of a
        # lobe narrower than the sample spacing has a ~0 column, and its Gauss-Newton step
        # (1e16 on torrance_sparrow) would throw it to the far bound, so that every trial was
        # rejected and the damping ran out ("converged" at a poor point).
        pos = lo > 0
        lo_t = jnp.maximum(lo, jnp.where(pos, y / STEP_FACTOR, -jnp.inf))
        hi_t = jnp.minimum(hi, jnp.where(pos, y * STEP_FACTOR, jnp.inf))
        y_new = jnp.clip(y + d, lo_t, hi_t)
        step = y_new - y
        # The trial point's loss and normal equations together (one fused evaluation; a rejected
        # trial wastes the Jacobian, but near convergence nearly every trial is accepted, and
        # under vmap a branch would evaluate both sides anyway).
        c_new, g_new, H_new = self._normal(fn, y_new, args)
        pred = -(2.0 * gf @ step + step @ (H @ step))
        rho = (c - c_new) / jnp.maximum(pred, jnp.finfo(y.dtype).tiny)
        accept = jnp.isfinite(c_new) & (c_new < c) & jnp.all(jnp.isfinite(H_new))
        lam_next = jnp.where(accept, lam * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), lam * nu)
        nu_next = jnp.where(accept, 2.0, nu * 2.0)
        y_next = jnp.where(accept, y_new, y)
        c_next = jnp.where(accept, c_new, c)
        g_next = jnp.where(accept, g_new, g)
        H_next = jnp.where(accept, H_new, H)

        # MINPACK's test: both the actual and the predicted relative decrease are small.
        small_f = accept & ((c - c_new) <= self.rtol * c) & (pred <= self.rtol * c) & (rho <= 2.0)
        col = jnp.sqrt(jnp.diag(H_next))
        col = jnp.where(col > 0, col, 1.0)  # a zero column has a zero gradient
        held_next = (~free) | ((y_next <= lo) & (g_next > 0)) | ((y_next >= hi) & (g_next < 0))
        cosine = jnp.where(held_next, 0.0, jnp.abs(g_next) / (col * jnp.sqrt(c_next)))
        small_g = jnp.max(cosine) <= self.rtol
        # The Gauss-Newton decrement at the new point: the decrease a full (undamped) step of the
        # free parameters would bring, g^T H^-1 g. When it is <= rtol x the loss, the next step
        # would pass MINPACK's test above: stop now instead of taking it (one step fewer on
        # nearly every fit; measured on the shared RGL files).
        mask_next = (~held_next)[:, None] & (~held_next)[None, :]
        A_next = jnp.where(mask_next, H_next / col[:, None] / col[None, :], eye)
        gs = jnp.where(held_next, 0.0, g_next) / col
        decrement = inverse_quadratic_form(A_next, gs)
        small_dec = accept & jnp.isfinite(decrement) & (decrement >= 0) & (decrement <= self.rtol * c_next)
        exact = c_next <= jnp.maximum(self.atol**2, options.get("loss_floor", 0.0))
        stuck = (~accept) & (lam_next > 1e16)
        done = small_f | small_g | small_dec | exact | stuck
        result = optx.RESULTS.where(jnp.isfinite(c_next), optx.RESULTS.successful, optx.RESULTS.nonfinite)
        new_state = _LMState(c=c_next, c0=state.c0, g=g_next, H=H_next, lam=lam_next, nu=nu_next, done=done, result=result)
        return y_next, new_state, None

    def terminate(self, fn, y, args, options, state: _LMState, tags):
        return state.done, state.result

    def postprocess(self, fn, y, aux, args, options, state: _LMState, tags, result):
        return y, aux, {"loss": state.c, "loss0": state.c0, "jtj": state.H}


# -- optimistix's stock solvers on an unconstrained variable ------------------------------------
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


def make_solver(name: str, rtol: float, atol: float, normal_equations: Callable | None = None):
    """The optimistix solver object behind a solver name (not ``scipy``)."""
    if name == "lm":
        return BoundedLevenbergMarquardt(rtol=rtol, atol=atol, normal_equations=normal_equations)
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


#: Column norm the stock solvers see at the start (Jacobi scaling, see ``_stock_run``).
COLUMN_NORM = 30.0


def fit_constants(model: Model, loss: str, data: Data):
    """What every step of a fit shares and computes once (jit-able): g(f_ref) of the loss
    (``losses.reference_transform``), the direction-only terms of a separable model
    (``structure.precompute_geometry``, or None), and the loss of an exact fit relative to the
    data ((1e-13)^2 x the loss of f = 0: residuals at roundoff level)."""
    from .structure import precompute_geometry

    wi, wo, ref, sqrt_w, cos_i, floor = data
    # Materialised once: XLA would otherwise recompute g(f_ref) (a log1p per value) inside every
    # fusion that reads it (loss floor, start, result check, metrics).
    g_ref, geometry = jax.lax.optimization_barrier(
        (L.reference_transform(loss, ref, cos_i, floor), precompute_geometry(model, data)))
    r0 = L.residual(loss, jnp.zeros_like(ref), ref, cos_i, sqrt_w, floor, g_ref)
    return g_ref, geometry, 1e-26 * jnp.sum(r0 * r0)


def result_check(value, l0, v, code, loss_floor):
    """(ok, code): whether the solver's point v with loss ``value`` (evaluated afresh) may stand,
    i.e. is finite and no worse than the start's loss l0 beyond roundoff, whatever the solver
    claims; if not, a failure code (2: worse, 3: non-finite) unless the solver gave one. A point
    at the exact-fit floor is converged."""
    finite = jnp.all(jnp.isfinite(v)) & jnp.isfinite(value)
    ok = finite & (value <= l0 * (1 + 1e-9) + loss_floor)
    # Non-finite first: a NaN loss also fails the comparison, and must not read as "worse".
    mine = jnp.where(finite, jnp.where(ok, 0, 2), 3)
    code = jnp.where(code != 0, code, mine)
    # An exact fit (residuals at roundoff level) has converged, whatever the solver's own stopping
    # test said: optimistix's Gauss-Newton and BFGS test the change of every unknown, which an exact
    # fit with a direction the data do not determine never settles (issue 28: blinn_phong and
    # oren_nayar on their own noise-free data, rel_rmse 1e-15, "did not converge" after 200 steps).
    code = jnp.where(finite & (value <= loss_floor), 0, code)
    return ok, code


def solve_one(model: Model, loss: str, solver_name: str, rtol: float, atol: float, max_steps: int):
    """The jit-able solve of one start: run(v0 (P,), data, lo, hi, free, consts) -> (v, loss, code,
    steps, J^T J at v, loss at v0); ``consts``: :func:`fit_constants` of the data. The caller
    checks the result (:func:`result_check`, done by ``program.fit_program`` on the best start's
    result, with the loss evaluated afresh for the metrics anyway)."""
    from .structure import gauss_newton_matrix, model_values, normal_equations

    fn = flat_residual(model, loss)
    values = model_values(model)

    def loss_of(v, data, consts):
        # The model's values by the step's route (model.eval costs ~10x more on ggx/UBO-81).
        g_ref, geometry, _ = consts
        wi, wo, ref, sqrt_w, cos_i, floor = data
        r = L.residual(loss, values(v, data, geometry), ref, cos_i, sqrt_w, floor, g_ref)
        return jnp.sum(r * r)

    if solver_name == "lm":
        ne = normal_equations(model, loss)
        # args = (data, g(f_ref), direction-only terms): computed once per fit, not at every step.
        solver = make_solver("lm", rtol, atol, normal_equations=lambda y, a: ne(y, *a))

        def run(v0, data, lo, hi, free, consts):
            v0 = jnp.clip(v0, lo, hi)
            g_ref, geometry, floor_loss = consts
            sol = optx.least_squares(lambda v, a: fn(v, a[0]), solver, v0, args=(data, g_ref, geometry),
                                     options={"lower": lo, "upper": hi, "free": free, "loss_floor": floor_loss},
                                     max_steps=max_steps, throw=False)
            # The iterate moves only to accepted points (finite, lower loss): the final state's
            # loss and J^T J are those of sol.value, and the start's loss is in the state.
            return (sol.value, sol.stats["loss"], _status_code(sol.result), sol.stats["num_steps"],
                    sol.stats["jtj"], sol.stats["loss0"])

        return run

    solver = make_solver(solver_name, rtol, atol)
    jtj = gauss_newton_matrix(model, loss)

    def run(v0, data, lo, hi, free, consts):
        """The stock solver works on z = x * s, x = from_box(v), s = |J_j(x0)| / COLUMN_NORM.

        Why: optimistix's Levenberg-Marquardt damps with lambda * I starting at 1, its dogleg
        starts with a unit trust radius and BFGS with an identity Hessian; our Jacobian columns
        span 1e-3..1e2, and unscaled they spent 60-160 steps reaching the Gauss-Newton regime.
        Jacobi scaling makes lambda * I act like Marquardt's damping."""
        v0 = jnp.clip(v0, lo, hi)
        x0 = from_box(v0, lo, hi)

        def fn_x(x, data):
            # Held parameters stay at their start value; their columns are zero.
            return fn(to_box(jnp.where(free, x, x0), lo, hi), data)

        jac = jax.jacfwd(fn_x)(x0, data)
        norms = jnp.sqrt(jnp.sum(jac**2, axis=0))
        norms = jnp.where(jnp.isfinite(norms), norms, 0.0)
        norms = jnp.maximum(norms, 1e-3 * jnp.max(norms)) / COLUMN_NORM
        scale = jnp.where(norms > 0, norms, 1.0)
        sol = optx.least_squares(lambda z, d: fn_x(z / scale, d), solver, x0 * scale, args=data,
                                 max_steps=max_steps, throw=False)
        v = to_box(jnp.where(free, sol.value / scale, x0), lo, hi)
        return v, loss_of(v, data, consts), _status_code(sol.result), sol.stats["num_steps"], jtj(v, data), \
            loss_of(v0, data, consts)

    return run


def solve_starts(model: Model, loss: str, solver_name: str, rtol: float, atol: float, max_steps: int):
    """run(starts (K, P), data, lo, hi, free, consts) -> the best of K solves (one vmapped
    solve): (v, loss, code, steps, index of the start, J^T J at v, loss at the start).
    ``consts``: as ``solve_one``; the result is not yet checked (:func:`result_check`).

    The best is the lowest loss; the fit is converged when that solve's own test passed."""
    single = solve_one(model, loss, solver_name, rtol, atol, max_steps)
    batched = jax.vmap(single, in_axes=(0, None, None, None, None, None))

    def run(starts, data, lo, hi, free, consts):
        if starts.shape[0] == 1:
            # One start (every single-lobe fit): no batch axis of length 1 in the loop.
            out = single(starts[0], data, lo, hi, free, consts)
            v, value, code, steps, jtj, l0 = jax.tree_util.tree_map(lambda a: a[None], out)
        else:
            v, value, code, steps, jtj, l0 = batched(starts, data, lo, hi, free, consts)
        key = jnp.where(jnp.isfinite(value) & jnp.all(jnp.isfinite(v), axis=1), value, jnp.inf)
        i = jnp.argmin(key)
        return v[i], value[i], code[i], steps[i], i, jtj[i], l0[i]

    return run


def solve_scipy(model, loss, v0, data, lo, hi, free, *, rtol, atol, max_steps, jac: str):
    """scipy.optimize.least_squares (TRF, bounded) on the free parameters of the flat vector.

    ``jac="exact"`` uses the JAX Jacobian (jit-compiled); "2-point"/"3-point" scipy's finite
    differences. Returns (v, loss value, status code, steps (function evaluations), compile s, run s).
    """
    from scipy.optimize import least_squares

    fn = flat_residual(model, loss)
    example = (jnp.asarray(v0, dtype=jnp.float64), data)
    res, c1 = compiled(("scipy_res", model, loss), lambda: fn, *example)
    jacf, c2 = compiled(("scipy_jac", model, loss), lambda: jax.jacfwd(fn), *example)
    lo, hi, free = np.asarray(lo, float), np.asarray(hi, float), np.asarray(free, bool)
    v_full = np.clip(np.asarray(v0, dtype=np.float64), lo, hi)

    def expand(u):
        v = v_full.copy()
        v[free] = u
        return jnp.asarray(v)

    def f(u):
        return np.asarray(res(expand(u), data))

    def j(u):
        return np.asarray(jacf(expand(u), data))[:, free]

    t0 = time.perf_counter()
    sol = least_squares(
        f, v_full[free], jac=j if jac == "exact" else jac, bounds=(lo[free], hi[free]), method="trf",
        # scipy's gtol is absolute (on the scaled gradient): left at its floor, ftol/xtol stop it.
        ftol=max(rtol, 1e-15), xtol=max(rtol, 1e-15), gtol=1e-15, max_nfev=max_steps * 10,
    )
    run_s = time.perf_counter() - t0
    v = np.asarray(expand(sol.x))
    value = float(np.sum(sol.fun**2))
    code = 0 if sol.status > 0 else (1 if sol.status == 0 else 4)
    if not (np.all(np.isfinite(v)) and np.isfinite(value)):
        v, value, code = v_full, float(np.sum(f(v_full[free]) ** 2)), 3
    return v, value, code, int(sol.nfev), c1 + c2, run_s
