"""``brdffit.fit_btf``: every texel of a BTF fitted on its own (SPEC 7).

The work unit is a *tile* of the BTF's cache (16 x 16 texels by default, see
:mod:`brdffit.btf.reader`): its texels are read with one sequential read and fitted together by
``fit_batch``'s array-level core (``brdffit.fitting.batch.solve_batch``: the program of ``fit``
mapped over the texels, spread over the process's JAX devices; no FitResult per texel, the maps
need only the parameters, loss, status and steps).

Resuming. With ``out=DIR``, every finished tile is written at once (atomically) to
``DIR/tiles/tile_NNNNN.npz``, beside ``DIR/tiles/run.json`` which identifies the run (the BTF's
content signature, model, loss, solver and options). A run that finds tiles of the same run
there fits only the missing ones; tiles of a different run are an error unless ``force``. When
all tiles are done the results (``params.exr``, previews, ``summary.json``, see
:mod:`brdffit.btf.maps`) are written and the tiles removed.

Several processes (``jax.distributed``). When JAX runs several processes (after
``jax.distributed.initialize(...)``, e.g. one per machine or per GPU, started by the user's
launcher: SLURM, mpirun, Kubernetes, or by hand), process p of n fits the tiles t with
t % n == p on its own devices, then the maps are gathered (``multihost_utils.process_allgather``)
so that every process returns the whole ``ParameterMaps``; process 0 alone writes the files.
Every process must be able to read the BTF (a shared file system, or its own copy). The fitted
numbers do not depend on the split: each texel is fitted by the same compiled code from the same
data, so one process and several give identical maps.

How a tile's texels are fitted (neighbouring texels' results as starts): :mod:`brdffit.btf.tile`.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from .._progress import progress_bar
from ..errors import UsageError
from ..fitting.problem import resolve_model
from . import tile as _tile
from .maps import ParameterMaps
from .reader import BTF

RUN_FILE = "run.json"
#: fit_btf's keyword options (``FitOptions``' fields that a batch takes).
_OPTIONS = ("solver", "max_steps", "rtol", "atol", "chunk", "lanes", "multistart", "bounds", "fixed", "physical")
def _tile_file(folder: Path, t: int) -> Path:
    return folder / f"tile_{t:05d}.npz"


def _save_tile(folder: Path, t: int, arrays: dict) -> None:
    target = _tile_file(folder, t)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        np.savez(f, **arrays)
    os.replace(tmp, target)


def _load_tile(folder: Path, t: int) -> dict | None:
    f = _tile_file(folder, t)
    if not f.is_file():
        return None
    try:
        with np.load(f) as z:
            return {k: z[k] for k in z.files}
    except Exception:  # noqa: BLE001 - a damaged tile is fitted again
        return None


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
    **batch_options,
) -> ParameterMaps:
    """Fit ``model`` to every texel of ``btf``; see the module docstring.

    ``solver`` and further keyword arguments (``max_steps``, ``rtol``, ``atol``, ``chunk``,
    ``lanes``, ``multistart``, ``bounds``, ``fixed``, ``physical``) mean what they mean for
    ``brdffit.fit_batch`` (its default solver when None). ``out``: folder for the results and
    the resumable tiles. ``progress``: a bar on stderr (default: when stderr is a terminal).
    ``max_tiles``: stop after fitting this many tiles (returns None; for tests of resuming and for
    splitting work by hand). ``neighbours``: start most texels from a fitted neighbour's result
    (see the module docstring); False starts every texel from the initialisation grid.
    """
    import jax

    from ..fitting.options import FitOptions

    if not isinstance(btf, BTF):
        raise UsageError(f"fit_btf needs a BTF from brdffit.load_btf, got {type(btf).__name__}")
    if solver is not None:
        batch_options["solver"] = solver
    unknown = sorted(set(batch_options) - set(_OPTIONS))
    if unknown:
        raise UsageError(f"fit_btf: unknown option(s) {', '.join(unknown)}")
    options = FitOptions(loss=loss, **batch_options).batched("fit_btf")
    loss = options.loss
    mdl = resolve_model(model, btf.channels)
    run = {"btf": btf.signature(), "model": mdl.name, "loss": loss, "options": {k: str(v) for k, v in sorted(batch_options.items())},
           "neighbours": bool(neighbours),
           "tile": btf.tile, "shape": [btf.height, btf.width]}
    pid, nproc = jax.process_index(), jax.process_count()

    tiles_dir = None
    if out is not None:
        out = Path(out)
        if (out / "params.exr").exists() and not force:
            raise UsageError(f"{out}: already holds a fit (use --force / force=True to replace it)")
        tiles_dir = out / "tiles"
        run_file = tiles_dir / RUN_FILE
        if run_file.is_file():
            try:
                previous = json.loads(run_file.read_text())
            except (OSError, ValueError):
                previous = None
            if previous != run:
                if not force:
                    raise UsageError(f"{tiles_dir}: holds tiles of another run (other BTF, model or options); "
                                     "use --force / force=True to start again")
                if pid == 0:
                    shutil.rmtree(tiles_dir, ignore_errors=True)
        _barrier(nproc, "brdffit-fit-btf-clean")
        tiles_dir.mkdir(parents=True, exist_ok=True)
        if pid == 0:
            lock = _lock(tiles_dir)
        if pid == 0 and not run_file.is_file():
            tmp = run_file.with_name(f".{RUN_FILE}.tmp")
            tmp.write_text(json.dumps(run))
            os.replace(tmp, run_file)

    mine = [t for t in range(btf.n_tiles) if t % nproc == pid]
    results: dict[int, dict] = {}
    for t in mine:
        if tiles_dir is not None:
            got = _load_tile(tiles_dir, t)
            if got is not None:
                results[t] = got
    todo = [t for t in mine if t not in results]
    sizes = {t: (lambda b: (b[1] - b[0]) * (b[3] - b[2]))(btf.tile_box(t)) for t in mine}
    enabled = sys.stderr.isatty() if progress is None else bool(progress)
    label = f"{mdl.name} on {btf.name}" + (f" (process {pid + 1}/{nproc})" if nproc > 1 else "")
    t0 = time.perf_counter()
    fitted = 0
    with progress_bar(label, sum(sizes.values()), shown=enabled, done=sum(sizes[t] for t in results),
                      rate="texels") as bar:
        # Tiles are fitted in groups (``tile.group_tiles``: a batch big enough for the backend's lanes), the
        # next group read and prepared in a thread while the current one is solved.
        run_now = todo if max_tiles is None else todo[:max_tiles]
        groups = _tile.group_tiles(btf, run_now)
        clock = {"read": 0.0, "compile": 0.0, "solve": 0.0}

        def load(group):
            t_read = time.perf_counter()
            loaded = _tile.load_tiles(btf, group, mdl, options)
            clock["read"] += time.perf_counter() - t_read
            return loaded

        with ThreadPoolExecutor(1) as reader:
            ahead = reader.submit(load, groups[0]) if groups else None
            for k, group in enumerate(groups):
                loaded = ahead.result()
                if k + 1 < len(groups):
                    ahead = reader.submit(load, groups[k + 1])
                fitted_group = _tile.fit_tiles(btf, group, mdl, options, neighbours, loaded=loaded, clock=clock)
                for t, arrays in zip(group, fitted_group):
                    if tiles_dir is not None:
                        _save_tile(tiles_dir, t, arrays)
                    results[t] = arrays
                    fitted += 1
                    bar.advance(sizes[t])
        if max_tiles is not None and len(todo) > max_tiles:
            return None
    seconds = time.perf_counter() - t0
    n_fitted = sum(sizes[t] for t in todo)

    maps = _assemble(btf, mdl, results)
    if nproc > 1:
        maps = _gather(maps, btf, mine)
    info = {"btf": btf.name, "source": btf.source, "btf_options": btf.meta.get("options", {}), "processes": nproc,
            "devices": [str(d) for d in jax.devices()],
            "texels_fitted_now": int(n_fitted) if nproc == 1 else None,
            "seconds": seconds, "texels_per_second": (n_fitted / seconds) if n_fitted and seconds > 0 else None,
            # where the time went: reading and preparing tiles (in a thread, beside the solves), compiling
            # and running the compiled stages (the device's share), and the rest (Python between calls)
            "seconds_read": clock["read"], "seconds_compile": clock["compile"], "seconds_solve": clock["solve"],
            "resumed_tiles": len(mine) - len(todo), "neighbours": bool(neighbours)}
    pm = ParameterMaps(model=mdl.name, params=maps["params"], loss=maps["loss"], converged=maps["converged"],
                       steps=maps["steps"], loss_name=loss, solver=options.solver,
                       info=info)
    if out is not None and pid == 0:
        pm.save(out, force=True)
        shutil.rmtree(tiles_dir, ignore_errors=True)
        lock.close()
    _barrier(nproc, "brdffit-fit-btf-done")
    return pm


def _lock(tiles_dir: Path):
    """An exclusive lock on the run's tile folder (released when the process ends, even killed):
    a second run writing the same place at once is refused instead of mixing tiles."""
    import fcntl

    f = open(tiles_dir / ".lock", "w")
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        f.close()
        raise UsageError(f"{tiles_dir.parent}: another fit-btf run is writing there") from None
    return f


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
