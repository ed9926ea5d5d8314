"""Solvers: optimistix (LM, Gauss-Newton, dogleg, BFGS) compiled once per problem shape, and
scipy's ``least_squares`` (TRF) as the reference baseline.

Compiled solves are cached per (model, loss, solver, tolerances, max_steps, argument shapes): the
measurement arrays are arguments, so a second data set of the same shape costs no compile.
Every solve runs with ``throw=False`` and returns a status; its result is never NaN: if the final
iterate is non-finite, or worse than the start, the start is returned (it is always finite) and
the status says so.
"""

from __future__ import annotations

import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np
import lineax as lx
import optimistix as optx

from ..errors import UsageError
from ..models.base import Model
from .problem import Data, flat_residual, unconstrained_residual

SOLVERS = ("lm", "gauss_newton", "dogleg", "bfgs", "lmb", "scipy")
_ALIASES = {"levenberg_marquardt": "lm", "gn": "gauss_newton", "gaussnewton": "gauss_newton", "trf": "scipy"}

DEFAULT_RTOL = 1e-7
DEFAULT_ATOL = 1e-10
DEFAULT_MAX_STEPS = 200

# optimistix result codes -> short status text.
STATUS_OK = "converged"


def check_solver(solver: str) -> str:
    key = str(solver).strip().lower()
    key = _ALIASES.get(key, key)
    if key not in SOLVERS:
        raise UsageError(f"unknown solver {solver!r}; known: {', '.join(SOLVERS)}")
    return key


def make_solver(name: str, rtol: float, atol: float):
    # Parameters held at a bound (active set, see ``fit``) have zero Jacobian columns: the
    # undamped Gauss-Newton step then needs a solver for rank-deficient systems (SVD).
    if name == "lm":
        return optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    if name == "gauss_newton":
        return optx.GaussNewton(rtol=rtol, atol=atol, linear_solver=lx.SVD())
    if name == "dogleg":
        return optx.Dogleg(rtol=rtol, atol=atol, linear_solver=lx.SVD())
    if name == "bfgs":
        # A minimiser: optimistix minimises the sum of squares of the residual.
        return optx.BFGS(rtol=rtol, atol=atol)
    raise ValueError(name)


def _status_code(result) -> jax.Array:
    """optimistix RESULTS -> int: 0 ok, 1 max steps, 2 diverged, 3 non-finite, 4 other."""
    R = optx.RESULTS
    return jnp.select(
        [result == R.successful, result == R.nonlinear_max_steps_reached, result == R.nonlinear_divergence,
         result == R.nonfinite],
        [0, 1, 2, 3],
        4,
    )


STATUS_TEXT = {
    0: STATUS_OK,
    1: "did not converge: maximum number of steps reached",
    2: "did not converge: the solve diverged",
    3: "did not converge: non-finite values during the solve",
    4: "did not converge: the solver failed",
}


#: Column scale the solver sees: each Jacobian column has this norm at the start (see _solve_core).
COLUMN_NORM = 30.0


def _solve_core(model: Model, loss: str, solver_name: str, rtol: float, atol: float, max_steps: int):
    """The jit-able solve. The solver works on z = x * s with s = |J_j(x0)| / COLUMN_NORM.

    Why: optimistix's Levenberg-Marquardt damps with lambda * I and starts at lambda = 1, shrinking it
    by 3.5x per accepted step; its dogleg starts with a unit trust radius and BFGS with an identity
    Hessian. Our Jacobians have column norms of 1e-3..1e2 (log residuals, log-axis roughness), so
    unscaled they spent 60-160 steps reaching the Gauss-Newton regime (measured on the RGL files).
    Jacobi scaling makes lambda * I act like Marquardt's diag(J^T J) damping, and a column norm of 30
    makes lambda = 1 a mild (1e-3 relative) damping, so the first steps are nearly Gauss-Newton.
    """
    base = unconstrained_residual(model, loss)
    solver = make_solver(solver_name, rtol, atol)

    # [params] lo, hi (flat, may be infinite): the fit's box (ParameterSpace), runtime arguments.
    def fn_x(x, data, free, anchor, lo, hi):
        # Held parameters (free = False) stay at their anchor value; their columns are zero.
        return base(jnp.where(free, x, anchor), data, lo, hi)

    def fn(z, args):
        data, free, anchor, scale, lo, hi = args
        return fn_x(z / scale, data, free, anchor, lo, hi)

    def loss_of(x, data, free, anchor, lo, hi):
        r = fn_x(x, data, free, anchor, lo, hi)
        return jnp.sum(r**2)

    def run(x0, data, free, lo, hi):
        jac = jax.jacfwd(fn_x)(x0, data, free, x0, lo, hi)
        norms = jnp.sqrt(jnp.sum(jac**2, axis=0))
        norms = jnp.where(jnp.isfinite(norms), norms, 0.0)
        # A column that is ~0 at the start (a lobe with rho = 0) must not get a huge z-step.
        norms = jnp.maximum(norms, 1e-3 * jnp.max(norms)) / COLUMN_NORM
        scale = jnp.where(norms > 0, norms, 1.0)
        args = (data, free, x0, scale, lo, hi)
        sol = optx.least_squares(fn, solver, x0 * scale, args=args, max_steps=max_steps, throw=False)
        x = jnp.where(free, sol.value / scale, x0)
        l0 = loss_of(x0, data, free, x0, lo, hi)
        l1 = loss_of(x, data, free, x0, lo, hi)
        ok = jnp.all(jnp.isfinite(x)) & jnp.isfinite(l1) & (l1 <= l0)
        code = _status_code(sol.result)
        # Fallback: the start (finite by construction) when the solve produced junk.
        code = jnp.where(ok | (code != 0), code, 2)
        code = jnp.where(jnp.isfinite(l1) | (code != 0), code, 3)
        x = jnp.where(ok, x, x0)
        value = jnp.where(ok, l1, l0)
        steps = sol.stats["num_steps"]
        return x, value, code, steps

    return run


@dataclasses.dataclass
class _Compiled:
    fn: object
    compile_s: float


_CACHE: dict = {}


def _shape_key(tree):
    return tuple((a.shape, str(a.dtype)) for a in jax.tree_util.tree_leaves(tree))


def compiled_solve(model, loss, solver_name, rtol, atol, max_steps, x0, data, free, lo, hi, batched: bool = False):
    """The compiled solve for these shapes, and its compile time (0 when cached)."""
    key = (model, loss, solver_name, rtol, atol, max_steps, _shape_key((x0, data, free, lo, hi)), batched)
    hit = _CACHE.get(key)
    if hit is not None:
        return hit.fn, 0.0
    core = _solve_core(model, loss, solver_name, rtol, atol, max_steps)
    fn = jax.vmap(core) if batched else core
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(x0, data, free, lo, hi).compile()
    dt = time.perf_counter() - t0
    _CACHE[key] = _Compiled(compiled, dt)
    return compiled, dt


def solve_optx(model, loss, solver_name, x0, data, free, lo, hi, *, rtol, atol, max_steps):
    """Returns (x, loss value, status code, steps, compile s, run s); ``free`` (P,) bool marks
    the parameters the solver may move (the others stay at x0); ``lo, hi``: the flat box."""
    free = jnp.asarray(free, dtype=bool)
    lo, hi = jnp.asarray(lo, dtype=jnp.float64), jnp.asarray(hi, dtype=jnp.float64)
    fn, compile_s = compiled_solve(model, loss, solver_name, rtol, atol, max_steps, x0, data, free, lo, hi)
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(x0, data, free, lo, hi))
    run_s = time.perf_counter() - t0
    x, value, code, steps = (np.asarray(a) for a in out)
    return x, float(value), int(code), int(steps), compile_s, run_s


_SCIPY_CACHE: dict = {}


def _scipy_fns(model, loss, v0, data):
    key = (model, loss, _shape_key((v0, data)))
    hit = _SCIPY_CACHE.get(key)
    if hit is not None:
        return hit, 0.0
    fn = flat_residual(model, loss)
    t0 = time.perf_counter()
    res = jax.jit(fn).lower(v0, data).compile()
    jac = jax.jit(jax.jacfwd(fn)).lower(v0, data).compile()
    dt = time.perf_counter() - t0
    _SCIPY_CACHE[key] = (res, jac)
    return (res, jac), dt


def solve_scipy(model, loss, v0, data, lo, hi, free, *, rtol, atol, max_steps, jac: str = "exact"):
    """scipy.optimize.least_squares (TRF, bounded) on the flat parameter vector.

    ``jac="exact"`` uses the JAX Jacobian; "2-point"/"3-point" scipy's finite differences.
    ``lo, hi`` (may be infinite), ``free``: the fit's box; held entries stay at v0 (scipy sees
    only the free ones: it needs lo < hi).
    Returns (v, loss value, status code, steps (function evaluations), compile s, run s).
    """
    from scipy.optimize import least_squares

    (res, jacf), compile_s = _scipy_fns(model, loss, jnp.asarray(v0), data)
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    free = np.asarray(free, dtype=bool)
    full0 = np.clip(np.asarray(v0, dtype=np.float64), lo, hi)

    def embed(u):
        out = full0.copy()
        out[free] = u
        return out

    def f(u):
        return np.asarray(res(jnp.asarray(embed(u)), data))

    def j(u):
        return np.asarray(jacf(jnp.asarray(embed(u)), data))[:, free]

    v0 = full0[free]
    t0 = time.perf_counter()
    sol = least_squares(
        f, v0, jac=j if jac == "exact" else jac, bounds=(lo[free], hi[free]), method="trf",
        ftol=max(rtol, 1e-15), xtol=max(rtol, 1e-15), gtol=max(atol, 1e-15), max_nfev=max_steps * 10,
    )
    run_s = time.perf_counter() - t0
    v = embed(sol.x)
    value = float(np.sum(sol.fun**2))
    code = 0 if sol.status > 0 else (1 if sol.status == 0 else 4)
    if not (np.all(np.isfinite(v)) and np.isfinite(value)):
        v, value, code = full0, float(np.sum(f(v0) ** 2)), 3
    return v, value, code, int(sol.nfev), compile_s, run_s


# -- brdffit's own bounded Levenberg-Marquardt ("lmb") -----------------------------------------
def _lmb_core(model: Model, loss: str, rtol: float, atol: float, max_steps: int):
    """Projected Levenberg-Marquardt on the bounded parameter values (no fold transform).

    Each iteration: one forward-mode Jacobian (``jax.linearize`` + vmap: P JVPs), the small P x P
    normal equations with Marquardt's diagonal scaling (H + lam diag H) d = -g solved by Cholesky
    over the *free* parameters (those on a bound whose gradient points out of the box are held:
    an active set recomputed every iteration), the step clipped to the box, Nielsen's damping
    update. Converged when the relative decrease of the loss and the relative step are both below
    rtol (or the projected gradient is below atol).
    """
    fn = flat_residual(model, loss)

    # [params] lo, hi: the fit's flat box (may be infinite), runtime arguments.
    def run(v0, data, free_mask, lo, hi):
        P = v0.shape[0]
        # Relative-step test: a finite scale per entry (an infinite box has none).
        box_scale = jnp.where(jnp.isfinite(hi - lo), hi - lo, 0.0) * 1e-6
        eye = jnp.eye(P, dtype=v0.dtype)

        def lin(v):
            r, f_jvp = jax.linearize(lambda u: fn(u, data), v)
            J = jax.vmap(f_jvp, out_axes=1)(eye)
            return r, J

        def cost(v):
            r = fn(v, data)
            return jnp.sum(r * r)

        r0, J0 = lin(v0)

        def body(state):
            v, r, J, lam, nu, k, done, code = state
            c = jnp.sum(r * r)
            g = J.T @ r
            H = J.T @ J
            held = (~free_mask) | ((v <= lo) & (g > 0)) | ((v >= hi) & (g < 0))
            gf = jnp.where(held, 0.0, g)
            dH = jnp.maximum(jnp.diag(H), 1e-30)
            A = H + lam * jnp.diag(dH)
            mask2 = (~held)[:, None] & (~held)[None, :]
            # Held parameters: identity rows / columns, zero gradient -> zero step.
            A = jnp.where(mask2, A, eye)
            L = jnp.linalg.cholesky(A)
            d = -jax.scipy.linalg.cho_solve((L, True), gf)
            d = jnp.where(jnp.all(jnp.isfinite(d)), d, -gf / dH)
            v_new = jnp.clip(v + d, lo, hi)
            step = v_new - v
            c_new = cost(v_new)
            pred = -(2.0 * gf @ step + step @ (H @ step))
            rho = (c - c_new) / jnp.maximum(pred, 1e-300)
            accept = jnp.isfinite(c_new) & (c_new < c)
            lam_acc = lam * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            lam = jnp.where(accept, lam_acc, lam * nu)
            nu = jnp.where(accept, 2.0, nu * 2.0)
            v_next = jnp.where(accept, v_new, v)
            r_next, J_next = jax.lax.cond(accept, lin, lambda _: (r, J), v_next)
            small_f = accept & ((c - c_new) <= rtol * c + atol**2)
            small_x = jnp.max(jnp.abs(step) / (jnp.abs(v) + atol + box_scale)) <= rtol * 10
            pg = jnp.max(jnp.abs(jnp.where(held, 0.0, J_next.T @ r_next)))
            conv = (small_f & small_x) | (pg <= atol) | (~accept & (lam > 1e16))
            return v_next, r_next, J_next, lam, nu, k + 1, conv, jnp.where(conv, 0, code)

        def cond(state):
            return (~state[6]) & (state[5] < max_steps)

        state = (v0, r0, J0, jnp.asarray(1e-3, v0.dtype), jnp.asarray(2.0, v0.dtype), 0, False, 1)
        v, r, J, lam, nu, k, done, code = jax.lax.while_loop(cond, body, state)
        l0 = cost(v0)
        l1 = jnp.sum(r * r)
        ok = jnp.all(jnp.isfinite(v)) & jnp.isfinite(l1)
        return jnp.where(ok, v, v0), jnp.where(ok, l1, l0), jnp.where(ok, code, 3), k

    return run


_LMB_CACHE: dict = {}


def solve_lmb(model, loss, v0, data, lo, hi, free, *, rtol, atol, max_steps):
    """Returns (v, loss value, status code, steps, compile s, run s); ``lo, hi, free``: the box."""
    lo, hi = jnp.asarray(lo, dtype=jnp.float64), jnp.asarray(hi, dtype=jnp.float64)
    v0 = jnp.clip(jnp.asarray(v0, dtype=jnp.float64), lo, hi)
    free = jnp.asarray(free, dtype=bool)
    key = (model, loss, rtol, atol, max_steps, _shape_key((v0, data)))
    compiled = _LMB_CACHE.get(key)
    compile_s = 0.0
    if compiled is None:
        t0 = time.perf_counter()
        compiled = jax.jit(_lmb_core(model, loss, rtol, atol, max_steps)).lower(v0, data, free, lo, hi).compile()
        compile_s = time.perf_counter() - t0
        _LMB_CACHE[key] = compiled
    t0 = time.perf_counter()
    out = jax.block_until_ready(compiled(v0, data, free, lo, hi))
    run_s = time.perf_counter() - t0
    v, value, code, steps = (np.asarray(a) for a in out)
    return v, float(value), int(code), int(steps), compile_s, run_s
