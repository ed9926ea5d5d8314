"""Issue 3 item 4: every model (and a composite) is finite and non-negative, with finite gradients
with respect to its parameters and to both directions, at each parameter's lower bound, upper
bound and default (and all-lower / all-upper corners), over extreme directions: normal incidence,
89, 89.9 and 90 degrees (the horizon), wi == wo, mirror pairs and opposite grazing pairs; in
float32 and float64. One jit compilation per (model, dtype): parameter sets are vmapped."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import brdffit
from brdffit.grid import spherical_to_cartesian
from brdffit.models import get, names

MODELS = names() + ["lambert+ggx+ggx", "oren_nayar+ward", "lafortune3"]
THETAS_DEG = (0.0, 1e-3, 15.0, 45.0, 75.0, 89.0, 89.9, 90.0)
PHIS_DEG = (0.0, 37.0, 90.0, 180.0, 271.0)


def extreme_pairs() -> tuple[np.ndarray, np.ndarray]:
    th, ph = np.meshgrid(np.deg2rad(THETAS_DEG), np.deg2rad(PHIS_DEG), indexing="ij")
    d = spherical_to_cartesian(th.ravel(), ph.ravel())
    d[np.abs(d) < 1e-15] = 0.0  # exact zeros: the horizon is z == 0, the pole x == y == 0
    n = len(d)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    all_pairs = (d[i.ravel()], d[j.ravel()])  # includes wi == wo
    mirror = (d, d * np.array([-1.0, -1.0, 1.0]))
    opposite_horizon = (np.array([[1.0, 0, 0], [0, 1.0, 0]]), np.array([[-1.0, 0, 0], [0, -1.0, 0]]))
    wi = np.concatenate([all_pairs[0], mirror[0], opposite_horizon[0]])
    wo = np.concatenate([all_pairs[1], mirror[1], opposite_horizon[1]])
    return wi, wo


def param_sets(model) -> list[dict[str, float]]:
    base = {p.name: p.default for p in model.params}
    sets = [dict(base), {p.name: p.lower for p in model.params}, {p.name: p.upper for p in model.params}]
    for p in model.params:
        sets += [dict(base, **{p.name: p.lower}), dict(base, **{p.name: p.upper})]
    return sets


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64], ids=["f32", "f64"])
@pytest.mark.parametrize("name", MODELS)
def test_finite_nonnegative_with_finite_gradients(name, dtype):
    model = get(name)
    wi_np, wo_np = extreme_pairs()
    wi, wo = jnp.asarray(wi_np, dtype), jnp.asarray(wo_np, dtype)
    sets = param_sets(model)
    flat = jnp.asarray(np.stack([np.asarray(model.flatten(s)) for s in sets]), dtype)

    def f(x, a, b):
        return model.eval(model.unflatten(x), a, b)

    def checks(x):
        val = f(x, wi, wo)
        jac = jax.jacfwd(f)(x, wi, wo)  # (N, C, P): per sample, per parameter
        gi, go = jax.grad(lambda a, b: jnp.sum(f(x, a, b)), argnums=(0, 1))(wi, wo)  # per sample
        return val, jac, gi, go

    val, jac, gi, go = jax.jit(jax.vmap(checks))(flat)
    assert val.dtype == dtype and jac.dtype == dtype, "the formula must not promote float32"
    names_ = [" ".join(f"{k}={v:g}" for k, v in s.items()) for s in sets]
    for k, label in enumerate(names_):
        v = np.asarray(val[k])
        bad = ~np.isfinite(v) | (v < 0)
        assert not bad.any(), f"{name} [{label}]: non-finite/negative value at wi={wi_np[bad.any(1)][0]}, wo={wo_np[bad.any(1)][0]}"
        for what, g in (("d/dparams", jac[k]), ("d/dwi", gi[k]), ("d/dwo", go[k])):
            g = np.asarray(g).reshape(len(wi_np), -1)
            badg = ~np.isfinite(g).all(axis=1)
            assert not badg.any(), f"{name} [{label}] {what} not finite at wi={wi_np[badg][0]}, wo={wo_np[badg][0]}"


def test_stability_pairs_cover_the_brief():
    wi, wo = extreme_pairs()
    assert np.any(np.all(wi == wo, axis=1) & (wi[:, 2] == 0))  # wi == wo at the horizon
    assert np.any(np.all(wo == wi * [-1, -1, 1], axis=1) & (np.abs(wi[:, 2] - np.cos(np.deg2rad(89.9))) < 1e-12))
    assert np.any(np.all(wi == [0, 0, 1], axis=1) & np.all(wo == [0, 0, 1], axis=1))
    assert brdffit.models.get("lambert").eval({"kd": 0.5}, wi[:3], wo[:3]).shape == (3, 3)
