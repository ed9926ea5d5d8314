"""One tile of a BTF fitted (``brdffit.fit_btf``'s unit of work, docs/btf.md#btfs-per-texel-fitting).

Neighbouring texels' results as starts (``neighbours=True``, the default). Inside a tile the
texels are fitted in passes over nested lattices (:func:`neighbour_passes`, strides 4, 2, 1):
the first pass (1/16 of the texels) starts from the initialisation grid like ``fit``, every
later texel starts from the mean of the results of its nearest texels fitted in an earlier pass
(those at the nearest distance, 1 or 1.4 texels away: up to four, which surround it) where they
agree (``AGREE``), else from the one of them whose result fits the texel's data best (ranked on the
grid's rows, as the grid's points are), without the grid; a texel that does not converge so is
fitted again from the grid. A mean of agreeing neighbours lies near the texel's optimum: its first step
is damped less than a guess's (``driver.solve(near=True)``, ``_fit_defaults.NEAR_START_DAMPING``).
The mean of the surrounding results is nearer a smooth map's value than any one of them: a 64 x 64
ggx BTF's texels took 1.96 instead of 2.49 steps on average, 837 instead of 685-721 texels/s on one
core. Where they disagree the texel lies at an edge between
materials, or in a texture that changes from texel to texel: the first of them, taken before,
was often another material's (a 32 x 32 ggx BTF of four materials in 3 x 3 blocks: 2.85 -> 1.75
steps a texel, 713 -> 802 texels/s on one core; in blocks of one texel 4.75 -> 3.45 steps,
501 -> 539 texels/s; ``benchmarks/README.md``).

Neighbour starts against the grid, measured when they were built (CPU time, which a shared machine
disturbs less than wall time; losses equal to the grid-started fits within 1e-7 relative): the
compiled program of a 64 x 64 ggx BTF's texel takes 6.9 ms from the grid and 3.78 steps, 5.1 ms
and 3.07 steps from its left neighbour's result; ``benchmarks/bench_btf.py --compare`` (64 x 64
ggx): 3.36 instead of 4.26 steps per texel, 7.7 instead of 8.5 ms of CPU per texel for the whole
fit_btf. A 16 x 16 mosaic of the 4 RGL materials: 7.75 -> 1.42 steps (a region's texels hold one
table: the neighbour's result is the answer); a 16 x 16 ggx BTF with maps that change fast from
texel to texel: 4.27 -> 4.30 (only the grid is saved).
Within a tile only, so that tiles stay independent (resuming, several processes).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from .reader import BTF, N_PAIRS

#: Lattice strides of the passes over a tile (see neighbour_passes): 1/16 of the texels start
#: from the initialisation grid, the others from fitted neighbours 1-2 texels away.
STRIDES = (4, 2, 1)
#: Nearest fitted texels whose results' mean starts a texel (a lattice cell's four corners or sides).
MAX_SOURCES = 4
#: Their mean starts a texel where they agree: every parameter of each within this fraction of the mean's
#: magnitude. Where they do not (an edge between two materials) the mean lies between two basins, and the
#: first of them starts it, as one neighbour did before: on a 32 x 32 mosaic of the four shared RGL
#: tables in stripes, the plain mean took 2.91 steps a texel against 1.67 from one neighbour, this rule
#: 1.59 (0.1 and 0.3 gave the same there; on smooth maps 0.1 averaged fewer texels: 2.20 steps, 0.3 1.96).
AGREE = 0.3


@functools.lru_cache(maxsize=16)
def neighbour_passes(h: int, w: int, strides=STRIDES) -> list[tuple[np.ndarray, np.ndarray]]:
    """The order in which the texels of an h x w tile are fitted, and where each one starts.

    Pass k fits the texels of the lattice of stride ``strides[k]`` (row and column multiples of
    it) that no earlier pass fitted; the last pass fits every texel left. Returns one
    ``(texels, sources)`` pair per pass (flat row-major indices): ``sources[i]`` (``MAX_SOURCES``
    entries, -1 for none) are the texels fitted in an earlier pass at the nearest distance from
    texel ``texels[i]``, in row-major order (the mean of their results starts it); all -1 in the
    first pass (the initialisation grid starts those)."""
    r, c = np.divmod(np.arange(h * w), w)
    done = np.zeros(h * w, bool)
    out = []
    for k, s in enumerate(strides):
        todo = ~done if k == len(strides) - 1 else (r % s == 0) & (c % s == 0) & ~done
        texels = np.flatnonzero(todo)
        if not len(texels):
            continue
        sources = np.full((len(texels), MAX_SOURCES), -1)
        if done.any():
            fitted = np.flatnonzero(done)
            # Nearest by Euclidean distance in texels, every one at that distance (at most MAX_SOURCES: on a
            # lattice, the corners or the sides of the cell around the texel).
            d2 = (r[texels, None] - r[None, fitted]) ** 2 + (c[texels, None] - c[None, fitted]) ** 2
            for i, row in enumerate(d2 <= d2.min(axis=1, keepdims=True)):
                near = fitted[row][:MAX_SOURCES]
                sources[i, : len(near)] = near
        out.append((texels, sources))
        done[texels] = True
    return out


#: Texels a group of tiles holds at least (``group_tiles``), per backend: on a CPU enough for every core's
#: chunks of lanes, on an accelerator for one call of all its lanes.
GROUP_TEXELS = {"cpu": 1024, "device": 32768}
#: Groups per worker process at least (``group_tiles``): a worker that finishes early takes another, so
#: that no core waits long for the slowest.
GROUPS_PER_WORKER = 4


def group_tiles(btf: BTF, tiles, workers: int = 1) -> list[list[int]]:
    """``tiles`` in groups fitted together (:func:`fit_tiles`), in order, each of at least GROUP_TEXELS
    texels (the last may hold fewer): a pass over one 16 x 16 tile is 16 to 192 texels, too few to keep
    a machine's lanes busy. For ``workers`` processes of one core each (``processes``), groups small
    enough that each worker gets several (a core's lanes are one at a time: any group keeps it busy)."""
    import jax

    backend = "cpu" if jax.local_devices()[0].platform == "cpu" else "device"
    per = max(1, -(-GROUP_TEXELS[backend] // (btf.tile * btf.tile)))
    tiles = list(tiles)
    if workers > 1:
        per = max(1, min(per, len(tiles) // (GROUPS_PER_WORKER * workers)))
    return [tiles[i : i + per] for i in range(0, len(tiles), per)]


def load_tiles(btf: BTF, tiles, mdl, options):
    """The prepared data of ``tiles`` (their texels one after another, row-major in each tile), ready for
    :func:`fit_tiles`: (Data, the space, the unit the fits are solved in, each tile's (h, w)). The
    values stay float32 (``problem.prepare_values``: the directions and weights the texels share held
    once); on an accelerator the per-texel arrays are sent to it here, so that a caller preparing the next
    tiles in a thread overlaps their transfer with the current solve."""
    import jax

    from ..fitting.losses import READS_FLOOR
    from ..fitting.problem import data_unit, prepare_values, prepare_values_device
    from ..grid import ubo_pairs

    wi, wo = ubo_pairs()
    name = f"{btf.name} tile {tiles[0]}" if len(tiles) == 1 else f"{btf.name} tiles {tiles[0]}-{tiles[-1]}"
    device = jax.local_devices()[0].platform != "cpu"
    boxes = [btf.tile_box(t) for t in tiles]
    shapes = [(r1 - r0, c1 - c0) for r0, r1, c0, c1 in boxes]
    offsets = np.cumsum([0] + [h * w for h, w in shapes])
    if device:  # sent as read, prepared there
        values = jax.numpy.concatenate([jax.device_put(btf.tile_values(t).reshape(-1, N_PAIRS, btf.channels))
                                        for t in tiles])
        data = prepare_values_device(values, wi, wo, np.ones(len(wi)), name=name)
    else:  # read straight into one buffer, prepared in place
        values = np.empty((int(offsets[-1]), N_PAIRS, btf.channels), np.float32)
        for t, s, e in zip(tiles, offsets[:-1], offsets[1:]):
            btf.tile_values(t, out=values[s:e])
        # The loss floors only where the loss reads them (not the default log loss's): their mean of |values|
        # is about 8 % of a texel's CPU time (``prepare_values``).
        data = prepare_values(values, wi, wo, np.ones(len(wi)), name=name, own=True,
                              floors=options.loss in READS_FLOOR)
    del values
    # The unit (``problem.data_unit``: 1 but for a loss a unit only rescales, on values far from
    # reflectance's range): the driver solves in it and gives the maps back in the BTF's.
    return data, options.space(mdl), data_unit(mdl, options.loss, data), shapes


def fit_tiles(btf: BTF, tiles, mdl, options, neighbours: bool = True, loaded=None,
              clock: dict | None = None) -> list[dict[str, np.ndarray]]:
    """Fit the texels of ``tiles`` together; per tile, arrays (h, w, ...) of params, loss, converged, steps.
    ``loaded``: :func:`load_tiles` of them, when the caller read them ahead. ``clock``: seconds are added to
    its "compile" and "solve" entries (the compiled stages' calls, the device's share of the work).

    Every pass runs the fit driver once on its texels of every tile (``driver.solve``: no FitResult per
    texel, the maps need only these arrays), so a pass is one batch of many texels. With ``neighbours``,
    in the passes of :func:`neighbour_passes` within each tile: the first fits a sparse lattice of texels
    from the initialisation grid, every later one starts each texel from the mean of its nearest fitted
    neighbours' results, without the grid (see the module docstring); those that do not converge so are
    fitted again from the grid."""
    data, space, unit, shapes = loaded if loaded is not None else load_tiles(btf, tiles, mdl, options)
    offsets = np.cumsum([0] + [h * w for h, w in shapes])
    n = int(offsets[-1])
    flat = np.zeros((n, mdl.n_free))
    out = {"loss": np.zeros(n), "converged": np.zeros(n, bool), "steps": np.zeros(n, int)}
    run = _Texels(data, space, unit, options, options.starts(mdl), clock)

    def fit(texels, starts=None):
        return _fit_texels(run, texels, starts)

    per_tile = [neighbour_passes(h, w) if neighbours else [(np.arange(h * w), np.full((h * w, MAX_SOURCES), -1))]
                for h, w in shapes]
    first = np.concatenate([off + passes[0][0] for off, passes in zip(offsets, per_tile)])
    for k in range(max(len(p) for p in per_tile)):
        texels = np.concatenate([off + p[k][0] for off, p in zip(offsets, per_tile) if k < len(p)])
        sources = np.concatenate([np.where(p[k][1] < 0, -1, off + p[k][1]) for off, p in zip(offsets, per_tile)
                                  if k < len(p)])
        v, value, converged, steps = fit(texels, None if k == 0 else neighbour_starts(flat, sources))
        flat[texels] = v
        out["loss"][texels], out["converged"][texels], out["steps"][texels] = value, converged, steps
    # A texel started from a neighbour that did not converge (a neighbour of another material, in
    # a basin of its own) is fitted again from the grid; the lower loss is kept.
    again = np.flatnonzero(~out["converged"] & ~np.isin(np.arange(n), first))
    if len(again):
        v, value, converged, steps = fit(again)
        better = (converged & ~out["converged"][again]) | (value < out["loss"][again])
        keep = again[better]
        flat[keep] = v[better]
        out["loss"][keep], out["converged"][keep], out["steps"][keep] = value[better], converged[better], steps[better]
    results = []
    for (h, w), s, e in zip(shapes, offsets[:-1], offsets[1:]):
        tile = {key: a[s:e].reshape(h, w) for key, a in out.items()}
        i = 0
        for p in mdl.params:
            tile[f"param:{p.name}"] = flat[s:e, i : i + mdl.size(p)].reshape(h, w, -1)
            i += mdl.size(p)
        results.append(tile)
    return results


def neighbour_starts(flat: np.ndarray, sources: np.ndarray) -> np.ndarray:
    """Start candidates (n, MAX_SOURCES, P): per row of ``sources`` (n, MAX_SOURCES; -1 for none), the mean
    of those rows of the fitted ``flat`` where they agree (every parameter within ``AGREE`` of the mean's
    magnitude), alone; else each of them (the first again where there are fewer): the driver then starts
    the texel from the one whose result fits its data best (``driver.solve``, ranked on the grid's rows).
    Each row is a point of the box, so their mean is one too, and lobes ordered in each stay ordered."""
    own = sources >= 0
    rows = flat[np.where(own, sources, sources[:, :1])]  # (n, MAX_SOURCES, P): -1 -> the first
    mean = (rows * own[..., None]).sum(axis=1) / own.sum(axis=1)[:, None]
    spread = np.where(own[..., None], np.abs(rows - mean[:, None]), 0.0).max(axis=1)  # (n, P)
    agree = np.all(spread <= AGREE * np.abs(mean), axis=1)
    return np.where(agree[:, None, None], mean[:, None], rows)


class _Texels(NamedTuple):
    """What the passes over a group of tiles share: their prepared data, the space, the unit the fits are
    solved in, the options and the starts a texel solves from the grid (``FitOptions.starts``), a clock."""

    data: object
    space: object
    unit: float
    options: object
    k: int
    clock: dict | None


def _fit_texels(run: _Texels, texels: np.ndarray, starts: np.ndarray | None = None):
    """The fit driver on ``texels`` (rows of the group's data; ``driver.solve``: no FitResult per texel, the
    maps need only these arrays), from the grid, or from ``starts`` (n, E, P) alone (the best of a texel's
    candidates where they differ). Returns flat params (n, P), loss, converged, steps."""
    from ..fitting.driver import solve

    res = solve(run.space, run.options, run.data, k=run.k, unit=run.unit, fits=texels, starts=starts,
                grid=starts is None, near=starts is not None, results=False)
    if run.clock is not None:
        run.clock["compile"] = run.clock.get("compile", 0.0) + res.seconds["compile"]
        run.clock["solve"] = run.clock.get("solve", 0.0) + res.seconds["run"]
    return res.v, res.loss, res.code == 0, res.steps


def pack_job(mdl, options, neighbours: bool) -> bytes:
    """What fits a tile, for another process (a Dask worker, a worker process): :func:`unpack_job` there."""
    import pickle

    return pickle.dumps((mdl, options, bool(neighbours)), protocol=pickle.HIGHEST_PROTOCOL)


@functools.lru_cache(maxsize=8)
def unpack_job(packed: bytes):
    """A packed job's model, options and neighbours, unpickled once per process: every tile of the job then
    uses the same objects, so their compiled programs are made (or loaded) once."""
    import pickle

    return pickle.loads(packed)


def fit_tile(btf: BTF, t: int, mdl, options, neighbours: bool = True) -> dict[str, np.ndarray]:
    """:func:`fit_tiles` of one tile."""
    return fit_tiles(btf, [t], mdl, options, neighbours)[0]
