"""Model evaluation cost: jitted ``model.eval`` on 1e6 direction pairs (what the renderer asks for)
and ``jacfwd`` over the flat parameters on the 6561 UBO pairs (what the fitter asks for, thousands
of times). Prints absolute times and ratios to ``ggx`` measured in the same run (machine noise
cancels in the ratios).

    .venv/bin/python benchmarks/bench_models.py [--n 1000000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

import brdffit
from brdffit.models import get, names


def best_of(fn, repeat):
    fn()  # compile + warm
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t)
    return min(times)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    th = np.arccos(rng.uniform(0, 1, (2, args.n)))
    ph = rng.uniform(0, 2 * np.pi, (2, args.n))
    v = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    wi, wo = jnp.asarray(v[0]), jnp.asarray(v[1])
    uwi, uwo = (jnp.asarray(a) for a in brdffit.ubo_pairs())
    rows = []
    for name in ["ggx"] + [n for n in names() if n != "ggx"] + ["lambert+ggx+ggx", "lafortune3"]:
        model = get(name)
        p = model.defaults()
        x = model.flatten(p)
        ev = jax.jit(lambda p, a, b, model=model: model.eval(p, a, b))
        # directions are arguments, not closed-over constants, so XLA cannot fold them away
        jac = jax.jit(jax.jacfwd(lambda x, a, b, model=model: model.eval(model.unflatten(x), a, b)))
        t_eval = best_of(lambda: ev(p, wi, wo), args.repeat)
        t_jac = best_of(lambda: jac(x, uwi, uwo), args.repeat)
        rows.append((name, model.n_free, t_eval, t_jac))
    base_eval, base_jac = rows[0][2], rows[0][3]
    print(f"{'model':<20} {'P':>3} {'eval 1e6 [ms]':>14} {'/ggx':>6} {'jacfwd UBO [ms]':>16} {'/ggx':>6}")
    for name, nfree, te, tj in rows:
        print(f"{name:<20} {nfree:>3} {te * 1e3:>14.1f} {te / base_eval:>6.2f} {tj * 1e3:>16.2f} {tj / base_jac:>6.2f}")
    print(f"(n = {args.n} pairs for eval, 6561 UBO pairs for jacfwd; best of {args.repeat}; float64; {jax.devices()[0]})")


if __name__ == "__main__":
    main()
