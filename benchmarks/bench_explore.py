"""How fast the explorer (``brdffit.explore``) follows its controls, on the bundled sample.

A parameter change (``Explorer.set_params``, what a slider does) is timed end to end: the model
evaluated for the table, slices and sphere, the loss and metrics, the six images made and encoded
(PNG, base64) and handed to the widget's synced state. Printed: the median and 90th percentile
over ``--changes`` random changes per model, where the time goes (evaluation, metrics, images), and
two baselines measured in the same run: the model alone on the 81x81 table through the evaluator
(the floor), and the static figures a notebook redraws for the same view (``brdffit.plot``'s
compare_table and slices, to PNG). Then a change of light, and Fit against ``brdffit.fit`` from the
same start. The target (docs/explorer.md#the-explorer): a parameter change in at most 100 ms median on 2 cores.

    .venv/bin/python benchmarks/bench_explore.py [--changes 40] [--models ggx lambert+ggx+ggx]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

import brdffit
import brdffit.plot
from brdffit.fitting.model_eval import eval_model

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "sample_ubo81.exr"


def timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def random_values(explorer, rng) -> dict:
    """One slider moved to a random position (as a user drags one), by its own axis."""
    s = explorer._sliders[rng.integers(len(explorer._sliders))]
    u = rng.uniform()
    value = s["lo"] * (s["hi"] / s["lo"]) ** u if s["log"] else s["lo"] + (s["hi"] - s["lo"]) * u
    current = explorer.params[s["param"]].copy()
    current[s["index"]] = value
    return {s["param"]: current}


def bench_model(m, name: str, changes: int, rng) -> None:
    e = brdffit.explore(m, model=name)
    for _ in range(3):  # warm: the model's programs, the slices' figure
        e.set_params(**random_values(e, rng))
    total, parts, images = [], {"evaluate": [], "metrics": [], "images": []}, {}
    for _ in range(changes):
        values = random_values(e, rng)
        total.append(timed(lambda: e.set_params(**values)))
        for k in parts:
            parts[k].append(e.timings[k])
        for k, seconds in e._live.seconds.items():
            images.setdefault(k, []).append(seconds)
    wi, wo = brdffit.ubo_pairs()
    floor = statistics.median(timed(lambda: eval_model(e._mdl, e.params, wi, wo)) for _ in range(changes))
    fit = brdffit.fit(m, name)
    theta = np.radians(e.light[0])
    static = statistics.median(
        timed(lambda: [brdffit.plot.png_bytes(f) for f in (brdffit.plot.compare_table(m, fit),
                                                             brdffit.plot.slices(m, fit, theta_light=theta))])
        for _ in range(3))
    med = statistics.median(total)
    p90 = float(np.percentile(total, 90))
    print(f"{name}: parameter change median {1e3 * med:.1f} ms, p90 {1e3 * p90:.1f} ms over {changes} changes "
          f"(target <= 100 ms median: {'met' if med <= 0.1 else 'NOT met'})")
    print("  where it goes (median ms): " + ", ".join(f"{k} {1e3 * statistics.median(v):.1f}" for k, v in parts.items())
          + f"; images sent {sum(len(v) for v in e._images.values()) / 1024:.0f} KiB base64")
    print("  the images (median ms, made and encoded; the measured ones are kept): "
          + ", ".join(f"{k} {1e3 * statistics.median(v):.1f}" for k, v in images.items()))
    print(f"  baselines: the model alone on the 81x81 table {1e3 * floor:.1f} ms (x{med / floor:.1f} of it); "
          f"the static figures redrawn {1e3 * static:.0f} ms (the explorer x{static / med:.0f} faster)")
    lights = [(15, 60), (60, 200), (30, 0), (75, 345), (45, 120)]
    light = statistics.median(timed(lambda t=t: setattr(e, "light", t)) for t in lights)
    print(f"  a change of light (slices' axes redrawn, measured sphere interpolated): median {1e3 * light:.0f} ms")


def bench_fit(m, name: str, repeat: int = 3) -> None:
    e = brdffit.explore(m, model=name)
    start = e.params
    e.fit()  # compile / load the fit's program once, for both
    ours, plain = [], []
    for _ in range(repeat):
        e.set_params(**start)
        ours.append(timed(e.fit))
        plain.append(timed(lambda: brdffit.fit(m, name, init=start)))
    a, b = statistics.median(ours), statistics.median(plain)
    print(f"{name}: Fit {1e3 * a:.0f} ms, brdffit.fit from the same start {1e3 * b:.0f} ms "
          f"(Fit adds the new view: {1e3 * (a - b):+.0f} ms; ratio {a / b:.2f})")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--changes", type=int, default=40)
    ap.add_argument("--models", nargs="+", default=["ggx", "lambert+ggx+ggx"])
    args = ap.parse_args()
    m = brdffit.load(SAMPLE)
    rng = np.random.default_rng(0)
    for name in args.models:
        bench_model(m, name, args.changes, rng)
    for name in args.models:
        bench_fit(m, name)
    print(f"({os.cpu_count()} cores; the machine may be shared: compare the ratios, not the times)")


if __name__ == "__main__":
    main()
