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

    The tile's values are prepared once (``problem.prepare_values``: the directions and weights its
    texels share held once, the values in the cache's float32) and every pass runs the fit driver on some
    of its texels (``driver.solve``: no FitResult per texel, the maps need only these arrays). With
    ``neighbours``, in the passes of :func:`neighbour_passes`: the first fits a sparse lattice of texels
    from the initialisation grid, every later one starts each texel from its nearest fitted neighbour's
    result, without the grid (see the module docstring); those that do not converge so are fitted again
    from the grid."""
    from ..fitting.driver import solve
    from ..fitting.problem import data_unit, in_unit, prepare_values
    from ..grid import ubo_pairs

    values = btf.tile_values(t)  # (h, w, 6561, C) float32
    h, w = values.shape[:2]
    n = h * w
    wi, wo = ubo_pairs()
    data = prepare_values(values.reshape(n, *values.shape[2:]), wi, wo, np.ones(len(wi)), name=f"{btf.name} tile {t}")
    del values
    space = options.space(mdl)
    # The tile's unit (``problem.data_unit``: 1 but for a loss a unit only rescales, on values far from
    # reflectance's range); the maps in the BTF's.
    unit = data_unit(mdl, options.loss, data)
    data, space = in_unit(data, unit), space.in_unit(unit)
    unscale = np.where(space.linear_mask(), unit, 1.0)

    flat = np.zeros((n, mdl.n_free))
    out = {"loss": np.zeros(n), "converged": np.zeros(n, bool), "steps": np.zeros(n, int)}

    def fit(texels, starts=None):
        res = solve(space, options, data, fits=texels, starts=starts, grid=starts is None, results=False)
        return res.v, res.loss, res.code == 0, res.steps

    passes = neighbour_passes(h, w) if neighbours else [(np.arange(n), np.full(n, -1))]
    for texels, sources in passes:
        v, value, converged, steps = fit(texels, None if sources[0] < 0 else flat[sources])
        flat[texels] = v
        out["loss"][texels], out["converged"][texels], out["steps"][texels] = value, converged, steps
    # A texel started from a neighbour that did not converge (a neighbour of another material, in
    # a basin of its own) is fitted again from the grid; the lower loss is kept.
    again = np.flatnonzero(~out["converged"] & ~np.isin(np.arange(n), passes[0][0]))
    if len(again):
        v, value, converged, steps = fit(again)
        better = (converged & ~out["converged"][again]) | (value < out["loss"][again])
        keep = again[better]
        flat[keep] = v[better]
        out["loss"][keep], out["converged"][keep], out["steps"][keep] = value[better], converged[better], steps[better]
    if unit != 1.0:
        flat *= unscale
        out["loss"] *= _loss_scale(options.loss, unit)
    out = {k: a.reshape(h, w) for k, a in out.items()}
    i = 0
    for p in mdl.params:
        out[f"param:{p.name}"] = flat[:, i : i + mdl.size(p)].reshape(h, w, -1)
        i += mdl.size(p)
    return out


def _loss_scale(loss: str, unit: float) -> float:
    """The factor from a loss value in the solve's unit to the table's: the losses a unit only rescales
    (``problem.data_unit``) are homogeneous in f, of degree 2 (l2, cosine_l2), 2/3 (cbrt) or 0 (relative)."""
    return {"l2": unit**2, "cosine_l2": unit**2, "cbrt": unit ** (2.0 / 3.0)}.get(loss, 1.0)
