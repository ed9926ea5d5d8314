"""One tile of a BTF fitted (``brdffit.fit_btf``'s unit of work, SPEC 7).

Neighbouring texels' results as starts (``neighbours=True``, the default). Inside a tile the
texels are fitted in passes over nested lattices (:func:`neighbour_passes`, strides 4, 2, 1):
the first pass (1/16 of the texels) starts from the initialisation grid like ``fit``, every
later texel starts from the result of its nearest texel fitted in an earlier pass (1 or 1.4
texels away), without the grid; a texel that does not converge so is fitted again from the
grid. Measured (CPU time, which a shared machine disturbs less than wall time; losses equal to
the grid-started fits within 1e-7 relative): the compiled program of a 64 x 64 ggx BTF's texel
takes 6.9 ms from the grid and 3.78 steps, 5.1 ms and 3.07 steps from its left neighbour's
result; ``benchmarks/bench_btf.py --compare`` (64 x 64 ggx): 3.36 instead of 4.26 steps per
texel, 7.7 instead of 8.5 ms of CPU per texel for the whole fit_btf. A 16 x 16 mosaic of the 4
RGL materials: 7.75 -> 1.42 steps (a region's texels hold one table: the neighbour's result is
the answer); a 16 x 16 ggx BTF with maps that change fast from texel to texel: 4.27 -> 4.30
(only the grid is saved).
Within a tile only, so that tiles stay independent (resuming, several processes).
"""

from __future__ import annotations

import numpy as np

from .reader import BTF

#: Texels per compiled call (solve_batch's chunk, unless fit_btf is given ``chunk``; solve_batch
#: splits a call's texels over its worker threads): the passes over a 16 x 16 tile hold 16, 48
#: and 192 texels.
GROUP = 16
#: Lattice strides of the passes over a tile (see neighbour_passes): 1/16 of the texels start
#: from the initialisation grid, the others from a fitted neighbour 1-2 texels away.
STRIDES = (4, 2, 1)


def neighbour_passes(h: int, w: int, strides=STRIDES) -> list[tuple[np.ndarray, np.ndarray]]:
    """The order in which the texels of an h x w tile are fitted, and where each one starts.

    Pass k fits the texels of the lattice of stride ``strides[k]`` (row and column multiples of
    it) that no earlier pass fitted; the last pass fits every texel left. Returns one
    ``(texels, sources)`` pair per pass (flat row-major indices): ``sources[i]`` is the nearest
    texel fitted in an earlier pass (its result starts texel ``texels[i]``), -1 in the first pass
    (the initialisation grid starts those)."""
    r, c = np.divmod(np.arange(h * w), w)
    done = np.zeros(h * w, bool)
    out = []
    for k, s in enumerate(strides):
        todo = ~done if k == len(strides) - 1 else (r % s == 0) & (c % s == 0) & ~done
        texels = np.flatnonzero(todo)
        if not len(texels):
            continue
        if not done.any():
            sources = np.full(len(texels), -1)
        else:
            fitted = np.flatnonzero(done)
            # Nearest by Euclidean distance in texels; ties go to the first in row-major order.
            d2 = (r[texels, None] - r[None, fitted]) ** 2 + (c[texels, None] - c[None, fitted]) ** 2
            sources = fitted[np.argmin(d2, axis=1)]
        out.append((texels, sources))
        done[texels] = True
    return out


def fit_tile(btf: BTF, t: int, mdl, options, neighbours: bool = True) -> dict[str, np.ndarray]:
    """Fit the texels of tile t; arrays (h, w, ...) of params, loss, converged, steps.

    With ``neighbours``, in the passes of :func:`neighbour_passes`: the first fits a sparse
    lattice of texels from the initialisation grid, every later one starts each texel from its
    nearest fitted neighbour's result, without the grid (see the module docstring); those that
    do not converge so are fitted again from the grid."""
    from ..fitting.problem import Data, prepare_stack

    from .reader import _texel_arrays

    values = btf.tile_values(t)  # (h, w, 6561, C) float32
    h, w = values.shape[:2]
    data = prepare_stack(np.asarray(values, np.float64).reshape(h * w, *values.shape[2:]), *_texel_arrays(),
                         name=f"{btf.name} tile {t}")
    n = h * w
    flat = np.zeros((n, mdl.n_free))
    out = {"loss": np.zeros(n), "converged": np.zeros(n, bool), "steps": np.zeros(n, int)}
    passes = neighbour_passes(h, w) if neighbours else [(np.arange(n), np.full(n, -1))]
    for texels, sources in passes:
        starts = None if sources[0] < 0 else flat[sources]
        v, value, converged, steps = _fit_texels(Data(*(a[texels] for a in data)), mdl, options, starts)
        flat[texels] = v
        out["loss"][texels], out["converged"][texels], out["steps"][texels] = value, converged, steps
    # A texel started from a neighbour that did not converge (a neighbour of another material, in
    # a basin of its own) is fitted again from the grid; the lower loss is kept.
    again = np.flatnonzero(~out["converged"] & ~np.isin(np.arange(n), passes[0][0]))
    if len(again):
        v, value, converged, steps = _fit_texels(Data(*(a[again] for a in data)), mdl, options)
        better = (converged & ~out["converged"][again]) | (value < out["loss"][again])
        keep = again[better]
        flat[keep] = v[better]
        out["loss"][keep], out["converged"][keep], out["steps"][keep] = value[better], converged[better], steps[better]
    out = {k: a.reshape(h, w) for k, a in out.items()}
    i = 0
    for p in mdl.params:
        out[f"param:{p.name}"] = flat[:, i : i + mdl.size(p)].reshape(h, w, -1)
        i += mdl.size(p)
    return out


def _fit_texels(data, mdl, options, starts=None):
    """The fit driver on a batch of texels' data (``driver.solve``: no FitResult per texel, fit_btf
    keeps only these maps), from the grid, or from ``starts`` (n, P) alone. Returns flat params
    (n, P), loss, converged, steps."""
    from ..fitting.driver import solve
    from ..fitting.problem import Data

    # Padded (repeating the last texel) to a multiple of GROUP: the calls of every pass, edge tile
    # and refit then share the few compiled shapes of full tiles' passes.
    n = len(data[0])
    pad = np.concatenate([np.arange(n), np.full(-n % GROUP, n - 1)])
    res = solve(options.space(mdl), options, Data(*(a[pad] for a in data)), grid=starts is None, batch=True,
                starts=None if starts is None else np.asarray(starts)[pad])
    return res.v[:n], res.loss[:n], res.code[:n] == 0, res.steps[:n]


