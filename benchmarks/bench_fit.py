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
    ap.add_argument("--batch", type=int, default=0, metavar="N",
                    help="instead: fit_batch on N synthetic ggx texels (UBO-81), chunked/sorted vs not, vs a loop of fit()")
    args = ap.parse_args(argv)
    if args.batch:
        return bench_batch(args.batch, args.loss)

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


def bench_batch(n: int, loss: str) -> int:
    """fit_batch: one vmapped solve runs every lane until the slowest stops; chunking + sorting by
    start loss limits that. Compares wall times (after a warm-up call of the same shapes)."""
    from brdffit.grid import ubo_pairs

    wi, wo = ubo_pairs()
    model = brdffit.models.get("ggx")
    rng = np.random.default_rng(0)
    ms = []
    for i in range(n):
        p = {"kd": rng.uniform(0.05, 0.6, 3), "ks": rng.uniform(0.1, 0.9, 3),
             "alpha": np.exp(rng.uniform(np.log(0.03), np.log(0.6), 1)), "f0": rng.uniform(0.02, 0.9, 1)}
        f = np.asarray(model.eval(p, wi, wo))
        ms.append(brdffit.Measurement(wi, wo, f * (1 + 0.01 * rng.standard_normal(f.shape)), grid="ubo81", name=f"t{i}"))
    configs = [(f"{solver}, {label}", dict(solver=solver, **kw)) for solver in ("lmb", "lm") for label, kw in (
        ("one chunk, unsorted", dict(chunk=n, sort=False)), ("chunks of 8, sorted", dict(chunk=8, sort=True)),
        ("chunks of 8, unsorted", dict(chunk=8, sort=False)))]
    for label, kw in configs:
        brdffit.fit_batch(ms[: kw["chunk"]] if kw["chunk"] < n else ms, "ggx", loss=loss, **kw)  # warm-up (compile)
        t0 = time.perf_counter()
        rs = brdffit.fit_batch(ms, "ggx", loss=loss, **kw)
        dt = time.perf_counter() - t0
        steps = [r.steps for r in rs]
        print(f"fit_batch {label:29s}: {dt:.2f}s for {n} fits ({dt / n * 1000:.0f} ms/fit), steps max {max(steps)} "
              f"median {int(np.median(steps))}, converged {sum(r.converged for r in rs)}/{n}", flush=True)
    for solver in ("lm", "lmb"):
        brdffit.fit(ms[0], "ggx", loss=loss, solver=solver)
        t0 = time.perf_counter()
        rs = [brdffit.fit(m, "ggx", loss=loss, solver=solver) for m in ms]
        dt = time.perf_counter() - t0
        print(f"loop of fit(solver={solver!r}){'':9s}: {dt:.2f}s for {n} fits ({dt / n * 1000:.0f} ms/fit), "
              f"converged {sum(r.converged for r in rs)}/{n}", flush=True)
    print(f"devices: {jax.devices()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
