"""Benchmark: wall time of ``brdffit fit data/sample_ubo81.exr --model ggx -o DIR`` in a new process
(docs/fitting.md#solvers: a second process, the compile cache filled by a first one, within 2.5 s on a quiet machine).

Prints the first process (empty compile cache, ``BRDFFIT_CACHE`` in a temporary folder), the median
and minimum of ``--repeat`` second processes (wall, and CPU = user + system of the child, which a
busy machine inflates less than wall), the load average, and where one second process spends its
time: interpreter start, imports, reading, fitting, fit.json, building and writing fit.png,
interpreter exit. The phases are timed inside an unmodified ``brdffit`` process by wrapping the
functions ``brdffit fit`` calls (``brdffit.load``, ``brdffit.fitting.fit``, ``FitResult.to_json``,
``brdffit.plot.fit_figure``, ``Figure.savefig``); "the rest of the command" is what is left of the
time inside the command.

    python benchmarks/bench_cli.py [--repeat 5] [--model ggx] [SOURCE]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# Runs in the child: wrap what `brdffit fit` calls, run the executable's entry(), report at exit.
CHILD = r"""
import atexit, functools, json, os, sys, time
T0, C0 = time.time(), time.process_time()
spans, cpu = {}, {}
def timed(name, fn):
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        t, c = time.perf_counter(), time.process_time()
        try:
            return fn(*args, **kwargs)
        finally:
            spans[name] = spans.get(name, 0.0) + time.perf_counter() - t
            cpu[name] = cpu.get(name, 0.0) + time.process_time() - c
    return wrapper
def report():
    spans["main"] = MAIN[1] - MAIN[0]
    cpu["main"] = MAIN[3] - MAIN[2]
    cpu["imports"] = MAIN[2] - C0
    with open(os.environ["BENCH_CLI_REPORT"], "w") as fh:
        json.dump({"first_line": T0, "main_start": MAIN_WALL[0], "atexit": time.time(), "spans": spans, "cpu": cpu}, fh)
atexit.register(report)  # registered first: runs after every other atexit handler
MAIN, MAIN_WALL = [], []
import gc
import brdffit.cli as cli  # what the executable imports before entry() ...
gc.set_threshold(*cli.GC_THRESHOLDS)  # ... which tunes the collector before the command's imports
# The command imports JAX and brdffit's fitting parts itself, after it has started the figure's
# worker: importing them here would move that work. Their functions are wrapped as they load.
import importlib.abc, importlib.util
def patch_fitting(m):
    m.fit = timed("fit", m.fit)
def patch_io(m):
    m.load = timed("read", m.load)
def patch_result(m):
    m.FitResult.to_json = timed("fit.json", m.FitResult.to_json)
def patch_plot(m):
    m.fit_figure_data = timed("fit.png: data", m.fit_figure_data)
def patch_figure_process(m):
    m.FigureProcess.savefig = timed("fit.png: drawn by the worker (waited for)", m.FigureProcess.savefig)
PATCHES = {"brdffit.fitting": patch_fitting, "brdffit.io": patch_io, "brdffit.fitting.result": patch_result,
           "brdffit.plot": patch_plot, "brdffit._figure_process": patch_figure_process, "brdffit._x64": None}
class AfterImport(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name not in PATCHES:
            return None
        sys.meta_path.remove(self)
        try:
            spec = importlib.util.find_spec(name)
        finally:
            sys.meta_path.insert(0, self)
        run = spec.loader.exec_module
        def exec_module(module, run=run, patch=PATCHES[name]):
            if patch is None:  # brdffit._x64: the import of JAX
                timed("import JAX (in the command)", run)(module)
            else:
                run(module)
                patch(module)
        spec.loader.exec_module = exec_module
        return spec
sys.meta_path.insert(0, AfterImport())
_main = cli.main
def main(argv=None):
    MAIN.extend((time.perf_counter(), 0.0, time.process_time(), 0.0)); MAIN_WALL.append(time.time())
    try:
        return _main(argv)
    finally:
        MAIN[1], MAIN[3] = time.perf_counter(), time.process_time()
cli.main = main
sys.argv = ["brdffit", *sys.argv[1:]]
cli.entry()
"""


def run(cmd: list[str], env: dict) -> tuple[float, float, subprocess.CompletedProcess]:
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime), proc


def check(proc: subprocess.CompletedProcess, out: Path) -> None:
    if proc.returncode not in (0, 1) or not (out / "fit.json").is_file() or not (out / "fit.png").is_file():
        raise SystemExit(f"brdffit fit failed (exit {proc.returncode}): {proc.stderr.strip()[-800:]}")


SAMPLE = str(REPO / "data" / "sample_ubo81.exr")


def cli_times(repeat: int = 3, source: str = SAMPLE, model: str = "ggx", phases: bool = False):
    """(first, seconds, phases): (wall, CPU) of a first ``brdffit fit SOURCE --model MODEL -o DIR``
    process (empty compile cache) and of ``repeat`` second ones; with ``phases``, the report of one
    more, instrumented second process (else None). A run that fails or writes no fit.json /
    fit.png raises SystemExit (a crash must not pass for a fast run)."""
    exe = Path(sys.executable).with_name("brdffit")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "brdffit"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        env = dict(os.environ, BRDFFIT_CACHE=str(tmp / "cache"), PYTHONPATH=str(REPO))
        # As on a user's machine, Python keeps the bytecode of what it imports: without it every
        # process compiles brdffit's sources again (~0.15 s). This sandbox sets
        # PYTHONDONTWRITEBYTECODE; the first process writes the bytecode, as a user's first run does.
        env.pop("PYTHONDONTWRITEBYTECODE", None)

        def fit_cmd(out: Path, prefix=cmd) -> list[str]:
            return [*prefix, "fit", source, "--model", model, "-o", str(out)]

        first, first_cpu, proc = run(fit_cmd(tmp / "first"), env)
        check(proc, tmp / "first")
        seconds = []
        for i in range(repeat):
            wall, cpu, proc = run(fit_cmd(tmp / f"second{i}"), env)
            check(proc, tmp / f"second{i}")
            seconds.append((wall, cpu))
        report = None
        if phases:
            started = time.time()
            wall, _, proc = run(fit_cmd(tmp / "phases", [sys.executable, "-c", CHILD]),
                                dict(env, BENCH_CLI_REPORT=str(tmp / "phases.json")))
            ended = time.time()
            check(proc, tmp / "phases")
            report = dict(json.loads((tmp / "phases.json").read_text()), started=started, ended=ended, wall=wall)
    return (first, first_cpu), seconds, report


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("source", nargs="?", default=SAMPLE)
    ap.add_argument("--model", default="ggx")
    ap.add_argument("--repeat", type=int, default=5, help="second processes timed (median, min)")
    args = ap.parse_args(argv)
    (first, first_cpu), seconds, phases = cli_times(args.repeat, args.source, args.model, phases=True)
    started, ended, wall = phases["started"], phases["ended"], phases["wall"]
    walls, cpus = [s[0] for s in seconds], [s[1] for s in seconds]
    print(f"brdffit fit {Path(args.source).name} --model {args.model} -o DIR   (load average "
          f"{os.getloadavg()[0]:.1f}, {os.cpu_count()} CPUs)")
    print(f"  first process  (empty compile cache): {first:.2f} s wall, {first_cpu:.2f} s CPU")
    print(f"  second process ({args.repeat} runs): median {statistics.median(walls):.2f} s wall "
          f"(min {min(walls):.2f}), median {statistics.median(cpus):.2f} s CPU (min {min(cpus):.2f})"
          f"   target <= 2.5 s wall on a quiet machine")
    spans, cpu = phases["spans"], phases["cpu"]
    named = ["import JAX (in the command)", "read", "fit", "fit.json", "fit.png: data",
             "fit.png: drawn by the worker (waited for)"]
    rest = "the rest of the command (checks, lock)"
    rows = [("interpreter start", phases["first_line"] - started, None),
            ("imports (brdffit.cli, click, NumPy)", phases["main_start"] - phases["first_line"], cpu["imports"])]
    rows += [(k, spans.get(k, 0.0), cpu.get(k, 0.0)) for k in named]
    rows += [(rest, spans["main"] - sum(spans.get(k, 0.0) for k in named),
              cpu["main"] - sum(cpu.get(k, 0.0) for k in named)),
             ("exit (atexit, interpreter teardown)", ended - phases["atexit"], None)]
    print(f"  one second process, {wall:.2f} s wall (the harness adds a little):")
    for name, s, c in rows:
        print(f"    {name:44s} {s * 1e3:7.0f} ms wall" + ("" if c is None else f" {c * 1e3:7.0f} ms CPU"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
