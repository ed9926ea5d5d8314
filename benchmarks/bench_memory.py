"""Peak memory of ``fit_btf`` (docs/btf.md#at-scale: one 96 x 96 tile in at most 2 GB, a 400 x 400 BTF in
at most 3 GB), each measured in a child process of its own (its own peak resident memory,
``peak_memory.peak_mb``: the JAX runtime and the compiled programs included).

The BTFs are generated straight into their tile caches (``btf.generate.model_btf``, in another child
process: the generator holds a light's tables for every texel), then fitted with the default options.
Printed per case: texels, tile, wall seconds, texels/s, the child's peak RSS, and the bound.

    python benchmarks/bench_memory.py [--cases tile96 btf400] [--model ggx]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from peak_memory import CHILD_PRELUDE

#: name -> (BTF side, tile, bound in GB)
CASES = {"tile96": (96, 96, 2.0), "btf400": (400, 16, 3.0)}

CHILD = CHILD_PRELUDE + """
import json, sys, time
from pathlib import Path
import brdffit
from brdffit.btf.reader import BTF
meta = json.loads(sys.argv[1])
btf = BTF(**{**meta, "cache": Path(meta["cache"])})
t = time.perf_counter()
processes = None if sys.argv[3] == "auto" else int(sys.argv[3])
maps = brdffit.fit_btf(btf, sys.argv[2], progress=False, processes=processes)
seconds = time.perf_counter() - t
print(json.dumps({"seconds": seconds, "peak_mb": peak_mb(), "workers": maps.info["worker_processes"] or 0,
                  "worker_peak_mb": maps.info["worker_peak_rss_mb"] or 0.0,
                  "converged": float(maps.converged.mean())}))
"""

GENERATE = """
import json, sys
from pathlib import Path
import brdffit
from brdffit.btf import generate as gen
side, tile, model, folder = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]
m = brdffit.models.get(model)
btf = gen.model_btf(m, gen.smooth_maps(m, side, side, seed=1), Path(folder), noise=0.01, seed=2, tile=tile)
print(json.dumps({"name": btf.name, "source": btf.source, "height": btf.height, "width": btf.width,
                  "channels": btf.channels, "tile": btf.tile, "cache": str(btf.cache), "meta": btf.meta}))
"""


def measure(side: int, tile: int, model: str, folder: str, processes: str = "auto") -> dict:
    """Generate (a child) and fit (another child) a side x side BTF of ``model`` in tiles of ``tile``."""
    gen = subprocess.run([sys.executable, "-c", GENERATE, str(side), str(tile), model, folder], capture_output=True,
                         text=True, check=True)
    meta = gen.stdout.strip().splitlines()[-1]
    run = subprocess.run([sys.executable, "-c", CHILD, meta, model, processes], capture_output=True, text=True,
                         check=True)
    return json.loads(run.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--model", default="ggx")
    ap.add_argument("--processes", default="auto", help="fit_btf's processes (auto: its own choice; 1: the child alone)")
    args = ap.parse_args()
    for name in args.cases:
        side, tile, bound = CASES[name]
        with tempfile.TemporaryDirectory(prefix="bench-memory-") as d:
            t = time.perf_counter()
            got = measure(side, tile, args.model, d, args.processes)
            n = side * side
            # With worker processes: the run's process and every worker at its peak at once (an upper bound).
            total = got["peak_mb"] + got["workers"] * got["worker_peak_mb"]
            workers = (f" + {got['workers']} worker processes of at most {got['worker_peak_mb']:.0f} MB each = "
                       f"{total:.0f} MB at most" if got["workers"] else "")
            print(f"{name}: {side}x{side} {args.model} BTF, tile {tile}: {n} texels in {got['seconds']:.1f} s "
                  f"({n / got['seconds']:.0f} texels/s), peak RSS {got['peak_mb']:.0f} MB{workers} (bound "
                  f"{bound * 1024:.0f} MB: {'holds' if total <= bound * 1024 else 'SHORT'}); converged "
                  f"{got['converged']:.4f}; with generation {time.perf_counter() - t:.0f} s")


if __name__ == "__main__":
    main()
