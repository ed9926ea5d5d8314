"""``brdffit.fit_btf``: every texel of a BTF fitted on its own (docs/btf.md#btfs-per-texel-fitting).

The work unit is a *tile* of the BTF's cache (16 x 16 texels by default, see
:mod:`brdffit.btf.reader`), fitted by :func:`brdffit.btf.tile.fit_tiles` (one read per tile, the texels
of a group of tiles fitted together, neighbouring texels' results as starts). A run (:class:`TileRun`) takes the
tiles that are not finished yet, has them fitted, and assembles the maps; where the tiles are
fitted is one of three:

- here, in groups of tiles on this process's JAX devices, the next group read while the current one
  is solved (the default);
- by the processes of a ``jax.distributed`` run (e.g. one per machine or per GPU, started by the
  user's launcher: SLURM, mpirun, Kubernetes, or by hand, each having called
  ``jax.distributed.initialize(...)``): process p of n fits the tiles t with t % n == p on its own
  devices, then the maps are gathered (``multihost_utils.process_allgather``) so that every
  process returns the whole ``ParameterMaps``; process 0 alone writes the files. Every process
  must be able to read the BTF (a shared file system, or its own copy);
- by the workers of a Dask cluster (``client=``, :mod:`brdffit.btf.cluster`): one task per tile.

The fitted numbers do not depend on where: each texel is fitted by the same compiled code from the
same data, so one process, several, or a Dask cluster give identical maps (tested bit for bit).

Resuming (:mod:`brdffit.btf.run`). With ``out=DIR``, every finished tile is written at once
(atomically) to ``DIR/tiles/tile_NNNNN.npz`` beside ``DIR/tiles/run.json``, which identifies the
run; a run that finds tiles of the same run there fits only the missing ones, whichever way those
were fitted. When all tiles are done the results (``params.exr``, previews, ``summary.json``, see
:mod:`brdffit.btf.maps`) are written and the tiles removed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import shutil
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from .._progress import progress_bar
from ..errors import UsageError
from ..fitting.problem import resolve_model
from . import run as _run
from . import tile as _tile
from .maps import ParameterMaps
from .reader import BTF

#: fit_btf's keyword options (``FitOptions``' fields that a batch takes).
_OPTIONS = ("solver", "max_steps", "rtol", "atol", "chunk", "lanes", "multistart", "bounds", "fixed", "physical",
            "jacobian")


@dataclasses.dataclass(frozen=True, eq=False)
class TileJob:
    """What fits a tile, the same wherever it is fitted: the resolved model and options, and the
    neighbour starts; ``record`` identifies the run (``run.json``)."""

    model: object
    options: object
    neighbours: bool
    record: dict


def tile_job(btf: BTF, model, loss: str = "log", solver: str | None = None, neighbours: bool = True,
             **batch_options) -> TileJob:
    """Check and resolve ``fit_btf``'s arguments once (see :func:`fit_btf`)."""
    if not isinstance(btf, BTF):
        raise UsageError(f"fit_btf needs a BTF from brdffit.load_btf, got {type(btf).__name__}")
    from ..fitting.objective import jacobian_precision

    options, batch_options = fit_options(loss, solver, batch_options)
    mdl = resolve_model(model, btf.channels)
    # The precision the texels' Jacobian is computed in, whether asked or by default: tiles of a run in the
    # other one (or of a version whose default was float64) are another run's.
    record = {"btf": btf.signature(), "model": mdl.name, "loss": options.loss,
              "options": {k: str(v) for k, v in sorted(batch_options.items())}, "neighbours": bool(neighbours),
              "jacobian": jacobian_precision(mdl, options.jacobian), "tile": btf.tile, "shape": [btf.height, btf.width]}
    return TileJob(mdl, options, bool(neighbours), record)


def fit_options(loss: str, solver: str | None, batch_options: dict):
    """``FitOptions`` of a BTF's fits from ``fit_btf``'s arguments (checked), and the options as
    given (``solver`` among them) for the run's record."""
    from ..fitting.options import FitOptions

    given = {**batch_options, **({} if solver is None else {"solver": solver})}
    unknown = sorted(set(given) - set(_OPTIONS))
    if unknown:
        raise UsageError(f"fit_btf: unknown option(s) {', '.join(unknown)}")
    # A texel's Jacobian in float32 (``objective.JACOBIANS``: its loss stays exact; measured equal to float64's
    # fits within 1e-6 relative): its evaluation ~20 % cheaper on a CPU, and half the arrays' memory.
    return FitOptions(loss=loss, **{"jacobian": "float32", **given}).batched("fit_btf"), given


def fit_btf(
    btf: BTF,
    model,
    *,
    loss: str = "log",
    solver: str | None = None,
    out=None,
    force: bool = False,
    progress: bool | None = None,
    max_tiles: int | None = None,
    neighbours: bool = True,
    client=None,
    processes: int | None = None,
    **batch_options,
) -> ParameterMaps:
    """Fit ``model`` to every texel of ``btf``; see the module docstring.

    ``solver`` and further keyword arguments (``max_steps``, ``rtol``, ``atol``, ``chunk``,
    ``lanes``, ``multistart``, ``bounds``, ``fixed``, ``physical``) mean what they mean for
    ``brdffit.fit_batch`` (its default solver when None); ``jacobian``: the precision of a step's Jacobian,
    "float32" by default here where the model declares it safe (``Model.float32_jacobian``; the loss is
    float64's), "float64" as ``fit``'s (docs/fitting.md#solvers). ``out``: folder for the results and
    the resumable tiles. ``progress``: a bar on stderr (default: when stderr is a terminal).
    ``max_tiles``: stop after fitting this many tiles (returns None; for tests of resuming and for
    splitting work by hand). ``neighbours``: start most texels from their fitted neighbours' results
    (see :mod:`brdffit.btf.tile`); False starts every texel from the initialisation grid.
    ``client``: a ``dask.distributed.Client``; its cluster's workers fit the tiles (see
    :mod:`brdffit.btf.cluster`: ``out`` must then be on a file system the workers share).
    ``processes``: on a CPU, worker processes of one core each fit the tiles (:mod:`brdffit.btf.processes`);
    None: one per core where the system allows it and the run has texels enough to repay their start, 1: this process alone.
    """
    job = tile_job(btf, model, loss, solver, neighbours, **batch_options)
    with open_run(btf, job, out=out, force=force, client=client, processes=processes) as run:
        enabled = sys.stderr.isatty() if progress is None else bool(progress)
        label = f"{job.model.name} on {btf.name}" + (f" (process {run.pid + 1}/{run.nproc})" if run.nproc > 1 else "")
        with progress_bar(label, run.texels(run.mine), shown=enabled, done=run.texels(run.results),
                          rate="texels") as bar:
            return run.fit(bar, max_tiles=max_tiles)


@contextlib.contextmanager
def open_run(btf: BTF, job: TileJob, *, out=None, force: bool = False, client=None, processes: int | None = None):
    """A :class:`TileRun` of ``job`` over ``btf``, its folder ``out`` checked, locked and read (the
    tiles finished before); the lock is released when the block ends. ``processes``: see :func:`fit_btf`."""
    import jax

    nproc = jax.process_count()
    if client is not None and nproc > 1:
        raise UsageError("fit_btf: client= (a Dask cluster) and jax.distributed processes: use one of them")
    pid = jax.process_index()
    barrier = (lambda name: _barrier(nproc, name))
    tiles_dir, held = None, None
    try:
        if out is not None:
            out = Path(out)
            if (out / "params.exr").exists() and not force:
                raise UsageError(f"{out}: already holds a fit (use --force / force=True to replace it)")
            tiles_dir = out / "tiles"
            _run.prepare(tiles_dir, job.record, force, pid == 0, barrier)
            if pid == 0:
                held = _run.lock(tiles_dir)
                if _run.read_run(tiles_dir) is None:
                    _run.write_run(tiles_dir, job.record)
        yield TileRun(btf, job, out, tiles_dir, pid, nproc, client, processes)
    finally:
        if held is not None:
            held.close()


class TileRun:
    """One run over a BTF's tiles: those finished before (``results``, read from the run's folder)
    and the others, fitted by :meth:`fit`. ``mine``: this process's share of the tiles; ``processes``: the
    worker processes that fit them (1: this process, see :func:`brdffit.btf.processes.count`)."""

    def __init__(self, btf: BTF, job: TileJob, out, tiles_dir, pid: int, nproc: int, client, processes=None):
        from . import processes as _processes

        self.btf, self.job, self.out, self.tiles_dir = btf, job, out, tiles_dir
        self.pid, self.nproc, self.client = pid, nproc, client
        self.mine = [t for t in range(btf.n_tiles) if t % nproc == pid]
        self.results: dict[int, dict] = {}
        if tiles_dir is not None:
            for t in self.mine:
                got = _run.load_tile(tiles_dir, t)
                if got is not None:
                    self.results[t] = got
        self.resumed = len(self.results)
        left = [t for t in self.mine if t not in self.results]
        self.processes = _processes.count(processes, len(left), self.texels(left), client)

    def texels(self, tiles) -> int:
        """Texels in ``tiles``."""
        total = 0
        for t in tiles:
            r0, r1, c0, c1 = self.btf.tile_box(t)
            total += (r1 - r0) * (c1 - c0)
        return total

    def fit(self, bar, max_tiles: int | None = None) -> ParameterMaps | None:
        """Fit the tiles left (``bar.advance(texels)`` after each), then assemble the maps (and,
        with a folder, write the results and remove the tiles). None when stopped by ``max_tiles``."""
        todo = [t for t in self.mine if t not in self.results]
        if max_tiles is not None and max_tiles < len(todo):
            todo = todo[:max_tiles]
            stopped = True
        else:
            stopped = False
        t0 = time.perf_counter()
        workers: set[str] = set()
        self.clock = {"read": 0.0, "compile": 0.0, "solve": 0.0}
        for t, arrays, where in self._fitted(todo):
            self.results[t] = arrays
            workers.add(where)
            bar.advance(self.texels([t]))
        if stopped:
            return None
        seconds = time.perf_counter() - t0
        return self._finish(seconds, self.texels(todo), workers)

    def _fitted(self, todo):
        """(tile, arrays, who fitted it) for every tile of ``todo``, as they are finished; the tile files
        written (by this process, or by the Dask worker that fitted the tile)."""
        if self.client is not None:
            from .cluster import fit_tiles

            yield from fit_tiles(self.client, self.btf, self.job, todo, self.tiles_dir)
            return
        if self.processes > 1:  # worker processes of a core each (processes.py)
            from .processes import fitted

            found = fitted(self.btf, self.job, _tile.group_tiles(self.btf, todo, self.processes), self.processes,
                           self.clock)
        else:
            found = self._fitted_here(todo)
        for t, arrays, where in found:
            if self.tiles_dir is not None:
                _run.save_tile(self.tiles_dir, t, arrays)
            yield t, arrays, where

    def _fitted_here(self, todo):
        """(tile, arrays, "this process") for every tile of ``todo``, fitted in this process: in groups
        (``tile.group_tiles``: a batch big enough for the backend's lanes), the next group read and prepared
        in a thread while the current one is solved."""
        from ..fitting import cache

        job, clock = self.job, self.clock

        def load(group):
            t_read = time.perf_counter()
            loaded = _tile.load_tiles(self.btf, group, job.model, job.options)
            clock["read"] += time.perf_counter() - t_read
            return loaded

        groups = _tile.group_tiles(self.btf, todo)
        # The programs the last run of this kind used load while the first tiles are read (the BTF's own
        # identity and shape aside: another BTF's run needs the same programs).
        kind = {k: v for k, v in job.record.items() if k not in ("btf", "shape")}
        with cache.ahead(f"fit_btf {json.dumps(kind, sort_keys=True)}"), ThreadPoolExecutor(1) as reader:
            ahead = reader.submit(load, groups[0]) if groups else None
            for k, group in enumerate(groups):
                loaded = ahead.result()
                if k + 1 < len(groups):
                    ahead = reader.submit(load, groups[k + 1])
                fitted = _tile.fit_tiles(self.btf, group, job.model, job.options, job.neighbours, loaded=loaded,
                                         clock=clock)
                for t, arrays in zip(group, fitted):
                    yield t, arrays, "this process"

    def _finish(self, seconds: float, n_fitted: int, workers: set[str]) -> ParameterMaps:
        import jax

        btf, mdl, options = self.btf, self.job.model, self.job.options
        maps = _assemble(btf, mdl, self.results)
        if self.nproc > 1:
            maps = _gather(maps, btf, self.mine)
        info = {"btf": btf.name, "source": btf.source, "btf_options": btf.meta.get("options", {}),
                "processes": self.nproc, "devices": [str(d) for d in jax.devices()] if self.client is None else None,
                "texels_fitted_now": int(n_fitted) if self.nproc == 1 else None,
                "seconds": seconds, "texels_per_second": (n_fitted / seconds) if n_fitted and seconds > 0 else None,
                # where the time went here: reading and preparing tiles (in a thread, beside the solves),
                # compiling and running the compiled stages (the device's share), the rest (Python between)
                "seconds_read": self.clock["read"], "seconds_compile": self.clock["compile"],
                "seconds_solve": self.clock["solve"],
                "resumed_tiles": self.resumed, "neighbours": self.job.neighbours,
                "worker_processes": self.processes if self.processes > 1 else None,
                "worker_peak_rss_mb": self.clock.get("worker_peak_rss_mb")}
        if self.client is not None:
            info["dask"] = {"scheduler": self.client.scheduler.address, "workers": len(workers)}
        pm = ParameterMaps(model=mdl.name, params=maps["params"], loss=maps["loss"], converged=maps["converged"],
                           steps=maps["steps"], loss_name=options.loss, solver=options.solver, info=info)
        if self.out is not None and self.pid == 0:
            pm.save(self.out, force=True)
            shutil.rmtree(self.tiles_dir, ignore_errors=True)
        _barrier(self.nproc, "brdffit-fit-btf-done")
        return pm


def _assemble(btf: BTF, mdl, results: dict[int, dict]) -> dict:
    h, w = btf.shape
    params = {p.name: np.zeros((h, w, mdl.size(p))) for p in mdl.params}
    loss = np.zeros((h, w))
    conv = np.zeros((h, w), bool)
    steps = np.zeros((h, w), int)
    for t, a in results.items():
        r0, r1, c0, c1 = btf.tile_box(t)
        for p in mdl.params:
            params[p.name][r0:r1, c0:c1] = a[f"param:{p.name}"]
        loss[r0:r1, c0:c1] = a["loss"]
        conv[r0:r1, c0:c1] = a["converged"]
        steps[r0:r1, c0:c1] = a["steps"]
    return {"params": params, "loss": loss, "converged": conv, "steps": steps}


def _gather(maps: dict, btf: BTF, mine: list[int]) -> dict:
    """Every process's tiles into one set of maps, on every process (a sum of disjoint parts)."""
    from jax.experimental import multihost_utils

    owned = np.zeros(btf.shape, bool)
    for t in mine:
        r0, r1, c0, c1 = btf.tile_box(t)
        owned[r0:r1, c0:c1] = True
    flat = {"owned": owned.astype(np.float64), "loss": maps["loss"], "converged": maps["converged"].astype(np.float64),
            "steps": maps["steps"].astype(np.float64), **{f"param:{k}": v for k, v in maps["params"].items()}}
    every = multihost_utils.process_allgather(flat)  # each (n_processes, ...)
    if not np.all(every["owned"].sum(axis=0) == 1):
        raise RuntimeError("fit_btf: the processes' tiles do not cover the BTF exactly once")

    def pick(a):
        own = every["owned"].astype(bool)
        own = own.reshape(own.shape + (1,) * (a.ndim - own.ndim))
        return np.where(own, a, 0).sum(axis=0)

    return {"params": {k[6:]: pick(v) for k, v in every.items() if k.startswith("param:")},
            "loss": pick(every["loss"]), "converged": pick(every["converged"]) > 0.5,
            "steps": np.rint(pick(every["steps"])).astype(int)}


def _barrier(nproc: int, name: str) -> None:
    if nproc > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices(name)
