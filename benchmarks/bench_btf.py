"""Throughput of ``brdffit.fit_btf`` (SPEC 7, issue 11).

A generated ``ggx`` BTF (default 64 x 64 texels, smooth parameter maps, 1% noise, EXR images in a
temporary folder) is read with ``load_btf`` and fitted with ``fit_btf``; in the same run a loop of
``brdffit.fit`` over a random sample of ``--loop`` texels (not all of them: at ~3 fits/s the
whole 64 x 64 would take half an hour) gives the baseline. Printed: the device(s) JAX runs on,
texels/s of both (compile included for fit_btf, as a user sees it; the loop is warmed up first),
their ratio, the CPU time per texel (steadier than wall time on a shared machine), the steps of the solves (mean, median, max, and how many texels took each count),
the losses' agreement on the sampled texels, the process's peak resident memory and the BTF's
memory figures. ``--compare`` also runs ``fit_btf(..., neighbours=False)`` (every texel from the
initialisation grid) in the same run: what the neighbour starts save.

    python benchmarks/bench_btf.py [--size 64] [--loop 64] [--model ggx] [--tile 16] [--compare]
"""

from __future__ import annotations

import argparse
import concurrent.futures
import multiprocessing
import resource
import tempfile
import time
from pathlib import Path

import numpy as np


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB


def generate(model_name: str, size: int, folder: str) -> str:
    """A size x size BTF of ``model_name`` with smooth maps and 1% noise (the benchmark's BTF)."""
    import brdffit
    from brdffit.btf import generate as gen

    model = brdffit.models.get(model_name)
    truth = gen.smooth_maps(model, size, size, seed=1)
    return str(gen.write_model_btf(Path(folder), model, truth, noise=0.01, seed=2))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=64, help="texels per side")
    ap.add_argument("--loop", type=int, default=64, help="texels fitted one by one with fit() for the baseline")
    ap.add_argument("--model", default="ggx")
    ap.add_argument("--tile", type=int, default=16)
    ap.add_argument("--compare", action="store_true", help="also fit every texel from the grid (neighbours=False)")
    args = ap.parse_args()

    import jax

    import brdffit

    print(f"devices: {jax.devices()} ({jax.process_count()} process(es))")
    model = brdffit.models.get(args.model)
    with tempfile.TemporaryDirectory(prefix="bench-btf-") as d:
        t = time.perf_counter()
        # In a child process, so that the peak memory printed below is load_btf's and fit_btf's
        # (the generator holds the whole BTF in memory).
        with concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            folder = pool.submit(generate, args.model, args.size, str(Path(d) / "btf")).result()
        print(f"generated {args.size}x{args.size} {args.model} BTF in {time.perf_counter() - t:.1f} s (another process)")
        t = time.perf_counter()
        btf = brdffit.load_btf(folder, tile=args.tile, cache_dir=Path(d) / "cache")
        read_s = time.perf_counter() - t
        mem = btf.memory()
        print(f"load_btf: {read_s:.1f} s; cache file {mem['cache_file'] / 2**20:.1f} MB, read buffer "
              f"{mem['read_buffer'] / 2**20:.1f} MB, one tile {mem['tile'] / 2**20:.1f} MB; peak RSS {peak_rss_mb():.0f} MB")

        rng = np.random.default_rng(0)
        sample = [tuple(x) for x in rng.integers(0, args.size, (args.loop, 2))]
        brdffit.fit(btf.texel(*sample[0]), model)  # warm-up: compile outside the timing
        t, cpu = time.perf_counter(), time.process_time()
        singles = [brdffit.fit(btf.texel(r, c), model) for r, c in sample]
        loop_s, loop_cpu = time.perf_counter() - t, time.process_time() - cpu
        loop_rate = len(sample) / loop_s
        print(f"loop of fit(): a random sample of {len(sample)} of the {args.size * args.size} texels in {loop_s:.1f} s = "
              f"{loop_rate:.2f} texels/s (warm); CPU time {loop_cpu / len(sample) * 1e3:.2f} ms per texel")

        n = args.size * args.size
        runs = [True, False] if args.compare else [True]
        rates, cpu_per = {}, {}
        for neighbours in runs:
            t, cpu = time.perf_counter(), time.process_time()
            maps = brdffit.fit_btf(btf, model, progress=False, neighbours=neighbours)
            fit_s, cpu_s = time.perf_counter() - t, time.process_time() - cpu
            rate = rates[neighbours] = n / fit_s
            cpu_per[neighbours] = cpu_s / n
            steps = maps.steps.ravel()
            counts = np.bincount(steps)
            print(f"fit_btf (neighbours={neighbours}): {n} texels in {fit_s:.1f} s = {rate:.2f} texels/s (compile included); "
                  f"CPU time {cpu_s:.1f} s = {cpu_s / n * 1e3:.2f} ms per texel; {int(maps.converged.sum())}/{n} converged")
            print(f"  steps: mean {steps.mean():.2f}, median {np.median(steps):.0f}, max {steps.max()}; texels per step count "
                  + ", ".join(f"{k}: {c}" for k, c in enumerate(counts) if c))
            print(f"  ratio fit_btf / loop of fit: {rate / loop_rate:.2f}x   (target >= 100 texels/s, aim 300)")
            dev = [abs(maps.loss[r, c] - s.loss_value) / s.loss_value for (r, c), s in zip(sample, singles)]
            print(f"  loss of fit_btf vs fit on the sampled texels: max relative difference {max(dev):.2e}")
            print(f"  peak RSS so far: {peak_rss_mb():.0f} MB")
        if args.compare:
            print(f"neighbour starts vs grid starts: {rates[True] / rates[False]:.2f}x texels/s, "
                  f"{cpu_per[False] / cpu_per[True]:.2f}x less CPU time per texel")
        print(f"peak RSS of this process: {peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
