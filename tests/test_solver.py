"""The fitting core's solver (docs/fitting.md#fitting): the default ``lm`` is an optimistix solver class, bounds and
held parameters are runtime arrays (infinite bounds included), tolerances are relative to the
data's scale, CLI and API share one set of defaults, statuses. Small synthetic problems, except
one composite fit on the bundled sample measurement."""

from __future__ import annotations

import json

import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import brdffit
from brdffit import models
from brdffit.fitting import fit, init
from brdffit.fitting.problem import prepare, resolve_model
from brdffit.fitting.solve import make_solver
from brdffit.fitting.solver_lm import BoundedLevenbergMarquardt
from brdffit.fitting.solver_optx import from_box, to_box
from brdffit.grid import spherical_to_cartesian
from conftest import REPO

TRUTH = {"kd": [0.3, 0.2, 0.1], "ks": [1.5, 1.2, 0.9], "alpha": [0.25], "f0": [0.3]}
#: ggx flat order: kd(3) ks(3) alpha f0
KS = slice(3, 6)


def _measurement(params=TRUTH, n=500, seed=0, scale=1.0, noise=0.01):
    rng = np.random.default_rng(seed)
    wi = spherical_to_cartesian(rng.uniform(0, 1.3, n), rng.uniform(0, 2 * np.pi, n))
    wo = spherical_to_cartesian(rng.uniform(0, 1.3, n), rng.uniform(0, 2 * np.pi, n))
    m = models.get("ggx")
    f = np.asarray(m.eval(m.check_params(params), wi, wo))
    f = f * (1 + noise * np.random.default_rng(seed + 1).standard_normal(f.shape))
    return brdffit.Measurement(wi, wo, f * scale, name="synthetic")


def _solve(meas, lo, hi, free, start, solver="lm", loss="log"):
    """The fit driver from ``start`` alone in the box lo, hi with ``free`` (held entries at ``start``)."""
    import dataclasses

    from brdffit.fitting.driver import solve
    from brdffit.fitting.options import FitOptions
    from brdffit.fitting.problem import stack_data

    prep = prepare(meas)
    options = FitOptions(loss=loss, solver=solver, rtol=1e-9, max_steps=200)
    start = np.asarray(start, float)
    free = np.asarray(free, bool)
    space = dataclasses.replace(options.space(resolve_model("ggx", 3)), lo=np.asarray(lo, float),
                                hi=np.asarray(hi, float), free=free, values=np.where(free, np.nan, start))
    out = solve(space, options, stack_data([prep.data]), k=1, starts=start[None], grid=False)
    return out.v[0], float(out.loss[0]), int(out.code[0]), int(out.steps[0])


START = np.asarray([0.2, 0.2, 0.2, 0.5, 0.5, 0.5, 0.3, 0.05])
LO = np.asarray([0, 0, 0, 0, 0, 0, 1e-4, 0.0])
HI_INF = np.asarray([1, 1, 1, np.inf, np.inf, np.inf, 1.0, 1.0])


def test_default_solver_is_an_optimistix_least_squares_solver():
    s = make_solver("lm", 1e-7, 0.0)
    assert isinstance(s, BoundedLevenbergMarquardt)
    assert isinstance(s, optx.AbstractLeastSquaresSolver)
    # ... and runs under optx.least_squares with bounds as runtime options: on the plain problem
    # min (y - 3)^2 + (y2 + 1)^2 with y in [0, 2], y2 in [0, inf), the optimum is the corner (2, 0).
    sol = optx.least_squares(lambda y, _: y - jnp.asarray([3.0, -1.0]), s, jnp.asarray([1.0, 1.0]),
                             options={"lower": jnp.asarray([0.0, 0.0]), "upper": jnp.asarray([2.0, jnp.inf]),
                                      "free": jnp.asarray([True, True])}, throw=False)
    assert sol.result == optx.RESULTS.successful
    np.testing.assert_allclose(sol.value, [2.0, 0.0], atol=1e-12)


def test_max_steps_reached_is_not_converged():
    s = make_solver("lm", 1e-12, 0.0)
    sol = optx.least_squares(lambda y, _: jnp.exp(y) - jnp.asarray([3.0, 0.5]), s, jnp.asarray([5.0, 5.0]),
                             options={"lower": jnp.full(2, -jnp.inf), "upper": jnp.full(2, jnp.inf),
                                      "free": jnp.ones(2, bool)}, max_steps=2, throw=False)
    assert sol.result == optx.RESULTS.nonlinear_max_steps_reached
    r = fit(_measurement(), "ggx", init="defaults", max_steps=2)
    assert not r.converged and "maximum number of steps" in r.status


def test_infinite_upper_bound_lets_ks_exceed_one():
    v, _, code, _ = _solve(_measurement(noise=0), LO, HI_INF, np.ones(8, bool), START)
    assert code == 0
    np.testing.assert_allclose(v[KS], TRUTH["ks"], rtol=1e-6)
    # The same data with ks <= 1: the bound holds, ks ends on it in the brightest channel, and
    # the loss is higher than without the bound.
    hi = HI_INF.copy()
    hi[KS] = 1.0
    v1, value1, code1, _ = _solve(_measurement(noise=0), LO, hi, np.ones(8, bool), START)
    assert code1 == 0
    assert np.all(v1[KS] <= 1.0) and v1[3] == 1.0
    assert value1 > 1e3 * _solve(_measurement(noise=0), LO, HI_INF, np.ones(8, bool), START)[1]


@pytest.mark.parametrize("solver", ["optx_lm", "dogleg"])
def test_stock_solvers_see_infinite_bounds_through_the_transform(solver):
    v, _, code, _ = _solve(_measurement(noise=0), LO, HI_INF, np.ones(8, bool), START, solver=solver)
    np.testing.assert_allclose(v[KS], TRUTH["ks"], rtol=1e-4)
    assert np.all(v >= LO)


def test_held_parameters_and_a_lower_bound_above_the_truth():
    free = np.ones(8, bool)
    free[7] = False  # f0 held at its start value 0.05
    lo = LO.copy()
    lo[6] = 0.3  # alpha >= 0.3 (truth 0.25): the fit ends on that bound
    v, _, code, _ = _solve(_measurement(), lo, HI_INF, free, START)
    assert code == 0
    assert v[7] == 0.05
    assert v[6] == 0.3


def test_box_transform_known_values():
    lo = jnp.asarray([0.0, 0.0, -jnp.inf, -jnp.inf, 1e-2])
    hi = jnp.asarray([1.0, jnp.inf, 2.0, jnp.inf, 1.0])
    x = jnp.asarray([1.25, -0.5, 3.0, -7.0, jnp.log(1e-2) - 0.5])
    # fold at 1 -> 0.75; reflection at 0 -> 0.5; reflection at 2 -> 1.0; identity; fold at log(1e-2)
    np.testing.assert_allclose(to_box(x, lo, hi), [0.75, 0.5, 1.0, -7.0, 1e-2 * np.exp(0.5)], rtol=1e-12)
    v = jnp.asarray([0.3, 4.0, -3.0, 5.0, 0.1])
    np.testing.assert_allclose(to_box(from_box(v, lo, hi), lo, hi), v, rtol=1e-12)


@pytest.mark.parametrize("scale", [1e-12, 1e12])
@pytest.mark.parametrize("loss", ["l2", "relative", "cbrt"])
def test_a_scaled_table_fits_to_the_same_relative_error(loss, scale):
    """Every stopping test is relative (README): a table times 1e-12 or 1e12 gives the same fit."""
    # Parameters inside ggx's bounds (an active bound, ks <= 1, is not scale-free by nature).
    inside = {**TRUTH, "ks": [0.6, 0.5, 0.4]}
    a = fit(_measurement(inside), "ggx", loss=loss)
    b = fit(_measurement(inside, scale=scale), "ggx", loss=loss)
    assert a.converged and b.converged, (a.status, b.status)
    np.testing.assert_allclose(b.metrics["rel_rmse"], a.metrics["rel_rmse"], rtol=1e-5)
    np.testing.assert_allclose(b.params["alpha"], a.params["alpha"], rtol=1e-5)
    np.testing.assert_allclose(b.params["kd"], scale * a.params["kd"], rtol=1e-5)


def test_log_loss_on_a_tiny_table_converges():
    b = fit(_measurement(scale=1e-12), "ggx")
    assert b.converged, b.status
    assert b.metrics["rel_rmse"] < 0.05


def test_grid_separates_lobes_of_one_kind():
    m = models.get("lambert+ggx+ggx")
    lo, hi = m.bounds()
    anchor = np.asarray(m.flatten(m.defaults()))
    g = init.grid_for(m, lo, hi, np.ones(m.n_free, bool), anchor)
    names = [p.name for p in m.params if not p.linear]
    a1, a2 = g[:, names.index("ggx1.alpha")], g[:, names.index("ggx2.alpha")]
    assert len(g) > 1 and np.all(a1 < a2)


def test_grid_uses_a_declared_range_where_a_bound_is_infinite():
    m = models.get("ggx")
    lo, hi = m.bounds()
    hi = hi.copy()
    hi[6] = np.inf  # alpha unbounded above: the grid stays in [alpha's lower bound, 1]
    g = init.grid_for(m, lo, hi, np.ones(m.n_free, bool), np.asarray(m.flatten(m.defaults())))
    assert np.all(np.isfinite(g)) and g[:, 0].max() <= 1.0 and g[:, 0].min() >= lo[6]


def test_cli_and_api_reach_the_same_loss_on_a_composite(tmp_path):
    from brdffit.cli import main

    source = REPO / "data" / "sample_ubo81.exr"
    api = fit(brdffit.load(source), "lambert+ggx+ggx")
    assert main(["fit", str(source), "--model", "lambert+ggx+ggx", "-o", str(tmp_path / "o")]) == 0
    saved = json.loads((tmp_path / "o" / "fit.json").read_text())
    assert saved["converged"] and api.converged
    np.testing.assert_allclose(saved["loss_value"], api.loss_value, rtol=1e-9)
    # The composite beats the single lobe on this paint.
    assert api.loss_value < fit(brdffit.load(source), "ggx").loss_value


def test_batch_equals_single_fits():
    ms = [_measurement({**TRUTH, "alpha": [a]}, n=300, seed=i) for i, a in enumerate((0.08, 0.3))]
    rs = brdffit.fit_batch(ms, "ggx")
    for r, m in zip(rs, ms):
        single = fit(m, "ggx")
        assert r.converged == single.converged
        np.testing.assert_allclose(r.loss_value, single.loss_value, rtol=1e-9)
        for k in single.params:
            np.testing.assert_allclose(r.params[k], single.params[k], rtol=1e-7, atol=1e-12)



def test_cli_defaults_are_the_apis():
    import inspect

    from brdffit.cli import _load_commands, cli

    _load_commands()
    options = {p.name: p.default for p in cli.commands["fit"].params}
    api = inspect.signature(fit).parameters
    for name in ("loss", "solver", "multistart", "max_steps"):
        assert options[name] == api[name].default, name


def test_progress_reports_the_phases():
    seen = []
    fit(_measurement(n=200), "ggx", progress=seen.append)
    text = " | ".join(seen)
    assert "initialising" in text and "solving" in text and "solved" in text


@pytest.mark.parametrize("name", ["ggx", "cook_torrance", "ward"])
def test_default_tolerance_stops_within_it_of_the_minimum(name):
    # The solver stops when the next step would bring less than rtol x the loss (MINPACK's test, or
    # the Gauss-Newton decrement at the new point): its loss is then within ~rtol of the minimum a
    # much tighter solve reaches from the same start. Noisy data (5 %), so that the loss is not ~0.
    from brdffit._fit_defaults import DEFAULT_RTOL

    m = _measurement(noise=0.05, seed=4)
    default = fit(m, name)
    tight = fit(m, name, init=default.start, rtol=1e-13, max_steps=500)
    assert default.converged, default.status
    assert tight.loss_value <= default.loss_value * (1 + 1e-12)
    assert default.loss_value <= tight.loss_value * (1 + 3 * DEFAULT_RTOL), (default.loss_value / tight.loss_value - 1)


def test_lm_takes_no_step_the_gauss_newton_decrement_says_is_not_needed():
    """README: lm stops when a step, or the Gauss-Newton decrement at the new point (g' (J'J)^-1 g,
    the decrease a full step would bring), would bring less than rtol x the loss. So where it
    stopped that decrement, computed here with NumPy, is below rtol x the loss, and one step
    earlier it was not (else that last step was not needed). A plain problem: a decaying
    exponential plus a constant, fitted to 60 noisy points."""
    import jax

    rtol = 1e-6
    t = np.linspace(0.0, 4.0, 60)
    y = 0.8 * np.exp(-1.3 * t) + 0.2 + 0.01 * np.random.default_rng(0).standard_normal(t.size)

    def residual(p, _):
        return (p[0] * jnp.exp(-p[1] * t) + p[2] - y) / np.sqrt(t.size)

    def solve(max_steps):
        return optx.least_squares(residual, make_solver("lm", rtol, 0.0), jnp.asarray([2.0, 0.3, 0.0]),
                                  options={"lower": jnp.full(3, -jnp.inf), "upper": jnp.full(3, jnp.inf),
                                           "free": jnp.ones(3, bool)}, max_steps=max_steps, throw=False)

    def decrement_and_loss(p):
        r = np.asarray(residual(p, None))
        J = np.asarray(jax.jacfwd(residual)(p, None))
        g = J.T @ r
        return g @ np.linalg.solve(J.T @ J, g), r @ r

    full = solve(200)
    assert full.result == optx.RESULTS.successful
    decrement, loss = decrement_and_loss(full.value)
    assert decrement <= rtol * loss
    decrement, loss = decrement_and_loss(solve(int(full.stats["num_steps"]) - 1).value)
    assert decrement > rtol * loss
