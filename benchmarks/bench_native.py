"""Native models against brdffit's own lobes on every shared measured material (issue 27).

For each material (the RGL files and the Cornell files under $BRDFFIT_DATA or ../shared/data) and
each model, one default fit (log loss, lm, the default start) through ``brdffit.fit``: its loss, its
log_rmse and rel_rmse, whether it converged, and its wall time (a second, warm fit: compilation is
reported apart). The ratio column is the loss against ``lambert+ggx+ggx`` on the same material.

    .venv/bin/python benchmarks/bench_native.py [--models ...]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import brdffit

MODELS = ["ggx", "lambert+ggx+ggx", "mitsuba:roughconductor", "mitsuba:roughplastic", "mitsuba:principled",
          "gltf:metallic_roughness", "blender:principled"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--models", nargs="+", default=MODELS)
    args = ap.parse_args()
    data = Path(os.environ.get("BRDFFIT_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
    files = sorted((data / "measured" / "rgl").glob("*.bsdf")) + sorted((data / "measured" / "cornell").glob("*.brdf"))
    if not files:
        raise SystemExit(f"no measured data under {data}")
    print(f"{'material':26s} {'model':24s} {'loss':>10s} {'x l+g+g':>8s} {'log_rmse':>9s} {'rel_rmse':>9s} "
          f"{'conv':>5s} {'run s':>7s} {'compile s':>9s}")
    for path in files:
        m = brdffit.load(path)
        rows = []
        for model in args.models:
            first = brdffit.fit(m, model)
            t = time.perf_counter()
            fit = brdffit.fit(m, model)
            rows.append((model, fit, time.perf_counter() - t, first.seconds.get("compile", 0.0)))
        ref = {model: fit.loss_value for model, fit, _, _ in rows}.get("lambert+ggx+ggx")
        for model, fit, wall, compile_s in rows:
            ratio = fit.loss_value / ref if ref else float("nan")
            print(f"{path.stem[:26]:26s} {model:24s} {fit.loss_value:10.4g} {ratio:8.3f} {fit.metrics['log_rmse']:9.4f} "
                  f"{fit.metrics['rel_rmse']:9.4f} {str(fit.converged):>5s} {wall:7.3f} {compile_s:9.2f}")


if __name__ == "__main__":
    main()
