"""What tests/test_btf_cluster.py does to its Dask workers.

:class:`KillAt`, a worker plugin: the worker that reaches a chosen moment of a chosen tile's task
ends its own process with SIGKILL, as a lost machine or the kernel's OOM killer would. Once per cluster: the first worker to get there creates ``marker`` and dies; the others,
and the worker the nanny starts in its place, go on. The marker holds the worker's pid and
whether the file ``watch`` existed when it died."""

from __future__ import annotations

import os
import signal

from distributed import WorkerPlugin


class KillAt(WorkerPlugin):
    """SIGKILL this worker when the task of tile ``tile`` enters the worker state ``state``
    ("executing": mid-tile, before anything is written; "memory": the tile's file written, its
    result not yet reported to the scheduler)."""

    name = "brdffit-test-kill"

    def __init__(self, tile: int, state: str, marker: str, watch: str):
        self.tile, self.state, self.marker, self.watch = tile, state, marker, watch

    def transition(self, key, start, finish, **kwargs):
        if finish != self.state or not str(key).startswith(f"brdffit-tile-{self.tile:05d}-"):
            return
        try:
            fd = os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            return
        os.write(fd, f"{os.getpid()} {int(os.path.exists(self.watch))}".encode())
        os.close(fd)
        os.kill(os.getpid(), signal.SIGKILL)


def set_environ(name: str, value: str | None) -> None:
    """Set (or, with None, remove) an environment variable of this worker process."""
    if value is None:
        os.environ.pop(name, None)
    else:
        os.environ[name] = value
