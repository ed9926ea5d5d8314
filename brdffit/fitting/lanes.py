"""Running the fit stages (``stages``) over many lanes: chunks, devices, and the solver's rounds.

A *lane* is one solve (one start of one fit). The driver hands :func:`run_stage` the lanes' own
arguments, the batch's data (``Data``: per-fit fields with one row per fit, shared fields without) and
the fit each lane belongs to; here the lanes are cut into chunks of a few compiled sizes, each chunk's
rows of the per-fit fields are gathered, and the chunks run on the process's devices. No Python runs
per fit: per chunk only.

How a backend is used (:func:`plan`, unless the caller sets ``chunk`` and ``lanes``):

- CPU: chunks of ``CPU_CHUNK`` lanes, ``CPU_LANES`` of them vectorised at a time inside the compiled
  call (one: a loop over the unbatched solve, ``stages.map_lanes``; a vectorised solve gains little on a
  CPU beyond sharing each operation's overhead, and its arrays must stay in the cache), as many chunks
  at once as the machine has cores (XLA runs a call without the GIL).
- GPU (and other accelerators): one call holds up to ``DEVICE_CHUNK`` lanes, all vectorised; the
  lane axis is split over the process's devices.

The fit driver runs its stages through :class:`Stages` (one per call: the space, options, data and plan
they share, the seconds they take).

Solver rounds (:func:`solve_rounds`): a vectorised solve runs every lane until its slowest is done, so
the solver runs at most ``ROUND_STEPS`` steps per call; between calls the lanes that are done leave
and the others continue from their state (``solver_lm.Resume``) exactly where they were.
"""

from __future__ import annotations

import dataclasses
import os
import time
from concurrent.futures import ThreadPoolExecutor

import jax
import numpy as np

from .cache import compiled
from .objective import objective_of
from .problem import Data
from .state import Rounds

#: Lanes per compiled call and lanes vectorised together on a CPU (see the module docstring). One lane at a
#: time: vectorising is slower on 2 cores (a 64 x 64 ggx BTF, warm: 768-792 texels/s one lane at a time,
#: 662-686 with 4, 596-603 with 16; one evaluation of ggx on UBO-81 holds ~20 arrays of 6561 values, and
#: several lanes' no longer fit the core's cache), and a lane computed alone is
#: computed identically whatever its chunk holds, so a BTF's maps do not depend on how its tiles were
#: grouped (processes, Dask workers, a resumed run).
CPU_CHUNK = 64
CPU_LANES = 1
#: Lanes per compiled call on an accelerator, all vectorised, at most: ggx on UBO-81 took 30 GB of an H200
#: at 16,384 lanes (about 2 MB a lane), so a device with less memory gets fewer (``plan``).
DEVICE_CHUNK = 16384
DEVICE_BYTES_PER_LANE = 2 * 2**20
#: Solver steps per round (see :func:`solve_rounds`), and the lanes below which the rest run in one call.
ROUND_STEPS = 4
ROUND_MIN_LANES = 4


@dataclasses.dataclass(frozen=True)
class Plan:
    """How lanes run: ``chunk`` lanes per compiled call (a multiple of ``lanes``), ``lanes`` vectorised
    together inside it, ``workers`` calls at once, on ``devices`` (the lane axis split over them)."""

    chunk: int
    lanes: int
    workers: int
    devices: tuple
    #: Ratio of one compiled size to the next (``sizes``): on an accelerator a program takes seconds to
    #: compile, so few sizes there (measured on an H200: 12 s of compiling in a first run).
    step: int = 4

    def sizes(self, n: int) -> list[tuple[int, int]]:
        """(lanes, compiled size) of each call for n lanes: full chunks, then the rest padded to the next of
        a few sizes (one lane per device times a power of ``step``), so that few programs are compiled."""
        out = [(self.chunk, self.chunk)] * (n // self.chunk)
        rest = n % self.chunk
        if rest:
            size = len(self.devices)
            while size < rest:
                size *= self.step
            out.append((rest, min(size, self.chunk)))
        return out


def plan(chunk: int | None = None, lanes: int | None = None) -> Plan:
    """The :class:`Plan` for this process's devices (``chunk`` / ``lanes`` override the backend's)."""
    devices = tuple(jax.local_devices())  # under jax.distributed, this process's own
    if devices[0].platform == "cpu":
        lanes = lanes or CPU_LANES
        chunk = chunk or CPU_CHUNK
        workers = max(1, min(_cores(), 8))
        devices = devices[:1]  # several host "devices" share the same cores: threads use them
    else:
        if chunk is None:
            limit = (devices[0].memory_stats() or {}).get("bytes_limit", 0)
            fits = int(0.5 * limit / DEVICE_BYTES_PER_LANE) if limit else DEVICE_CHUNK
            chunk = max(256, min(DEVICE_CHUNK, fits))
        lanes = lanes or chunk
        workers = 1
    unit = lanes * len(devices)
    chunk = max(unit, -(-chunk // unit) * unit)
    return Plan(chunk=chunk, lanes=lanes, workers=workers, devices=devices, step=4 if devices[0].platform == "cpu" else 256)


def _cores() -> int:
    """The cores this process may run on (its affinity: a container's or ``taskset``'s share, not the
    machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _rows(a, idx):
    return a[idx] if isinstance(a, np.ndarray) else jax.numpy.take(a, idx, axis=0)


def _place(tree, devices):
    """The lane axis of every array split over ``devices`` (one device: as it is)."""
    if len(devices) == 1:
        return tree
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    mesh = Mesh(np.asarray(devices), ("lanes",))
    return jax.device_put(tree, NamedSharding(mesh, PartitionSpec("lanes")))


def run_stage(key: tuple, build, lane_args, data: Data, fits: np.ndarray, shared: tuple, p: Plan, *,
              on_chunk=None, note=None) -> tuple[dict, float, float]:
    """``build()(lane_args, data, *shared)`` (a stage of ``stages``) for every lane: ``lane_args`` a pytree
    of arrays with the lane axis first (L, ...), ``fits`` (L,) the row of ``data``'s per-fit fields each
    lane reads. Returns (the outputs as NumPy with the lane axis first, compile seconds, run seconds).
    ``on_chunk(lanes)`` is called after each call; ``note(text)`` hears of a compile."""
    from .stages import per_lane

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
        chunk_data = Data(*(_rows(a, rows) if m else a for a, m in zip(data, mask)))
        lane = jax.tree_util.tree_map(lambda a: _rows(a, padded), lane_args)
        placed = _place((lane, Data(*(a if m else None for a, m in zip(chunk_data, mask)))), p.devices)
        return (placed[0], Data(*(b if m else a for a, b, m in zip(chunk_data, placed[1], mask))), *shared)

    compile_s = 0.0
    programs = {}
    for _, padded in calls:  # compile (or load) each size once, before the calls run on threads
        size = len(padded)
        if size not in programs:
            programs[size], c_s = compiled(key, build, *call_args(padded), note=note)
            compile_s += c_s

    def run(call):
        idx, padded = call
        out = jax.tree_util.tree_map(lambda a: np.asarray(a)[: len(idx)], programs[len(padded)](*call_args(padded)))
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
                 data: Data, fits: np.ndarray, bounds: tuple, p: Plan, *, progress=None, note=None) -> Rounds:
    """Solve every lane from ``v0`` (L, P) (lane i reads row ``fits[i]`` of the per-fit fields) in rounds of
    at most ``ROUND_STEPS`` steps; between rounds the lanes that are done leave (see the module docstring).
    ``bounds``: (lo, hi, free). A stock optimistix solver runs all its steps in one round.
    ``progress(fraction)``: called after each round with the share of the lanes that ended in it."""
    from .stages import RESUMABLE, round_stage

    n = len(v0)
    v = np.array(v0, dtype=np.float64)
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
        lane_args = (v[active], None if first else jax.tree_util.tree_map(lambda a: a[active], state))
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

    def _count(self, compile_s: float, run_s: float, init: bool = False) -> None:
        self.seconds["compile"] += compile_s
        self.seconds["run"] += run_s
        if init:
            self.seconds["init"] += compile_s + run_s

    def starts(self, fits: np.ndarray, given: np.ndarray, k: int, grids=None, subset=None, grid: bool = True):
        """The k best candidates (len(fits), k, P) of each fit: grid points (the default grid, or a grid of
        each fit's own: ``grids`` (n, G, m); none without ``grid``) and the ``given`` (n, E, P), ranked on
        ``subset``'s rows; fewer (at least one) where there are not k of them."""
        from .init import cached_grid, subset_rows
        from .stages import per_lane, start_stage

        lo, hi, free = self.bounds
        if not grid:
            points, lane_args = np.zeros((0, 1)), given
        elif grids is None:
            points = cached_grid(self.model, lo, hi, free, self.space.anchor)
            lane_args = given
        else:
            points, lane_args = np.zeros((0, 0)), (grids, given)
        k = max(1, min(k, (len(points) if grids is None else np.shape(grids)[1]) + np.shape(given)[1]))
        if subset is None:
            subset = subset_rows(Data(*(a[0] if own else a for a, own in zip(self.data, per_lane(self.data)))))
        key = (self.objective, k, grid, self.plan.lanes)
        out, c_s, r_s = run_stage(_key("start", *key), lambda: start_stage(*key), lane_args, self.data, fits,
                                  (points, lo, hi, free, self.space.anchor, subset), self.plan, note=self.note)
        self._count(c_s, r_s, init=True)
        return out[0]

    def solve(self, v0: np.ndarray, fits: np.ndarray, progress=None) -> Rounds:
        o = self.options
        if o.solver == "scipy":  # in Python, one start after another; scipy is imported only here
            from .solver_scipy import solve_lanes

            r = solve_lanes(self.objective, v0, self.data, fits, self.bounds, rtol=o.rtol, atol=o.atol,
                            max_steps=o.max_steps, jac=o.scipy_jac, progress=progress)
        else:
            r = solve_rounds(self.objective, o.solver, o.rtol, o.atol, o.max_steps, v0, self.data, fits,
                             self.bounds, self.plan, progress=progress, note=self.note)
        self._count(r.compile_s, r.run_s)
        return r

    def finish(self, v: np.ndarray, fits: np.ndarray, metrics: bool, jtj: bool) -> dict:
        from .stages import finish_stage

        key = (self.objective, metrics, jtj, self.plan.lanes)
        out, c_s, r_s = run_stage(_key("finish", *key), lambda: finish_stage(*key), v, self.data, fits, (), self.plan,
                                  note=self.note)
        self._count(c_s, r_s)
        return out
