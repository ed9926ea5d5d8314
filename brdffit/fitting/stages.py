"""The stages of every fit (docs/fitting.md#fitting): starts, solver rounds, the finish, and how they run.

``fit``, ``fit_batch`` and ``fit_btf`` all run these programs: the fit driver (``driver``) runs them through
:class:`Stages` (one per call: the space, options, data and plan they share, the seconds they take). Each
program works on a chunk of lanes (``lanes``: a lane is one solve, with its own row of the per-fit arrays
beside the arrays every lane shares), so one compiled program serves any number of fits of a shape.

- ``init.start_stage``: the variable-projection grid on a subset of the samples, and any starts the
  caller gives, ranked by their loss there: the ``k`` best starts of each lane. The default grid is
  built once per model and space (``init.cached_grid``; :class:`Stages` holds it); a lobe the data do
  not see (``ParameterSpace.unseen_lobes``) is started again from a grid of its own (``init.reseed_grids``).
- :func:`round_stage`: at most ``steps`` solver steps of each lane, from its start or from the
  state the previous round left (``state.Resume``). A vectorised solve runs every lane until its
  slowest is done, so :func:`solve_rounds` runs at most ``ROUND_STEPS`` steps per call; between calls
  the lanes that are done leave and the others continue exactly where they were. optimistix's stock
  solvers cannot resume: one round with every step.
- :func:`finish_stage`: the fit's loss afresh (the check of a solver's claim), and, for a result of
  ``fit`` / ``fit_batch``, every metric and J^T J (the standard errors' need).

:func:`run_stage` runs one stage for every lane: the lanes cut into chunks of a few compiled sizes
(``lanes.Plan``), each chunk's rows of the per-fit fields gathered, the chunks run on the process's
devices. No Python runs per fit: per chunk only. Compiled programs are kept per process and on disk
(``cache.compiled``): a second process loads them without tracing, and without importing optimistix.
"""

from __future__ import annotations

import functools
import time
from concurrent.futures import ThreadPoolExecutor

import jax
import numpy as np

from .._fit_defaults import SOLVERS, START_DAMPING
from ..errors import UsageError
from .init import cached_grid, start_stage, subset_rows
from .cache import compiled
from .lanes import Plan, gather_rows, in_solve_dtype, map_lanes, per_lane, place_lanes, plan, shared_geometry
from .objective import Objective, objective_of
from .problem import Data
from .state import Rounds


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


#: Solver steps per round (see :func:`solve_rounds`), and the lanes below which the rest run in one call.
ROUND_STEPS = 4

ROUND_MIN_LANES = 4


# -- stages -----------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def round_stage(objective: Objective, solver: str, rtol: float, atol: float, max_steps: int, first: bool, lanes: int):
    """run((v (L, P), then), data, lo, hi, free, steps, count) -> (v, resume, done (L,), code (L,), steps (L,)): at most
    ``steps`` (a run-time scalar, <= ``max_steps``) steps of each lane. ``first``: from the start v, ``then`` (L,)
    each lane's damping of lm's first step (``_fit_defaults.START_DAMPING``); else from the previous round's state,
    ``then`` its ``resume`` (``state.Resume``, one row per lane). A stock solver (not resumable) runs ``max_steps``
    in its one round; its ``resume`` holds the loss at v and at the start (``c``, ``c0``) and J^T J (``H``)."""
    from .solve import solve_one  # optimistix: imported only when a program is traced

    @_over_lanes(objective, lanes)
    def run(lane, data, consts, lo, hi, free, steps):
        v, then = lane
        # Built where the lane's function is traced (once or twice a program: Python closures, no numbers).
        solve = solve_one(objective, solver, rtol, atol, max_steps)
        if solver in RESUMABLE:
            if first:
                return solve(v, data, lo, hi, free, consts, steps=steps, damping=then)
            return solve(v, data, lo, hi, free, consts, resume=then, steps=steps)
        return solve(v, data, lo, hi, free, consts)

    return run


@functools.lru_cache(maxsize=None)
def finish_stage(objective: Objective, metrics: bool, jtj: bool, lanes: int):
    """run(v (L, P), data, count) -> dict: ``loss`` (L,) at v afresh, ``floor`` (L,) the loss of an exact fit
    (``solve.fit_constants``); with ``metrics`` every metric (dict of (L,)), with ``jtj`` J^T J (L, P, P)
    (the standard errors' need)."""
    loss, ne = objective.loss, objective.normal_equations

    @_over_lanes(objective, lanes)
    def run(v, data, consts):
        values = objective.measures(v, data, consts.geometry)
        out = {"loss": values[loss], "floor": consts.loss_floor}
        if metrics:
            out["metrics"] = values
        if jtj:
            out["jtj"] = ne(v, data, consts.g_ref, consts.geometry)[2]
        return out

    return run


def _over_lanes(objective: Objective, lanes: int):
    """A stage's function of one lane, ``one(lane_arg, data, consts, *args)``, made the stage's program
    ``run(lane_args, data, *args, count)`` over the first ``count`` lanes (``lanes.map_lanes``): each lane's
    data in the solve's precision, with its fit's constants (``objective.fit_constants``); the direction-only
    terms computed once for the lanes when they share their directions (``lanes.shared_geometry``)."""

    def over_lanes(one):
        def run(lane_args, data, *args):
            *args, count = args
            geometry = shared_geometry(objective, data)

            def lane(x, d):
                d = in_solve_dtype(d)
                return one(x, d, objective.constants(d, geometry), *args)

            return map_lanes(lane, lane_args, data, lanes, count)

        return run

    return over_lanes


# -- running a stage over lanes ------------------------------------------------------------------------
def run_stage(key: tuple, build, lane_args, data: Data, fits: np.ndarray, shared: tuple, p: Plan, *,
              on_chunk=None, note=None) -> tuple[dict, float, float]:
    """``build()(lane_args, data, *shared, count)`` (a stage of ``stages``) for every lane: ``lane_args`` a
    pytree of arrays with the lane axis first (L, ...), ``fits`` (L,) the row of ``data``'s per-fit fields each
    lane reads; ``count`` (an int32 scalar) the call's own lanes, before its compiled size's padding. Returns
    (the outputs as NumPy with the lane axis first, compile seconds, run seconds). ``on_chunk(lanes)`` is
    called after each call; ``note(text)`` hears of a compile."""
    fits = np.asarray(fits)
    n = len(fits)
    mask = per_lane(data)
    leaves = jax.tree_util.tree_leaves(lane_args)
    assert all(len(a) == n for a in leaves), "one row of lane_args per lane"
    calls, start = [], 0
    for count, size in p.sizes(n):
        idx = np.arange(start, start + count)
        calls.append((idx, np.concatenate([idx, np.full(size - count, idx[0])])))
        start += count

    def call_args(padded):
        rows = fits[padded]
        chunk_data = Data(*(gather_rows(a, rows) if m else a for a, m in zip(data, mask)))
        lane = jax.tree_util.tree_map(lambda a: gather_rows(a, padded), lane_args)
        placed = place_lanes((lane, Data(*(a if m else None for a, m in zip(chunk_data, mask)))), p.devices)
        return (placed[0], Data(*(b if m else a for a, b, m in zip(chunk_data, placed[1], mask))), *shared)

    compile_s = 0.0
    programs = {}
    for _, padded in calls:  # compile (or load) each size once, before the calls run on threads
        size = len(padded)
        if size not in programs:
            programs[size], c_s = compiled(key, build, *call_args(padded), np.int32(size), note=note)
            compile_s += c_s

    def run(call):
        idx, padded = call
        program = programs[len(padded)]
        out = program(*call_args(padded), np.int32(len(idx)))  # the padding's lanes are not computed
        out = jax.tree_util.tree_map(lambda a: np.asarray(a)[: len(idx)], out)
        if on_chunk is not None:
            on_chunk(len(idx))
        return out

    t0 = time.perf_counter()
    if p.workers == 1 or len(calls) == 1:
        outs = [run(c) for c in calls]
    else:
        with ThreadPoolExecutor(min(p.workers, len(calls))) as pool:
            outs = list(pool.map(run, calls))
    result = jax.tree_util.tree_map(lambda *a: np.concatenate(a), *outs)
    return result, compile_s, time.perf_counter() - t0


def _key(stage: str, objective, *options) -> tuple:
    """A compiled stage's key (``cache.compiled``): the stage, the model, loss and Jacobian it reads, its options."""
    return (stage, objective.model, objective.loss, objective.jacobian, *options)


def solve_rounds(objective, solver: str, rtol: float, atol: float, max_steps: int, v0: np.ndarray,
                 data: Data, fits: np.ndarray, bounds: tuple, p: Plan, *, damping=START_DAMPING, progress=None,
                 note=None) -> Rounds:
    """Solve every lane from ``v0`` (L, P) (lane i reads row ``fits[i]`` of the per-fit fields) in rounds of
    at most ``ROUND_STEPS`` steps; between rounds the lanes that are done leave (see the module docstring).
    ``bounds``: (lo, hi, free). ``damping``: lm's first step's, one for every lane or (L,) each lane's. A stock
    optimistix solver runs all its steps in one round.
    ``progress(fraction)``: called after each round with the share of the lanes that ended in it."""
    n = len(v0)
    v = np.array(v0, dtype=np.float64)
    damping = np.broadcast_to(np.asarray(damping, np.float64), (n,))
    out = {"code": np.zeros(n, int), "steps": np.zeros(n, int)}
    state = None
    active = np.arange(n)
    compile_s = run_s = 0.0
    taken = 0
    first = True
    while len(active):
        resumable = solver in RESUMABLE
        # Rounds where lanes are vectorised (a lane alone runs its own steps and ends with them) and more
        # than a few are left; else the rest of the steps in one call. The budget is a run-time argument:
        # one compiled solve serves every round.
        rounds = resumable and p.lanes > 1 and len(active) > ROUND_MIN_LANES
        steps = min(ROUND_STEPS, max_steps - taken) if rounds else max_steps - taken
        build_args = (objective, solver, rtol, atol, max_steps, first, p.lanes)
        lane_args = (v[active], damping[active] if first else jax.tree_util.tree_map(lambda a: a[active], state))
        res, c_s, r_s = run_stage(_key("round", *build_args), lambda: round_stage(*build_args), lane_args, data,
                                  fits[active], (*bounds, np.int32(steps)), p, note=note)
        compile_s, run_s = compile_s + c_s, run_s + r_s
        v_new, resume, done, code, took = res
        if state is None:
            state = jax.tree_util.tree_map(lambda a: np.zeros((n, *a.shape[1:]), a.dtype), resume)
        for whole, part in zip(state, resume):
            whole[active] = part
        v[active] = v_new
        out["steps"][active] += took
        taken += steps
        # A lane not done after its round's steps reports "maximum number of steps" (code 1): it goes
        # on while the fit's own budget lasts; any other code ends it.
        out["code"][active] = code
        going = ~done & (code == 1) & (taken < max_steps)
        first = False
        ended = len(active) - (int(going.sum()) if resumable else 0)
        active = active[going] if resumable else active[:0]
        if progress is not None and ended:
            progress(ended / n)
    return Rounds(v, state.c, state.c0, state.H, out["code"], out["steps"], compile_s, run_s)


class Stages:
    """The stages of one call of the fit driver (``driver.solve``) run here: the space, the options, the data
    and the plan they share, and the seconds they take (compile, run; the starts' also as "init").
    :meth:`starts` (the start stage), :meth:`solve` (every lane's solve: the compiled solvers' rounds,
    scipy's in Python) and :meth:`finish` (the finish stage)."""

    def __init__(self, space, options, data: Data, note, seconds: dict | None = None):
        self.space, self.options, self.data, self.note = space, options, data, note
        self.model = space.model
        self.objective = objective_of(self.model, options.loss, options.jacobian)
        self.plan = plan(options.chunk, options.lanes)
        self.bounds = (space.lo, space.hi, np.asarray(space.free, bool))
        self.seconds = {"compile": 0.0, "run": 0.0, "init": 0.0} if seconds is None else seconds

    @functools.cached_property
    def grid(self) -> np.ndarray:
        """The default grid of starts of this model and space (``init.cached_grid``: built once per model and
        space), built when a start stage first ranks it: a call that solves from given starts alone, or only
        finishes (the table's own ``Stages`` of a fit solved in another unit), never needs it."""
        return cached_grid(self.model, *self.bounds, self.space.anchor)

    def starts(self, fits: np.ndarray, given: np.ndarray, k: int, grids=None, subset=None, grid: bool = True):
        """The k best candidates (len(fits), k, P) of each fit: grid points (the default grid, or a grid of
        each fit's own: ``grids`` (n, G, m); none without ``grid``) and the ``given`` (n, E, P), ranked on
        ``subset``'s rows; fewer (at least one) where there are not k of them."""
        lo, hi, free = self.bounds
        if not grid:
            points, lane_args = np.zeros((0, 1)), given
        elif grids is None:
            points = self.grid
            lane_args = given
        else:
            points, lane_args = np.zeros((0, 0)), (grids, given)
        k = max(1, min(k, (len(points) if grids is None else np.shape(grids)[1]) + np.shape(given)[1]))
        if subset is None:
            subset = subset_rows(Data(*(a[0] if own else a for a, own in zip(self.data, per_lane(self.data)))))
        key = (self.objective, k, grid, self.plan.lanes)
        out, c_s, r_s = run_stage(_key("start", *key), lambda: start_stage(*key), lane_args, self.data, fits,
                                  (points, lo, hi, free, self.space.anchor, subset), self.plan, note=self.note)
        self.seconds["compile"] += c_s
        self.seconds["run"] += r_s
        self.seconds["init"] += c_s + r_s
        return out[0]

    def solve(self, v0: np.ndarray, fits: np.ndarray, progress=None, damping=START_DAMPING) -> Rounds:
        o = self.options
        if o.solver != "scipy":
            r = solve_rounds(self.objective, o.solver, o.rtol, o.atol, o.max_steps, v0, self.data, fits,
                             self.bounds, self.plan, damping=damping, progress=progress, note=self.note)
        else:  # in Python, one start after another; scipy is imported only here
            from .solver_scipy import solve_lanes

            r = solve_lanes(self.objective, v0, self.data, fits, self.bounds, rtol=o.rtol, atol=o.atol,
                            max_steps=o.max_steps, jac=o.scipy_jac, progress=progress)
        self.seconds["compile"] += r.compile_s
        self.seconds["run"] += r.run_s
        return r

    def finish(self, v: np.ndarray, fits: np.ndarray, metrics: bool, jtj: bool) -> dict:
        key = (self.objective, metrics, jtj, self.plan.lanes)
        out, c_s, r_s = run_stage(_key("finish", *key), lambda: finish_stage(*key), v, self.data, fits, (), self.plan,
                                  note=self.note)
        self.seconds["compile"] += c_s
        self.seconds["run"] += r_s
        return out
