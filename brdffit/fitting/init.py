"""Robust default start: a coarse grid over the nonlinear parameters with the linear ones solved
exactly at every grid point (variable projection), vectorised in JAX.

For every grid point of the nonlinear parameters (roughness and exponents on log axes, Fresnel
f0, sigma, lobe shape on linear axes) the model is linear in the parameters declared
``Param(linear=True)`` (kd, ks, rho): f = f_0 + sum_j x_j A_j. ``A_j`` comes from one model
evaluation per linear *parameter* (all its channels at once: a per-channel parameter acts on its
own channel only, which holds for every model of SPEC 4). The x_j are then the box-constrained
(usually non-negative) least-squares solution of the loss linearised at the reference —
weights (dg/df(f_ref))^2, so that for the ``log`` loss the bright specular peak does not dominate
— solved by projected coordinate descent on the small normal equations. Each grid point is then
scored by the *true* loss (exact, because f is linear in x), and the best point (or the best k
distinct points for multistart) goes to the solver.
"""

from __future__ import annotations

import functools
import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..models.base import Model, Param
from . import losses as L
from .problem import Data

#: Total number of grid points to aim for (split evenly over the nonlinear parameters).
GRID_BUDGET = 128
#: Fraction of each axis kept away from the bounds (a roughness of exactly 1e-4 is a bad start).
GRID_MARGIN = 0.04


def _axis_values(p: Param, k: int, lower: float, upper: float) -> np.ndarray:
    # [params] the axis spans the fit's box; an infinite side takes the parameter's finite range
    # (``Param.finite_range``: its physical range there).
    a = lower if math.isfinite(lower) else p.finite_range[0]
    b = upper if math.isfinite(upper) else p.finite_range[1]
    if b <= a:  # a box entirely beyond the finite range (bounds=(2, inf) for alpha): widen it
        b = a * 100.0 if p.scale == "log" else a + max(1.0, abs(a))
    if lower == upper:
        return np.asarray([lower])
    a, b = (math.log(a), math.log(b)) if p.scale == "log" else (a, b)
    t = np.linspace(a + GRID_MARGIN * (b - a), b - GRID_MARGIN * (b - a), k)
    return np.exp(t) if p.scale == "log" else t


def grid_for(model: Model, budget: int = GRID_BUDGET, space=None) -> np.ndarray:
    """Grid points (G, n_nonlinear_params): every nonlinear parameter shares one value over its
    channels at the start. ``space`` (a ``ParameterSpace``; default: the declared bounds) sets the
    axes; a fixed parameter has a single value and takes no share of the budget."""
    nonlin = [p for p in model.params if not p.linear]
    if not nonlin:
        return np.zeros((1, 0))
    lo, hi = (model.bounds() if space is None else (space.lo, space.hi))
    first = dict(_first_entries(model))
    fixed = [lo[first[p.name]] == hi[first[p.name]] for p in nonlin]
    n_moving = max(1, len(nonlin) - sum(fixed))
    k = max(2, int(math.floor(budget ** (1.0 / n_moving) + 1e-9)))
    k = min(k, 24)
    axes = [_axis_values(p, k, float(lo[first[p.name]]), float(hi[first[p.name]])) for p in nonlin]
    return np.asarray(list(itertools.product(*axes)), dtype=np.float64)


def _first_entries(model: Model):
    i = 0
    for p in model.params:
        yield p.name, i
        i += model.size(p)


def _params_at(model: Model, point, linear_values: dict[str, jax.Array]):
    params, i = {}, 0
    for p in model.params:
        n = model.size(p)
        if p.linear:
            params[p.name] = linear_values[p.name]
        else:
            params[p.name] = jnp.full((n,), point[i])
            i += 1
    return params


def _box_lsq(gram, rhs, lo, hi, sweeps: int = 40):
    """min 0.5 x'Gx - b'x on lo <= x <= hi, projected coordinate descent (G small, PSD)."""
    n = rhs.shape[0]
    diag = jnp.maximum(jnp.diag(gram), 1e-300)
    # Start from the unconstrained-diagonal solution, clipped.
    x0 = jnp.clip(rhs / diag, lo, hi)

    def sweep(_, x):
        def coord(j, x):
            g = rhs[j] - gram[j] @ x + gram[j, j] * x[j]
            return x.at[j].set(jnp.clip(g / diag[j], lo[j], hi[j]))

        return jax.lax.fori_loop(0, n, coord, x)

    return jax.lax.fori_loop(0, sweeps, sweep, x0)


@functools.lru_cache(maxsize=None)
def vp_grid_fn(model: Model, loss: str):
    """Compiled: (grid (G, m), data, lo (P,), hi (P,)) -> (flat params (G, P), loss (G,)) for every
    grid point; ``lo, hi``: the fit's flat box (its entries for linear parameters are used)."""
    lin = [p for p in model.params if p.linear]
    C = model.channels
    zeros = {p.name: jnp.zeros((model.size(p),)) for p in lin}
    # Element j of the linear unknowns: (param index, channel or -1 for a shared parameter).
    elements = []
    for i, p in enumerate(lin):
        if model.size(p) == 1:
            elements.append((i, -1))
        else:
            elements.extend((i, c) for c in range(model.size(p)))
    # [params] flat indices of the linear unknowns: their box (lo, hi) is a runtime argument.
    starts = dict(_first_entries(model))
    lin_index = np.asarray([starts[lin[i].name] + max(c, 0) for i, c in elements], dtype=int)

    def one(point, data: Data, lo, hi):
        wi, wo, ref, sqrt_w, cos_i, floor = data
        f0 = model.eval(_params_at(model, point, zeros), wi, wo)
        if not lin:
            x = jnp.zeros((0,))
            f = f0
        else:
            groups = []
            for p in lin:
                vals = dict(zeros)
                vals[p.name] = jnp.ones((model.size(p),))
                groups.append(model.eval(_params_at(model, point, vals), wi, wo) - f0)
            cols = []
            for i, c in elements:
                g = groups[i]
                cols.append(g if c < 0 else g * (jnp.arange(C) == c))
            A = jnp.stack(cols, axis=-1)  # (N, C, L)
            u = sqrt_w**2 * L.linearised_row_weights(loss, ref, cos_i, floor)  # (N, C)
            Au = A * u[..., None]
            gram = jnp.einsum("ncl,nck->lk", Au, A)
            rhs = jnp.einsum("ncl,nc->l", Au, ref - f0)
            # Scale to unit diagonal for a well-conditioned descent.
            s = jnp.sqrt(jnp.maximum(jnp.diag(gram), 1e-300))
            x = _box_lsq(gram / s[:, None] / s[None, :], rhs / s, lo * s, hi * s) / s
            x = jnp.clip(x, lo, hi)
            f = f0 + jnp.einsum("ncl,l->nc", A, x)
        r = L.residual(loss, f, ref, cos_i, sqrt_w, floor)
        value = jnp.sum(r**2)
        value = jnp.where(jnp.isfinite(value), value, jnp.inf)
        # Assemble the flat parameter vector in model order.
        linear_values, j = {}, 0
        for p in lin:
            n = model.size(p)
            if n == 1:
                linear_values[p.name] = x[j : j + 1]
            else:
                linear_values[p.name] = x[j : j + n]
            j += n
        flat = model.flatten(_params_at(model, point, linear_values)) if model.params else jnp.zeros((0,))
        return flat, value

    def run(grid, data, lo_flat, hi_flat):
        lo, hi = lo_flat[lin_index], hi_flat[lin_index]
        return jax.lax.map(lambda pt: one(pt, data, lo, hi), grid, batch_size=16)

    return jax.jit(run)


_COMPILED: dict = {}

#: The grid scores at most this many samples (a fixed pseudo-random subset, the same for every
#: data set of a shape); the solver then polishes on all of them. A start only has to land in
#: the right basin, and the grid is the larger part of a fit's run time.
GRID_SAMPLES = 2048


def _subset(data: Data) -> Data:
    n = data[0].shape[0]
    if n <= GRID_SAMPLES:
        return data
    # Pseudo-random, not strided: a stride aligned with the 81-view rows of a UBO table would
    # keep the same views for every light (and could miss every mirror configuration).
    idx = np.sort(np.random.default_rng(0).choice(n, GRID_SAMPLES, replace=False))
    return Data(*(a[idx] if a.ndim and a.shape[0] == n else a for a in data))


def best_starts(model: Model, loss: str, data: Data, k: int = 1, budget: int = GRID_BUDGET, space=None):
    """The k best grid starts: flat params (k, P), their losses (k,), compile s, run s.

    ``space``: the fit's ``ParameterSpace`` (default: the declared bounds, nothing fixed)."""
    import time

    grid = jnp.asarray(grid_for(model, budget, space))
    lo, hi = model.bounds() if space is None else (space.lo, space.hi)
    lo, hi = jnp.asarray(lo), jnp.asarray(hi)
    data = _subset(data)
    key = (model, loss, grid.shape, tuple((a.shape, str(a.dtype)) for a in data))
    compiled, compile_s = _COMPILED.get(key), 0.0
    if compiled is None:
        t0 = time.perf_counter()
        compiled = vp_grid_fn(model, loss).lower(grid, data, lo, hi).compile()
        compile_s = time.perf_counter() - t0
        _COMPILED[key] = compiled
    t0 = time.perf_counter()
    flats, values = jax.block_until_ready(compiled(grid, data, lo, hi))
    order = np.argsort(np.asarray(values))[:k]
    run_s = time.perf_counter() - t0
    flats = np.asarray(flats)[order]
    if space is not None:  # a fixed per-channel value the shared grid value could not carry
        flats = np.stack([space.clip(f) for f in flats])
    return flats, np.asarray(values)[order], compile_s, run_s
