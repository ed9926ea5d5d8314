"""Benchmark (``make bench``): brdffit's default fit against the fit a user writes by hand.

On every shared material (../shared/data or $BRDFFIT_DATA: RGL files on UBO-81, Cornell files as
their scattered samples), model ``ggx``, loss ``log``, three fits of the same data:

- hand-written: a NumPy ``ggx`` residual written from the formula of docs/models.md#models, the ``log`` loss,
  ``scipy.optimize.least_squares(method="trf", jac="2-point")``, bounds kd [0, 1], ks >= 0
  (no upper bound), alpha [1e-3, 1], f0 [0, 1], start kd 0.2, ks 0.5, alpha 0.3, f0 0.05;
- jitted scipy: ``brdffit.fit(m, "ggx", solver="scipy", init=<the same start>)`` (brdffit's
  jit-compiled residual, exact forward-mode Jacobian, the same TRF);
- default: ``brdffit.fit(m, "ggx")`` (grid start + ``lm``), start included in its time.

All three use the same normalised residual (weights summing to 1), so losses compare directly.
Printed per material: loss ratios (default / hand-written, target <= 1.001), warm wall-time
ratios (hand-written / default >= 20, jitted scipy / default >= 3), ``lambert+ggx+ggx`` with
defaults (converged, loss / hand-written single ggx <= 1, warm time <= 0.5 s), the default fit's
compiled program time (start, solve, metrics) and steps, and what one step computes (loss, J^T r,
J^T J) timed next to its FLOP count (XLA's cost analysis), structured (the solver's) and dense. Then the
wall time of ``brdffit fit data/sample_ubo81.exr --model ggx -o DIR`` in a first process (empty
compile cache) and a second one (target <= 2.5 s). Times are medians of ``--repeat`` runs after
a warm-up, and of as many more as fit in ``MIN_SECONDS`` for the short ones (the best times' ratio
to the hand-written fit is printed beside the medians'); ratios are within one run (the machine
may be shared).

``--batch N``: ``fit_batch`` on N ggx UBO-81 texels (synthetic, 1 % noise): fits per second.

``--step``: one evaluation of the normal equations as a fit runs it (ggx, cook_torrance, lambert+ggx+ggx; the
Jacobian's rows in float32, fit_btf's, and in float64, fit's, where the switch does nothing), with the basis's
partials materialised before the rows read them (``objective.PARTIALS_ONCE``) and without, alternating. Run it
on one core (``taskset -c 0``), as a lane of fit_btf runs.
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
from brdffit._fit_defaults import DEFAULT_RTOL
from brdffit.fitting.objective import flat_residual
from brdffit.fitting.problem import prepare, resolve_model

REPO = Path(__file__).resolve().parents[1]
START = {"kd": 0.2, "ks": 0.5, "alpha": 0.3, "f0": 0.05}


def data_files() -> list[Path]:
    env = os.environ.get("BRDFFIT_DATA")
    root = Path(env) if env else REPO.parent / "shared" / "data"
    if not (root / "measured").is_dir():
        root = Path("/work/shared/data")
    files = sorted((root / "measured" / "rgl").glob("*.bsdf")) + sorted((root / "measured" / "cornell").glob("*.brdf"))
    if not files:
        sys.exit(f"no measurements found under {root}/measured (set BRDFFIT_DATA)")
    return files


# -- the hand-written fit -----------------------------------------------------------------------
def numpy_ggx(v, wi, wo):
    """docs/models.md#models ggx: kd/pi + ks F G D / (4 cos_i cos_o), v = kd(3), ks(3), alpha, f0."""
    kd, ks, alpha, f0 = v[0:3], v[3:6], v[6], v[7]
    h = wi + wo
    h = h / np.linalg.norm(h, axis=1, keepdims=True)
    cos_h = h[:, 2]
    a2 = alpha * alpha
    d = a2 / (np.pi * (cos_h**2 * a2 + (1 - cos_h**2)) ** 2)

    def g1(w):
        c2 = w[:, 2] ** 2
        return 2.0 / (1.0 + np.sqrt(1.0 + a2 * (1 - c2) / c2))

    f = f0 + (1 - f0) * (1 - np.sum(wi * h, axis=1)) ** 5
    spec = f * g1(wi) * g1(wo) * d / (4 * wi[:, 2] * wo[:, 2])
    return kd[None, :] / np.pi + ks[None, :] * spec[:, None]


def hand_written(meas):
    prep = prepare(meas)
    wi, wo, ref, sqrt_w, cos_i, _ = (np.asarray(a) for a in prep.data)
    used = sqrt_w[:, 0] > 0
    wi, wo, ref, sqrt_w, cos_i = wi[used], wo[used], ref[used], sqrt_w[used], cos_i[used]
    target = np.log1p(ref * cos_i)

    def residual(v):
        return (sqrt_w * (np.log1p(numpy_ggx(v, wi, wo) * cos_i) - target)).ravel()

    from scipy.optimize import least_squares

    v0 = np.asarray([START["kd"]] * 3 + [START["ks"]] * 3 + [START["alpha"], START["f0"]])
    lo = np.asarray([0, 0, 0, 0, 0, 0, 1e-3, 0.0])
    hi = np.asarray([1, 1, 1, np.inf, np.inf, np.inf, 1.0, 1.0])
    t0 = time.perf_counter()
    sol = least_squares(residual, v0, jac="2-point", bounds=(lo, hi), method="trf")
    return float(np.sum(sol.fun**2)), time.perf_counter() - t0, sol


#: Untimed runs before the timed ones: the first compiles; the next ones still ran ~1.5x slower
#: on this machine (memory first touched, XLA's thread pool waking), which is not a warm fit.
WARMUP = 3


#: A timed function runs at least ``repeat`` times and until its runs add up to this many seconds
#: (at most ``MAX_RUNS``): a 10 ms fit timed 3 times gave a median that one disturbed run could
#: double (colodur: 18.9 ms in one ``make bench``, 10.7 ms median of 20 fits a minute later),
#: while each of the hand-written fit's 3 runs spans ~0.4 s and averages such disturbances out.
MIN_SECONDS = 0.5
MAX_RUNS = 50


def timed(fn, repeat):
    for _ in range(WARMUP):
        fn()
    out, times = None, []
    while len(times) < repeat or (sum(times) < MIN_SECONDS and len(times) < MAX_RUNS):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times), min(times)


def step_cost(meas, model_name: str, repeat: int = 200) -> dict:
    """FLOPs (XLA's cost analysis) and time (best of 5 runs of ``repeat``) of what one ``lm`` step
    computes (loss, J^T r, J^T J at a trial point), in the structured form the solver uses and in
    the dense jacfwd form, on ``meas``."""
    from brdffit.fitting.objective import dense_normal_equations, normal_equations

    prep = prepare(meas)
    model = resolve_model(model_name, prep.channels)
    v = jnp.asarray(model.default_vector())
    out = {}
    for name, fn in (("structured", normal_equations(model, "log")), ("dense", dense_normal_equations(model, "log"))):
        compiled = jax.jit(fn).lower(v, prep.data).compile()
        cost = compiled.cost_analysis()
        cost = cost[0] if isinstance(cost, list) else cost
        jax.block_until_ready(compiled(v, prep.data))
        best = float("inf")
        for _ in range(5):
            t0 = time.perf_counter()
            for _ in range(repeat):
                r = compiled(v, prep.data)
            jax.block_until_ready(r)
            best = min(best, (time.perf_counter() - t0) / repeat)
        out[name] = (float(cost.get("flops", float("nan"))), best)
    return out


def evaluation_cost(meas, model_name: str, jacobian: str, repeat: int = 300) -> dict:
    """Time of one evaluation of the normal equations as a fit runs them (the direction-only terms precomputed,
    ``jacobian`` the rows' precision: "float32" is fit_btf's), with the basis's partials materialised before the
    rows read them (``objective.PARTIALS_ONCE``, the default on a CPU) and without: {True: s, False: s}, the best
    of 7 runs of ``repeat``, the two alternating."""
    from brdffit.fitting import objective

    prep = prepare(meas)
    model = resolve_model(model_name, prep.channels)
    v = jnp.asarray(model.default_vector())
    consts = jax.jit(lambda d: objective.fit_constants(model, "log", d, jacobian=jacobian))(prep.data)
    args = (v, prep.data, consts.g_ref, consts.geometry)
    programs = {}
    for once in (True, False):
        objective.PARTIALS_ONCE = once  # read when the program is traced
        jax.clear_caches()
        programs[once] = jax.jit(objective.normal_equations(model, "log", jacobian)).lower(*args).compile()
        jax.block_until_ready(programs[once](*args))
    objective.PARTIALS_ONCE = True
    best = {True: float("inf"), False: float("inf")}
    for _ in range(7):
        for once, program in programs.items():
            t0 = time.perf_counter()
            for _ in range(repeat):
                out = program(*args)
            jax.block_until_ready(out)
            best[once] = min(best[once], (time.perf_counter() - t0) / repeat)
    return best


def print_evaluation_costs() -> None:
    meas = brdffit.load(REPO / "data" / "sample_ubo81.exr")
    for name in ("ggx", "cook_torrance", "lambert+ggx+ggx"):
        for jacobian in ("float32", "float64"):
            t = evaluation_cost(meas, name, jacobian)
            print(f"one evaluation, {name}, {jacobian} rows (data/sample_ubo81.exr): partials once "
                  f"{t[True] * 1e6:.1f} us, per channel {t[False] * 1e6:.1f} us, x{t[False] / t[True]:.2f}", flush=True)


def cli_times(repeat: int = 3) -> tuple[float, float]:
    """First process (empty compile cache) and the median of ``repeat`` second ones, wall seconds
    (``bench_cli``: a run that fails or writes no fit.json / fit.png raises SystemExit)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_cli import cli_times as times

    (first, _), seconds, _ = times(repeat)
    return first, statistics.median(w for w, _ in seconds)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--batch", type=int, default=0, metavar="N", help="instead: fit_batch on N synthetic texels")
    ap.add_argument("--no-cli", action="store_true", help="skip the first/second process CLI timing")
    ap.add_argument("--step", action="store_true", help="instead: one evaluation of the normal equations, timed")
    args = ap.parse_args(argv)
    if args.batch:
        return bench_batch(args.batch)
    if args.step:
        print(f"devices: {jax.devices()} (one thread: XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r})", flush=True)
        print_evaluation_costs()
        return 0
    print(f"devices: {jax.devices()}, CPU cores: {os.cpu_count()} (ratios are within this run)", flush=True)
    rows = []
    for path in data_files():
        meas = brdffit.load(path)
        # The hand-written fit warms up as the others do (its first run also reads every array
        # for the first time).
        for _ in range(WARMUP - 1):
            hand_written(meas)
        hw_loss, hw_s, sol = hand_written(meas)
        hw_times = [hw_s] + [hand_written(meas)[1] for _ in range(args.repeat - 1)]
        hw_s, hw_best = statistics.median(hw_times), min(hw_times)
        sc, sc_s, _ = timed(lambda: brdffit.fit(meas, "ggx", solver="scipy", init=START), args.repeat)
        d, d_s, d_best = timed(lambda: brdffit.fit(meas, "ggx"), args.repeat)
        comp = None
        if meas.grid == "ubo81":
            comp, comp_s, _ = timed(lambda: brdffit.fit(meas, "lambert+ggx+ggx"), args.repeat)
        # Medians are what the targets are judged on; the best times (timeit's convention: the
        # least disturbed run of each) are printed beside them, since the hand-written fit's
        # median moves by 1.5x between runs on a shared machine.
        row = dict(name=meas.name, rgl=meas.grid == "ubo81", hw=hw_loss, sc=sc.loss_value, d=d.loss_value, hw_s=hw_s, sc_s=sc_s, d_s=d_s,
                   best_ratio=hw_best / d_best,
                   steps=d.steps, status=d.status, program_s=d.seconds["run"],
                   comp=comp, comp_s=comp_s if comp else None)
        rows.append(row)
        print(f"{meas.name:26s} loss hand {hw_loss:.6e} scipy-jit {sc.loss_value:.6e} default {d.loss_value:.6e} "
              f"ratio {d.loss_value / hw_loss:.5f} | warm hand {hw_s * 1e3:.1f} ms ({sol.nfev} evals) scipy-jit "
              f"{sc_s * 1e3:.1f} ms default {d_s * 1e3:.1f} ms (compiled program {d.seconds['run'] * 1e3:.1f} ms, "
              f"{d.steps} steps, {d.status}) speed-up x{hw_s / d_s:.1f} / x{sc_s / d_s:.1f} (best times: "
              f"hand {hw_best * 1e3:.1f} ms, default {d_best * 1e3:.1f} ms, x{hw_best / d_best:.1f})"
              + (f" | lambert+ggx+ggx {comp.status}, loss/hand {comp.loss_value / hw_loss:.4f}, "
                 f"{comp_s * 1e3:.0f} ms, {comp.steps} steps" if comp else ""), flush=True)
    step = step_cost(brdffit.load(REPO / "data" / "sample_ubo81.exr"), "ggx")

    print()
    hdr = ("material", "loss default/hand", "loss scipy-jit/hand", "hand ms", "scipy-jit ms", "default ms",
           "x vs hand", "x vs hand (best times)", "x vs scipy-jit", "steps", "program ms", "l+g+g converged", "l+g+g loss/hand ggx", "l+g+g ms")
    print(" | ".join(hdr))
    print(" | ".join("---" for _ in hdr))
    fails = []
    for r in rows:
        c = r["comp"]
        print(f"{r['name']} | {r['d'] / r['hw']:.5f} | {r['sc'] / r['hw']:.5f} | {r['hw_s'] * 1e3:.1f} | "
              f"{r['sc_s'] * 1e3:.1f} | {r['d_s'] * 1e3:.1f} | {r['hw_s'] / r['d_s']:.1f} | {r['best_ratio']:.1f} | {r['sc_s'] / r['d_s']:.1f} | "
              f"{r['steps']} | {r['program_s'] * 1e3:.1f} | " + (f"{c.converged} | {c.loss_value / r['hw']:.10f} | "
                                                                f"{r['comp_s'] * 1e3:.0f}" if c else "- | - | -"))
        if r["d"] > 1.001 * r["hw"]:
            fails.append(f"{r['name']}: loss ratio {r['d'] / r['hw']:.5f} > 1.001")
        # The speed targets are set on the RGL files (UBO-81, 6561 samples); the Cornell files
        # (~1,400 scattered samples) are printed for reference.
        if r["rgl"] and r["hw_s"] / r["d_s"] < 20:
            fails.append(f"{r['name']}: x{r['hw_s'] / r['d_s']:.1f} vs hand-written < 20")
        if r["rgl"] and r["sc_s"] / r["d_s"] < 3:
            fails.append(f"{r['name']}: x{r['sc_s'] / r['d_s']:.1f} vs jitted scipy < 3")
        # "loss <= the hand-written single ggx": up to the solvers' relative tolerance (DEFAULT_RTOL):
        # where the data want one lobe (paper_white), the composite's second lobe vanishes and both
        # fits reach the same minimum, each to its own convergence test.
        if c is not None and not (c.converged and c.loss_value <= r["hw"] * (1 + DEFAULT_RTOL) and r["comp_s"] <= 0.5):
            fails.append(f"{r['name']}: lambert+ggx+ggx converged={c.converged} loss/hand {c.loss_value / r['hw']:.10f} "
                         f"{r['comp_s']:.2f} s")
    (f_s, t_s), (f_d, t_d) = step["structured"], step["dense"]
    print(f"\nggx/UBO-81 step (loss, J^T r, J^T J at one point; data/sample_ubo81.exr): structured {f_s / 1e6:.1f} MFLOP "
          f"in {t_s * 1e3:.3f} ms ({f_s / t_s / 1e9:.2f} GFLOP/s); dense jacfwd {f_d / 1e6:.1f} MFLOP in {t_d * 1e3:.3f} ms "
          f"({f_d / t_d / 1e9:.2f} GFLOP/s); x{t_d / t_s:.2f}")
    if not args.no_cli:
        cli_repeat = max(args.repeat, 5)  # 2.5 s each: a median of 3 moved with one disturbed run
        first, second = cli_times(cli_repeat)
        print(f"brdffit fit data/sample_ubo81.exr --model ggx -o DIR: first process {first:.2f} s (empty compile "
              f"cache), second process {second:.2f} s (median of {cli_repeat}; target <= 2.5 s; load average "
              f"{os.getloadavg()[0]:.1f})")
        if second > 2.5:
            fails.append(f"second-process CLI {second:.2f} s > 2.5 s")
    print("\nmisses against the targets:" if fails else "\nall targets met", *fails, sep="\n  ")
    return 0


def bench_batch(n: int) -> int:
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
    brdffit.fit_batch(ms, "ggx")  # warm-up (compiles)
    t0 = time.perf_counter()
    rs = brdffit.fit_batch(ms, "ggx")
    dt = time.perf_counter() - t0
    steps = [r.steps for r in rs]
    print(f"fit_batch ggx, {n} UBO-81 texels: {dt:.2f} s = {n / dt:.0f} texels/s, steps max {max(steps)} median "
          f"{int(np.median(steps))}, converged {sum(r.converged for r in rs)}/{n}; devices {jax.devices()}")
    brdffit.fit(ms[0], "ggx")  # warm-up (compiles)
    t0 = time.perf_counter()
    for m in ms[:8]:
        brdffit.fit(m, "ggx")
    dt1 = (time.perf_counter() - t0) / 8
    print(f"loop of brdffit.fit: {1 / dt1:.0f} fits/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
