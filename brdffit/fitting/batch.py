"""`brdffit.fit_batch`: many independent fits of one model (BTF texels, many materials).

All measurements must have the same number of samples and channels. Every fit runs the program
of ``fit`` (``program.fit_program``: grid start, solve, metrics, J^T J), mapped over the batch in
chunks of ``chunk`` fits per compiled call, the batch axis sharded over every device JAX sees
(when the chunk divides evenly).

Inside a chunk, ``lanes`` fits are vectorised together (``jax.lax.map`` with that batch size):
a vmapped solve runs every lane until the slowest lane stops, and on CPU vmap gains nothing
else. Measured (16 ggx UBO-81 texels, 2 shared cores): vmapping all 16 took 1.63 s for the solve
and 0.78 s for the starts, one lane at a time 0.54 s and 0.06 s; so ``lanes=1`` by default (more
lanes may pay on a GPU).

``starts``: one start per fit (e.g. a neighbouring texel's result), ranked beside the grid's
points by its loss on the grid's samples; with ``grid=False`` it is the only start (no grid).

:func:`solve_batch` is the array-level core (no FitResult per fit): ``fit_btf`` uses it to fill
parameter maps.
"""

from __future__ import annotations

import functools
import os
import time
from concurrent.futures import ThreadPoolExecutor
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import UsageError
from ..measurement import Measurement
from .api import DEFAULT_LOSS, DEFAULT_SOLVER, _result, _start_from, default_starts, parameter_space, space_options
from .losses import check_loss
from .problem import Data, data_unit, in_unit, prepare, resolve_model
from .._fit_defaults import DEFAULT_ATOL, DEFAULT_MAX_STEPS, DEFAULT_RTOL
from .program import check_solver, compiled, fit_program, program_args
from .result import FitResult

#: Fits per compiled call.
DEFAULT_CHUNK = 256


@functools.lru_cache(maxsize=None)
def _program_batched(model, loss, solver, rtol, atol, max_steps, k, grid, lanes):
    one = fit_program(model, loss, solver, rtol, atol, max_steps, k, grid)

    def batched(grid_points, given, data, lo, hi, free, anchor, subset):
        return jax.lax.map(lambda x: one(grid_points, x[0], x[1], lo, hi, free, anchor, subset), (given, data),
                           batch_size=lanes)

    return batched


def _shard(tree):
    # This process's devices: under jax.distributed, jax.devices() also lists other processes'
    # devices, which this process cannot put its data on (fit_btf gives each process its own texels).
    devices = jax.local_devices()
    if len(devices) == 1:
        return tree
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    n = jax.tree_util.tree_leaves(tree)[0].shape[0]
    if n % len(devices):
        return tree
    mesh = Mesh(np.asarray(devices), ("b",))
    return jax.device_put(tree, NamedSharding(mesh, PartitionSpec("b")))


def solve_batch(space, loss: str, data: Data, *, solver: str = DEFAULT_SOLVER, max_steps: int = DEFAULT_MAX_STEPS,
                rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL, chunk: int = DEFAULT_CHUNK, k: int = 1,
                starts: np.ndarray | None = None, grid: bool = True, lanes: int = 1, workers: int | None = None,
                on_chunk=None) -> dict:
    """Fit every row of ``data`` (a ``Data`` of arrays with a leading batch axis (n, ...)) in
    ``space`` (a ``ParameterSpace``). ``starts``: (n, P) or None. Returns NumPy arrays with the
    batch axis first: ``v`` (canonical lobe order, fixed entries exact), ``loss``, ``code``,
    ``steps``, ``start``, ``jtj`` (in ``v``'s order), ``metrics`` (dict), and ``compile_s``,
    ``run_s`` (floats, whole batch). ``on_chunk(done)`` is called after each chunk (from a worker
    thread). ``workers``: chunks run at once (default: the CPU count)."""
    mdl = space.model
    n, P = data[0].shape[0], mdl.n_free
    if starts is None and not grid:
        raise UsageError("fit_batch: grid=False needs starts")
    given = np.zeros((n, 0, P)) if starts is None else np.asarray(starts, np.float64).reshape(n, 1, P)
    args = program_args(mdl, space, Data(*(a[0] for a in data)), given[0], grid=grid)
    pts, anchor, subset = args[0], args[6], args[7]
    k = max(1, min(k, (len(pts) if grid else 0) + given.shape[1]))
    chunk = min(chunk, n)
    space_args = (jnp.asarray(space.lo), jnp.asarray(space.hi), jnp.asarray(space.free, dtype=bool),
                  jnp.asarray(anchor), jnp.asarray(subset))
    # Chunks run on ``workers`` threads at once (XLA runs a compiled call without the GIL; one
    # fit's arrays are too small to keep two cores busy: measured 1.3x on 2 cores).
    workers = max(1, min(workers or os.cpu_count() or 1, n))
    chunk = min(chunk, -(-n // workers))
    bounds = [(s, min(s + chunk, n)) for s in range(0, n, chunk)]

    def call_args(s, e):
        idx = np.arange(s, e)
        idx_p = np.concatenate([idx, np.repeat(idx[-1:], chunk - len(idx))])  # one compiled shape
        d = _shard(Data(*(jnp.asarray(np.asarray(a)[idx_p]) for a in data)))
        g = _shard(jnp.asarray(given[idx_p]))
        return (jnp.asarray(pts), g, d, *space_args)

    fn, compile_s = compiled(("fit_batch", mdl, loss, solver, rtol, atol, max_steps, k, grid, lanes),
                             lambda: _program_batched(mdl, loss, solver, rtol, atol, max_steps, k, grid, lanes),
                             *call_args(*bounds[0]))

    def run(b):
        out = jax.block_until_ready(fn(*call_args(*b)))
        out = jax.tree_util.tree_map(lambda a: np.asarray(a)[: b[1] - b[0]], out)
        if on_chunk is not None:
            on_chunk(b[1] - b[0])
        return out

    t0 = time.perf_counter()
    if workers == 1:
        outs = [run(b) for b in bounds]
    else:
        with ThreadPoolExecutor(workers) as pool:
            outs = list(pool.map(run, bounds))
    run_s = time.perf_counter() - t0
    res = jax.tree_util.tree_map(lambda *a: np.concatenate(a), *outs)
    # Fixed entries exactly at their values, lobes of one kind narrowest first (a swap of whole
    # interchangeable lobes: f_r and the loss are unchanged; J^T J follows the swap).
    v = np.where(space.free, np.clip(res["v"], space.lo, space.hi), space.values)
    if space.order:
        perms = np.stack([space.canonical_order(row) for row in v])
        v = np.take_along_axis(v, perms, axis=1)
        res["jtj"] = np.stack([h[np.ix_(p, p)] for h, p in zip(res["jtj"], perms)])
    res["v"] = v
    res["compile_s"], res["run_s"] = compile_s, run_s
    return res


def fit_batch(
    measurements: Sequence[Measurement],
    model,
    *,
    loss: str = DEFAULT_LOSS,
    solver: str = DEFAULT_SOLVER,
    max_steps: int = DEFAULT_MAX_STEPS,
    rtol: float = DEFAULT_RTOL,
    atol: float = DEFAULT_ATOL,
    chunk: int = DEFAULT_CHUNK,
    multistart: int | None = None,
    progress: bool = False,
    lanes: int = 1,
    bounds=None,
    fixed=None,
    physical: bool = False,
    starts=None,
    grid: bool = True,
) -> list[FitResult]:
    """Fit ``model`` to each measurement independently; see the module docstring.

    Same defaults as ``fit`` (loss, solver, starts, tolerances). ``progress=True`` shows a
    progress bar (rich, on stderr) over the fits. ``bounds``, ``fixed``, ``physical``: the
    parameter space, as for ``fit``. ``starts``: one start per measurement (flat vectors (n, P),
    or params dicts / FitResults), ranked beside the grid; ``grid=False``: those starts only."""
    loss = check_loss(loss)
    solver = check_solver(solver)
    if solver == "scipy":
        raise UsageError("fit_batch: solver 'scipy' is not batched; use fit() per measurement")
    if chunk < 1 or lanes < 1:
        raise UsageError("fit_batch: chunk and lanes must be at least 1")
    measurements = list(measurements)
    if not measurements:
        return []
    shapes = {(m.n_samples, m.n_channels) for m in measurements}
    if len(shapes) != 1:
        raise UsageError(f"fit_batch: all measurements need the same samples and channels, got {sorted(shapes)}")
    preps = [prepare(m) for m in measurements]
    mdl = resolve_model(model, preps[0].channels)
    pspace = parameter_space(mdl, bounds, fixed, physical)
    n = len(measurements)
    if starts is not None:
        if len(starts) != n:
            raise UsageError(f"fit_batch: {len(starts)} starts for {n} measurements")
        starts = np.stack([np.asarray(s, np.float64).reshape(-1) if not isinstance(s, (dict, FitResult))
                           else _start_from(s, mdl, pspace.lo, pspace.hi) for s in starts])
        if starts.shape[1] != mdl.n_free:
            raise UsageError(f"fit_batch: starts have {starts.shape[1]} values, model {mdl.name} has {mdl.n_free}")
    k = 1 + (default_starts(mdl) - 1 if multistart is None else int(multistart))
    # One unit for the batch (``problem.data_unit``: a table far from reflectance's range is fitted in
    # units of a power of ten), so that the bounds the batch shares stay one set.
    unit = data_unit(mdl, *preps)
    unscale = np.where(pspace.linear_mask(), unit, 1.0)
    solved = [in_unit(p, unit) for p in preps]
    data = Data(*(np.stack([np.asarray(p.data[i]) for p in solved]) for i in range(6)))
    if starts is not None:
        starts = starts / unscale

    bar = None
    if progress:
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        # on stderr, like every progress display of brdffit (stdout stays for results)
        bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                       console=Console(stderr=True), transient=False)
        bar.start()
        task = bar.add_task(f"fit_batch {mdl.name}", total=n)
    try:
        res = solve_batch(pspace.in_unit(unit), loss, data, solver=solver, max_steps=max_steps, rtol=rtol, atol=atol, chunk=chunk,
                          k=k, starts=starts, grid=grid, lanes=lanes,
                          on_chunk=None if bar is None else (lambda done: bar.update(task, advance=done)))
    finally:
        if bar is not None:
            bar.stop()

    compile_s, run_s = res["compile_s"], res["run_s"]
    results = []
    for i, (m, prep) in enumerate(zip(measurements, preps)):
        given_back = unit == 1.0  # else the metrics, J^T J and loss are computed afresh in the table's unit
        results.append(_result(
            pspace, loss, solver, m, prep, res["v"][i] * unscale, float(res["loss"][i]) if given_back else None,
            int(res["code"][i]), int(res["steps"][i]), res["start"][i] * unscale,
            metrics={key: float(x[i]) for key, x in res["metrics"].items()} if given_back else None,
            jtj=res["jtj"][i] if given_back else None,
            seconds={"compile": compile_s / n, "run": run_s / n, "init": 0.0},
            options={"max_steps": max_steps, "rtol": rtol, "atol": atol, "batch": True, "chunk": min(chunk, n),
                     "starts": k, "multistart": multistart, "init": "grid" if grid else "given",
                     **({"data_unit": unit} if unit != 1.0 else {}),
                     **space_options(bounds, fixed, physical)},
        ))
    return results
