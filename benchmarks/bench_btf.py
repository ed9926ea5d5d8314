"""Throughput of ``brdffit.fit_btf`` (docs/btf.md#at-scale) against a loop of ``brdffit.fit``, in one run.

A generated BTF of ``--model`` (default ``ggx``, ``--size`` x ``--size`` texels, smooth parameter maps, or
with ``--texture B`` B x B blocks of four materials at random; 1 % noise) is fitted with ``fit_btf``
twice: the first run as a user sees it (compiling included, or loading the compiled programs from the
disk cache), the second warm. In the same run a loop of
``brdffit.fit`` over a random sample of ``--loop`` texels (warmed up first) gives the baseline. ``--repeat R``
times the loop and each warm run R times and reports the fastest of each (on a shared machine one timing of
the loop varied from 85 to 154 texels/s).

Printed: the device(s) JAX runs on; texels/s of both and their ratio; CPU time per texel; the solver's
steps; the largest relative difference of fit_btf's loss from fit()'s on the sampled texels; where
fit_btf's time went (reading and preparing tiles, in a thread beside the solves; compiling; the compiled
stages, i.e. the device's share; the rest, Python on the host; with worker processes, ``--processes``,
summed over them); the process's peak resident memory (and the workers');
with ``--device`` the accelerator's peak memory. ``--one-process`` also runs ``fit_btf(..., processes=1)`` and
prints the ratio to it. ``--jacobian64`` also runs ``fit_btf(..., jacobian="float64")`` (the Jacobian in float64, as
``fit``'s) and prints the ratio to it. ``--compare`` also runs ``fit_btf(..., neighbours=False)``
(every texel from the initialisation grid). ``--cold`` keeps compiled programs in a new, empty folder
(``BRDFFIT_CACHE``), so that the first run compiles every program it needs, as on a new machine.

The BTF is written straight into the tile cache (``btf.generate.model_btf``: no 6561 images to write
and decode); ``--images`` writes the image folder and reads it with ``load_btf`` instead.

    python benchmarks/bench_btf.py [--size 64] [--loop 64] [--model ggx] [--tile 16] [--compare]
                                   [--device] [--images] [--processes N] [--one-process] [--cold]
                                   [--texture B] [--repeat R]
"""

from __future__ import annotations

import argparse
import concurrent.futures
import multiprocessing
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB


def cpu_seconds() -> float:
    """CPU time of this process and of fit_btf's worker processes (``brdffit.btf.processes``), from /proc."""
    from brdffit.btf import processes

    total = time.process_time()
    for pid in processes.worker_pids():
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime
        except (OSError, ValueError, IndexError):
            pass
    return total


def fastest(times, n: int) -> str:
    """', the fastest of R: ...' (the texels/s of every one of R timings), or nothing for one."""
    if len(times) < 2:
        return ""
    return f", the fastest of {len(times)}: " + ", ".join(f"{n / t[0]:.1f}" for t in times) + " texels/s"


def generate(model_name: str, size: int, folder: str, tile: int, images: bool, texture: int = 0):
    """The benchmark's BTF: smooth maps, or with ``texture`` B x B blocks of four materials at random
    (``generate.block_maps``); 1 % noise (in a child process for --images: the image writer holds the whole
    BTF in memory, and the peak memory printed is the fit's)."""
    import brdffit
    from brdffit.btf import generate as gen

    model = brdffit.models.get(model_name)
    if texture:
        truth = gen.block_maps(model, size, size, texture, seed=1)
    else:
        truth = gen.smooth_maps(model, size, size, seed=1)
    if images:
        return str(gen.write_model_btf(Path(folder), model, truth, noise=0.01, seed=2))
    return gen.model_btf(model, truth, Path(folder), noise=0.01, seed=2, tile=tile, name=f"{model_name}-{size}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=64, help="texels per side")
    ap.add_argument("--loop", type=int, default=64, help="texels fitted one by one with fit() for the baseline")
    ap.add_argument("--model", default="ggx")
    ap.add_argument("--tile", type=int, default=16)
    ap.add_argument("--compare", action="store_true", help="also fit every texel from the grid (neighbours=False)")
    ap.add_argument("--device", action="store_true", help="also print the accelerator's figures (peak memory)")
    ap.add_argument("--images", action="store_true", help="write an image folder and read it with load_btf")
    ap.add_argument("--processes", type=int, default=None,
                    help="fit_btf's processes (default: its own choice; 1: this process alone)")
    ap.add_argument("--one-process", action="store_true",
                    help="also run fit_btf with processes=1 (first and warm) and print the ratio to it")
    ap.add_argument("--texture", type=int, default=0, metavar="B",
                    help="a textured BTF: B x B blocks of four materials at random (default: smooth maps)")
    ap.add_argument("--jacobian64", action="store_true",
                    help="also run fit_btf with jacobian='float64' (first and warm) and print the ratio to it")
    ap.add_argument("--repeat", type=int, default=1, metavar="R",
                    help="time the loop of fit() and each warm fit_btf run R times and report the fastest (as timeit "
                         "does: the run the machine disturbed least), every one of them printed")
    ap.add_argument("--cold", action="store_true",
                    help="compiled programs kept in a new, empty folder: the first run compiles them all")
    args = ap.parse_args()
    if args.cold:  # before brdffit is imported: its cache folder is read once (worker processes inherit it)
        os.environ["BRDFFIT_CACHE"] = tempfile.mkdtemp(prefix="bench-btf-cache-")
        print(f"compiled programs kept in {os.environ['BRDFFIT_CACHE']} (empty at the start)")

    import jax

    import brdffit

    devices = jax.devices()
    print(f"devices: {devices} ({jax.process_count()} process(es)); backend {jax.default_backend()}")
    model = brdffit.models.get(args.model)
    with tempfile.TemporaryDirectory(prefix="bench-btf-") as d:
        t = time.perf_counter()
        if args.images:
            with concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
                folder = pool.submit(generate, args.model, args.size, str(Path(d) / "btf"), args.tile, True,
                                     args.texture).result()
            print(f"generated {args.size}x{args.size} {args.model} BTF images in {time.perf_counter() - t:.1f} s")
            t = time.perf_counter()
            btf = brdffit.load_btf(folder, tile=args.tile, cache_dir=Path(d) / "cache")
            print(f"load_btf: {time.perf_counter() - t:.1f} s")
        else:
            btf = generate(args.model, args.size, str(Path(d) / "cache"), args.tile, False, args.texture)
            print(f"generated {args.size}x{args.size} {args.model} BTF (its tile cache) in {time.perf_counter() - t:.1f} s")
        mem = btf.memory()
        print(f"cache file {mem['cache_file'] / 2**20:.1f} MB, one tile {mem['tile'] / 2**20:.1f} MB; "
              f"peak RSS {peak_rss_mb():.0f} MB")

        rng = np.random.default_rng(0)
        sample = [tuple(x) for x in rng.integers(0, args.size, (args.loop, 2))]
        loop_rate = None
        if sample:
            brdffit.fit(btf.texel(*sample[0]), model)  # warm-up: compile outside the timing
            times = []
            for _ in range(args.repeat):
                t, cpu = time.perf_counter(), time.process_time()
                singles = [brdffit.fit(btf.texel(r, c), model) for r, c in sample]
                times.append((time.perf_counter() - t, time.process_time() - cpu))
            loop_s, loop_cpu = min(times)
            loop_rate = len(sample) / loop_s
            print(f"loop of fit(): a random sample of {len(sample)} of the {args.size * args.size} texels in {loop_s:.2f} s "
                  f"= {loop_rate:.1f} texels/s (warm{fastest(times, len(sample))}); CPU time "
                  f"{loop_cpu / len(sample) * 1e3:.2f} ms per texel")

        n = args.size * args.size
        runs = [(True, "first", args.processes), (True, "warm", args.processes)]
        runs += [(True, "first", 1), (True, "warm", 1)] if args.one_process else []
        runs += [(False, "first", args.processes), (False, "warm", args.processes)] if args.compare else []
        runs = [(*r, None) for r in runs]
        runs += [(True, "first", args.processes, "float64"), (True, "warm", args.processes, "float64")] \
            if args.jacobian64 else []
        rates = {}
        for neighbours, which, processes, jacobian in runs:
            times = []
            for _ in range(args.repeat if which == "warm" else 1):
                t, cpu = time.perf_counter(), cpu_seconds()
                maps = brdffit.fit_btf(btf, model, progress=False, neighbours=neighbours, processes=processes,
                                       **({} if jacobian is None else {"jacobian": jacobian}))
                times.append((time.perf_counter() - t, cpu_seconds() - cpu, maps))
            fit_s, cpu_s, maps = min(times, key=lambda x: x[0])
            rate = n / fit_s
            if jacobian is None:
                rates[neighbours, which, processes] = rate
            info = maps.info
            workers = info.get("worker_processes")
            steps = maps.steps.ravel()
            counts = np.bincount(steps)
            label = f"neighbours={neighbours}, processes={processes}" + (f", jacobian={jacobian}" if jacobian else "")
            print(f"fit_btf ({label}, {which} run{fastest(times, n)}): {n} texels in {fit_s:.2f} s = "
                  f"{rate:.1f} texels/s{' (compile included)' if which == 'first' else ''}; CPU time "
                  f"{cpu_s / n * 1e3:.3f} ms per texel{' (the workers included)' if workers else ''}; "
                  f"{int(maps.converged.sum())}/{n} converged; "
                  + (f"{workers} worker processes, peak RSS {info['worker_peak_rss_mb']:.0f} MB each at most"
                     if workers else "in this process"))
            if loop_rate:
                print(f"  ratio fit_btf / loop of fit: {rate / loop_rate:.1f}x")
            if which == "warm" and jacobian:
                print(f"  ratio fit_btf (its float32 Jacobian) / fit_btf (jacobian={jacobian}), warm: "
                      f"{rates[True, 'warm', args.processes] / rate:.2f}x")
            if which == "warm" and processes == 1 and (True, "warm", args.processes) in rates and args.processes != 1:
                print(f"  ratio fit_btf (processes={args.processes}) / fit_btf (processes=1), warm: "
                      f"{rates[True, 'warm', args.processes] / rate:.2f}x")
            where = "summed over the workers, in them" if workers else "a thread beside the solves"
            print(f"  time: reading+preparing tiles {info['seconds_read']:.2f} s ({where}), "
                  f"compiling {info['seconds_compile']:.2f} s, compiled stages {info['seconds_solve']:.2f} s"
                  + ("" if workers else f", the rest (host, Python) "
                     f"{max(fit_s - info['seconds_compile'] - info['seconds_solve'], 0.0):.2f} s"))
            print(f"  steps: mean {steps.mean():.2f}, median {np.median(steps):.0f}, max {steps.max()}; texels per step "
                  "count " + ", ".join(f"{k}: {c}" for k, c in enumerate(counts) if c))
            if sample:
                dev = [abs(maps.loss[r, c] - s.loss_value) / s.loss_value for (r, c), s in zip(sample, singles)]
                print(f"  loss of fit_btf vs fit on the sampled texels: max relative difference {max(dev):.2e}")
            print(f"  peak RSS so far: {peak_rss_mb():.0f} MB")
            if args.device:
                stats = devices[0].memory_stats() or {}
                if stats:
                    print(f"  device memory: peak {stats.get('peak_bytes_in_use', 0) / 2**30:.2f} GiB, "
                          f"in use {stats.get('bytes_in_use', 0) / 2**30:.2f} GiB")
        if args.compare:
            print(f"neighbour starts vs grid starts (warm): "
                  f"{rates[True, 'warm', args.processes] / rates[False, 'warm', args.processes]:.2f}x texels/s")
        print(f"peak RSS of this process: {peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
