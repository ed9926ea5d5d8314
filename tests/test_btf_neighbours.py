"""fit_btf's neighbour starts (docs/btf.md#neighbour-starts): the order of the passes over a tile, and that a texel
started from its neighbour's result ends where a start from the grid ends."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.btf import fit as btf_fit
from brdffit.btf import tile as btf_tile
from brdffit.btf import generate as gen


def test_passes_of_a_4x4_tile_by_hand():
    passes = btf_tile.neighbour_passes(4, 4, strides=(4, 2, 1))
    assert len(passes) == 3
    (t1, s1), (t2, s2), (t3, s3) = passes
    def nearest(sources):  # the rows' sources without the -1 padding
        return [[int(x) for x in row if x >= 0] for row in sources]

    # pass 1: the stride-4 lattice is texel (0, 0) alone, started by the grid
    assert t1.tolist() == [0] and nearest(s1) == [[]]
    # pass 2: the rest of the stride-2 lattice, (0,2) (2,0) (2,2), all nearest to (0,0)
    assert t2.tolist() == [2, 8, 10] and nearest(s2) == [[0], [0], [0]]
    # pass 3: every other texel from all its nearest of (0,0) (0,2) (2,0) (2,2), in row-major order:
    # (0,1) is 1 from (0,0) and (0,2); (1,3) is sqrt 2 from (0,2) and (2,2); (3,3) 1.4 from (2,2) alone;
    # (3,0) 1 from (2,0); (1,1) is sqrt 2 from all four
    want = {1: [0, 2], 3: [2], 4: [0, 8], 5: [0, 2, 8, 10], 6: [2, 10], 7: [2, 10], 9: [8, 10], 11: [10],
            12: [8], 13: [8, 10], 14: [10], 15: [10]}
    assert t3.tolist() == sorted(want) and nearest(s3) == [want[t] for t in sorted(want)]


@pytest.mark.parametrize("shape", [(16, 16), (5, 7), (1, 3), (1, 1)])
def test_passes_cover_every_texel_once_from_earlier_passes(shape):
    h, w = shape
    passes = btf_tile.neighbour_passes(h, w)
    seen = np.concatenate([t for t, _ in passes])
    assert sorted(seen.tolist()) == list(range(h * w))
    assert (passes[0][1] == -1).all()
    done = set(passes[0][0].tolist())
    for texels, sources in passes[1:]:
        own = sources >= 0
        assert own[:, 0].all() and set(sources[own].tolist()) <= done  # at least one, each fitted before
        # neighbours, not any fitted texels: within the previous lattice's cell (stride 4 -> 2 * sqrt 2), all
        # at one distance, the nearest of the fitted texels
        r, c = np.divmod(texels, w)
        rs, cs = np.divmod(sources, w)
        d = np.where(own, np.sqrt((r[:, None] - rs) ** 2 + (c[:, None] - cs) ** 2), np.nan)
        assert np.nanmax(d) <= 2 * np.sqrt(2) + 1e-12
        assert np.allclose(np.nanmin(d, axis=1), np.nanmax(d, axis=1))
        fr, fc = np.divmod(np.asarray(sorted(done)), w)
        assert np.allclose(np.nanmin(d, axis=1), np.sqrt((r[:, None] - fr) ** 2 + (c[:, None] - fc) ** 2).min(axis=1))
        done |= set(texels.tolist())
    if h * w >= 16:  # most texels start from a neighbour
        assert len(passes[0][0]) <= h * w / 8


def test_a_texel_starts_from_its_neighbours_mean_where_they_agree_else_from_the_best_of_them():
    """Neighbours that agree (each parameter within AGREE of the mean's magnitude) start a texel from their
    mean; across an edge between two materials the mean would lie between two basins: each of them is a
    candidate (the first again in the slots of missing ones), and the driver starts from the best."""
    flat = np.array([[1.0, 0.10], [1.2, 0.12], [1.0, 0.10], [9.0, 0.50], [1.1, 0.30]])
    sources = np.array([[0, 1, -1, -1],  # agree: mean (1.1, 0.11)
                        [2, 3, -1, -1],  # an edge: (1, 0.1) and (9, 0.5), each a candidate
                        [4, -1, -1, -1],  # one neighbour: itself
                        [0, 4, 1, -1]])  # first parameter agrees, second not (0.1 against 0.3): each
    starts = btf_tile.neighbour_starts(flat, sources)
    assert starts.shape == (4, btf_tile.MAX_SOURCES, 2)
    want = [[[1.1, 0.11]] * 4,
            [[1.0, 0.10], [9.0, 0.50], [1.0, 0.10], [1.0, 0.10]],
            [[1.1, 0.30]] * 4,
            [[1.0, 0.10], [1.1, 0.30], [1.2, 0.12], [1.0, 0.10]]]
    np.testing.assert_allclose(starts, want, rtol=1e-15)


@pytest.fixture(scope="module")
def small_ggx(tmp_path_factory):
    model = brdffit.models.get("ggx")
    maps = gen.smooth_maps(model, 6, 6, seed=5)
    return gen.write_model_btf(tmp_path_factory.mktemp("sg") / "btf", model, maps, noise=0.01, seed=6)


def test_neighbour_starts_reach_the_grid_starts_results(small_ggx, monkeypatch):
    btf = brdffit.load_btf(small_ggx, tile=6)
    calls = []
    real = btf_tile._fit_texels

    def recorded(run, texels, starts=None):
        out = real(run, texels, starts)
        calls.append((None if starts is None else np.array(starts), out[0]))
        return out

    monkeypatch.setattr(btf_tile, "_fit_texels", recorded)
    with_nb = brdffit.fit_btf(btf, "ggx", progress=False)
    passes = btf_tile.neighbour_passes(6, 6)
    assert [c[0] is None for c in calls] == [True, False, False]  # the grid for the first pass only
    # every later texel started from the mean of the results of its nearest earlier-fitted texels where they
    # agree, else from the best of them
    fitted = {}
    for (texels, sources), (starts, v) in zip(passes, calls):
        if starts is not None:
            want = []
            for row in sources:
                near = np.stack([fitted[int(s)] for s in row if s >= 0])
                mean = near.mean(axis=0)
                agree = (np.abs(near - mean) <= btf_tile.AGREE * np.abs(mean)).all()
                pad = [near[0]] * (btf_tile.MAX_SOURCES - len(near))
                want.append([mean] * btf_tile.MAX_SOURCES if agree else [*near, *pad])
            np.testing.assert_allclose(starts, np.stack(want), rtol=1e-15, atol=0)
        fitted.update(zip(texels.tolist(), v))
    flat = np.concatenate([with_nb.params[p.name].reshape(36, -1) for p in btf_fit.resolve_model("ggx", 3).params], 1)
    np.testing.assert_array_equal(flat, np.stack([fitted[i] for i in range(36)]))  # the maps hold those results
    monkeypatch.setattr(btf_tile, "_fit_texels", real)
    grid_only = brdffit.fit_btf(btf, "ggx", progress=False, neighbours=False)
    assert with_nb.converged.all() and grid_only.converged.all()
    np.testing.assert_allclose(with_nb.loss, grid_only.loss, rtol=1e-6)
    for k in grid_only.params:
        if k != "f0":  # not determined by one table next to ks (see generate.smooth_maps)
            np.testing.assert_allclose(with_nb.params[k], grid_only.params[k], rtol=1e-3, err_msg=k)
    assert with_nb.info["neighbours"] and not grid_only.info["neighbours"]


def test_unknown_options_are_usage_errors(small_ggx):
    btf = brdffit.load_btf(small_ggx, tile=6)
    with pytest.raises(brdffit.UsageError, match="unknown option"):
        brdffit.fit_btf(btf, "ggx", progress=False, sort=True)
    with pytest.raises(brdffit.UsageError, match="not batched"):
        brdffit.fit_btf(btf, "ggx", progress=False, solver="scipy")


def test_texels_not_converged_from_a_neighbour_are_fitted_again_from_the_grid(small_ggx, monkeypatch):
    btf = brdffit.load_btf(small_ggx, tile=6)
    calls = []
    real = btf_tile._fit_texels

    def failing(run, texels, starts=None):
        v, value, converged, steps = real(run, texels, starts)
        if starts is not None:  # as if every neighbour start had failed, at a higher loss
            value, converged = value * 2, np.zeros_like(converged)
        calls.append((starts is None, len(value)))
        return v, value, converged, steps

    monkeypatch.setattr(btf_tile, "_fit_texels", failing)
    maps = brdffit.fit_btf(btf, "ggx", progress=False)
    first = len(btf_tile.neighbour_passes(6, 6)[0][0])
    assert calls[-1] == (True, 36 - first)  # every neighbour-started texel, once more from the grid
    assert maps.converged.all()
    monkeypatch.setattr(btf_tile, "_fit_texels", real)
    grid_only = brdffit.fit_btf(btf, "ggx", progress=False, neighbours=False)
    np.testing.assert_array_equal(maps.loss, grid_only.loss)  # the grid's results were kept


def test_a_worse_refit_from_the_grid_is_not_kept(small_ggx, monkeypatch):
    btf = brdffit.load_btf(small_ggx, tile=6)
    real = btf_tile._fit_texels
    calls = []

    def failing(run, texels, starts=None):
        v, value, converged, steps = real(run, texels, starts)
        calls.append(starts is None)
        if starts is not None:  # neighbour starts: not converged, loss x2
            value, converged = value * 2, np.zeros_like(converged)
        elif len(calls) > 1:  # the refit from the grid: not converged either, loss x3
            value, converged = value * 3, np.zeros_like(converged)
        return v, value, converged, steps

    monkeypatch.setattr(btf_tile, "_fit_texels", failing)
    maps = brdffit.fit_btf(btf, "ggx", progress=False)
    monkeypatch.setattr(btf_tile, "_fit_texels", real)
    grid_only = brdffit.fit_btf(btf, "ggx", progress=False, neighbours=False)
    first = np.zeros(36, bool)
    first[btf_tile.neighbour_passes(6, 6)[0][0]] = True
    first = first.reshape(6, 6)
    np.testing.assert_allclose(maps.loss[~first], 2 * grid_only.loss[~first], rtol=1e-6)  # the x2 kept, not the x3
    assert not maps.converged[~first].any() and maps.converged[first].all()


def test_block_maps_are_squares_of_a_few_materials():
    """``generate.block_maps`` (``bench_btf.py --texture``): B x B squares, each one of ``kinds`` parameter sets."""
    maps = gen.block_maps("ggx", 10, 7, 3, kinds=4, seed=2)
    flat = np.concatenate([maps[p.name] for p in btf_fit.resolve_model("ggx", 3).params], axis=-1)  # (10, 7, P)
    assert flat.shape == (10, 7, 8)
    r, c = np.meshgrid(np.arange(10), np.arange(7), indexing="ij")
    np.testing.assert_array_equal(flat, flat[r // 3 * 3, c // 3 * 3])  # constant in each square
    assert 1 < len(np.unique(flat.reshape(-1, 8), axis=0)) <= 4
