"""`brdffit.fit_batch`: many independent fits of one model (BTF texels, many materials).

All measurements must have the same number of samples and channels. The initialisation grid and
the solve are vmapped over the batch and the batch axis is sharded over every device JAX sees.

A vmapped optimistix solve runs every lane until the slowest lane stops (converged lanes idle but
still cost a step). Mitigations used here: (1) lanes are *chunked* (``chunk`` fits per compiled
call), so one hard fit holds back only its chunk; (2) lanes are *sorted* by their start loss
before chunking, so fits of similar difficulty share a chunk. Each fit gets the same active-set
treatment as ``fit`` (parameters on a bound with an outward gradient are held there), in two
rounds. Returns one FitResult per input, in input order; ``seconds`` of each result are the
chunk's times divided by its number of lanes.

The default solver is ``lmb`` (brdffit's projected Levenberg-Marquardt, which handles bounds by
an active set inside every iteration and converges in ~10-30 iterations, so idle lanes cost
little). Measured with ``python benchmarks/bench_fit.py --batch 32`` (ggx, 32 synthetic UBO-81
texels, 2 shared CPU cores, one JAX device): ``lmb`` batched 319-337 ms/fit, about the same
as a loop of ``fit(solver="lmb")`` (311 ms/fit; the variable-projection grid dominates and one
CPU device gains nothing from vmap), all 32 converged. With optimistix ``lm`` batching was
*slower* than a loop of ``fit`` (2.7-5.4 s/fit against 0.8 s/fit: lanes' step counts differ by
10x, max 226, median 25) and only 20/32 converged within the two fixed active-set rounds;
chunks of 8 helped (85 s against 173 s for one chunk), sorting by start loss did not here.
So ``lmb`` is the batch default; the optimistix path is kept for comparisons.
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
from .api import _jacobian_fn, standard_errors
from .losses import check_loss
from .problem import Data, evaluate, flat_residual, prepare, resolve_model
from .result import FitResult
from .solve import DEFAULT_ATOL, DEFAULT_MAX_STEPS, DEFAULT_RTOL, STATUS_TEXT, _lmb_core, _solve_core, check_solver


@functools.lru_cache(maxsize=None)
def _batched_grid(model, loss):
    run = _init.vp_grid_fn(model, loss)

    def one(grid, data):
        flats, values = run(grid, data)
        i = jnp.argmin(values)
        return flats[i], values[i]

    return jax.jit(jax.vmap(one, in_axes=(None, 0)))


@functools.lru_cache(maxsize=None)
def _batched_solve(model, loss, solver, rtol, atol, max_steps):
    return jax.jit(jax.vmap(_solve_core(model, loss, solver, rtol, atol, max_steps)))


@functools.lru_cache(maxsize=None)
def _batched_lmb(model, loss, rtol, atol, max_steps):
    return jax.jit(jax.vmap(_lmb_core(model, loss, rtol, atol, max_steps)))


@functools.lru_cache(maxsize=None)
def _batched_outward(model, loss):
    jac = jax.jacfwd(flat_residual(model, loss))
    fn = flat_residual(model, loss)
    lo, hi = (jnp.asarray(b) for b in model.bounds())

    def one(v, data):
        g = jac(v, data).T @ fn(v, data)
        tol = 1e-9 * (hi - lo)
        return ((v <= lo + tol) & (g > 0)) | ((v >= hi - tol) & (g < 0))

    return jax.jit(jax.vmap(one))


def _shard(tree):
    # This process's devices: under jax.distributed, jax.devices() also lists other processes'
    # devices, which this process cannot put its data on (fit_btf gives each process its own texels).
    devices = jax.local_devices()
    if len(devices) == 1:
        return tree
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    mesh = Mesh(np.asarray(devices), ("b",))
    n = jax.tree_util.tree_leaves(tree)[0].shape[0]
    if n % len(devices):
        return tree
    return jax.device_put(tree, NamedSharding(mesh, PartitionSpec("b")))


def fit_batch(
    measurements: Sequence[Measurement],
    model,
    *,
    loss: str = "log",
    solver: str = "lmb",
    max_steps: int = DEFAULT_MAX_STEPS,
    rtol: float = DEFAULT_RTOL,
    atol: float = DEFAULT_ATOL,
    chunk: int = 64,
    sort: bool = True,
    grid_budget: int = _init.GRID_BUDGET,
) -> list[FitResult]:
    """Fit ``model`` to each measurement independently; see the module docstring."""
    loss = check_loss(loss)
    solver = check_solver(solver)
    if solver == "scipy":
        raise UsageError("fit_batch: solver 'scipy' is not batched; use fit() per measurement")
    measurements = list(measurements)
    if not measurements:
        return []
    shapes = {(m.n_samples, m.n_channels) for m in measurements}
    if len(shapes) != 1:
        raise UsageError(f"fit_batch: all measurements need the same samples and channels, got {sorted(shapes)}")
    preps = [prepare(m) for m in measurements]
    mdl = resolve_model(model, preps[0].channels)
    data = Data(*(jnp.stack([p.data[i] for p in preps]) for i in range(6)))
    grid = jnp.asarray(_init.grid_for(mdl, grid_budget))
    n = len(measurements)

    t0 = time.perf_counter()
    v0, l0 = jax.block_until_ready(_batched_grid(mdl, loss)(grid, _shard(data)))
    init_s = time.perf_counter() - t0
    order = np.argsort(np.asarray(l0)) if sort else np.arange(n)

    solve = None if solver == "lmb" else _batched_solve(mdl, loss, solver, rtol, atol, max_steps)
    outward = _batched_outward(mdl, loss)
    v_all = np.asarray(v0).copy()
    val_all = np.zeros(n)
    code_all = np.zeros(n, int)
    steps_all = np.zeros(n, int)
    secs = np.zeros(n)
    for s in range(0, n, chunk):
        idx = order[s : s + chunk]
        pad = chunk - len(idx) if n > chunk else 0  # keep one compiled shape for every chunk
        idx_p = np.concatenate([idx, np.repeat(idx[-1:], pad)])
        d = _shard(Data(*(a[idx_p] for a in data)))
        v = jnp.asarray(v_all[idx_p])
        t1 = time.perf_counter()
        steps = np.zeros(len(idx_p), int)
        if solver == "lmb":
            v, value, code, st = _batched_lmb(mdl, loss, rtol, atol, max_steps)(v, d, jnp.ones(v.shape, bool))
            steps += np.asarray(st)
        for _round in range(0 if solver == "lmb" else 2):
            held = outward(v, d)
            x0 = jax.vmap(lambda vv: mdl.to_unconstrained(mdl.unflatten(vv)))(v)
            x, value, code, st = solve(x0, d, ~held)
            v = jax.vmap(lambda xx: mdl.flatten(mdl.from_unconstrained(xx)))(x)
            steps += np.asarray(st)
        jax.block_until_ready(v)
        dt = time.perf_counter() - t1
        k = len(idx)
        v_all[idx] = np.asarray(v)[:k]
        val_all[idx] = np.asarray(value)[:k]
        code_all[idx] = np.asarray(code)[:k]
        steps_all[idx] = steps[:k]
        secs[idx] = dt / len(idx_p)

    results = []
    for i, (m, prep) in enumerate(zip(measurements, preps)):
        params = {k: np.asarray(a) for k, a in mdl.unflatten(jnp.asarray(v_all[i])).items()}
        results.append(FitResult(
            model=mdl, params=params, loss=loss, loss_value=float(val_all[i]),
            metrics=evaluate(mdl, params, prep.data), steps=int(steps_all[i]), converged=bool(code_all[i] == 0),
            status=STATUS_TEXT[int(code_all[i])],
            seconds={"compile": 0.0, "run": float(secs[i] + init_s / n), "init": init_s / n},
            solver=solver, data_name=m.name, n_used=prep.n_used, n_excluded=prep.n_excluded, excluded=prep.excluded,
            stderr=standard_errors(mdl, loss, params, prep.data, float(val_all[i]), prep.n_used * prep.channels),
            start={k: np.asarray(a) for k, a in mdl.unflatten(jnp.asarray(np.asarray(v0)[i])).items()},
            options={"max_steps": max_steps, "rtol": rtol, "atol": atol, "batch": True, "chunk": chunk},
        ))
    return results
