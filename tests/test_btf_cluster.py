"""fit_btf on a Dask cluster (docs/btf.md#at-scale): a LocalCluster of two worker processes on this
machine, started once for the module. The maps equal a local run's bit for bit, a killed worker's
tile runs again and the run completes, an interrupted run resumes (with Dask or without), a
worker that cannot read the BTF fails the run with one line naming it, and the CLI's --scheduler."""

from __future__ import annotations

import concurrent.futures
import dataclasses
import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed", reason="brdffit[cluster] (Dask) is not installed")

import cloudpickle  # noqa: E402 - Dask's own serialiser, installed with it
from distributed import Client, LocalCluster  # noqa: E402

import brdffit  # noqa: E402
from brdffit.btf import cluster as btf_cluster  # noqa: E402
from brdffit.btf import generate as gen  # noqa: E402
from brdffit.btf import tile as btf_tile  # noqa: E402
from brdffit.cli import main  # noqa: E402
from brdffit.errors import BrdffitWarning  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from btf_helpers import dask_workers  # noqa: E402

# the plugin travels by value: the workers need not import this test folder
cloudpickle.register_pickle_by_value(dask_workers)


@pytest.fixture(scope="module")
def client():
    """Two worker processes of one thread each (a tile's fit uses the process's cores itself), without
    MALLOC_TRIM_THRESHOLD_ (brdffit.btf.cluster.TRIM). Dask's nanny writes its workers' environment
    into this process's os.environ: put back as it was, for the tests that start processes later."""
    import dask

    saved = dict(os.environ)
    try:
        with dask.config.set({f"distributed.nanny.pre-spawn-environ.{btf_cluster.TRIM}": None}), \
                LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                Client(cluster) as c:
            yield c
    finally:
        os.environ.clear()
        os.environ.update(saved)


def _btf(tmp_path_factory, model: str, size: int, seed: int) -> Path:
    maps = gen.smooth_maps(model, size, size, seed=seed)
    return gen.write_model_btf(tmp_path_factory.mktemp(model) / "btf", model, maps, noise=0.01, seed=seed + 1)


@pytest.fixture(scope="module")
def ggx_btf(tmp_path_factory):
    """8 x 8 texels of ggx in 4 tiles of 4 x 4."""
    return brdffit.load_btf(_btf(tmp_path_factory, "ggx", 8, 5), tile=4, cache_dir=tmp_path_factory.mktemp("c"))


@pytest.fixture(scope="module")
def lambert_btf(tmp_path_factory):
    """12 x 12 texels of lambert in 9 tiles of 4 x 4: cheap, for the run's mechanics."""
    return brdffit.load_btf(_btf(tmp_path_factory, "lambert", 12, 7), tile=4, cache_dir=tmp_path_factory.mktemp("c"))


@pytest.fixture(scope="module")
def lambert_local(lambert_btf):
    return brdffit.fit_btf(lambert_btf, "lambert", progress=False)


def _assert_same_maps(a, b):
    assert a.params.keys() == b.params.keys()
    for k in a.params:
        np.testing.assert_array_equal(a.params[k], b.params[k], err_msg=k)
    np.testing.assert_array_equal(a.loss, b.loss)
    np.testing.assert_array_equal(a.converged, b.converged)
    np.testing.assert_array_equal(a.steps, b.steps)


def _events(client, run: str | None = None) -> list[dict]:
    """The tile tasks' events (brdffit.btf.cluster.EVENTS), of one run (its token) or all."""
    return [m for _, m in client.get_events(btf_cluster.EVENTS) if run is None or m["run"] == run]


def _last_run(client) -> str:
    return _events(client)[-1]["run"]


def test_dask_maps_equal_a_local_run_bit_for_bit(client, ggx_btf, tmp_path):
    local = brdffit.fit_btf(ggx_btf, "ggx", progress=False)
    out = tmp_path / "fit"
    maps = brdffit.fit_btf(ggx_btf, "ggx", progress=False, client=client, out=out)
    _assert_same_maps(maps, local)
    assert maps.converged.all()
    events = _events(client, _last_run(client))
    done = sorted(m["tile"] for m in events if m["phase"] == "done")
    assert done == [0, 1, 2, 3]
    assert os.getpid() not in {m["pid"] for m in events}  # fitted by the workers, not here
    assert maps.info["dask"]["workers"] >= 1 and maps.info["resumed_tiles"] == 0
    # the results a local run writes, and no tile left behind
    assert (out / "params.exr").is_file() and (out / "summary.json").is_file() and not (out / "tiles").exists()
    back = brdffit.ParameterMaps.load(out / "params.exr")
    np.testing.assert_array_equal(back.params["alpha"], local.params["alpha"].astype(np.float32))


@pytest.mark.parametrize("state", ["executing", "memory"])
def test_a_killed_worker_s_tile_runs_again_and_the_run_completes(client, lambert_btf, lambert_local, tmp_path, state):
    """SIGKILL of the worker that runs tile 4: when it starts the tile ("executing"), or when the
    tile is fitted and its file written but the result not yet reported ("memory")."""
    marker, out = tmp_path / "killed", tmp_path / "fit"
    client.register_plugin(dask_workers.KillAt(4, state, str(marker), str(out / "tiles" / "tile_00004.npz")))
    try:
        # a run that waits for ever (tasks bound to the dead worker) fails here instead of hanging
        pool = concurrent.futures.ThreadPoolExecutor(1)
        try:
            maps = pool.submit(brdffit.fit_btf, lambert_btf, "lambert", progress=False, client=client,
                               out=out).result(timeout=300)
        finally:
            pool.shutdown(wait=False)  # (such a run ends when the module's cluster is closed)
    finally:
        client.unregister_worker_plugin(dask_workers.KillAt.name)
    killed, written = (int(x) for x in marker.read_text().split())  # a worker did die
    assert written == (state == "memory")  # mid-tile: nothing written yet; after: the file was there
    _assert_same_maps(maps, lambert_local)  # nothing lost, nothing mixed up
    events = _events(client, _last_run(client))
    assert sorted({m["tile"] for m in events if m["phase"] == "done"}) == list(range(9))
    # tile 4 was fitted again, by another worker than the one killed
    assert killed not in [m["pid"] for m in events if m["tile"] == 4 and m["phase"] == "done"][-1:]
    assert sorted(p.name for p in (tmp_path / "fit").iterdir() if not p.name.startswith(".")) == sorted(
        ["params.exr", "summary.json", "maps.png", *[f"preview_{k}.png" for k in ("kd", "loss", "converged", "steps")]])
    client.wait_for_workers(2, timeout=120)  # the nanny's replacement, for the next test


def test_an_interrupted_dask_run_resumes_with_dask_or_without(client, lambert_btf, lambert_local, tmp_path, monkeypatch):
    out = tmp_path / "fit"
    assert brdffit.fit_btf(lambert_btf, "lambert", progress=False, client=client, out=out, max_tiles=3) is None
    first = sorted(p.name for p in (out / "tiles").glob("tile_*.npz"))
    assert len(first) == 3 and (out / "tiles" / "run.json").is_file() and not (out / "params.exr").exists()
    # resumed on the cluster: only the tiles without a file are submitted
    assert brdffit.fit_btf(lambert_btf, "lambert", progress=False, client=client, out=out, max_tiles=3) is None
    second = {m["tile"] for m in _events(client, _last_run(client))}
    assert len(second) == 3 and not second & {int(n[5:10]) for n in first}
    # and finished here: the workers' tile files are a local run's
    calls = []
    real = btf_tile.fit_tiles

    def counted(b, tiles, *args, **kwargs):
        calls.extend(tiles)
        return real(b, tiles, *args, **kwargs)

    monkeypatch.setattr(btf_tile, "fit_tiles", counted)
    maps = brdffit.fit_btf(lambert_btf, "lambert", progress=False, out=out)
    assert len(calls) == 3 and not set(calls) & (second | {int(n[5:10]) for n in first})
    assert maps.info["resumed_tiles"] == 6
    _assert_same_maps(maps, lambert_local)


def test_a_worker_reads_the_source_where_the_cache_is_not_there(client, lambert_btf, lambert_local, tmp_path):
    """As on another machine: no cache file at the client's path, the source at the same path."""
    elsewhere = dataclasses.replace(lambert_btf, cache=tmp_path / "not-on-this-machine.f32", _owner=None)
    maps = brdffit.fit_btf(elsewhere, "lambert", progress=False, client=client)
    _assert_same_maps(maps, lambert_local)


def test_a_worker_that_cannot_read_the_btf_fails_the_run_with_one_line(client, lambert_btf, tmp_path):
    lost = dataclasses.replace(lambert_btf, cache=tmp_path / "gone.f32", source=str(tmp_path / "moved"), _owner=None)
    with pytest.raises(brdffit.InputError, match="neither the BTF's cache file nor its source") as info:
        brdffit.fit_btf(lost, "lambert", progress=False, client=client, out=tmp_path / "fit")
    assert info.value.path == str(tmp_path / "moved") and "\n" not in str(info.value)
    assert not (tmp_path / "fit" / "params.exr").exists()


def test_workers_with_dask_s_malloc_trim_threshold_are_warned_about(client, lambert_btf):
    import warnings

    client.run(dask_workers.set_environ, btf_cluster.TRIM, "65536")  # what Dask's nanny sets by default
    try:
        with pytest.warns(BrdffitWarning, match="distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"):
            brdffit.fit_btf(lambert_btf, "lambert", progress=False, client=client)
    finally:
        client.run(dask_workers.set_environ, btf_cluster.TRIM, None)
    with warnings.catch_warnings():
        warnings.simplefilter("error", BrdffitWarning)
        brdffit.fit_btf(lambert_btf, "lambert", progress=False, client=client)


def test_a_database_on_the_cluster(client, lambert_btf, lambert_local, tmp_path):
    db = tmp_path / "db"
    db.mkdir()
    for name in ("a", "b"):
        (db / name).symlink_to(lambert_btf.source)
    result = brdffit.fit_btf_database(db, "lambert", out=tmp_path / "out", tile=4, client=client)
    assert [r["material"] for r in result.rows] == ["a", "b"]
    for name in ("a", "b"):
        back = brdffit.ParameterMaps.load(tmp_path / "out" / name / "params.exr")
        np.testing.assert_array_equal(back.params["kd"], lambert_local.params["kd"].astype(np.float32))
        assert json.loads((tmp_path / "out" / name / "summary.json").read_text())["dask"]["workers"] >= 1


def test_cli_scheduler(client, lambert_btf, lambert_local, tmp_path, capsys):
    import dask

    out = tmp_path / "fit"
    args = ["fit-btf", lambert_btf.source, "--model", "lambert", "--tile", "4", "-o", str(out)]
    assert main([*args, "--scheduler", client.scheduler.address]) == 0
    maps = brdffit.ParameterMaps.load(out / "params.exr")
    np.testing.assert_array_equal(maps.params["kd"], lambert_local.params["kd"].astype(np.float32))
    assert client.scheduler.address in (out / "summary.json").read_text()
    capsys.readouterr()
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        assert main([*args[:-1], str(tmp_path / "x"), "--scheduler", "tcp://127.0.0.1:9"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("brdffit: --scheduler tcp://127.0.0.1:9: cannot connect") and "\n" not in err
    assert not (tmp_path / "x").exists()
