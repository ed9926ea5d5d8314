"""What a Dask cluster costs against a local run of ``brdffit.fit_btf`` (docs/btf.md#at-scale).

A generated BTF (default 32 x 32 ``ggx`` texels in 16 tiles of 8 x 8, 1% noise) is fitted in the
same run: locally (``fit_btf(btf, model)``, twice: the first includes compiling in this process,
the second is warm), then on a ``LocalCluster`` of one worker process with one thread: with Dask's
default settings (twice: the first includes the worker's compiling or loading its program from
the on-disk compile cache), with ``MALLOC_TRIM_THRESHOLD_`` unset in the worker's environment
(Dask's nanny sets it to 65536), and with the worker's statistical profiler off too; and of
``--workers`` worker processes with both (warm). Printed: wall seconds, texels/s and their ratio to the
warm local run; and CPU seconds, this process's (the client; a LocalCluster's scheduler runs in
it too) plus every worker process's (``client.run(time.process_time)`` before and after), which
a shared machine disturbs far less than wall time. The Dask overhead per tile is the warm
one-worker run's CPU time against the warm local run's, over the tiles: scheduling a task,
shipping its arguments and results, the worker's tile file, the worker's own event loop. The maps
are checked equal to the local run's.

    python benchmarks/bench_cluster.py [--size 32] [--tile 8] [--model ggx] [--workers 2]
"""

from __future__ import annotations

import argparse
import concurrent.futures
import multiprocessing
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np


def generate(model_name: str, size: int, folder: str) -> str:
    import brdffit
    from brdffit.btf import generate as gen

    model = brdffit.models.get(model_name)
    truth = gen.smooth_maps(model, size, size, seed=1)
    return str(gen.write_model_btf(Path(folder), model, truth, noise=0.01, seed=2))


def timed(label: str, n: int, fit, baseline: tuple | None, reference=None, client=None):
    """Run ``fit``; print and return (wall s, CPU s of this process and the client's workers)."""
    workers = (lambda: sum(client.run(time.process_time).values())) if client is not None else (lambda: 0.0)
    w0, t, cpu = workers(), time.perf_counter(), time.process_time()
    maps = fit()
    s, here, there = time.perf_counter() - t, time.process_time() - cpu, workers() - w0
    cpu_s = here + there
    ratio = "" if baseline is None else f"  x{baseline[0] / s:.2f} texels/s, x{cpu_s / baseline[1]:.2f} CPU of the warm local run"
    split = f" (here {here:.2f} + workers {there:.2f})" if client is not None else ""
    print(f"{label:<36} {s:6.2f} s {n / s:6.1f} texels/s  CPU {cpu_s:6.2f} s{split}{ratio}")
    if reference is not None:
        same = all(np.array_equal(maps.params[k], reference.params[k]) for k in maps.params)
        assert same and np.array_equal(maps.loss, reference.loss), f"{label}: maps differ from the local run's"
    return (s, cpu_s), maps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=32, help="texels per side")
    ap.add_argument("--tile", type=int, default=8)
    ap.add_argument("--model", default="ggx")
    ap.add_argument("--workers", type=int, default=2, help="worker processes of the second cluster")
    args = ap.parse_args()

    import os

    import dask
    from distributed import Client, LocalCluster

    import brdffit

    with tempfile.TemporaryDirectory(prefix="bench-cluster-") as d:
        with concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            folder = pool.submit(generate, args.model, args.size, str(Path(d) / "btf")).result()
        btf = brdffit.load_btf(folder, tile=args.tile, cache_dir=Path(d) / "cache")
        n, tiles = args.size * args.size, btf.n_tiles
        print(f"{args.size}x{args.size} {args.model} BTF, {tiles} tiles of {args.tile}x{args.tile}; "
              f"{os.cpu_count()} cores (shared machine: compare the ratios)")
        _, local = timed("local, first run (compiles here)", n, lambda: brdffit.fit_btf(btf, args.model, progress=False), None)
        base, local = timed("local, warm", n, lambda: brdffit.fit_btf(btf, args.model, progress=False), None)
        rows = {}
        # Dask's nanny starts its workers with MALLOC_TRIM_THRESHOLD_=65536 (to give freed memory
        # back to the system), which turns glibc's dynamic mmap threshold off: every large array
        # is a fresh mmap, its pages faulted in anew; and a worker samples its threads' stacks
        # every 10 ms (its statistical profiler). Both are the cluster's settings:
        untrim = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
        quiet = {**untrim, "distributed.worker.profile.enabled": False}
        settings = [("Dask's defaults", 1, {}), ("MALLOC_TRIM_THRESHOLD_ unset", 1, untrim),
                    ("and the profiler off", 1, quiet), ("both", args.workers, quiet)]
        for name, workers, config in settings:
            saved = dict(os.environ)  # the nanny writes its workers' environment into ours
            t = time.perf_counter()
            with dask.config.set(config), LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                       dashboard_address=None) as cluster, Client(cluster) as client:
                print(f"LocalCluster of {workers} worker(s), {name}: started in {time.perf_counter() - t:.2f} s")

                def on_dask():
                    return brdffit.fit_btf(btf, args.model, progress=False, client=client)

                with warnings.catch_warnings():  # the run's BrdffitWarning about the trim threshold: known here
                    warnings.simplefilter("ignore")
                    if not rows:
                        timed("  first run (the worker's program)", n, on_dask, base, local, client)
                    rows[name] = timed("  warm", n, on_dask, base, local, client)[0]
            os.environ.clear()
            os.environ.update(saved)
        wall0, cpu0 = base
        for name, workers, _ in settings[:3]:
            wall1, cpu1 = rows[name]
            print(f"Dask overhead per tile, 1 worker ({name}) vs local, warm: CPU {(cpu1 - cpu0) / tiles * 1e3:+.0f} ms "
                  f"of {cpu0 / tiles * 1e3:.0f} ms ({(cpu1 / cpu0 - 1) * 100:+.0f} %); wall "
                  f"{(wall1 - wall0) / tiles * 1e3:+.0f} ms of {wall0 / tiles * 1e3:.0f} ms ({(wall1 / wall0 - 1) * 100:+.0f} %)")

if __name__ == "__main__":
    main()
