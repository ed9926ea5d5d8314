"""The batched fit program: many independent fits of one model at once (``brdffit.fit_batch``,
``brdffit.fit_btf``: BTF texels, many materials), run by the fit driver (``driver.solve``).

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

:func:`solve_batch` is the array-level core (no FitResult per fit); the driver makes FitResults of
its rows (``fit_batch``) or parameter maps (``fit_btf``).
"""

from __future__ import annotations

import functools
import os
import time
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np

from .options import FitOptions
from .problem import Data
from .program import compiled, fit_program, program_args


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


def solve_batch(space, options: FitOptions, data: Data, *, k: int = 1, starts: np.ndarray | None = None,
                grid: bool = True, workers: int | None = None, on_chunk=None) -> dict:
    """Fit every row of ``data`` (a ``Data`` of arrays with a leading batch axis (n, ...)) in
    ``space`` (a ``ParameterSpace``) with ``options`` (its solver, tolerances, ``chunk``, ``lanes``).
    ``starts``: (n, P) or None. Returns NumPy arrays with the batch axis first: ``v``, ``loss``,
    ``code``, ``steps``, ``start``, ``jtj``, ``metrics`` (dict), and ``compile_s``, ``run_s`` (floats,
    whole batch); the driver (``driver.solve``) puts the lobes in order. ``on_chunk(done)`` is called
    after each chunk (from a worker thread). ``workers``: chunks run at once (default: the CPU count)."""
    mdl = space.model
    n, P = data[0].shape[0], mdl.n_free
    given = np.zeros((n, 0, P)) if starts is None else np.asarray(starts, np.float64).reshape(n, 1, P)
    args = program_args(mdl, space, Data(*(a[0] for a in data)), given[0], grid=grid)
    k = max(1, min(k, (len(args.grid_points) if grid else 0) + given.shape[1]))
    chunk = min(options.chunk, n)
    space_args = (jnp.asarray(args.lo), jnp.asarray(args.hi), jnp.asarray(args.free), jnp.asarray(args.anchor),
                  jnp.asarray(args.subset))
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
        return (jnp.asarray(args.grid_points), g, d, *space_args)

    program = (mdl, options.loss, options.solver, options.rtol, options.atol, options.max_steps, k, grid, options.lanes)
    fn, compile_s = compiled(("fit_batch", *program), lambda: _program_batched(*program), *call_args(*bounds[0]))

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
    res = jax.tree_util.tree_map(lambda *a: np.concatenate(a), *outs)
    res["compile_s"], res["run_s"] = compile_s, time.perf_counter() - t0
    return res
