"""XLA's vector width on a CPU (``brdffit.fitting.cache.compiler_options``): one solver round of a batch of
texels compiled with XLA's default and with the options brdffit compiles its programs with, in one run.

A generated ``--model`` BTF's texels (ggx: 8 x 8, 1 % noise) from starts 3 % off their fit, one lane at a
time as ``fit_btf`` runs them on a CPU: the best of ``--repeat`` runs of each program, alternating, their
ratio, and the largest relative difference of the results (the options change rounding only).

    python benchmarks/bench_vector_width.py [--model ggx] [--repeat 5]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="ggx")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()

    import jax
    import jax.numpy as jnp

    import brdffit
    from brdffit._fit_defaults import START_DAMPING
    from brdffit.btf import generate as gen
    from brdffit.fitting import cache, stages
    from brdffit.fitting.driver import solve
    from brdffit.fitting.objective import objective_of
    from brdffit.fitting.options import FitOptions
    from brdffit.fitting.problem import prepare_values
    from brdffit.grid import ubo_pairs

    options = cache.compiler_options()
    print(f"device {jax.devices()[0]}; brdffit's compiler options here: {options or 'none (XLA defaults)'}")
    model = brdffit.models.get(args.model)
    wi, wo = ubo_pairs()
    with tempfile.TemporaryDirectory() as d:
        btf = gen.model_btf(model, gen.smooth_maps(model, 8, 8, seed=1), Path(d), noise=0.01, seed=2, tile=8, name="v")
        values = btf.tile_values(0).reshape(-1, len(wi), btf.channels)
    data = prepare_values(values, wi, wo, np.ones(len(wi)))
    o = FitOptions(chunk=64, lanes=1)
    space = o.space(model)
    fitted = solve(space, o, data, k=o.starts(model), results=False)
    rng = np.random.default_rng(0)
    starts = np.clip(fitted.v * (1 + 0.03 * rng.standard_normal(fitted.v.shape)), space.lo, space.hi)
    round_stage = jax.jit(stages.round_stage(objective_of(model, o.loss), "lm", o.rtol, o.atol, o.max_steps, True, 1))
    dampings = np.full(len(starts), START_DAMPING)  # the first round's lanes: their first step's damping
    call = ((jnp.asarray(starts), dampings), data, jnp.asarray(space.lo), jnp.asarray(space.hi),
            np.asarray(space.free, bool), np.int32(o.max_steps), np.int32(len(starts)))
    programs = {"XLA default": round_stage.lower(*call).compile(),
                "brdffit's": round_stage.lower(*call).compile(compiler_options=options)}
    best = dict.fromkeys(programs, np.inf)
    out = {}
    for _ in range(args.repeat):
        for name, program in programs.items():
            t = time.perf_counter()
            out[name] = jax.block_until_ready(program(*call))
            best[name] = min(best[name], time.perf_counter() - t)
    n = len(starts)
    for name in programs:
        print(f"{name:12s}: {best[name] / n * 1e3:.3f} ms a texel's round (best of {args.repeat}), "
              f"steps mean {np.mean(out[name][4]):.2f}")
    v0, v1 = (np.asarray(out[name][0]) for name in programs)
    ratio = best["XLA default"] / best["brdffit's"]
    print(f"ratio XLA default / brdffit's: {ratio:.2f}x; "
          f"results' largest relative difference {np.max(np.abs(v1 - v0) / np.maximum(np.abs(v0), 1e-300)):.1e}")


if __name__ == "__main__":
    main()
