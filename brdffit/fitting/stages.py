"""The compiled stages of every fit (docs/fitting.md#fitting): starts, solver rounds, the finish.

``fit``, ``fit_batch`` and ``fit_btf`` all run these programs (the fit driver, ``driver``, calls them
through ``lanes``). Each program works on a *chunk of lanes*: a lane is one solve, with its own row of
the per-fit arrays (``Data`` fields with a leading axis) beside the arrays every lane shares (``Data``
fields without one: the directions of a BTF's texels, their weights). So a BTF's directions are held
once, not once per texel, and one compiled program serves any number of fits of a shape.

- :func:`start_stage`: the variable-projection grid (``init``) on a subset of the samples, and any
  starts the caller gives, ranked by their loss there: the ``k`` best starts of each lane.
- :func:`round_stage`: at most ``steps`` solver steps of each lane, from its start or from the
  state the previous round left (``state.Resume``): the driver lets the lanes that are done
  leave between rounds, so that a vectorised chunk does not run every lane until its slowest
  converges. optimistix's stock solvers cannot resume: one round with every step.
- :func:`finish_stage`: the fit's loss afresh (the check of a solver's claim), and, for a result of
  ``fit`` / ``fit_batch``, every metric and J^T J (the standard errors' need).

Inside a chunk ``lanes`` lanes are vectorised together (``jax.lax.map`` with that batch size): on a
GPU the whole chunk, on a CPU a few (a vectorised solve gains little there; see ``lanes``).

Compiled programs are kept per process and on disk (``cache.compiled``): a second process loads them
without tracing, and without importing optimistix.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from .._fit_defaults import SOLVERS
from ..errors import UsageError
from . import init as _init
from .losses import values_metrics
from .objective import Objective
from .problem import Data


#: Solvers that run compiled (and vectorise): everything but scipy.
COMPILED_SOLVERS = SOLVERS[:-1]
#: Solvers that continue from a previous round's state (the others run all their steps in one round).
RESUMABLE = ("lm",)
_ALIASES = {"levenberg_marquardt": "lm", "gn": "gauss_newton", "gaussnewton": "gauss_newton", "trf": "scipy"}


def check_solver(solver: str) -> str:
    key = str(solver).strip().lower()
    key = _ALIASES.get(key, key)
    if key not in SOLVERS:
        raise UsageError(f"unknown solver {solver!r}; known: {', '.join(SOLVERS)}")
    return key


# -- lanes and shared arrays ---------------------------------------------------------------------
#: Array ranks of one fit's ``Data`` fields; a field of one more rank holds one row per lane.
_RANKS = Data(wi=2, wo=2, ref=2, sqrt_w=2, cos_i=2, floor=1)


def per_lane(data: Data) -> Data:
    """True for the fields that hold one row per lane (a leading axis), False for shared ones."""
    return Data(*(jnp.ndim(a) == r + 1 for a, r in zip(data, _RANKS)))


def _split(data: Data):
    lane = per_lane(data)
    return (Data(*(a if m else None for a, m in zip(data, lane))),
            Data(*(None if m else a for a, m in zip(data, lane))))


def _join(own: Data, shared: Data) -> Data:
    return Data(*(a if a is not None else b for a, b in zip(own, shared)))


def map_lanes(fn, lane_args, data: Data, lanes: int):
    """``fn(lane_args_i, data_i)`` for every lane i (the leading axis of ``lane_args`` and of ``data``'s
    per-lane fields), ``lanes`` of them vectorised at a time; shared fields are passed whole.

    One lane at a time (a CPU's lanes) is a loop over the unbatched ``fn``: a vectorised batch of one gave
    the same run time through a larger program (ggx's round stage lowered in 0.8-1.0 s and compiled in
    4.4-4.6 s, against 0.54 s and 3.4 s). A lane's numbers must not depend on the program's size (a BTF's
    maps must not depend on how its tiles were grouped), so the loop is one XLA cannot see through: its
    trip count is hidden (a loop of one lane is otherwise unrolled into its surroundings), and a single
    lane's arrays are doubled (an axis of length one is laid out otherwise); either changed the last bits
    of a lane's result."""
    own, shared = _split(data)
    if lanes > 1:
        return jax.lax.map(lambda x: fn(x[0], _join(x[1], shared)), (lane_args, own), batch_size=lanes)
    lanes_in = (lane_args, own)
    n = jax.tree_util.tree_leaves(lanes_in)[0].shape[0]
    if n == 1:
        lanes_in = jax.tree_util.tree_map(lambda a: jnp.concatenate([a, a]), lanes_in)
    out = jax.eval_shape(lambda x: fn(x[0], _join(x[1], shared)), jax.tree_util.tree_map(lambda a: a[0], lanes_in))

    def one(i, acc):
        x = jax.tree_util.tree_map(lambda a: a[i], lanes_in)
        return jax.tree_util.tree_map(lambda o, v: o.at[i].set(v), acc, fn(x[0], _join(x[1], shared)))

    empty = jax.tree_util.tree_map(lambda s: jnp.zeros((n, *s.shape), s.dtype), out)
    return jax.lax.fori_loop(0, jax.lax.optimization_barrier(jnp.int32(n)), one, empty)


def shared_geometry(objective: Objective, data: Data):
    """The direction-only terms of a separable model (``objective.precompute_geometry``) when every lane
    shares its directions (a BTF's texels): computed once per call, outside the lanes' loop; else None."""
    lane = per_lane(data)
    if lane.wi or lane.wo:
        return None
    return objective.geometry(_solve_dtype(data))


def _solve_dtype(data: Data) -> Data:
    """The data in the solve's precision (a BTF's values arrive as float32, as stored)."""
    dtype = data.wi.dtype
    return data._replace(ref=data.ref.astype(dtype))


# -- stages -----------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def start_stage(objective: Objective, k: int, grid: bool, lanes: int):
    """run(lane, data, grid_points (G, m), lo, hi, free, anchor, subset (S,) int) -> (starts (L, k, P), values
    (L, k)): per lane the k candidates with the lowest loss on the ``subset`` rows, among the grid points
    (``init.vp_grid``: the linear parameters solved at each) when ``grid``, and the E given starts. ``lane``:
    the given starts (L, E, P), or (grids (L, G, m), given) for a grid of each lane's own (then
    ``grid_points`` is not read). Among equal losses the grid (listed first) wins."""
    vp = _init.vp_grid(objective.model, objective.loss)
    residual = objective.residual

    def one(grid_points, given, data, lo, hi, free, anchor, subset):
        sub = _init.take_rows(_solve_dtype(data), subset)
        given = jnp.where(free, jnp.clip(given, lo, hi), anchor)

        def subset_loss(v):
            r = residual(v, sub)
            r = jnp.where(jnp.isfinite(r), r, jnp.inf)  # as in init.vp_grid: the loss computed in XLA's own loop
            value = r @ r
            return jnp.where(jnp.isfinite(value), value, jnp.inf)

        flats, values = [given], [jax.vmap(subset_loss)(given)]
        if grid:
            g_flats, g_values = vp(grid_points, sub, lo, hi, free, anchor)
            flats.insert(0, g_flats)
            values.insert(0, g_values)
        flats, values = jnp.concatenate(flats), jnp.concatenate(values)
        order = jnp.argsort(values, stable=True)[:k]
        return flats[order], values[order]

    def run(lane, data, grid_points, lo, hi, free, anchor, subset):
        if isinstance(lane, tuple):  # (grids (L, G, m), given): a grid of each lane's own (a lobe re-seeded)
            return map_lanes(lambda x, d: one(x[0], x[1], d, lo, hi, free, anchor, subset), lane, data, lanes)
        return map_lanes(lambda g, d: one(grid_points, g, d, lo, hi, free, anchor, subset), lane, data, lanes)

    return run


@functools.lru_cache(maxsize=None)
def round_stage(objective: Objective, solver: str, rtol: float, atol: float, max_steps: int, first: bool, lanes: int):
    """run((v (L, P), resume), data, lo, hi, free, steps) -> (v, resume, done (L,), code (L,), steps (L,)):
    at most ``steps`` (a run-time scalar, <= ``max_steps``) steps of each lane. ``first``: from the start v
    (``resume`` is None); else from the previous round's ``resume`` (``state.Resume``, one row per
    lane). A stock solver (not resumable) runs ``max_steps`` in its one round; its ``resume`` holds the loss
    at v and at the start (``c``, ``c0``) and J^T J (``H``)."""
    from .solve import solve_one  # optimistix: imported only when a program is traced

    solve = solve_one(objective, solver, rtol, atol, max_steps)

    def one(v, resume, data, lo, hi, free, steps, geometry):
        data = _solve_dtype(data)
        consts = objective.constants(data, geometry)
        if solver in RESUMABLE:
            return solve(v, data, lo, hi, free, consts, resume, steps)
        return solve(v, data, lo, hi, free, consts)

    def run(lane, data, lo, hi, free, steps):
        geometry = shared_geometry(objective, data)
        return map_lanes(lambda x, d: one(x[0], x[1], d, lo, hi, free, steps, geometry), lane, data, lanes)

    return run


@functools.lru_cache(maxsize=None)
def finish_stage(objective: Objective, metrics: bool, jtj: bool, lanes: int):
    """run(v (L, P), data) -> dict: ``loss`` (L,) at v afresh, ``floor`` (L,) the loss of an exact fit
    (``solve.fit_constants``); with ``metrics`` every metric (dict of (L,)), with ``jtj`` J^T J (L, P, P)
    (the standard errors' need)."""
    loss, ne = objective.loss, objective.normal_equations

    def one(v, data, geometry):
        data = _solve_dtype(data)
        consts = objective.constants(data, geometry)
        values = values_metrics(objective.values(v, data, consts.geometry), data, (loss,))
        out = {"loss": values[loss], "floor": consts.loss_floor}
        if metrics:
            out["metrics"] = values
        if jtj:
            out["jtj"] = ne(v, data, consts.g_ref, consts.geometry)[2]
        return out

    def run(v, data):
        geometry = shared_geometry(objective, data)
        return map_lanes(lambda x, d: one(x, d, geometry), v, data, lanes)

    return run
