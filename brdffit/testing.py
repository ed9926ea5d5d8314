"""Assertions for users' own pytest suites (and brdffit's).

    from brdffit.testing import assert_model_well_behaved, assert_fit_quality, assert_reciprocal

    def test_my_model():                      # a model of your own, or a composite
        assert_model_well_behaved("lambert+ggx+ggx", dtype="float32")

    def test_material_fit(my_measurement):
        result = brdffit.fit(my_measurement, "ggx")
        assert_fit_quality(result, max_log_rmse=0.05)

Fixtures for real data and the UBO grid: add ``pytest_plugins = ["brdffit.pytest_plugin"]`` to your
``conftest.py``. Each assertion raises ``AssertionError`` with a message that says where it failed.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from . import _x64  # noqa: F401 - float64 before any JAX work (brdffit/_x64.py)
from .grid import spherical_to_cartesian
from .models import Model, get

#: Polar angles that stress a formula: normal incidence, near-normal, the UBO rings, grazing, the horizon.
EXTREME_THETAS_DEG = (0.0, 1e-3, 15.0, 45.0, 75.0, 89.0, 89.9, 90.0)
EXTREME_PHIS_DEG = (0.0, 37.0, 90.0, 180.0, 271.0)


def extreme_pairs() -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo) pairs over the closed upper hemisphere that break naive formulas: every pair of
    the extreme directions (so wi == wo too), mirror pairs, and opposite grazing pairs whose half
    vector is undefined."""
    th, ph = np.meshgrid(np.deg2rad(EXTREME_THETAS_DEG), np.deg2rad(EXTREME_PHIS_DEG), indexing="ij")
    d = spherical_to_cartesian(th.ravel(), ph.ravel())
    d[np.abs(d) < 1e-15] = 0.0  # exact zeros: the horizon is z == 0, the pole x == y == 0
    n = len(d)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    mirror = d * np.array([-1.0, -1.0, 1.0])
    opposite = (np.array([[1.0, 0, 0], [0, 1.0, 0]]), np.array([[-1.0, 0, 0], [0, -1.0, 0]]))
    wi = np.concatenate([d[i.ravel()], d, opposite[0]])
    wo = np.concatenate([d[j.ravel()], mirror, opposite[1]])
    return wi, wo


#: Where a parameter's bound is infinite, it is also stressed at this multiple of the finite end
#: of its ``Param.finite_range`` (e.g. a roughness of 1e3, an exponent of 1e7): far beyond any
#: plausible value, the values a free solver step can reach.
BEYOND_FACTOR = 1e3


def stress_parameter_sets(model: Model) -> list[dict[str, float]]:
    """Defaults, all-lower, all-upper, and each parameter alone at its lower and upper end.

    The ends are ``Param.finite_range``: the bounds, or the physical range on a side where the
    bound is infinite; such a parameter is also stressed at ``BEYOND_FACTOR`` times that end.
    """
    base = {p.name: p.default for p in model.params}
    lo = {p.name: p.finite_range[0] for p in model.params}
    hi = {p.name: p.finite_range[1] for p in model.params}
    sets = [dict(base), dict(lo), dict(hi)]
    for p in model.params:
        sets += [dict(base, **{p.name: lo[p.name]}), dict(base, **{p.name: hi[p.name]})]
        if p.upper == float("inf"):
            sets.append(dict(base, **{p.name: BEYOND_FACTOR * max(hi[p.name], 1.0)}))
    return sets


def model_problems(model: str | Model, dtype="float64", param_sets=None, pairs=None) -> list[str]:
    """Everything wrong with a model's values and gradients at stress parameters and directions.

    Checks, per parameter set: values finite and >= 0, in ``dtype`` (no promotion of float32);
    the Jacobian with respect to the parameters and the gradients with respect to wi and wo
    finite; and the structure the solver relies on (``brdffit.fitting.objective``): channel c of
    f_r depends on channel c of a 3-channel parameter only, and f_r is affine in the parameters
    declared ``linear``. One jit compilation: the parameter sets are vmapped. Returns [] when all
    is well.
    """
    model = get(model) if isinstance(model, str) else model
    dtype = jnp.dtype(dtype)
    wi_np, wo_np = pairs if pairs is not None else extreme_pairs()
    wi, wo = jnp.asarray(wi_np, dtype), jnp.asarray(wo_np, dtype)
    sets = param_sets if param_sets is not None else stress_parameter_sets(model)
    flat = jnp.asarray(np.stack([np.asarray(model.flatten(s)) for s in sets]), dtype)

    f = model.flat.f_r  # (x, wi, wo) -> (N, C): the formula as a fit evaluates it

    def checks(x):
        val = f(x, wi, wo)
        jac = jax.jacfwd(f)(x, wi, wo)  # (N, C, P): per sample, per parameter
        gi, go = jax.grad(lambda a, b: jnp.sum(f(x, a, b)), argnums=(0, 1))(wi, wo)
        return val, jac, gi, go

    val, jac, gi, go = jax.jit(jax.vmap(checks))(flat)
    problems = []
    if val.dtype != dtype or jac.dtype != dtype:
        problems.append(f"{model.name}: evaluated in {val.dtype}, not {dtype} (the formula promotes)")
    for k, s in enumerate(sets):
        label = " ".join(f"{name}={value:g}" for name, value in s.items())
        v = np.asarray(val[k])
        bad = (~np.isfinite(v) | (v < 0)).any(axis=1)
        if bad.any():
            problems.append(f"{model.name} [{label}]: non-finite or negative value at wi={wi_np[bad][0]}, wo={wo_np[bad][0]}")
        for what, g in (("d/dparams", jac[k]), ("d/dwi", gi[k]), ("d/dwo", go[k])):
            badg = ~np.isfinite(np.asarray(g).reshape(len(wi_np), -1)).all(axis=1)
            if badg.any():
                problems.append(f"{model.name} [{label}] {what} not finite at wi={wi_np[badg][0]}, wo={wo_np[badg][0]}")
    problems += _structure_problems(model, np.asarray(flat[0], np.float64), wi_np, wo_np)
    return problems


def _structure_problems(model: Model, x: np.ndarray, wi, wo) -> list[str]:
    """Channel-by-channel dependence and linearity of the declared linear parameters, at x (float64)."""
    wi, wo = jnp.asarray(wi, jnp.float64), jnp.asarray(wo, jnp.float64)
    keep = (np.asarray(wi)[:, 2] > 1e-3) & (np.asarray(wo)[:, 2] > 1e-3)  # away from the horizon
    wi, wo = wi[keep], wo[keep]
    x = jnp.asarray(x)

    def f(v):
        return model.flat.f_r(v, wi, wo)

    jac = np.asarray(jax.jacfwd(f)(x))  # (N, C, P)
    out, i = [], 0
    lin = np.zeros(model.n_free, bool)
    for p in model.params:
        n = model.size(p)
        if n > 1:
            for c in range(n):
                other = np.delete(jac[:, :, i + c], c, axis=1)
                if np.any(other != 0):
                    out.append(f"{model.name}: channel {c} of {p.name} changes another channel of f_r "
                               "(formulas must work channel by channel)")
                    break
        lin[i : i + n] = p.linear
        i += n
    if lin.any():
        # Affine in the linear parameters: f(x) = f(x with them 0) + sum_j x_j df/dx_j.
        x0 = jnp.where(jnp.asarray(lin), 0.0, x)
        pred = np.asarray(f(x0)) + np.einsum("ncp,p->nc", jac[:, :, lin], np.asarray(x)[lin])
        val = np.asarray(f(x))
        if not (np.all(np.isfinite(val)) and np.all(np.isfinite(pred))):
            return out  # non-finite values are reported above
        if not np.allclose(pred, val, rtol=1e-9, atol=1e-12 * max(np.abs(val).max(), 1e-300)):
            out.append(f"{model.name}: f_r is not affine in the parameters declared linear "
                       f"({', '.join(p.name for p in model.params if p.linear)})")
    return out


def assert_model_well_behaved(model: str | Model, dtype="float64", **options) -> None:
    """Assert :func:`model_problems` finds nothing (at most 5 problems are listed)."""
    problems = model_problems(model, dtype, **options)
    if problems:
        more = f"\n... and {len(problems) - 5} more" if len(problems) > 5 else ""
        raise AssertionError("\n".join(problems[:5]) + more)


def assert_reciprocal(model: str | Model, params=None, rtol: float = 1e-9, pairs=None) -> None:
    """Assert f_r(wi, wo) == f_r(wo, wi) (Helmholtz reciprocity) on the given or extreme pairs."""
    model = get(model) if isinstance(model, str) else model
    params = model.defaults() if params is None else model.check_params(params)
    wi, wo = pairs if pairs is not None else extreme_pairs()
    a = np.asarray(model.eval(params, wi, wo))
    b = np.asarray(model.eval(params, wo, wi))
    err = np.abs(a - b) / np.maximum(np.maximum(np.abs(a), np.abs(b)), 1e-300)
    k = int(np.argmax(err.max(axis=1)))
    if err[k].max() > rtol:
        raise AssertionError(f"{model.name}: not reciprocal at wi={wi[k]}, wo={wo[k]}: {a[k]} vs {b[k]} (rel. {err[k].max():.3g})")


def assert_fit_quality(result, *, max_log_rmse: float | None = None, max_rmse: float | None = None,
                       max_relative: float | None = None, require_converged: bool = True) -> None:
    """Assert a FitResult converged (unless told otherwise) and its metrics are within the limits."""
    failures = []
    if require_converged and not result.converged:
        failures.append(f"did not converge: {result.status}")
    metrics = result.metrics
    for key, limit in (("log_rmse", max_log_rmse), ("rmse", max_rmse), ("relative", max_relative)):
        if limit is None:
            continue
        value = metrics.get(key, metrics.get(f"{key}_rmse")) if key == "relative" else metrics.get(key)
        if value is None:
            failures.append(f"metric {key!r} missing (have {sorted(metrics)})")
        elif not value <= limit:
            failures.append(f"{key} {value:.4g} > {limit:.4g}")
    if failures:
        raise AssertionError(f"fit of {result.model_name} to {result.data_name}: " + "; ".join(failures))
