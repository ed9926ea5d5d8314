"""Benchmark: scene-aware fitting (docs/scene.md#scene-aware-fitting).

1. Time of ``brdffit.scene_usage`` on scenes/grazing_floor.xml (96x64 px, 16 spp, path tracing
   depth 2), first call in the process (LLVM kernels compiled) and warm (median of 3).
2. For every shared RGL material: a plain ``ggx`` fit (UBO-81 pairs, unweighted) and the
   scene-aware one (UBO-81 pairs plus 2048 pairs drawn from where the scene looks, weighted by
   ``usage.weights``); FLIP of the grazing-floor scene rendered with each fit against the scene
   rendered with Mitsuba's ``measured`` plugin (64 spp, same seed), and FLIP of
   ``brdffit.validate`` (spheres, 5 lights, 64 px) of each fit. Prints gain (scene FLIP plain -
   scene-aware) and cost (sphere FLIP scene-aware - plain).

Usage: ``python benchmarks/bench_scene.py``.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from conftest import RGL_FILES  # noqa: E402

import brdffit  # noqa: E402
from brdffit.scene.compare import scene_gain  # noqa: E402

SCENE = REPO / "scenes" / "grazing_floor.xml"


def main() -> int:
    t = time.perf_counter()
    u = brdffit.scene_usage(SCENE, "floor", spp=16)
    cold = time.perf_counter() - t
    warm = []
    for _ in range(3):
        t = time.perf_counter()
        brdffit.scene_usage(SCENE, "floor", spp=16)
        warm.append(time.perf_counter() - t)
    print(f"scene_usage {u.pixels[0]}x{u.pixels[1]} px, 16 spp: {len(u)} pairs; first call {cold:.2f} s, "
          f"warm {statistics.median(warm):.2f} s (median of 3)")
    if not RGL_FILES:
        print("no RGL data found: set BRDFFIT_DATA (skipping the fit comparison)")
        return 0
    print(f"\n{'material':26s} {'scene FLIP plain':>16s} {'scene-aware':>12s} {'gain':>8s}   "
          f"{'sphere FLIP plain':>17s} {'scene-aware':>12s} {'cost':>8s}  gain > cost")
    ok = True
    for path in RGL_FILES:
        g = scene_gain(path, SCENE, "floor")
        ok &= g.gain > 0 and g.gain > g.cost
        print(f"{g.material:26s} {g.scene_flip_plain:16.4f} {g.scene_flip_scene:12.4f} {g.gain:+8.4f}   "
              f"{g.sphere_flip_plain:17.4f} {g.sphere_flip_scene:12.4f} {g.cost:+8.4f}  {g.gain > g.cost}", flush=True)
    print("\nevery material: lower scene FLIP and gain > cost:", ok)
    return 0


if __name__ == "__main__":
    sys.exit(main())
