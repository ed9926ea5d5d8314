"""The default start: a small grid over the nonlinear parameters with the linear ones solved at
every grid point (variable projection), vectorised in JAX, on a subset of the samples.

The model is linear in the parameters declared ``Param(linear=True)`` (kd, ks, rho):
f = f_0 + sum_j x_j A_j. ``A_j`` comes from one model evaluation per linear *parameter* (all its
channels at once). The x_j are the box-constrained least-squares solution of the loss linearised
at the reference (weights (dg/df(f_ref))^2, so that for the ``log`` loss the bright specular peak
does not dominate): the unconstrained normal equations, clipped to the box, then a few sweeps of
projected coordinate descent. Each grid point is scored by the true loss, and the start stage
(:func:`start_stage`, a compiled program of the fit's stages, run over lanes by ``stages.run_stage``) ranks
the points with any starts the caller gives: the best K of each fit start its solves.

Grid (structure-aware, small, so that the start costs less than the solve):

* roughness and exponents get ``POINTS_ROUGHNESS`` values on a log axis (``POINTS_LOBES`` for
  repeated lobes), other nonlinear
  parameters (Fresnel f0, shape) ``POINTS_OTHER`` values; a parameter that declares its grid
  values (``Param.grid``: Lafortune's C) those;
* lobes of one kind in a composite (``ggx1``, ``ggx2``) are started at *separated* roughnesses:
  only strictly increasing combinations (ggx1.alpha < ggx2.alpha), so one lobe takes the sharp
  peak and the other the broad sheen; their other nonlinear parameters share one grid value;
* a parameter held by ``free = False`` has the single value ``anchor``;
* where a bound is infinite, the grid uses the parameter's declared range (``Param.lower`` /
  ``Param.upper`` when finite, else ``ROLE_RANGE`` of its role) intersected with the bounds.
"""

from __future__ import annotations

import functools
import itertools
import math
import re

import jax
import jax.numpy as jnp
import numpy as np

from ..models.base import Model, Param
from .lanes import in_solve_dtype, map_lanes
from .linalg import spd_solve
from .problem import Data
from .objective import Objective

POINTS_ROUGHNESS = 10
#: Roughness values shared by repeated lobes (their strictly increasing pairs: 45 for 10 values; 8 values missed the best basin of vch_golden_yellow).
POINTS_LOBES = 10
POINTS_OTHER = 3
#: Most grid points scored: a product grid larger than this (a model with many nonlinear
#: parameters: 10 x 10 x 3^8 = 656 100 for ``mitsuba:principled``) is replaced by this many of its
#: points drawn without repetition by a fixed seed, so that a start's time and memory are bounded
#: whatever the model (each roughness value still appears about GRID_MAX_POINTS / 10 times).
GRID_MAX_POINTS = 2048
#: Grid points evaluated at once (``lax.map`` batches): memory grows with this, not with the grid.
GRID_BATCH = 256
#: Fraction of each axis kept away from its ends (a roughness of exactly 1e-4 is a bad start).
GRID_MARGIN = 0.04
#: Grid range of a nonlinear parameter whose bound (and declared bound) is infinite, by role.
ROLE_RANGE = {"roughness": (1e-3, 1.0), "exponent": (1.0, 1e4), "fresnel": (0.0, 1.0),
              "shape": (0.0, 1.0), "anisotropy": (-1.0, 1.0), "albedo": (0.0, 1.0)}
#: The grid scores at most this many samples (a fixed pseudo-random subset, the same for every
#: data set of a shape); the solver then works on all of them. A start only has to land in the
#: right basin.
GRID_SAMPLES = 768
#: Projected coordinate-descent sweeps after the clipped unconstrained solution.
SWEEPS = 4

_NAME = re.compile(r"^(?P<kind>[a-z_]+?)(?P<index>\d+)\.(?P<suffix>.+)$")


def _points(p: Param, repeated: bool = False) -> int:
    """How many grid values a nonlinear parameter gets (``repeated``: one of several lobes of a kind)."""
    if p.role in ("roughness", "exponent"):
        return POINTS_LOBES if repeated else POINTS_ROUGHNESS
    return POINTS_OTHER


def _axis(p: Param, lo: float, hi: float, k: int) -> np.ndarray:
    if p.grid is not None:  # the model's own values for the start (inside this fit's bounds)
        return np.unique(np.clip(np.asarray(p.grid, np.float64), lo, hi))
    a = lo if np.isfinite(lo) else (p.lower if np.isfinite(p.lower) else ROLE_RANGE.get(p.role, (0.0, 1.0))[0])
    b = hi if np.isfinite(hi) else (p.upper if np.isfinite(p.upper) else ROLE_RANGE.get(p.role, (0.0, 1.0))[1])
    if not np.isfinite(lo) and a > min(b, hi):
        a = min(b, hi)
    if not np.isfinite(hi) and b < a:
        b = max(a * 100 if a > 0 else a + 1, lo)
    if b <= a:
        return np.asarray([a])
    log = a > 0 and b / a >= 100.0
    ta, tb = (math.log(a), math.log(b)) if log else (a, b)
    t = np.linspace(ta + GRID_MARGIN * (tb - ta), tb - GRID_MARGIN * (tb - ta), k)
    return np.exp(t) if log else t


def _layout(model: Model):
    """Flat index of the first element of every parameter."""
    out, i = {}, 0
    for p in model.params:
        out[p.name] = i
        i += model.size(p)
    return out


def grid_for(model: Model, lo, hi, free, anchor) -> np.ndarray:
    """Grid points (G, number of nonlinear parameters), one shared value over a parameter's channels."""
    lo, hi, free, anchor = (np.asarray(a) for a in (lo, hi, free, anchor))
    start = _layout(model)
    nonlin = [p for p in model.params if not p.linear]
    if not nonlin:
        return np.zeros((1, 0))
    # Groups: parameters of repeated lobes of one kind with the same name (ggx1.alpha, ggx2.alpha).
    groups: dict[tuple, list[int]] = {}
    for j, p in enumerate(nonlin):
        m = _NAME.match(p.name)
        key = (m["kind"], m["suffix"]) if m else (p.name,)
        groups.setdefault(key, []).append(j)
    factors = []  # (column indices, rows of values)
    for cols in groups.values():
        axes = []
        for j in cols:
            p = nonlin[j]
            i = start[p.name]
            if not free[i]:
                axes.append(np.asarray([anchor[i]]))
            else:
                k = _points(p, repeated=len(cols) > 1)
                axes.append(_axis(p, lo[i], hi[i], k))
        if len(cols) == 1:
            rows = axes[0][:, None]
        elif nonlin[cols[0]].role in ("roughness", "exponent") and all(len(a) > 1 for a in axes):
            # Separated lobes: strictly increasing combinations of one shared axis.
            rows = np.asarray(list(itertools.combinations(axes[0], len(cols))))
        elif all(len(a) == len(axes[0]) for a in axes):
            rows = np.stack(axes, axis=1)  # tied: one value for every lobe
        else:
            rows = np.asarray(list(itertools.product(*axes)))
        factors.append((cols, rows))
    shape = tuple(len(rows) for _, rows in factors)
    total = math.prod(shape)
    if total <= GRID_MAX_POINTS:
        combos = itertools.product(*(range(n) for n in shape))
    else:  # a fixed subset of the product, never materialised in full
        picked = np.sort(np.random.default_rng(0).choice(total, GRID_MAX_POINTS, replace=False))
        combos = zip(*np.unravel_index(picked, shape))
    points = []
    for combo in combos:
        pt = np.zeros(len(nonlin))
        for (cols, rows), r in zip(factors, combo):
            pt[cols] = rows[r]
        points.append(pt)
    return np.asarray(points, dtype=np.float64)


def cached_grid(model: Model, lo, hi, free, anchor) -> np.ndarray:
    """:func:`grid_for`, built once per model and space (read-only)."""
    arrays = (np.asarray(lo, np.float64), np.asarray(hi, np.float64), np.asarray(free, bool),
              np.asarray(anchor, np.float64))
    return _cached_grid(model, *(a.tobytes() for a in arrays))


@functools.lru_cache(maxsize=64)
def _cached_grid(model: Model, lo: bytes, hi: bytes, free: bytes, anchor: bytes) -> np.ndarray:
    lo, hi, anchor = (np.frombuffer(b, dtype=np.float64) for b in (lo, hi, anchor))
    pts = grid_for(model, lo, hi, np.frombuffer(free, dtype=bool), anchor)
    pts.flags.writeable = False
    return pts


def _box_lsq(gram, rhs, lo, hi, sweeps: int = SWEEPS):
    """min 0.5 x'Gx - b'x on lo <= x <= hi (G small, PSD, unit diagonal, or a zero row and column
    where a column of the data is zero): the unconstrained solution clipped, then projected
    coordinate descent."""
    n = rhs.shape[0]
    ridge = 1e-9 * jnp.eye(n, dtype=gram.dtype)
    x = spd_solve(gram + ridge, rhs)
    x = jnp.where(jnp.all(jnp.isfinite(x)), x, rhs)
    x = jnp.clip(x, lo, hi)
    for _ in range(sweeps):
        for j in range(n):  # n is small and static: unrolled
            d = gram[j, j]
            g = rhs[j] - gram[j] @ x + d * x[j]
            # A column the data do not see (d = 0: the parameter changes no used sample) has no say:
            # it keeps its value; 0 / 0 would make it NaN, and through gram[k] @ x every other one.
            x = x.at[j].set(jnp.where(d > 0, jnp.clip(g / jnp.where(d > 0, d, 1.0), lo[j], hi[j]), x[j]))
    return x


@functools.lru_cache(maxsize=None)
def vp_grid(objective: Objective):
    """run(grid (G, m), data, lo, hi, free, anchor) -> (flat params (G, P), loss (G,)): the variable projection of
    ``objective`` at each grid point (the linear parameters solved under the loss made linear at the reference)."""
    model, residual, row_weights = objective.model, objective.values_residual, objective.row_weights
    lin = [p for p in model.params if p.linear]
    nonlin = [p for p in model.params if not p.linear]
    C = model.channels
    start = _layout(model)
    # Element j of the linear unknowns: (linear param index, channel or -1 if shared, flat index).
    elements = []
    for i, p in enumerate(lin):
        if model.size(p) == 1:
            elements.append((i, -1, start[p.name]))
        else:
            elements.extend((i, c, start[p.name] + c) for c in range(model.size(p)))
    el_flat = np.asarray([e[2] for e in elements], dtype=int)
    nl_flat = [(start[p.name], model.size(p)) for p in nonlin]

    def flat_of(point, x):
        v = jnp.zeros((model.n_free,), dtype=point.dtype if nonlin else x.dtype)
        for (i, n), val in zip(nl_flat, point):
            v = v.at[i : i + n].set(val)
        if len(el_flat):
            v = v.at[el_flat].set(x)
        return v

    # Separable models whose linear parameters are all per channel (every model of the library
    # but ashikhmin_shirley): one formula evaluation per grid point gives f_0 and every column
    # (``Objective.basis``), and the linear least squares splits into one small system per channel.
    per_channel = objective.basis is not None and all(model.size(p) == C for p in lin)
    basis = objective.basis if per_channel else None
    lin_flat = np.asarray([[start[p.name] + c for p in lin] for c in range(C)], dtype=int)  # (C, L)

    def one_per_channel(point, data: Data, lo, hi, free, anchor):
        wi, wo, ref, sqrt_w, cos_i, floor = data
        F = basis(jnp.asarray(point, ref.dtype).reshape(-1), wi, wo)  # (L + 1, N)
        b0, B = F[-1], F[:-1] - F[-1:]  # (N,), (L, N)
        u = (sqrt_w**2 * row_weights(ref, cos_i, floor)).T  # (C, N)
        gram = jnp.einsum("cn,jn,kn->cjk", u, B, B)
        rhs = jnp.einsum("cn,jn->cj", u * (ref.T - b0[None]), B)
        s = jnp.sqrt(jnp.maximum(jnp.diagonal(gram, axis1=1, axis2=2), jnp.finfo(ref.dtype).tiny))  # (C, L)
        elo = jnp.where(free[lin_flat], lo[lin_flat], anchor[lin_flat])
        ehi = jnp.where(free[lin_flat], hi[lin_flat], anchor[lin_flat])
        x = jax.vmap(_box_lsq)(gram / s[:, :, None] / s[:, None, :], rhs / s, elo * s, ehi * s) / s
        x = jnp.clip(x, elo, ehi)  # (C, L)
        f = b0[None] + x @ B  # (C, N)
        r = residual(f, ref.T, cos_i.T, sqrt_w.T, floor[:, None])
        # A non-finite residual makes the point's value infinite (as a NaN value is below). The select also keeps
        # XLA from handing the whole log loss to the YNNPACK fusion of the sum, where it ran at ~5 ns a value
        # against ~2 ns in XLA's own loop: ggx's start stage 0.68-0.74 -> 0.43-0.53 ms a lane on one core.
        r = jnp.where(jnp.isfinite(r), r, jnp.inf)
        value = jnp.sum(r**2)
        v = flat_of(point, jnp.zeros((len(el_flat),), dtype=ref.dtype)).at[lin_flat].set(x)
        return v, jnp.where(jnp.isfinite(value), value, jnp.inf)

    def one(point, data: Data, lo, hi, free, anchor):
        if basis is not None:
            return one_per_channel(point, data, lo, hi, free, anchor)
        wi, wo, ref, sqrt_w, cos_i, floor = data
        zero = jnp.zeros((len(el_flat),), dtype=ref.dtype)
        f0 = model.flat.f_r(flat_of(point, zero), wi, wo)
        if not lin:
            x, f = zero, f0
        else:
            cols = []
            for i, p in enumerate(lin):
                ones = jnp.zeros((len(el_flat),), dtype=ref.dtype)
                ones = ones.at[np.asarray([j for j, e in enumerate(elements) if e[0] == i])].set(1.0)
                g = model.flat.f_r(flat_of(point, ones), wi, wo) - f0
                for e in elements:
                    if e[0] == i:
                        cols.append(g if e[1] < 0 else g * (jnp.arange(C) == e[1]))
            A = jnp.stack(cols, axis=-1)  # (N, C, L)
            u = sqrt_w**2 * row_weights(ref, cos_i, floor)  # (N, C)
            Au = A * u[..., None]
            gram = jnp.einsum("ncl,nck->lk", Au, A)
            rhs = jnp.einsum("ncl,nc->l", Au, ref - f0)
            s = jnp.sqrt(jnp.maximum(jnp.diag(gram), jnp.finfo(ref.dtype).tiny))
            elo = jnp.where(free[el_flat], lo[el_flat], anchor[el_flat])
            ehi = jnp.where(free[el_flat], hi[el_flat], anchor[el_flat])
            x = _box_lsq(gram / s[:, None] / s[None, :], rhs / s, elo * s, ehi * s) / s
            x = jnp.clip(x, elo, ehi)
            f = f0 + jnp.einsum("ncl,l->nc", A, x)
        r = residual(f, ref, cos_i, sqrt_w, floor)
        r = jnp.where(jnp.isfinite(r), r, jnp.inf)  # as in one_per_channel
        value = jnp.sum(r**2)
        return flat_of(point, x), jnp.where(jnp.isfinite(value), value, jnp.inf)

    def run(grid, data, lo, hi, free, anchor):
        return jax.lax.map(lambda point: one(point, data, lo, hi, free, anchor), grid, batch_size=GRID_BATCH)

    return run


@functools.lru_cache(maxsize=16)
def _subset_index(n: int) -> np.ndarray | None:
    if n <= GRID_SAMPLES:
        return None
    # Pseudo-random, not strided: a stride aligned with the 81-view rows of a UBO table would
    # keep the same views for every light (and could miss every mirror configuration).
    return np.sort(np.random.default_rng(0).choice(n, GRID_SAMPLES, replace=False))


def subset_index(data: Data) -> np.ndarray | None:
    """Rows the grid scores for ``data``: the fixed pseudo-random subset of a table whose samples are
    all used; where some are not (weight 0, NaN), the subset is drawn from the used ones (all of them
    when they are fewer, the rest of its fixed length filled with unused rows, which weigh nothing),
    so that masked samples do not crowd out the data (docs/fitting.md#hostile-but-valid-data: 5 valid samples in a UBO table were
    about 0.6 in a random subset, and the fit ended on a needle lobe the same samples given alone
    did not). None: all rows. A lobe the subset misses (a narrow peak on a few mirror samples) and
    the solve then switches off is tried again on every row (:func:`reseed_points`, ``driver.solve``)."""
    n = data[0].shape[0]
    idx = _subset_index(n)
    if idx is None:
        return None
    sqrt_w = np.asarray(data[3]).reshape(n, -1)
    used = np.flatnonzero(sqrt_w.max(axis=1) > 0)
    if len(used) == n:
        return idx
    if len(used) >= GRID_SAMPLES:
        return np.sort(np.random.default_rng(0).choice(used, GRID_SAMPLES, replace=False))
    unused = np.setdiff1d(np.arange(n), used)
    return np.sort(np.concatenate([used, unused[: GRID_SAMPLES - len(used)]]))


def subset_rows(data: Data) -> np.ndarray:
    """Rows the grid scores (:func:`subset_index`: drawn from the used samples), or all."""
    idx = subset_index(data)
    return np.arange(data[0].shape[-2]) if idx is None else idx


def take_rows(data: Data, idx) -> Data:
    """The samples ``idx`` of every per-sample array (``floor`` is per channel: kept whole)."""
    n = data[0].shape[0]
    return Data(*(a[idx] if a.ndim and a.shape[0] == n else a for a in data))


# -- the start stage (a compiled program that ``stages.run_stage`` runs over lanes) ---------------------
@functools.lru_cache(maxsize=None)
def start_stage(objective: Objective, k: int, grid: bool, lanes: int):
    """run(lane, data, grid_points (G, m), lo, hi, free, anchor, subset (S,) int, count) -> (starts (L, k, P),
    values (L, k)): per lane (the first ``count``: ``lanes.map_lanes``) the k candidates with the lowest loss
    on the ``subset`` rows, among the grid points (:func:`vp_grid`: the linear parameters solved at each) when
    ``grid``, and the E given starts. ``lane``: the given starts (L, E, P), or (grids (L, G, m), given) for a
    grid of each lane's own (then ``grid_points`` is not read). Among equal losses the grid (listed first) wins."""
    vp = vp_grid(objective)
    residual = objective.residual

    def one(grid_points, given, data, lo, hi, free, anchor, subset):
        sub = take_rows(in_solve_dtype(data), subset)
        given = jnp.where(free, jnp.clip(given, lo, hi), anchor)

        def subset_loss(v):
            r = residual(v, sub)
            r = jnp.where(jnp.isfinite(r), r, jnp.inf)  # as in vp_grid: the loss computed in XLA's own loop
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

    def run(lane, data, grid_points, lo, hi, free, anchor, subset, count):
        if isinstance(lane, tuple):  # (grids (L, G, m), given): a grid of each lane's own (a lobe re-seeded)
            return map_lanes(lambda x, d: one(x[0], x[1], d, lo, hi, free, anchor, subset), lane, data, lanes, count)
        return map_lanes(lambda g, d: one(grid_points, g, d, lo, hi, free, anchor, subset), lane, data, lanes, count)

    return run


#: Most points of a re-seeding grid (:func:`reseed_grids`). It is scored on every sample, not on the start
#: grid's GRID_SAMPLES: 256 points on UBO-81's 6561 samples cost about what the start grid's 2048 on 768 do.
#: A larger product (``mitsuba:principled``'s one lobe: 10 x 3^5 = 2700 points, 7.2 s of a fit on the
#: bundled sample) is replaced by this many of its points drawn by a fixed seed (each roughness value still
#: about 25 times there).
RESEED_MAX_POINTS = 256


def reseed_grids(space, v: np.ndarray, lobe: tuple[str, ...]) -> np.ndarray:
    """Grid points (n, G, nonlinear parameters) for :func:`vp_grid`, one grid per fit (rows of ``v``
    (n, P)): the fit with the nonlinear parameters named in ``lobe`` moved over the default grid's axes
    (its roughness on POINTS_ROUGHNESS values, the others on POINTS_OTHER; at most RESEED_MAX_POINTS of
    them); the linear parameters are solved again at each point."""
    m = space.model
    v = np.asarray(v, dtype=np.float64).reshape(-1, m.n_free)
    slices = dict(m.flat.slices)
    nonlin = [p for p in m.params if not p.linear]
    base = np.stack([v[:, slices[p.name]].mean(axis=1) for p in nonlin], axis=1) if nonlin else np.zeros((len(v), 0))
    cols, axes = [], []
    for j, p in enumerate(nonlin):
        s = slices[p.name]
        if p.name in lobe and space.free[s].any():
            cols.append(j)
            axes.append(_axis(p, space.lo[s.start], space.hi[s.start], _points(p)))
    combos = np.asarray(list(itertools.product(*axes)), dtype=np.float64).reshape(-1, len(cols))
    if len(combos) > RESEED_MAX_POINTS:  # a fixed subset, as the start grid's (GRID_MAX_POINTS)
        combos = combos[np.sort(np.random.default_rng(0).choice(len(combos), RESEED_MAX_POINTS, replace=False))]
    grids = np.repeat(base[:, None, :], len(combos), axis=1)
    grids[:, :, cols] = combos[None]
    return grids
