"""``fit_btf(..., client=CLIENT)``: a BTF's tiles fitted as Dask tasks on a cluster's workers
(docs/btf.md#at-scale; ``pip install 'brdffit[cluster]'``).

Dask (``dask.distributed``) is the engine: a ``Client`` of any of its clusters (``LocalCluster``,
SSH, Kubernetes, SLURM / PBS / ... through ``dask-jobqueue``) is given to ``fit_btf``, which submits
one task per tile left to fit and collects the results as they finish. What Dask does and brdffit
relies on: tasks go to free workers; when a worker dies (killed, out of memory, its node lost) the
tasks it was running, and the results it held that had not reached the client yet, are run again on
other workers (``distributed.scheduler.allowed-failures`` times, 3 by default, before the run fails
with ``KilledWorker``); when the client goes away (Ctrl-C, ``max_tiles``) its pending tasks are
cancelled.

What brdffit does on top:

- A task fits its tile with :func:`brdffit.btf.tile.fit_tile` (the same code and data as a local
  run: the maps equal a local run's bit for bit), writes ``DIR/tiles/tile_NNNNN.npz`` itself
  (atomically, only while ``DIR/tiles/run.json`` is still its run), and returns the arrays to the
  client, which assembles the maps from them. So ``DIR`` must be on a file system the workers share
  with the client for the run to resume; the maps do not depend on it (a worker that does not see
  ``DIR/tiles/run.json`` writes no tile file: the run completes, but cannot resume). A tile run twice (after its
  worker died) writes the same file twice with the same content: nothing is lost or duplicated.
- How workers get the BTF. The task carries the BTF's description (source, read options, shape, the
  path of its tile-major cache file), not its values. A worker reads the cache file where it finds
  it, complete, at that path: always on the client's machine (a ``LocalCluster``), and on other
  machines when ``load_btf(..., cache_dir=...)`` put it on a shared file system (then nothing is
  decoded twice). Otherwise the worker reads the BTF's source itself, once per worker process, into a
  temporary cache of its own; the source must then be at the same path on the worker (a shared file
  system), with the same size and time stamp (the BTF's signature is checked). A worker that can do
  neither fails the run with one line naming the paths. (A temporary cache made by ``load_btf``
  without ``cache_dir`` belongs to the loading process and lives in its machine's temporary folder.)
- Workers compile the fit program once per process: the model and options travel pickled, and a
  worker unpickles each distinct job once and keeps it, so every tile it fits uses the same
  objects and the compiled program kept for them (loaded from brdffit's on-disk compile cache,
  :mod:`brdffit.fitting.cache`, when the worker shares it). Give workers one thread each
  (``threads_per_worker=1``): a tile's fit uses the process's cores itself.
- Dask's nanny starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536`` (to give freed memory back
  to the system). That turns glibc's dynamic mmap threshold off: every large array of a tile's fit
  is a fresh ``mmap`` whose pages fault in anew, which costs a tile's fit measurable CPU time
  (``benchmarks/bench_cluster.py``; results in benchmarks/README.md). A
  run whose workers have it set warns once (a ``BrdffitWarning``) with the cure: start the workers
  with ``distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_`` set to None in their Dask
  configuration.
- Every task logs ``{"tile", "phase": "start" | "done", "pid", "host", "run"}`` to the cluster's
  event log under the topic ``brdffit-fit-btf`` (``client.get_events("brdffit-fit-btf")``): which
  worker fitted which tile, and which tiles ran twice.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import socket
import uuid
import warnings
from collections.abc import Iterator
from pathlib import Path

from ..errors import BrdffitWarning, InputError, UsageError
from . import run as _run
from . import tile as _tile
from .reader import BTF

#: The cluster's event-log topic of the tile tasks.
EVENTS = "brdffit-fit-btf"
#: The environment variable of Dask's workers that makes a tile's fit slower (module docstring).
TRIM = "MALLOC_TRIM_THRESHOLD_"


def fit_tiles(client, btf: BTF, job, todo: list[int], tiles_dir: Path | None) -> Iterator[tuple[int, dict, str]]:
    """Submit one task per tile of ``todo``; yield (tile, arrays, worker address) as they finish.
    The tasks not finished when the caller stops (an error, an interrupt) are cancelled."""
    from distributed import as_completed

    if not todo:
        return
    shipped = dataclasses.replace(btf, _owner=None)  # the description, not the owner of a temporary cache
    packed = _tile.pack_job(job.model, job.options, job.neighbours)
    folder = None if tiles_dir is None else str(Path(tiles_dir).absolute())
    token = uuid.uuid4().hex[:10]
    futures = {}
    for t in todo:
        f = client.submit(fit_tile_task, shipped, t, packed, folder, job.record, token,
                          key=f"brdffit-tile-{t:05d}-{token}", retries=0)
        futures[f] = t
    trimmed = set()
    try:
        for f in as_completed(list(futures)):
            try:
                arrays, where, trim = f.result()
            except Exception as exc:  # noqa: BLE001 - named by its tile; an error of the input stays one
                raise _named(exc, futures[f]) from exc
            if trim:
                trimmed.add(where)
            yield futures[f], arrays, where
            f.release()
    finally:
        client.cancel(list(futures))
    if trimmed:
        warnings.warn(f"{len(trimmed)} Dask worker(s) ran with {TRIM} set (Dask's default), which costs a tile's fit "
                      f"up to a third more CPU time; start the workers with the Dask setting "
                      f"distributed.nanny.pre-spawn-environ.{TRIM} = None", BrdffitWarning, stacklevel=2)


def _named(exc: Exception, t: int) -> Exception:
    if isinstance(exc, _WorkerInputError):
        return InputError(exc.path, exc.problem)
    name = type(exc).__name__
    if name == "KilledWorker":
        return RuntimeError(f"tile {t}: the Dask workers fitting it died again and again ({exc}); see the workers' logs "
                            "(out of memory? distributed.scheduler.allowed-failures)")
    return RuntimeError(f"tile {t} on a Dask worker: {name}: {exc}")


def fit_tile_task(btf: BTF, t: int, packed: bytes, tiles_dir: str | None, record: dict, token: str):
    """A Dask task: fit tile ``t`` on this worker, write its file; return the arrays, the worker's
    address, and whether it runs with ``TRIM`` set."""
    from distributed import get_worker

    worker = get_worker()
    here = {"tile": int(t), "pid": os.getpid(), "host": socket.gethostname(), "run": token}
    worker.log_event(EVENTS, {**here, "phase": "start"})
    mdl, options, neighbours = _tile.unpack_job(packed)
    try:
        arrays = _tile.fit_tile(readable(btf), t, mdl, options, neighbours)
    except InputError as exc:  # as a plain exception: InputError's (path, problem) do not survive pickling
        raise _WorkerInputError(exc.path, exc.problem) from None
    if tiles_dir is not None:
        _run.save_tile(Path(tiles_dir), t, arrays, run=record)
    worker.log_event(EVENTS, {**here, "phase": "done"})
    return arrays, worker.address, TRIM in os.environ


class _WorkerInputError(Exception):
    """An InputError raised on a worker, in a form that crosses to the client whole."""

    def __init__(self, path, problem):
        super().__init__(path, problem)
        self.path, self.problem = path, problem

    def __str__(self) -> str:
        return f"{self.path}: {self.problem}" if self.path else self.problem


def readable(btf: BTF) -> BTF:
    """``btf`` where its cache file is here, complete; else the same BTF read from its source into
    a temporary cache of this process (once: the last one read is kept). An InputError names the
    paths when neither is readable here."""
    try:
        size = btf.cache.stat().st_size
    except OSError:
        size = -1
    if size == btf.memory()["cache_file"]:
        return btf
    return _from_source(btf.source, btf.name, btf.signature(), _options_key(btf.meta.get("options", {})))


def _options_key(options: dict) -> tuple:
    return tuple(sorted((k, tuple(v) if isinstance(v, list) else v) for k, v in options.items()))


@functools.lru_cache(maxsize=1)
def _from_source(source: str, name: str, signature: str, options: tuple) -> BTF:
    from .reader import load_btf

    where = f"on {socket.gethostname()}"
    if not Path(source).exists():
        raise InputError(source, f"{where}, neither the BTF's cache file nor its source can be read: put the cache "
                                 "on a file system the Dask workers share (load_btf(..., cache_dir=...), "
                                 "brdffit fit-btf --cache-dir)")
    btf = load_btf(source, name=name, **dict(options))
    if btf.signature() != signature:
        raise InputError(source, f"{where}, the BTF's source is not the client's (other path, size or time stamp); "
                                 "put the cache on a file system the Dask workers share (cache_dir=...)")
    return btf


def connect(address: str):
    """A ``dask.distributed.Client`` of the scheduler at ``address``, or a UsageError naming it
    (after Dask's connect timeout, ``distributed.comm.timeouts.connect``: 30 s unless configured,
    e.g. ``DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT=5s``)."""
    try:
        from distributed import Client
    except ImportError:
        raise UsageError("--scheduler needs Dask: pip install 'brdffit[cluster]'") from None
    try:
        return Client(address)
    except (OSError, TimeoutError, ValueError) as exc:
        raise UsageError(f"--scheduler {address}: cannot connect to a Dask scheduler there "
                         f"({' '.join(str(exc).split())[:200]})") from None

