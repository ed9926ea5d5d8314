"""One compiled program per fit: start, solve, metrics (SPEC 5).

``fit``, ``fit_batch`` and ``fit_btf`` all run :func:`fit_program`: the variable-projection grid
on a subset of the samples (``init``), the best ``k`` candidates (grid points and any starts the
caller gives, ranked by their loss on that subset) solved at once (``solve.solve_starts``), then
every loss and metric and J^T J at the solution (the standard errors' need; the default solver
returns it from its last step). One dispatch per fit: a warm ggx fit spends its time in the
solve, not in Python between compiled pieces.

Compiled programs are kept per process and on disk (``cache.compiled``): a second process
loads the program without tracing it, and without importing optimistix (``solve``).

``fit_batch`` maps the same program over a batch (``jax.lax.map``: a vmapped solve would run
every lane until the slowest converges).
"""

from __future__ import annotations

import functools
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._fit_defaults import SOLVERS
from ..errors import UsageError
from ..models.base import Model
from . import init as _init
# compiled: the per-process and on-disk program cache (``cache``), imported from here too
from .cache import compiled  # noqa: F401
from .problem import Data, flat_residual, values_metrics

#: Solvers that run compiled (and vmap): everything but scipy.
COMPILED_SOLVERS = SOLVERS[:-1]
_ALIASES = {"levenberg_marquardt": "lm", "gn": "gauss_newton", "gaussnewton": "gauss_newton", "trf": "scipy"}




def check_solver(solver: str) -> str:
    key = str(solver).strip().lower()
    key = _ALIASES.get(key, key)
    if key not in SOLVERS:
        raise UsageError(f"unknown solver {solver!r}; known: {', '.join(SOLVERS)}")
    return key


@functools.lru_cache(maxsize=None)
def fit_program(model: Model, loss: str, solver: str, rtol: float, atol: float, max_steps: int, k: int,
                grid: bool = True):
    """run(grid (G, m), given (E, P), data, lo, hi, free, anchor, subset (S,) int) -> dict with
    ``v``, ``loss``, ``code``, ``steps``, ``start`` (the start the best solve came from),
    ``metrics`` (dict), ``jtj`` (P, P).

    Candidates: the G grid points (linear parameters solved at each) when ``grid``, and the E
    ``given`` starts; the k with the lowest loss on the ``subset`` rows start the solver
    (G + E >= k)."""
    from .solve import fit_constants, result_check as check, solve_starts  # optimistix: imported only when a program is traced
    from .structure import model_values

    vp = _init.vp_grid(model, loss)
    residual = flat_residual(model, loss)
    solve = solve_starts(model, loss, solver, rtol, atol, max_steps)
    model_at = model_values(model)

    def run(grid_points, given, data: Data, lo, hi, free, anchor, subset):
        sub = _init.take_rows(data, subset)
        given = jnp.where(free, jnp.clip(given, lo, hi), anchor)

        def subset_loss(v):
            r = residual(v, sub)
            value = r @ r
            return jnp.where(jnp.isfinite(value), value, jnp.inf)

        flats, values = [given], [jax.vmap(subset_loss)(given)]
        if grid:
            g_flats, g_values = vp(grid_points, sub, lo, hi, free, anchor)
            flats.insert(0, g_flats)
            values.insert(0, g_values)
        flats, values = jnp.concatenate(flats), jnp.concatenate(values)
        # Stable: among equal losses the grid (listed first) wins.
        starts = flats[jnp.argsort(values, stable=True)[:k]]
        consts = fit_constants(model, loss, data)
        best = solve(starts, data, lo, hi, free, consts)
        v, v0 = best.v, jnp.clip(starts[best.index], lo, hi)

        def metrics_at(u):
            return values_metrics(model_at(u, data, consts.geometry), data, (loss,))

        # The result's loss evaluated afresh (the metrics need the model's values anyway) checks
        # the solver's claim; a point worse than its start (or not finite) gives way to the start.
        metrics = metrics_at(v)
        ok, code = check(metrics[loss], best.start_loss, v, best.code, consts.loss_floor)
        metrics = jax.lax.cond(ok, lambda: metrics, lambda: metrics_at(v0))
        return {"v": jnp.where(ok, v, v0), "loss": metrics[loss], "code": code, "steps": best.steps,
                "start": starts[best.index], "metrics": metrics, "jtj": jnp.where(ok, best.jtj, jnp.nan)}

    return run


class ProgramArgs(NamedTuple):
    """The arguments of :func:`fit_program` for one fit (batched: ``given`` and ``data`` with a
    leading fit axis)."""

    grid_points: np.ndarray  # (G, nonlinear parameters): the start grid (``init.grid_for``), or (0, 0)
    given: np.ndarray  # (E, P): starts the caller gives, ranked beside the grid's
    data: Data
    lo: np.ndarray  # (P,) the box, in the table's solve unit
    hi: np.ndarray  # (P,)
    free: np.ndarray  # (P,) bool: False for a held parameter
    anchor: np.ndarray  # (P,) the held parameters' values (defaults, clipped into the box)
    subset: np.ndarray  # (S,) int: the rows the grid scores its points on


def subset_rows(data: Data) -> np.ndarray:
    """Rows the grid scores (``init.subset_index``: drawn from the used samples), or all."""
    idx = _init.subset_index(data)
    return np.arange(data[0].shape[-2]) if idx is None else idx


@functools.lru_cache(maxsize=64)
def _grid_points(model: Model, lo: bytes, hi: bytes, free: bytes, anchor: bytes) -> np.ndarray:
    """``init.grid_for`` once per model and space (the arrays as bytes: hashable)."""
    lo, hi, anchor = (np.frombuffer(b, dtype=np.float64) for b in (lo, hi, anchor))
    pts = _init.grid_for(model, lo, hi, np.frombuffer(free, dtype=bool), anchor)
    pts.flags.writeable = False
    return pts


def program_args(model: Model, space, data: Data, given: np.ndarray, grid: bool = True) -> ProgramArgs:
    """The arguments of :func:`fit_program` for one fit in ``space`` (a ``ParameterSpace``)."""
    lo, hi, free = space.lo, space.hi, np.asarray(space.free, dtype=bool)
    anchor = space.clip(model.default_vector())
    pts = _grid_points(model, lo.tobytes(), hi.tobytes(), free.tobytes(), anchor.tobytes()) if grid else np.zeros((0, 0))
    return ProgramArgs(pts, np.asarray(given, np.float64).reshape(-1, model.n_free), data, lo, hi, free, anchor,
                       subset_rows(data))


def run_fit(model: Model, loss: str, solver: str, rtol: float, atol: float, max_steps: int, k: int,
            args: ProgramArgs, grid: bool = True, note=None):
    """Compile (once per process, and through the disk cache once per machine) and run one fit's
    program. Returns (outputs as NumPy, compile seconds, run seconds)."""
    # NumPy arguments go straight to the compiled call (no eager device_put per array).
    fn, compile_s = compiled(("fit", model, loss, solver, rtol, atol, max_steps, k, grid),
                             lambda: fit_program(model, loss, solver, rtol, atol, max_steps, k, grid), *args, note=note)
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    run_s = time.perf_counter() - t0
    return jax.tree_util.tree_map(np.asarray, out), compile_s, run_s
