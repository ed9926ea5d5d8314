"""``scipy``: scipy.optimize.least_squares (TRF), the reference baseline (docs/fitting.md#fitting), run in Python
one start at a time (the JAX residual and Jacobian compiled through the program cache). The fit driver runs
it where the compiled solvers run their rounds (:func:`solve_lanes`): the starts, the re-seeding, the finish
and the status tests around it are every fit's."""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from .cache import compiled
from .objective import Objective
from .problem import Data
from .state import Rounds


def solve_scipy(objective: Objective, v0, data, lo, hi, free, *, rtol, atol, max_steps, jac: str):
    """scipy.optimize.least_squares (TRF, bounded) on the free parameters of the flat vector.

    ``jac="exact"`` uses the JAX Jacobian (jit-compiled); "2-point"/"3-point" scipy's finite
    differences. Returns (v, loss value, status code, steps (function evaluations), the loss at the
    start, compile s, run s).
    """
    from scipy.optimize import least_squares

    fn = objective.residual
    example = (jnp.asarray(v0, dtype=jnp.float64), data)
    res, c1 = compiled(("scipy_res", objective.model, objective.loss), lambda: fn, *example)
    jacf, c2 = compiled(("scipy_jac", objective.model, objective.loss), lambda: jax.jacfwd(fn), *example)
    lo, hi, free = np.asarray(lo, float), np.asarray(hi, float), np.asarray(free, bool)
    v_full = np.clip(np.asarray(v0, dtype=np.float64), lo, hi)

    def expand(u):
        v = v_full.copy()
        v[free] = u
        return jnp.asarray(v)

    # The residuals divided by their norm at the start (the same optimum; numbers of order one whatever the
    # table's unit), and TRF's variables scaled by the Jacobian's columns (x_scale="jac"): at x1e-12 scipy's
    # absolute gradient test stopped at 1e7 times the optimum's loss, and at x1e12 the kd ~ 1e11 hid
    # alpha's steps from its relative step test.
    r0 = np.asarray(res(jnp.asarray(v_full), data))
    start_value = float(r0 @ r0)
    size = float(np.sqrt(start_value))
    size = size if np.isfinite(size) and size > 0 else 1.0

    def f(u):
        return np.asarray(res(expand(u), data)) / size

    def j(u):
        return np.asarray(jacf(expand(u), data))[:, free] / size

    t0 = time.perf_counter()
    sol = least_squares(
        f, v_full[free], jac=j if jac == "exact" else jac, bounds=(lo[free], hi[free]), method="trf", x_scale="jac",
        # scipy's gtol is absolute (on the scaled gradient): left at its floor, ftol/xtol stop it.
        ftol=max(rtol, 1e-15), xtol=max(rtol, 1e-15), gtol=1e-15, max_nfev=max_steps * 10,
    )
    run_s = time.perf_counter() - t0
    v = np.asarray(expand(sol.x))
    value = float(np.sum(sol.fun**2)) * size**2
    code = 0 if sol.status > 0 else (1 if sol.status == 0 else 4)
    if not (np.all(np.isfinite(v)) and np.isfinite(value)):
        v, value, code = v_full, float(np.sum(f(v_full[free]) ** 2)) * size**2, 3
    return v, value, code, int(sol.nfev), start_value, c1 + c2, run_s


def solve_lanes(objective: Objective, v0: np.ndarray, data: Data, fits: np.ndarray, bounds: tuple, *, rtol: float,
                atol: float, max_steps: int, jac: str, progress=None) -> Rounds:
    """:func:`solve_scipy` from each start ``v0`` (L, P) on row ``fits[i]`` of the per-fit fields, one after
    another: the lanes of ``stages.solve_rounds``, with no J^T J (NaN: the driver's finish computes it)."""
    from .lanes import per_lane

    lo, hi, free = bounds
    lane = per_lane(data)
    rows = []
    for start, row in zip(v0, fits):
        one = Data(*(np.asarray(a)[row] if m else np.asarray(a) for a, m in zip(data, lane)))
        rows.append(solve_scipy(objective, start, one, lo, hi, free, rtol=rtol, atol=atol, max_steps=max_steps,
                                jac=jac))
        if progress is not None:
            progress(1 / len(fits))
    v, value, code, steps, start_value, c_s, r_s = (np.asarray(x) for x in zip(*rows)) if rows else [np.zeros(0)] * 7
    P = len(lo)
    return Rounds(v.reshape(-1, P), value, start_value, np.full((len(rows), P, P), np.nan), code.astype(int),
                  steps.astype(int), float(np.sum(c_s)), float(np.sum(r_s)))
