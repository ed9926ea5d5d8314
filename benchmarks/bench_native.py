"""Native models against brdffit's own lobes on every shared measured material: fit quality, time, memory.

For each material (the RGL files and the Cornell files under $BRDFFIT_DATA or ../shared/data) and
each model, a default fit (log loss, lm, the default start) through ``brdffit.fit`` in a fresh
process: its loss, log_rmse and rel_rmse, whether it converged, its wall time (a second, warm fit:
compilation, or loading the kept program, is the first fit's), and the process's peak memory. The
ratios are against ``ggx`` on the same material in this run (time, memory) and against
``lambert+ggx+ggx`` (loss). The machine may be shared: compare ratios, not seconds.

    .venv/bin/python benchmarks/bench_native.py [--models ...] [--materials NAME ...]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from peak_memory import CHILD_PRELUDE

MODELS = ["ggx", "lambert+ggx+ggx", "mitsuba:roughconductor", "mitsuba:roughplastic", "mitsuba:principled",
          "gltf:metallic_roughness", "blender:principled"]

CASE = CHILD_PRELUDE + r"""
import json, sys, time
import brdffit
m = brdffit.load(sys.argv[1])
t = time.perf_counter(); brdffit.fit(m, sys.argv[2]); first = time.perf_counter() - t
t = time.perf_counter(); fit = brdffit.fit(m, sys.argv[2]); warm = time.perf_counter() - t
print("RESULT", json.dumps({"loss": fit.loss_value, "log_rmse": fit.metrics["log_rmse"], "rel_rmse": fit.metrics["rel_rmse"],
                            "converged": bool(fit.converged), "warm": warm, "first": first,
                            "mb": peak_mb()}))
"""


def run_case(path: Path, model: str) -> dict | str:
    run = subprocess.run([sys.executable, "-c", CASE, str(path), model], capture_output=True, text=True)
    if run.returncode != 0 or "RESULT " not in run.stdout:
        lines = run.stderr.strip().splitlines()
        return lines[-1] if lines else f"exit {run.returncode}"
    return json.loads(run.stdout.rsplit("RESULT ", 1)[1].splitlines()[0])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--models", nargs="+", default=MODELS)
    ap.add_argument("--materials", nargs="+", help="file stems to keep (default: every shared file)")
    args = ap.parse_args()
    models = ["ggx"] + [m for m in args.models if m != "ggx"]  # the baseline first
    data = Path(os.environ.get("BRDFFIT_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
    files = sorted((data / "measured" / "rgl").glob("*.bsdf")) + sorted((data / "measured" / "cornell").glob("*.brdf"))
    if args.materials:
        files = [f for f in files if f.stem in args.materials]
    if not files:
        raise SystemExit(f"no measured data under {data}")
    print(f"{'material':26s} {'model':24s} {'loss':>10s} {'x l+g+g':>8s} {'log_rmse':>9s} {'rel_rmse':>9s} "
          f"{'conv':>5s} {'warm s':>7s} {'x ggx':>6s} {'peak MB':>8s} {'x ggx':>6s} {'first s':>8s}")
    for path in files:
        results = {model: run_case(path, model) for model in models}
        ggx = results["ggx"] if isinstance(results["ggx"], dict) else None
        ref = results.get("lambert+ggx+ggx")
        for model, r in results.items():
            if isinstance(r, str):
                print(f"{path.stem[:26]:26s} {model:24s} failed: {r[:100]}")
                continue
            loss_ratio = r["loss"] / ref["loss"] if isinstance(ref, dict) and ref["loss"] else float("nan")
            t_ratio = r["warm"] / ggx["warm"] if ggx else float("nan")
            m_ratio = r["mb"] / ggx["mb"] if ggx else float("nan")
            print(f"{path.stem[:26]:26s} {model:24s} {r['loss']:10.4g} {loss_ratio:8.3f} {r['log_rmse']:9.4f} "
                  f"{r['rel_rmse']:9.4f} {str(r['converged']):>5s} {r['warm']:7.3f} {t_ratio:6.1f} {r['mb']:8.0f} "
                  f"{m_ratio:6.2f} {r['first']:8.2f}", flush=True)


if __name__ == "__main__":
    main()
