"""Noise of the brdffit BSDF's importance sampling against Mitsuba's own ``roughconductor``.

A glossy ``ggx`` fit (kd = 0, ks = 1, f0 = 1: exactly ``roughconductor`` with ``material none``)
on a sphere over a diffuse floor, lit by a rectangular area light and a dim sky, path traced
(``max_depth`` 4) at equal samples per pixel. Noise = RMSE against a high-spp reference
(``roughconductor``, the same BRDF). Printed: the RMSE of ``roughconductor``, of the brdffit BSDF
with its lobe mixture, and of the brdffit BSDF with cosine sampling only (before docs/DESIGN.md#where-users-meet-brdffit), and
the ratios to ``roughconductor`` within this run.

    PYTHONPATH=. python benchmarks/bench_sampling.py [--size 96] [--spp 16] [--ref-spp 1024] [--alpha 0.1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def scene(mi, bsdf, size: int) -> dict:
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4},
        "sensor": {
            "type": "perspective",
            "fov": 35,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, -4.5, 2.2], target=[0, 0, 0.2], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent"},
        },
        "ball": {"type": "sphere", "to_world": mi.ScalarTransform4f().translate([0, 0, 0.2]), "bsdf": bsdf},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, -0.8]).scale(4),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.45, 0.4]}}},
        "lamp": {"type": "rectangle", "to_world": mi.ScalarTransform4f().look_at(origin=[1.5, 1.0, 3.0], target=[0, 0, 0], up=[0, 0, 1]).scale(0.6),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 12.0}}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.15}},
    }


def measure(size: int = 96, spp: int = 16, ref_spp: int = 1024, alpha: float = 0.1, seeds: int = 2) -> dict:
    """RMSE against the reference for each sampler (mean over ``seeds`` renders) and seconds."""
    import brdffit
    from brdffit._mitsuba import mitsuba
    from brdffit.render.sampling import Mixture
    from brdffit.render.symbolic_bsdf import symbolic_bsdf

    mi = mitsuba()
    params = {"kd": 0.0, "ks": 1.0, "alpha": alpha, "f0": 1.0}
    conductor = {"type": "roughconductor", "distribution": "ggx", "alpha": alpha, "material": "none"}
    model = brdffit.models.get("ggx")
    cosine_only = symbolic_bsdf(model, model.check_params(params), Mixture.cosine(), "ggx (cosine sampling)")
    reference = np.asarray(mi.render(mi.load_dict(scene(mi, conductor, size)), spp=ref_spp, seed=1000))
    out = {}
    for label, bsdf in (("roughconductor", conductor), ("brdffit mixture", brdffit.mitsuba_bsdf("ggx", params)),
                        ("brdffit cosine only", cosine_only)):
        s = mi.load_dict(scene(mi, bsdf, size))
        errors = []
        t = time.perf_counter()
        for seed in range(seeds):
            img = np.asarray(brdffit._mitsuba.render(s, spp=spp, seed=seed))
            errors.append(float(np.sqrt(np.mean((img - reference) ** 2))))
        out[label] = {"rmse": float(np.mean(errors)), "seconds": (time.perf_counter() - t) / seeds}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=96)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--alpha", type=float, default=0.1)
    ap.add_argument("--seeds", type=int, default=2)
    a = ap.parse_args()
    res = measure(a.size, a.spp, a.ref_spp, a.alpha, a.seeds)
    base = res["roughconductor"]["rmse"]
    print(f"glossy ggx alpha={a.alpha}, {a.size}x{a.size}, {a.spp} spp (reference: roughconductor, {a.ref_spp} spp)")
    for label, r in res.items():
        print(f"  {label:<22} rmse {r['rmse']:.5f}  x{r['rmse'] / base:5.2f} of roughconductor   {r['seconds']:.2f} s/render")


if __name__ == "__main__":
    main()
