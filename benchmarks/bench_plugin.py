"""Render time and peak memory of fits in Mitsuba, per model and variant, against Mitsuba's own BSDFs.

Each case renders one scene (a unit sphere under a constant environment and one sun, path tracer at
depth 8) in a fresh process -- so that peak memory (VmHWM) is the case's own -- once to compile
(the JIT variants' kernels), then once timed:

  native roughconductor   Mitsuba's own plugin (what a mitsuba:roughconductor fit exports as): the
                          baseline every ratio of the variant is against
  native roughplastic     Mitsuba's own plugin (a mitsuba:roughplastic fit)
  native principled       Mitsuba's own plugin (a mitsuba:principled fit: clearcoat and sheen on)
  brdffit MODEL           a fit as <bsdf type="brdffit">: its JAX formula translated (Dr.Jit, or
                          Python floats in scalar variants), sampled by its lobe mixture
  brdffit lambert+ggx maps  the same with 64 x 64 parameter maps (bitmap textures)
  python floor            a Python BSDF doing nothing (a constant diffuse): what any Python BSDF
                          costs in that variant (Mitsuba calls it per ray in scalar variants)
  measured (RGL)          Mitsuba's measured plugin on a shared RGL file (RGB variants, data present)

The scalar variants render a smaller image (their renders take seconds per case); ratios are within
one variant, in this run (the machine may be shared: compare ratios, not seconds): "x time" and
"x memory" against native roughconductor, "x floor" against the Python floor -- in the scalar
variants Mitsuba calls a Python BSDF per ray from its render threads, which share one interpreter.

    .venv/bin/python benchmarks/bench_plugin.py [--variants ...] [--models ...] [--size 128] [--spp 16]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from peak_memory import CHILD_PRELUDE

CASE = CHILD_PRELUDE + r"""
import json, sys, time
import numpy as np
import mitsuba as mi
variant, case, size, spp, rgl = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
mi.set_variant(variant)
import brdffit
brdffit.register_mitsuba()
PARAMS = {
    "ggx": {"kd": [0.2, 0.15, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": 0.2, "f0": 0.04},
    "lambert+ggx+ggx": {"kd": [0.2, 0.15, 0.1], "ggx1.ks": 0.5, "ggx1.alpha": 0.1, "ggx1.f0": 0.04,
                        "ggx2.ks": 0.3, "ggx2.alpha": 0.4, "ggx2.f0": 0.04},
    "blender:principled": {"base_color": [0.6, 0.4, 0.2], "metallic": 0.3, "roughness": 0.4, "ior": 1.5, "specular_tint": 1.0},
    "gltf:metallic_roughness": {"base_color": [0.6, 0.4, 0.2], "metallic": 0.3, "roughness": 0.4},
    "ashikhmin_shirley": {"rd": [0.2, 0.15, 0.1], "rs": [0.05, 0.05, 0.05], "nu": 40.0, "nv": 10.0},
}
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
elif case == "python floor":
    class Floor(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]
        def eval(self, ctx, si, wo, active=True):
            return mi.Spectrum(0.1)
        def pdf(self, ctx, si, wo, active=True):
            return mi.warp.square_to_cosine_hemisphere_pdf(wo)
        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)
        def sample(self, ctx, si, s1, s2, active=True):
            bs = mi.BSDFSample3f()
            bs.wo = mi.warp.square_to_cosine_hemisphere(s2)
            bs.pdf, bs.eta = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo), 1.0
            bs.sampled_type, bs.sampled_component = mi.UInt32(+mi.BSDFFlags.DiffuseReflection), mi.UInt32(0)
            return bs, mi.Spectrum(0.3)
        def traverse(self, callback):
            pass
    mi.register_bsdf("floor", Floor)
    bsdf = {"type": "floor"}
elif case.endswith(" maps"):
    rng = np.random.default_rng(0)
    bsdf = brdffit.mitsuba_bsdf("lambert+ggx", {"kd": rng.uniform(0.05, 0.3, (64, 64, 3)), "ggx1.ks": 0.5,
                                                "ggx1.alpha": rng.uniform(0.05, 0.4, (64, 64)), "ggx1.f0": 0.04})
else:
    model = case.split(" ", 1)[1]
    bsdf = brdffit.mitsuba_bsdf(model, PARAMS[model])
scene = mi.load_dict({
    "type": "scene", "integrator": {"type": "path", "max_depth": 8},
    "sensor": {"type": "perspective", "fov": 30,
               "to_world": mi.ScalarTransform4f().look_at(origin=[0, -4, 1.5], target=[0, 0, 0], up=[0, 0, 1]),
               "film": {"type": "hdrfilm", "width": size, "height": size}},
    "ball": {"type": "sphere", "bsdf": bsdf},
    "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.3}},
    "sun": {"type": "directional", "direction": [0.3, 0.5, -0.8], "irradiance": {"type": "rgb", "value": 2.0}},
})
mi.render(scene, spp=spp, seed=1)  # the JIT variants compile their kernels once, as any session rendering twice
t = time.perf_counter()
image = np.asarray(mi.render(scene, spp=spp, seed=1))
seconds = time.perf_counter() - t
print("RESULT", json.dumps({"seconds": seconds, "maxrss_mb": peak_mb(),
                            "mean": float(image.mean())}))
"""

VARIANTS = ["scalar_rgb", "scalar_spectral", "llvm_ad_rgb", "llvm_ad_spectral", "llvm_ad_mono"]
MODELS = ["ggx", "lambert+ggx+ggx", "blender:principled", "gltf:metallic_roughness", "ashikhmin_shirley"]


def run_case(variant: str, case: str, size: int, spp: int, rgl: Path) -> dict | str:
    run = subprocess.run([sys.executable, "-c", CASE, variant, case, str(size), str(spp), str(rgl)],
                         capture_output=True, text=True)
    if run.returncode != 0 or "RESULT " not in run.stdout:
        lines = run.stderr.strip().splitlines()
        return lines[-1] if lines else f"exit {run.returncode}"
    return json.loads(run.stdout.rsplit("RESULT ", 1)[1].splitlines()[0])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--variants", nargs="+", default=VARIANTS)
    ap.add_argument("--models", nargs="+", default=MODELS)
    ap.add_argument("--size", type=int, default=128, help="image side in JIT variants")
    ap.add_argument("--spp", type=int, default=16, help="samples per pixel in JIT variants")
    ap.add_argument("--scalar-size", type=int, default=32)
    ap.add_argument("--scalar-spp", type=int, default=8)
    args = ap.parse_args()
    data = Path(os.environ.get("BRDFFIT_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
    rgl = data / "measured" / "rgl" / "vch_golden_yellow_rgb.bsdf"
    print(f"{'variant':26s} {'case':32s} {'image':>10s} {'seconds':>8s} {'x time':>7s} {'x floor':>7s} {'peak MB':>8s} "
          f"{'x memory':>8s}")
    for variant in args.variants:
        scalar = variant.startswith("scalar")
        size, spp = (args.scalar_size, args.scalar_spp) if scalar else (args.size, args.spp)
        cases = ["native roughconductor", "python floor", "native roughplastic", "native principled"]
        cases += [f"brdffit {m}" for m in args.models] + ["brdffit lambert+ggx maps"]
        if "rgb" in variant and rgl.is_file():
            cases.append("measured (RGL)")
        base = floor = None
        for case in cases:
            r = run_case(variant, case, size, spp, rgl)
            if isinstance(r, str):
                print(f"{variant:26s} {case:32s} failed: {r[:120]}")
                continue
            base = base or r
            floor = r if case == "python floor" else floor
            x_floor = f"{r['seconds'] / floor['seconds']:7.1f}" if floor else f"{'':7s}"
            print(f"{variant:26s} {case:32s} {f'{size}x{size}x{spp}':>10s} {r['seconds']:8.3f} "
                  f"{r['seconds'] / base['seconds']:7.1f} {x_floor} {r['maxrss_mb']:8.0f} "
                  f"{r['maxrss_mb'] / base['maxrss_mb']:8.2f}", flush=True)


if __name__ == "__main__":
    main()
