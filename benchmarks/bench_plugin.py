"""Render time and peak memory of a fit in Mitsuba: the brdffit plugin against Mitsuba's own BSDFs.

Each case renders the same scene (a unit sphere under a constant environment and one sun, path
tracer at depth 8, 256 x 256) in a fresh process, so that peak memory (ru_maxrss) is the case's own:

  native roughconductor   Mitsuba's own plugin (what a mitsuba:roughconductor fit exports as)
  native roughplastic     Mitsuba's own plugin (a mitsuba:roughplastic fit)
  native principled       Mitsuba's own plugin (a mitsuba:principled fit: clearcoat and sheen on)
  brdffit plugin          a ggx fit as <bsdf type="brdffit">: the JAX formula run by Dr.Jit, symbolic
  brdffit callback        the same fit through the JAX callback inside evaluated_calls() (the path
                          the plugin used before; still what measured tables and parameter maps use)
  measured (RGL)          Mitsuba's measured plugin on a shared RGL file (when the data are present)

Ratios are against native roughconductor at the same spp, in this run.

    .venv/bin/python benchmarks/bench_plugin.py [--spp 64 256] [--size 256]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

CASE = r"""
import json, resource, sys, time
import numpy as np
import brdffit
from brdffit._mitsuba import evaluated_calls, mitsuba
mi = mitsuba()
case, size, spp, rgl = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
ggx = {"kd": [0.2, 0.15, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": 0.2, "f0": 0.04}
if case == "native roughconductor":
    bsdf = {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2}
elif case == "native roughplastic":
    bsdf = {"type": "roughplastic", "distribution": "ggx", "alpha": 0.2, "int_ior": 1.5, "ext_ior": 1.0,
            "diffuse_reflectance": {"type": "rgb", "value": [0.2, 0.15, 0.1]}}
elif case == "native principled":
    from brdffit.models import get
    bsdf = get("mitsuba:principled").native({"base_color": [0.2, 0.15, 0.1], "roughness": 0.45, "metallic": 0.0,
                                             "specular": 0.5, "anisotropic": 0.0, "sheen": 0.3, "clearcoat": 0.5,
                                             "clearcoat_gloss": 0.5})
elif case == "measured (RGL)":
    bsdf = {"type": "measured", "filename": rgl}
else:
    bsdf = brdffit.mitsuba_bsdf("ggx", ggx)
    if case == "brdffit callback":
        from brdffit.models import get
        from brdffit.render.bsdf import callback_bsdf, model_brdf
        from brdffit.render.sampling import Mixture
        m = get("ggx")
        bsdf = callback_bsdf(model_brdf(m, ggx), "ggx", Mixture.for_model(m, m.check_params(ggx)))
scene = mi.load_dict({
    "type": "scene", "integrator": {"type": "path", "max_depth": 8},
    "sensor": {"type": "perspective", "fov": 30,
               "to_world": mi.ScalarTransform4f().look_at(origin=[0, -4, 1.5], target=[0, 0, 0], up=[0, 0, 1]),
               "film": {"type": "hdrfilm", "width": size, "height": size}},
    "ball": {"type": "sphere", "bsdf": bsdf},
    "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.3}},
    "sun": {"type": "directional", "direction": [0.3, 0.5, -0.8], "irradiance": {"type": "rgb", "value": 2.0}},
})
def render():
    if case == "brdffit callback":
        with evaluated_calls():
            return np.asarray(mi.render(scene, spp=spp, seed=1))
    return np.asarray(mi.render(scene, spp=spp, seed=1))
render()  # kernels compiled once, as in any session that renders more than one frame
t = time.perf_counter()
image = render()
seconds = time.perf_counter() - t
print(json.dumps({"seconds": seconds, "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "mean": float(image.mean())}))
"""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--spp", type=int, nargs="+", default=[64, 256])
    ap.add_argument("--size", type=int, default=256)
    args = ap.parse_args()
    data = Path(os.environ.get("BRDFFIT_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
    rgl = data / "measured" / "rgl" / "vch_golden_yellow_rgb.bsdf"
    cases = ["native roughconductor", "native roughplastic", "native principled", "brdffit plugin", "brdffit callback"]
    if rgl.is_file():
        cases.append("measured (RGL)")
    else:
        print(f"(no RGL file at {rgl}: the measured row is left out)")
    print(f"{'case':24s} {'spp':>4s} {'seconds':>8s} {'x time':>7s} {'peak MB':>8s} {'x memory':>8s}")
    for spp in args.spp:
        base = None
        for case in cases:
            run = subprocess.run([sys.executable, "-c", CASE, case, str(args.size), str(spp), str(rgl)],
                                 capture_output=True, text=True)
            if run.returncode != 0:
                print(f"{case:24s} {spp:4d} failed: {run.stderr.strip().splitlines()[-1] if run.stderr.strip() else run.returncode}")
                continue
            r = json.loads(run.stdout.strip().splitlines()[-1])
            base = base or r
            print(f"{case:24s} {spp:4d} {r['seconds']:8.2f} {r['seconds'] / base['seconds']:7.2f} "
                  f"{r['maxrss_mb']:8.0f} {r['maxrss_mb'] / base['maxrss_mb']:8.2f}")


if __name__ == "__main__":
    main()
