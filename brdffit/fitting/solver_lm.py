"""``lm``, the default solver: brdffit's bounded Levenberg-Marquardt as an optimistix solver (docs/fitting.md#fitting).

:class:`BoundedLevenbergMarquardt` is a projected Levenberg-Marquardt written as an optimistix
least-squares solver and run by ``optx.least_squares(..., throw=False)``: bounds are handled inside
every iteration (the step is projected onto the box, and parameters on a bound whose gradient points
out of it are held for that iteration: an active set recomputed at every step), so a fit is one
compiled call with no Python rounds around it, and it vmaps (several starts of one fit, the texels
of a BTF). The bounds ``lower``/``upper`` (may be -inf/+inf) and the mask ``free`` (False: held at
the start value) are *runtime* arrays (optimistix ``options``), so one compiled solver serves any
bounds. Tolerances are relative, so that a table multiplied by 1e-12 converges exactly as the
original.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._fit_defaults import START_DAMPING
from .linalg import inverse_quadratic_form, spd_solve
from .objective import Objective
from .state import Resume

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Array, Bool, Float, Int


def status_code(result) -> jax.Array:
    """optimistix RESULTS -> int: 0 ok, 1 max steps, 2 diverged, 3 non-finite, 4 other."""
    R = optx.RESULTS
    return jnp.select(
        [result == R.successful, result == R.nonlinear_max_steps_reached, result == R.nonlinear_divergence,
         result == R.nonfinite],
        [0, 1, 2, 3],
        4,
    )


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
    taken: Int[Array, ""]  # steps of this solve (the budget of ``options["steps"]``)


def _normal_equations(fn, y, args):
    """Loss r.r, gradient J^T r and Gauss-Newton matrix J^T J at y for any residual ``fn``, with
    the Jacobian by forward mode (the generic route; a fit passes the structured
    ``objective.normal_equations`` of its model instead)."""
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
    the start value); ``damping``: lam of the first step (default ``START_DAMPING``). The start must lie in
    the box.

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
    #: ``objective.normal_equations`` gives a model's exact, cheaper form.
    normal_equations: Callable | None = eqx.field(static=True, default=None)

    def _normal(self, fn, y, args):
        if self.normal_equations is None:
            return _normal_equations(fn, y, args)
        return self.normal_equations(y, args)

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        resume = options.get("resume")
        if resume is not None:
            # A solve continued from a previous round's state (:class:`Resume`): exactly the iteration
            # that one long solve would have run, with no evaluation at the start.
            return _LMState(c=resume.c, c0=resume.c0, g=resume.g, H=resume.H, lam=resume.lam, nu=resume.nu,
                            done=jnp.asarray(False), result=optx.RESULTS.successful, taken=jnp.asarray(0))
        c, g, H = self._normal(fn, y, args)
        dtype = y.dtype
        lam = jnp.asarray(options.get("damping", START_DAMPING), dtype)
        return _LMState(c=c, c0=c, g=g, H=H, lam=lam, nu=jnp.asarray(2.0, dtype),
                        done=jnp.asarray(False), result=optx.RESULTS.successful, taken=jnp.asarray(0))

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
        new_state = _LMState(c=c_next, c0=state.c0, g=g_next, H=H_next, lam=lam_next, nu=nu_next, done=done, result=result,
                             taken=state.taken + 1)
        return y_next, new_state, None

    def terminate(self, fn, y, args, options, state: _LMState, tags):
        # ``options["steps"]``: this solve's budget at run time (a round of a fit solved in rounds), below the
        # compiled ``max_steps``: one compiled solve serves every round.
        budget = options.get("steps")
        if budget is None:
            return state.done, state.result
        spent = ~state.done & (state.taken >= budget)
        return state.done | spent, optx.RESULTS.where(spent, optx.RESULTS.nonlinear_max_steps_reached, state.result)

    def postprocess(self, fn, y, aux, args, options, state: _LMState, tags, result):
        return y, aux, {"resume": Resume(state.c, state.c0, state.g, state.H, state.lam, state.nu), "done": state.done}


def solve_lm(objective: Objective, rtol: float, atol: float, max_steps: int):
    """run(v0 (P,), data, lo, hi, free, consts, resume=None, steps=None, damping=None) -> (v, Resume, done, code,
    steps) with :class:`BoundedLevenbergMarquardt` on the model's structured normal equations: at most ``max_steps``
    steps (or ``steps``, a run-time budget below it) from v0 (``damping``: the first step's, a run-time scalar;
    None: ``START_DAMPING``), or from a previous round's ``resume`` (then v0 is that round's v).
    ``Resume.c`` is the loss at v, ``Resume.H`` J^T J there, ``Resume.c0`` the loss at the first start;
    ``done``: the solver's own test passed."""
    fn, ne = objective.residual, objective.normal_equations
    # args = (data, g(f_ref), direction-only terms): computed once per fit, not at every step.
    solver = BoundedLevenbergMarquardt(rtol=rtol, atol=atol, normal_equations=lambda y, a: ne(y, *a))

    def run(v0, data, lo, hi, free, consts, resume=None, steps=None, damping=None):
        v0 = jnp.clip(v0, lo, hi)
        options = {"lower": lo, "upper": hi, "free": free, "loss_floor": consts.loss_floor}
        if damping is not None:
            options["damping"] = damping
        if resume is not None:
            options["resume"] = resume
        if steps is not None:
            options["steps"] = steps
        sol = optx.least_squares(lambda v, a: fn(v, a[0]), solver, v0, args=(data, consts.g_ref, consts.geometry),
                                 options=options, max_steps=max_steps, throw=False)
        # The iterate moves only to accepted points (finite, lower loss): the final state's
        # loss and J^T J are those of sol.value, and the start's loss is in the state.
        return sol.value, sol.stats["resume"], sol.stats["done"], status_code(sol.result), sol.stats["num_steps"]

    return run
