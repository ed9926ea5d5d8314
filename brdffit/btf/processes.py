"""``fit_btf`` on a CPU: the tiles fitted by worker processes on this machine, one per core
(docs/btf.md#at-scale).

Why processes, not threads. XLA's CPU client makes its thread pool as wide as the cores the process
may run on and spreads every compiled call over it; two calls at once (the driver's threads) then
share both cores with a cost of their own: on the project's 2-core machine a texel's fit took 2.29
ms of CPU time in one process on both cores and 1.3-1.8 ms in a process confined to one core, and
two such processes fitted 1.5x the texels a second of the one (benchmarks/README.md). So a
worker here is confined to one core before JAX makes its client (its pool is then one thread),
and the tiles are shared out among the workers as a Dask cluster's are: one request per group of
tiles, to whichever worker is free; the arrays come back, and the run writes the tile files as
a run in one process does (resuming, the maps, the summary are the same code).

The maps equal a run in one process to rounding, not to the bit: a texel's fit is the same code on the
same data (``lanes``: one lane at a time on a CPU, so the group does not change it), but XLA may split a
sum over its thread pool, and a worker's pool is one thread wide (seen: 4e-16 relative, the same steps;
``tests/test_btf_processes.py``). Runs in workers equal each other to the bit.

A worker is ``python -c`` importing :func:`serve`: a helper process of this run
(``_files.start_process``: a session of its own, so a terminal's Ctrl-C reaches only brdffit, which
ends the workers before it removes what it wrote). It reads requests (pickled) on its standard
input and answers on a duplicate of its standard output (the output itself goes to its log, so
that nothing printed can break an answer); it ends when its input closes (this process ended).
Workers stay between runs of one process (a database's materials, a notebook's second fit) and
keep their compiled programs; :func:`close` ends them (at exit too).

Used where it pays and can be done (:func:`count`): the CPU backend, one process of
``jax.distributed``, no Dask client, the process's affinity settable (Linux), more than one core,
texels enough to repay the workers' start (``AUTO_MIN_TEXELS``), and at most as many workers as the memory
available has room for (``WORKER_BYTES`` each), unless ``processes`` says.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import pickle
import queue
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

from ..errors import InputError, UsageError

#: Texels a run fits at least for ``processes=None`` to start workers: their start (Python and JAX 0.55 s, the
#: compiled programs from the disk cache 0.25 s, each worker on its core) is repaid by their faster solves only
#: from some thousands of texels on 2 cores. ``bench_btf.py --size S --processes 2 --one-process``, ggx, first
#: runs in workers / in one process: 64 x 64 1,441-1,468 / 1,687-1,720 texels/s; 80 x 80 1,688 / 1,616; 96 x 96
#: 2,060 / 1,689 (benchmarks/README.md). With more cores the workers gain more (XLA's pool is wider).
AUTO_MIN_TEXELS = 8192
#: Memory one worker is given room for when ``processes=None`` chooses how many (at most the memory available
#: now over this): measured peaks 361 MB (lambert, a 400 x 400 BTF in tiles of 16) to 630 MB (ggx, 64 x 64).
WORKER_BYTES = 2**30


def available_memory() -> int | None:
    """Bytes of memory available now (Linux's MemAvailable), or None where unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def cores() -> list[int]:
    """The cores this process may run on, or [] where a process cannot be confined to one (not Linux)."""
    if not hasattr(os, "sched_setaffinity"):
        return []
    try:
        return sorted(os.sched_getaffinity(0))
    except OSError:
        return []


def count(processes: int | None, tiles: int, texels: int, client=None) -> int:
    """How many worker processes fit a run of ``tiles`` tiles (``texels`` texels): ``processes`` as asked
    (None: one per core where that can be done, pays and the memory available has room for, see the module
    docstring; 1: none, the run's own process fits every tile); at most one per core and per tile. Returns 1
    for "in this process"."""
    import jax

    if processes is not None and (not isinstance(processes, int) or isinstance(processes, bool) or processes < 1):
        raise UsageError(f"fit_btf: processes must be a whole number >= 1 or None, got {processes!r}")
    if processes == 1:
        return 1
    here = jax.local_devices()[0].platform == "cpu" and jax.process_count() == 1 and client is None
    if processes is not None and not here:
        raise UsageError("fit_btf: processes= needs the CPU backend in one process without a Dask client "
                         "(on a GPU the device fits the tiles; with client= Dask's workers do)")
    n = len(cores())
    if processes is not None and n == 0:
        raise UsageError("fit_btf: processes= needs a system where a process can be confined to a core (Linux)")
    if processes is None:
        room = available_memory()
        n = n if room is None else min(n, room // WORKER_BYTES)  # one process per core, if memory allows
        if not here or n < 2 or texels < AUTO_MIN_TEXELS:
            return 1
    return max(1, min(n, tiles, processes or n))


def fitted(btf, job, groups: list[list[int]], workers: int, clock: dict) -> Iterator[tuple[int, dict, str]]:
    """(tile, arrays, which worker) for every tile of ``groups``, as the ``workers`` processes finish
    them (a free worker takes the next group); their seconds are added to ``clock``. When the caller
    stops early (an error, an interrupt) the workers end: their requests are not waited for."""
    with _BUSY:  # one run at a time talks to the workers (two threads' runs would mix their answers)
        yield from _fitted(btf, job, groups, workers, clock)


def _fitted(btf, job, groups, workers, clock):
    import dataclasses

    from .tile import pack_job

    pool = _pool(workers)
    shipped = dataclasses.replace(btf, _owner=None)  # the description; the cache file stays this process's
    packed = pack_job(job.model, job.options, job.neighbours)
    todo: queue.SimpleQueue = queue.SimpleQueue()
    for group in groups:
        todo.put(group)
    done: queue.SimpleQueue = queue.SimpleQueue()
    stop = threading.Event()

    def drive(worker: _Worker) -> None:  # one thread per worker: its requests, one after another
        while not stop.is_set():
            try:
                group = todo.get_nowait()
            except queue.Empty:
                return
            answer = worker.ask((shipped, group, packed))
            done.put((group, answer, worker))
            if answer is None:
                return

    threads = [threading.Thread(target=drive, args=(w,), name=f"brdffit-worker-{w.core}", daemon=True)
               for w in pool.workers]
    for t in threads:
        t.start()
    ok = False
    try:
        for _ in groups:
            group, answer, worker = _next(done)
            result = worker.result(group, answer)
            for key in ("read", "compile", "solve"):
                clock[key] = clock.get(key, 0.0) + result["clock"].get(key, 0.0)
            clock["worker_peak_rss_mb"] = max(clock.get("worker_peak_rss_mb", 0.0), result["peak_rss_mb"])
            for t, arrays in zip(group, result["tiles"]):
                yield t, arrays, f"worker process on core {worker.core}"
        ok = True
    finally:
        stop.set()
        if not ok:  # workers busy with requests nobody will read: ended (the next run starts new ones)
            close(kill=True)
        for t in threads:
            t.join()


def _next(done: queue.SimpleQueue):
    while True:  # a wait with a timeout: a Ctrl-C reaches this thread between two
        try:
            return done.get(timeout=0.5)
        except queue.Empty:
            continue


# -- the pool, in this process --------------------------------------------------------------------
class _Worker:
    """One worker process, confined to ``core``; its standard error goes to ``log``."""

    def __init__(self, core: int, log) -> None:
        from .._files import start_process

        self.core, self.log = core, log
        # This brdffit, whatever the working folder holds (-P: not the working folder first) and however this
        # process found it; the CPU backend, which is the one this process fits on.
        root = str(Path(__file__).resolve().parents[2])
        env = {**os.environ, "JAX_PLATFORMS": "cpu",
               "PYTHONPATH": os.pathsep.join([root, *filter(None, [os.environ.get("PYTHONPATH")])])}
        self.proc = start_process([sys.executable, "-P", "-c", f"from brdffit.btf.processes import serve; serve({core})"],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, env=env)

    def ask(self, request):
        """Its answer to ``request`` (btf, tiles, packed job), or None when it died."""
        try:
            pickle.dump(request, self.proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
            self.proc.stdin.flush()
            return pickle.load(self.proc.stdout)
        except (EOFError, OSError, ValueError, pickle.UnpicklingError):
            return None

    def result(self, tiles: list[int], answer) -> dict:
        """The fitted tiles of an answer, or the error it stands for (InputError for the input's)."""
        which = f"tiles {tiles[0]}-{tiles[-1]}" if len(tiles) > 1 else f"tile {tiles[0]}"
        if answer is None:
            try:  # its pipe closed as it died: its exit status a moment later
                code = self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                code = None
            said = self.last_words()
            raise RuntimeError(f"{which}: the worker process on core {self.core} ended"
                               + (f" (exit status {code})" if code is not None else "")
                               + (f": {said}" if said else " (killed? out of memory?)"))
        if answer[0] == "input":
            raise InputError(answer[1], answer[2])
        if answer[0] == "error":
            raise RuntimeError(f"{which} in the worker process on core {self.core}: {answer[1]}: {answer[2]}")
        return answer[1]

    def last_words(self) -> str:
        """The last line of its log (why it ended), or ''."""
        with contextlib.suppress(OSError):
            with open(self.log.name, "rb") as f:
                f.seek(max(0, os.fstat(f.fileno()).st_size - 4000))
                lines = [x.strip() for x in f.read().decode(errors="replace").splitlines() if x.strip()]
                return lines[-1] if lines else ""
        return ""

    def end(self, kill: bool) -> None:
        """Ended: asked to (its input closed), or killed (a request of it may be under way)."""
        from .._files import forget_process

        if kill:
            with contextlib.suppress(OSError):
                self.proc.kill()
        with contextlib.suppress(OSError):
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        with contextlib.suppress(OSError):
            self.proc.stdout.close()
        self.log.close()
        forget_process(self.proc)


class _Pool:
    """Worker processes, one on each core of ``cores``, their logs in a scratch folder of this run."""

    def __init__(self, cores: list[int]) -> None:
        from .._files import scratch_dir

        self.cores = tuple(cores)
        self.logs = scratch_dir("brdffit-workers-")
        self.workers = [_Worker(c, open(self.logs / f"worker-core{c}.log", "wb")) for c in cores]

    def close(self, kill: bool) -> None:
        from .._files import remove_scratch

        for w in self.workers:
            w.end(kill)
        remove_scratch(self.logs)


_POOL: dict[str, _Pool] = {}
_LOCK = threading.Lock()
_BUSY = threading.Lock()


def _pool(workers: int) -> _Pool:
    """The pool of ``workers`` processes on the first cores of this process's (kept between runs)."""
    wanted = cores()[:workers]
    with _LOCK:
        pool = _POOL.get("pool")
        if pool is not None and list(pool.cores) != wanted:
            close()
            pool = None
        if pool is None:
            pool = _POOL["pool"] = _Pool(wanted)
        return pool


def worker_pids() -> list[int]:
    """The process ids of the workers running now (none: [])."""
    pool = _POOL.get("pool")
    return [] if pool is None else [w.proc.pid for w in pool.workers]


def close(kill: bool = False) -> None:
    """End the worker processes (the next run that needs them starts new ones)."""
    pool = _POOL.pop("pool", None)
    if pool is not None:
        pool.close(kill)


atexit.register(close)


# -- a worker ---------------------------------------------------------------------------------------
def serve(core: int) -> None:
    """A worker's life (see the module docstring): confined to ``core``, it answers requests until its
    input closes."""
    _confine(core)
    answers = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # what anything prints goes to the log, not into an answer
    requests = sys.stdin.buffer
    while True:
        try:
            request = pickle.load(requests)
        except EOFError:
            return
        pickle.dump(_answer(*request), answers, protocol=pickle.HIGHEST_PROTOCOL)
        answers.flush()


def _confine(core: int) -> None:
    """Every thread of this process on ``core`` alone (before JAX makes its client: its thread pool is
    then one thread; threads started later inherit it)."""
    try:
        threads = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        threads = [0]
    for t in threads:
        with contextlib.suppress(OSError):
            os.sched_setaffinity(t, {core})


def _answer(btf, tiles: list[int], packed: bytes):
    import resource
    import time

    from . import tile as _tile

    try:
        model, options, neighbours = _tile.unpack_job(packed)
        t_read = time.perf_counter()
        loaded = _tile.load_tiles(btf, tiles, model, options)
        clock = {"read": time.perf_counter() - t_read, "compile": 0.0, "solve": 0.0}
        arrays = _tile.fit_tiles(btf, tiles, model, options, neighbours, loaded=loaded, clock=clock)
    except InputError as exc:
        return ("input", exc.path, exc.problem)
    except Exception as exc:  # noqa: BLE001 - named in the run's error, by its tiles
        return ("error", type(exc).__name__, " ".join(str(exc).split())[:500])
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB
    return ("ok", {"tiles": arrays, "clock": clock, "peak_rss_mb": peak})
