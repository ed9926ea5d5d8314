"""Benchmark: brdffit.fit (defaults) against scipy least_squares on every real material.

For each material in ../shared/data (or $BRDFFIT_DATA): RGL files sampled on UBO-81, Cornell files
as their scattered samples. Model ``ggx``, loss ``log``.

- brdffit: ``brdffit.fit(m, "ggx", loss="log")`` with all defaults (variable-projection grid
  start, optimistix Levenberg-Marquardt, exact forward-mode Jacobians, float64), and the same
  with ``solver="lmb"`` (brdffit's own projected Levenberg-Marquardt, see fitting/solve.py).
- scipy: ``scipy.optimize.least_squares(method="trf", bounds=model bounds, jac="2-point")`` from
  kd 0.2, ks 0.5, alpha 0.3, f0 0.05, on the *same* residual (the same normalised log-loss
  residual vector, evaluated by the same jit-compiled JAX function, so scipy is not handicapped
  by a slow Python residual).

Times: compile (XLA compilation: brdffit's grid + solver; scipy's residual function) and run
(wall clock of the work after compilation) are reported separately. brdffit's run time includes
its initialisation grid. Each timed run is repeated ``--repeat`` times and the median taken (the
machine may be shared). Usage: ``python benchmarks/bench_fit.py [--repeat 3] [--model ggx]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import brdffit
from brdffit.fitting.problem import flat_residual, prepare, resolve_model

SCIPY_START = {"kd": 0.2, "ks": 0.5, "alpha": 0.3, "f0": 0.05}


def data_files() -> list[Path]:
    env = os.environ.get("BRDFFIT_DATA")
    root = Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "data"
    files = sorted((root / "measured" / "rgl").glob("*.bsdf")) + sorted((root / "measured" / "cornell").glob("*.brdf"))
    if not files:
        sys.exit(f"no measurements found under {root}/measured (set BRDFFIT_DATA)")
    return files


def scipy_fit(meas, model_name: str, loss: str):
    from scipy.optimize import least_squares

    prep = prepare(meas)
    model = resolve_model(model_name, prep.channels)
    start = {k: v for k, v in SCIPY_START.items() if k in model.param_names}
    v0 = np.asarray(model.flatten({**model.defaults(), **start}))
    fn = flat_residual(model, loss)
    t0 = time.perf_counter()
    res = jax.jit(fn).lower(jnp.asarray(v0), prep.data).compile()
    compile_s = time.perf_counter() - t0
    lo, hi = model.bounds()

    def f(v):
        return np.asarray(res(jnp.asarray(v), prep.data))

    t0 = time.perf_counter()
    sol = least_squares(f, v0, jac="2-point", bounds=(lo, hi), method="trf")
    run_s = time.perf_counter() - t0
    return float(np.sum(sol.fun**2)), compile_s, run_s, sol


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--model", default="ggx")
    ap.add_argument("--loss", default="log")
    args = ap.parse_args(argv)

    rows = []
    for path in data_files():
        meas = brdffit.load(path)
        # brdffit: first call compiles (cached per shape afterwards), then timed repeats.
        first = brdffit.fit(meas, args.model, loss=args.loss)
        runs = [brdffit.fit(meas, args.model, loss=args.loss) for _ in range(args.repeat)]
        b_run = statistics.median(r.seconds["run"] for r in runs)
        b_init = statistics.median(r.seconds["init"] for r in runs)
        r = runs[0]
        first_b = brdffit.fit(meas, args.model, loss=args.loss, solver="lmb")
        runs_b = [brdffit.fit(meas, args.model, loss=args.loss, solver="lmb") for _ in range(args.repeat)]
        lmb_run = statistics.median(x.seconds["run"] for x in runs_b)
        rb = runs_b[0]
        s_loss, s_compile, _, sol = scipy_fit(meas, args.model, args.loss)
        s_runs = [scipy_fit(meas, args.model, args.loss)[2] for _ in range(args.repeat)]
        s_run = statistics.median(s_runs)
        rows.append((meas.name, r.loss_value, s_loss, first.seconds["compile"], b_run, b_init, r.steps,
                     r.status, s_compile, s_run, sol.nfev, sol.status, rb.loss_value, lmb_run,
                     first_b.seconds["compile"], rb.steps))
        print(
            f"{meas.name:24s} loss brdffit {r.loss_value:.6e} scipy {s_loss:.6e} ratio {r.loss_value / s_loss:.4f} | "
            f"run brdffit {b_run:.3f}s (grid {b_init:.3f}s, {r.steps} steps, {r.status}) scipy {s_run:.3f}s "
            f"({sol.nfev} evals, status {sol.status}) speed-up x{s_run / b_run:.1f} | "
            f"compile brdffit {first.seconds['compile']:.2f}s scipy {s_compile:.2f}s",
            flush=True,
        )
        print(
            f"{'':24s} lmb: loss {rb.loss_value:.6e} ratio {rb.loss_value / s_loss:.4f} run {lmb_run:.3f}s "
            f"({rb.steps} steps, {rb.status}) speed-up x{s_run / lmb_run:.1f} compile {first_b.seconds['compile']:.2f}s",
            flush=True,
        )

    print()
    hdr = ("material", "loss lm (default)", "loss lmb", "loss scipy", "ratio lm", "ratio lmb", "run lm s",
           "run lmb s", "run scipy s", "speed-up lm", "speed-up lmb", "compile lm s", "compile lmb s", "compile scipy s")
    print(" | ".join(hdr))
    print(" | ".join("---" for _ in hdr))
    worse = slower = worse_b = slower_b = 0
    for (name, bl, sl, bc, br, bi, st, status, sc, sr, nfev, sstat, lb, rbt, cb, stb) in rows:
        print(f"{name} | {bl:.6e} | {lb:.6e} | {sl:.6e} | {bl / sl:.6f} | {lb / sl:.6f} | {br:.3f} | {rbt:.3f} | "
              f"{sr:.3f} | {sr / br:.1f} | {sr / rbt:.1f} | {bc:.2f} | {cb:.2f} | {sc:.2f}")
        worse += bl > sl * (1 + 1e-6)
        slower += br >= sr
        worse_b += lb > sl * (1 + 1e-6)
        slower_b += rbt >= sr
    print(f"\n{len(rows)} materials: loss higher than scipy's (by > 1e-6 relative): lm {worse}, lmb {worse_b}; "
          f"not faster (run): lm {slower}, lmb {slower_b}.")
    print(f"devices: {jax.devices()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
