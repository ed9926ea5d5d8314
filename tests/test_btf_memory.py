"""Memory is bounded by the tile, not the BTF (docs/btf.md#at-scale): one 96 x 96 tile (9,216 texels, 725 MB
of float32 values) is fitted in at most 2 GB, measured as the peak resident memory of a child process of its
own (the JAX runtime and compiled programs included). Before, a tile's texels each held their own copy of
the shared directions in float64 and every pass copied rows: 96 x 96 passed 3 GB."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

import brdffit
from brdffit.btf import generate as gen

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_memory.py"


@pytest.mark.slow
def test_a_96x96_tile_is_fitted_in_2_gb(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(BENCH.parent))  # the benchmark imports its neighbour peak_memory.py
    spec = importlib.util.spec_from_file_location("bench_memory", BENCH)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    model = brdffit.models.get("lambert")
    btf = gen.model_btf(model, gen.smooth_maps(model, 96, 96, seed=1), tmp_path, noise=0.01, seed=2, tile=96)
    assert btf.n_tiles == 1 and btf.memory()["tile"] > 690 * 2**20  # 9,216 x 6,561 x 3 float32
    meta = json.dumps({"name": btf.name, "source": btf.source, "height": btf.height, "width": btf.width,
                       "channels": btf.channels, "tile": btf.tile, "cache": str(btf.cache), "meta": btf.meta})
    run = subprocess.run([sys.executable, "-c", bench.CHILD, meta, "lambert", "auto"], capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["converged"] == 1.0
    assert got["peak_mb"] <= 2048, got
