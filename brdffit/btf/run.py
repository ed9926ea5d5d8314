"""A ``fit_btf`` run's folder, ``DIR/tiles``: what identifies the run, one file per finished tile,
the lock (docs/btf.md#resuming).

- ``run.json`` identifies the run: the BTF's content signature, model, loss, solver options,
  neighbour starts, the precision of the texels' Jacobian, tile edge and shape. A run that finds the same ``run.json`` fits only the tiles
  without a file; another run's tiles are an error unless ``force`` (then they are removed).
- ``tile_NNNNN.npz`` holds a finished tile's arrays (``param:<name>``, ``loss``, ``converged``,
  ``steps``), written atomically (a hidden temporary file renamed onto its name). The process that
  fitted the tile writes it: the run's own process, each ``jax.distributed`` process, or the Dask
  worker (then ``DIR`` must be on a file system the workers share with the client). A tile fitted
  twice (a Dask task run again after its worker died having written the file) is written twice with
  the same content; a tile of a run that is no longer the folder's (a late task of a cancelled run)
  is not written.
- ``.lock``: an exclusive ``flock`` held by the run's main process while it runs (released when it
  ends, even killed): a second run writing the same folder at once is refused (exit 2).
"""

from __future__ import annotations

import json
import os
import shutil
import socket
from pathlib import Path

import numpy as np

from .._files import scratch_file
from ..errors import UsageError

RUN_FILE = "run.json"


def tile_file(folder: Path, t: int) -> Path:
    return Path(folder) / f"tile_{t:05d}.npz"


def read_run(folder: Path) -> dict | None:
    """The ``run.json`` in ``folder``, or None (absent or unreadable)."""
    try:
        return json.loads((Path(folder) / RUN_FILE).read_text())
    except (OSError, ValueError):
        return None


def write_run(folder: Path, run: dict) -> None:
    target = Path(folder) / RUN_FILE
    tmp = target.with_name(f".{RUN_FILE}.{socket.gethostname()}.{os.getpid()}.tmp")
    with scratch_file(tmp):  # a Ctrl-C of the executable removes it
        tmp.write_text(json.dumps(run))
        os.replace(tmp, target)


def save_tile(folder: Path, t: int, arrays: dict, run: dict | None = None) -> bool:
    """Write tile ``t``'s arrays atomically; with ``run``, only while the folder's ``run.json`` is
    that run (False: not written). The temporary name holds host and process: two machines that
    fit the same tile at once do not write the same temporary file."""
    if run is not None and read_run(folder) != run:
        return False
    target = tile_file(folder, t)
    tmp = target.with_name(f".{target.name}.{socket.gethostname()}.{os.getpid()}.tmp")
    with scratch_file(tmp):  # a Ctrl-C of the executable removes it
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, target)
    return True


def load_tile(folder: Path, t: int) -> dict | None:
    f = tile_file(folder, t)
    if not f.is_file():
        return None
    try:
        with np.load(f) as z:
            return {k: z[k] for k in z.files}
    except Exception:  # noqa: BLE001 - a damaged tile is fitted again
        return None


def prepare(tiles_dir: Path, run: dict, force: bool, main: bool, barrier) -> None:
    """Check ``tiles_dir`` against ``run`` (another run's tiles: an error, or removed with
    ``force``), create it and write ``run.json``. ``main``: this process removes and writes (the
    others of a ``jax.distributed`` run only check); ``barrier(name)`` waits for every process."""
    previous = read_run(tiles_dir) if (tiles_dir / RUN_FILE).is_file() else run
    if previous != run:
        if not force:
            raise UsageError(f"{tiles_dir}: holds tiles of another run (other BTF, model or options); "
                             "use --force / force=True to start again")
        if main:
            shutil.rmtree(tiles_dir, ignore_errors=True)
    barrier("brdffit-fit-btf-clean")
    tiles_dir.mkdir(parents=True, exist_ok=True)


def lock(folder: Path, what: str = "fit-btf run"):
    """An exclusive lock on ``folder`` (``folder/.lock``, released when the returned file is closed
    or the process ends, even killed), or a UsageError naming the folder."""
    import fcntl

    f = open(Path(folder) / ".lock", "w")
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        f.close()
        raise UsageError(f"{folder.parent if folder.name == 'tiles' else folder}: another {what} is writing there") from None
    return f
