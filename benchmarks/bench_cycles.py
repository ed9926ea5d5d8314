"""Cycles (through the Blender worker) against Mitsuba: the fit renders of one sphere validation, and
what one gonioreflectometer sample costs.

1. A blender:principled fit rendered on the validation sphere (docs/validation.md#validation-rendering framing, the 5 default
   lights) by ``brdffit.render_sphere(..., renderer=...)``: Mitsuba (the brdffit plugin: the JAX
   formula, this model through the evaluated callback, since its table gather has no Dr.Jit
   translation) and Cycles (Blender's own Principled BSDF in the worker, one request per light).
   Each a second time in the same process (warm: JIT compiled, worker started); the first call's
   time is shown apart. Ratios against Mitsuba at the same size and spp.
2. The gonioreflectometer: N direction pairs of one material in one request (one Cycles render of a
   4 x 4 image per pair), per-sample seconds; and Blender's start (a new worker) for scale.

    .venv/bin/python benchmarks/bench_cycles.py [--sizes 128 256] [--spp 4 16] [--pairs 200]

Needs .venv-blender (``make setup-blender``) or BRDFFIT_BLENDER_PYTHON.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def timed(f):
    t = time.perf_counter()
    out = f()
    return time.perf_counter() - t, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[128, 256])
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 16])
    ap.add_argument("--pairs", type=int, default=200)
    args = ap.parse_args()

    from brdffit import cycles, models
    from brdffit.render import default_lights, render_sphere

    missing = cycles.available()
    if missing:
        raise SystemExit(missing)
    model = models.get("blender:principled")
    params = {"base_color": [0.6, 0.3, 0.15], "metallic": 0.2, "roughness": 0.35, "ior": 1.5, "specular_tint": 1.0}
    fit = ("blender:principled", params)
    lights = default_lights()

    first = {}
    for renderer in ("mitsuba", "cycles"):
        first[renderer], _ = timed(lambda: render_sphere(fit, lights, size=32, spp=1, renderer=renderer))
    print(f"first call (JIT compile / worker start included), 5 lights at 32 px, 1 spp: "
          f"mitsuba {first['mitsuba']:.2f} s, cycles {first['cycles']:.2f} s\n")
    print(f"{'size':>5} {'spp':>4} {'mitsuba s':>10} {'cycles s':>9} {'x time':>7} {'mean ratio c/m':>15}")
    for size in args.sizes:
        for spp in args.spp:
            tm, m = timed(lambda: render_sphere(fit, lights, size=size, spp=spp))
            tc, c = timed(lambda: render_sphere(fit, lights, size=size, spp=spp, renderer="cycles"))
            ratio = c.reshape(5, -1, 3).mean(1) / m.reshape(5, -1, 3).mean(1)
            print(f"{size:>5} {spp:>4} {tm:>10.3f} {tc:>9.3f} {tc / tm:>7.2f} "
                  f"{ratio.min():>7.4f}-{ratio.max():.4f}")

    rng = np.random.default_rng(0)
    theta = np.radians(rng.uniform(0, 85, (args.pairs, 2)))
    phi = rng.uniform(0, 2 * np.pi, (args.pairs, 2))
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    native = model.native(params)
    cycles.gonio(native, d[:2, 0], d[:2, 1])  # warm
    t1, _ = timed(lambda: cycles.gonio(native, d[:1, 0], d[:1, 1]))
    tn, _ = timed(lambda: cycles.gonio(native, d[:, 0], d[:, 1]))
    tstart, w = timed(cycles.Worker)
    w.close()
    print(f"\ngonioreflectometer: one request of 1 pair {t1 * 1e3:.1f} ms; {args.pairs} pairs in one request "
          f"{tn:.2f} s = {tn / args.pairs * 1e3:.1f} ms a sample; a new worker (Blender start) {tstart:.2f} s")


if __name__ == "__main__":
    main()
