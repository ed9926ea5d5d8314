"""`brdffit.fit_batch`: many independent fits of one model (BTF texels, many materials).

All measurements must have the same number of samples and channels. The same two compiled steps
as ``fit`` (the variable-projection grid, then the vmapped solve of the best starts, see
``solve.solve_starts``), vmapped once more over the batch, in chunks of ``chunk`` fits, the batch
axis sharded over every device JAX sees (when the chunk divides evenly).

Inside a chunk, ``lanes`` fits are vectorised together (``jax.lax.map`` with that batch size):
a vmapped solve runs every lane until the slowest lane stops, and on CPU vmap gains nothing
else. Measured (16 ggx UBO-81 texels, 2 shared cores): vmapping all 16 took 1.63 s for the solve
and 0.78 s for the starts, one lane at a time 0.54 s and 0.06 s; so ``lanes=1`` by default (more
lanes may pay on a GPU). Fits are sorted by their start loss (``sort``) so that lanes of similar
difficulty share a vector. Returns one FitResult per input, in input order; ``seconds`` of each
result are its chunk's times divided by its fits.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import UsageError
from ..measurement import Measurement
from . import init as _init
from .api import DEFAULT_LOSS, DEFAULT_SOLVER, _result, default_starts, normal_matrix_fn, parameter_space, space_options
from .losses import check_loss
from .problem import Data, loss_values, prepare, resolve_model
from .result import FitResult
from .solve import DEFAULT_ATOL, DEFAULT_MAX_STEPS, DEFAULT_RTOL, check_solver, compiled, solve_starts

#: Fits per compiled call.
DEFAULT_CHUNK = 256


@functools.lru_cache(maxsize=None)
def _grid_batched(model, loss, k, lanes):
    run = _init.vp_grid(model, loss)

    def batched(grid, data, lo, hi, free, anchor):
        def one(d):
            flats, values = run(grid, d, lo, hi, free, anchor)
            order = jnp.argsort(values)[:k]
            return flats[order], values[order]

        return jax.lax.map(one, data, batch_size=lanes)

    return batched


@functools.lru_cache(maxsize=None)
def _solve_batched(model, loss, solver, rtol, atol, max_steps, lanes):
    one = solve_starts(model, loss, solver, rtol, atol, max_steps)

    def batched(starts, data, lo, hi, free):
        return jax.lax.map(lambda x: one(x[0], x[1], lo, hi, free), (starts, data), batch_size=lanes)

    return batched


@functools.lru_cache(maxsize=None)
def _post(model, loss):
    values = loss_values(model)
    jtj = normal_matrix_fn(model, loss)
    return lambda v, data: jax.lax.map(lambda x: (values(*x), jtj(*x)), (v, data))


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
    sort: bool = True,
    multistart: int | None = None,
    progress: bool = False,
    lanes: int = 1,
    bounds=None,
    fixed=None,
    physical: bool = False,
) -> list[FitResult]:
    """Fit ``model`` to each measurement independently; see the module docstring.

    Same defaults as ``fit`` (loss, solver, starts, tolerances). ``progress=True`` shows a
    progress bar (rich, on stderr) over the fits. ``bounds``, ``fixed``, ``physical``: the
    parameter space, as for ``fit``."""
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
    lo, hi, free = pspace.lo, pspace.hi, pspace.free
    anchor = pspace.clip(np.asarray(mdl.flatten(mdl.defaults())))
    k = 1 + (default_starts(mdl) - 1 if multistart is None else int(multistart))
    data = Data(*(np.stack([np.asarray(p.data[i]) for p in preps]) for i in range(6)))
    n = len(measurements)
    chunk = min(chunk, n)
    grid = jnp.asarray(_init.grid_for(mdl, lo, hi, free, anchor))
    k = min(k, grid.shape[0])
    space = (jnp.asarray(lo), jnp.asarray(hi), jnp.asarray(free), jnp.asarray(anchor))

    bar = None
    if progress:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                       transient=False)
        bar.start()
        task = bar.add_task(f"fit_batch {mdl.name}: starts", total=2 * n)
    try:
        # Starts, chunk by chunk (the grid's memory grows with the chunk).
        starts = np.zeros((n, k, mdl.n_free))
        start_loss = np.zeros(n)
        init_s = compile_s = 0.0
        for s in range(0, n, chunk):
            idx = np.arange(s, min(s + chunk, n))
            idx_p = np.concatenate([idx, np.repeat(idx[-1:], chunk - len(idx))])
            d = _shard(_init.subset_batch(data, idx_p))
            fn, c_s = compiled(("init_batch", mdl, loss, k, lanes), lambda: _grid_batched(mdl, loss, k, lanes), grid, d,
                               *space)
            t0 = time.perf_counter()
            flats, values = jax.block_until_ready(fn(grid, d, *space))
            init_s += time.perf_counter() - t0
            compile_s += c_s
            starts[idx] = np.asarray(flats)[: len(idx)]
            start_loss[idx] = np.asarray(values)[: len(idx), 0]
            if bar is not None:
                bar.update(task, advance=len(idx))
        if bar is not None:
            bar.update(task, description=f"fit_batch {mdl.name}: solving")

        order = np.argsort(start_loss) if sort else np.arange(n)
        out = [None] * n
        secs = np.zeros(n)
        run_s_total = 0.0
        for s in range(0, n, chunk):
            idx = order[s : s + chunk]
            idx_p = np.concatenate([idx, np.repeat(idx[-1:], chunk - len(idx))])  # one compiled shape
            d = _shard(Data(*(jnp.asarray(a[idx_p]) for a in data)))
            v0 = _shard(jnp.asarray(starts[idx_p]))
            fn, c_s = compiled(("solve_batch", mdl, loss, solver, rtol, atol, max_steps, lanes),
                               lambda: _solve_batched(mdl, loss, solver, rtol, atol, max_steps, lanes), v0, d,
                               *space[:3])
            compile_s += c_s
            t0 = time.perf_counter()
            res = jax.block_until_ready(fn(v0, d, *space[:3]))
            dt = time.perf_counter() - t0
            run_s_total += dt
            v, value, code, steps, i_best = (np.asarray(a) for a in res[:5])
            for j, i in enumerate(idx):
                out[i] = (v[j], float(value[j]), int(code[j]), int(steps[j]), starts[i, int(i_best[j])])
                secs[i] = dt / len(idx_p)
            if bar is not None:
                bar.update(task, advance=len(idx))
    finally:
        if bar is not None:
            bar.stop()

    # Fixed entries exactly at their values, lobes of one kind narrowest first (a swap of whole
    # interchangeable lobes: f_r and the loss are unchanged), before metrics and J^T J.
    out = [(pspace.canonical(pspace.clip(o[0])), *o[1:]) for o in out]
    # Metrics and J^T J (for the standard errors) of every fit, chunk by chunk in one call each.
    post = _post(mdl, loss)
    v_all = np.stack([o[0] for o in out])
    metrics_all, jtj_all = [], []
    for s in range(0, n, chunk):
        idx = np.arange(s, min(s + chunk, n))
        idx_p = np.concatenate([idx, np.repeat(idx[-1:], chunk - len(idx))])
        args = (jnp.asarray(v_all[idx_p]), Data(*(jnp.asarray(a[idx_p]) for a in data)))
        fn, c_s = compiled(("post_batch", mdl, loss), lambda: post, *args)
        compile_s += c_s
        metrics, jtj = fn(*args)
        metrics_all.append({k: np.asarray(x)[: len(idx)] for k, x in metrics.items()})
        jtj_all.append(np.asarray(jtj)[: len(idx)])
    jtj_all = np.concatenate(jtj_all)
    metrics_all = {k: np.concatenate([m[k] for m in metrics_all]) for k in metrics_all[0]}

    results = []
    for i, (m, prep) in enumerate(zip(measurements, preps)):
        v, value, code, steps, v0 = out[i]
        results.append(_result(
            pspace, loss, solver, m, prep, v, value, code, steps, v0,
            metrics={k: float(x[i]) for k, x in metrics_all.items()}, jtj=jtj_all[i],
            seconds={"compile": compile_s / n, "run": float(secs[i] + init_s / n), "init": init_s / n},
            options={"max_steps": max_steps, "rtol": rtol, "atol": atol, "batch": True, "chunk": chunk,
                     "starts": k, "multistart": multistart, **space_options(bounds, fixed, physical)},
        ))
    return results
