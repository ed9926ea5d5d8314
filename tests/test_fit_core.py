"""Fitting engine: losses, exclusion counting, JSON round trip, statuses, negative data, compare,
select, batch. Small problems (a few hundred samples) so that the file runs in well under a minute."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import brdffit
from brdffit import models
from brdffit.errors import UsageError
from brdffit.fitting import LOSSES, FitResult, compare, fit, fit_batch, select
from brdffit.fitting import losses as L
from brdffit.fitting.measurements import standard_errors
from brdffit.fitting.problem import resolve_model
from brdffit.grid import spherical_to_cartesian

TRUE = {"kd": [0.3, 0.2, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": [0.25], "f0": [0.3]}


def _directions(n=400, seed=0):
    rng = np.random.default_rng(seed)
    ti, to = rng.uniform(0, 1.3, n), rng.uniform(0, 1.3, n)
    pi, po = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 2 * np.pi, n)
    return spherical_to_cartesian(ti, pi), spherical_to_cartesian(to, po)


def _measurement(params=TRUE, model="ggx", n=400, noise=0.0, seed=0, **kw):
    wi, wo = _directions(n, seed)
    m = models.get(model)
    f = np.asarray(m.eval(m.check_params(params), wi, wo))
    if noise:
        f = f * (1 + noise * np.random.default_rng(seed + 1).standard_normal(f.shape))
    return brdffit.Measurement(wi, wo, f, name=f"synthetic-{model}", **kw)


@pytest.fixture(scope="module")
def ggx_fit():
    return fit(_measurement(), "ggx")


def test_exact_data_recovers_parameters(ggx_fit):
    assert ggx_fit.converged, ggx_fit.status
    for k, v in TRUE.items():
        np.testing.assert_allclose(ggx_fit.params[k], v, rtol=1e-4)
    assert ggx_fit.loss_value < 1e-12
    assert ggx_fit.metrics["rmse"] < 1e-5


def test_result_fields(ggx_fit):
    r = ggx_fit
    assert r.model_name == "ggx" and r.solver == "lm" and r.loss == "log"
    assert set(r.params) == {"kd", "ks", "alpha", "f0"}
    assert {"rmse", "log_rmse", "rel_rmse"} <= set(r.metrics)
    assert r.seconds["compile"] >= 0 and r.seconds["run"] > 0
    assert r.n_used == 400 and r.n_excluded == 0
    assert r.steps >= 1
    assert r.data_name == "synthetic-ggx"


def test_json_round_trip_is_exact(ggx_fit, tmp_path):
    text = ggx_fit.to_json()
    d = json.loads(text)
    assert d["model"] == "ggx" and d["channels"] == 3 and set(d["params"]) == {"kd", "ks", "alpha", "f0"}
    back = FitResult.from_json(text)
    for k in ggx_fit.params:
        assert np.array_equal(back.params[k], ggx_fit.params[k])
    assert back.loss_value == ggx_fit.loss_value and back.metrics == ggx_fit.metrics
    assert back.converged == ggx_fit.converged and back.status == ggx_fit.status
    path = tmp_path / "fit.json"
    ggx_fit.to_json(path)
    back2 = FitResult.from_json(path)
    assert back2.to_json() == text
    wi, wo = _directions(20, seed=5)
    np.testing.assert_array_equal(back2.eval(wi, wo), ggx_fit.eval(wi, wo))


def test_from_json_bad_input(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(brdffit.InputError, match="bad.json"):
        FitResult.from_json(bad)
    bad.write_text(json.dumps({"model": "ggx", "params": {"kd": [1, 2]}}))
    with pytest.raises(brdffit.InputError):
        FitResult.from_json(bad)


def test_standard_errors_shrink_with_less_noise():
    a = fit(_measurement(noise=0.02), "ggx")
    b = fit(_measurement(noise=0.002), "ggx")
    assert a.stderr["alpha"] is not None and b.stderr["alpha"] is not None
    assert b.stderr["alpha"][0] < a.stderr["alpha"][0] / 3
    # The truth lies within a few standard errors.
    assert abs(a.params["alpha"][0] - 0.25) < 5 * a.stderr["alpha"][0]


@pytest.mark.parametrize("loss, solver", [("l2", "lm"), ("cosine_l2", "lm"), ("l2", "scipy")])
def test_standard_errors_equal_scipy_curve_fit(loss, solver):
    """A known value: Lambert (f = kd / pi) on one noisy channel is a linear least-squares problem
    (weighted by cos theta_i for cosine_l2), whose estimate and covariance scipy's curve_fit gives
    independently: s^2 (J'J)^-1 with s^2 = sum r^2 / (n - p)."""
    from scipy.optimize import curve_fit

    rng = np.random.default_rng(11)
    n = 200
    wi = np.asarray(spherical_to_cartesian(rng.uniform(0.0, 1.2, n), rng.uniform(0.0, 2 * np.pi, n)))
    wo = np.asarray(spherical_to_cartesian(rng.uniform(0.0, 1.2, n), rng.uniform(0.0, 2 * np.pi, n)))
    y = 0.5 / np.pi + 0.02 * rng.normal(size=n)
    r = fit(brdffit.Measurement(wi=wi, wo=wo, values=y[:, None]), "lambert", loss=loss, solver=solver)
    sigma = 1.0 / wi[:, 2] if loss == "cosine_l2" else None
    popt, pcov = curve_fit(lambda x, kd: kd / np.pi * np.ones_like(x), np.zeros(n), y, p0=[0.4], sigma=sigma)
    assert r.converged and r.status == ("converged (scipy least_squares)" if solver == "scipy" else "converged")
    np.testing.assert_allclose(r.params["kd"], popt, rtol=1e-8)
    np.testing.assert_allclose(r.stderr["kd"], np.sqrt(np.diag(pcov)), rtol=1e-6)


def test_exclusions_are_counted_and_ignored():
    m = _measurement()
    values = np.array(m.values)
    weights = np.array(m.weights)
    wi = np.array(m.wi)
    values[:5] = np.nan
    values[5:8] = 1e6  # junk, but weight 0
    weights[5:8] = 0
    wi[8:10] = [0.6, 0.0, -0.8]  # below the horizon
    r = fit(m.replace(values=values, weights=weights, wi=wi), "ggx")
    assert r.n_used == 390 and r.n_excluded == 10
    assert r.excluded == {"weight 0": 3, "non-finite value": 5, "light below horizon": 2}
    assert all(np.all(np.isfinite(v)) for v in r.params.values())
    np.testing.assert_allclose(r.params["alpha"], 0.25, rtol=1e-4)


@pytest.mark.parametrize("loss", LOSSES)
def test_every_loss_fits_noisy_negative_data(loss):
    # Small additive noise makes some low values negative (as the golden yellow RGL file).
    m = _measurement({**TRUE, "kd": [0.3, 0.2, 0.01]})
    v = np.array(m.values) + 0.01 * np.random.default_rng(3).standard_normal(m.values.shape)
    assert (v < 0).any()
    r = fit(m.replace(values=v), "ggx", loss=loss)
    assert r.converged, r.status
    assert all(np.all(np.isfinite(x)) for x in r.params.values())
    assert np.isfinite(r.loss_value)
    if loss != "relative":
        # (The relative loss divides by |f_ref| + 1 % of its mean: additive noise on near-zero
        # samples then dominates it by design, so its optimum moves; it only has to stay finite.)
        np.testing.assert_allclose(r.params["alpha"], 0.25, rtol=0.1)


def test_loss_definitions():
    f = jnp.asarray([[0.5], [2.0]])
    ref = jnp.asarray([[0.25], [-0.1]])
    cos = jnp.asarray([[0.5], [1.0]])
    one = jnp.ones((2, 1))
    floor = jnp.asarray([0.01])
    np.testing.assert_allclose(L.residual("l2", f, ref, cos, one, floor), f - ref)
    np.testing.assert_allclose(L.residual("cosine_l2", f, ref, cos, one, floor), (f - ref) * cos)
    np.testing.assert_allclose(L.residual("log", f, ref, cos, one, floor), np.log1p(f * cos) - np.log1p(ref * cos))
    np.testing.assert_allclose(L.residual("relative", f, ref, cos, one, floor), (f - ref) / (np.abs(ref) + 0.01))
    c = np.asarray(L.residual("cbrt", f, ref, cos, one, floor))
    np.testing.assert_allclose(c, np.cbrt(f * cos) - np.cbrt(ref * cos), atol=2e-3)
    # The sign-preserving cube root is odd and has a finite slope at 0.
    g = jax.grad(lambda x: L._cbrt(x, 1e-6))(0.0)
    assert np.isfinite(g) and g > 0
    with pytest.raises(UsageError):
        L.check_loss("nope")


@pytest.mark.parametrize("solver", ["lm", "optx_lm", "bfgs"])
def test_tiny_max_steps_is_a_status_not_an_error(solver):
    r = fit(_measurement(noise=0.01), "ggx", init="defaults", max_steps=1, solver=solver)
    assert not r.converged
    assert "maximum number of steps" in r.status
    assert all(np.all(np.isfinite(v)) for v in r.params.values())
    assert r.to_dict()["converged"] is False


@pytest.mark.parametrize("solver", ["optx_lm", "gauss_newton", "dogleg", "bfgs", "scipy"])
def test_solvers_agree(ggx_fit, solver):
    m = _measurement(noise=0.01)
    ref = fit(m, "ggx")
    r = fit(m, "ggx", solver=solver)
    assert r.solver == solver
    assert r.loss_value <= ref.loss_value * (1 + 1e-3)
    np.testing.assert_allclose(r.params["alpha"], ref.params["alpha"], rtol=1e-3)


@pytest.mark.parametrize("solver", ["lm", "scipy"])
def test_optimum_on_a_bound_converges(solver):
    # (optimistix's stock solvers see the box through a fold transform, whose kink at the bound
    # they zig-zag across: bounds inside every iteration are the default lm's job.)
    # ks = 1 and kd = 0 in one channel: the optimum lies on the bounds.
    truth = {"kd": [0.0, 0.2, 0.1], "ks": [1.0, 0.5, 0.4], "alpha": [0.3], "f0": [0.2]}
    r = fit(_measurement(truth), "ggx", init={"kd": 0.2, "ks": 0.5, "alpha": 0.3, "f0": 0.05}, solver=solver)
    assert r.converged, r.status
    np.testing.assert_allclose(r.params["ks"], truth["ks"], rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(r.params["kd"], truth["kd"], atol=1e-6)
    if r.params["ks"][0] == 1.0:
        assert r.stderr["ks"] is None  # at a bound: no Gaussian standard error


def test_init_options_and_bad_arguments():
    m = _measurement()
    r = fit(m, "ggx", init=TRUE)
    assert r.converged and r.steps <= 5
    r2 = fit(m, "ggx", multistart=2)
    np.testing.assert_allclose(r2.params["alpha"], 0.25, rtol=1e-4)
    for kwargs in ({"loss": "bad"}, {"solver": "bad"}, {"init": "bad"}, {"max_steps": 0}):
        with pytest.raises(UsageError):
            fit(m, "ggx", **kwargs)
    with pytest.raises(UsageError, match=r"^multistart must be >= 0$"):
        fit(m, "ggx", multistart=-1)
    with pytest.raises(UsageError):
        fit(m, "no_such_model")


def test_monochrome_data_fits_a_one_channel_model():
    m = _measurement()
    mono = m.replace(values=np.asarray(m.values)[:, :1])
    r = fit(mono, "ggx")
    assert r.channels == 1 and r.params["kd"].shape == (1,)
    np.testing.assert_allclose(r.params["kd"], [0.3], rtol=1e-4)


def test_compare_report_and_select(tmp_path):
    m = _measurement(noise=0.01)
    rep = compare(m, ["lambert", "ggx"], ["lm", "scipy"], ["log", "l2"])
    assert len(rep.rows) == 8
    for row in rep.rows:
        assert all(f"loss_{k}" in row for k in LOSSES)
    # one row per (model, loss, solver), each fit run with its row's loss
    assert [(r["model"], r["loss"], r["solver"]) for r in rep.rows] == [
        (name, x, s) for name in ("lambert", "ggx") for x in ("log", "l2") for s in ("lm", "scipy")]
    assert [r.loss for r in rep.results] == [r["loss"] for r in rep.rows]
    from brdffit.fitting.compare import COLUMNS
    for row, r in zip(rep.rows, rep.results):
        assert set(row) == set(COLUMNS), set(row) ^ set(COLUMNS)
        assert (row["compile_s"], row["run_s"], row["steps"]) == (r.seconds["compile"], r.seconds["run"], r.steps)
        for key in ("rmse", "log_rmse", "rel_rmse"):
            assert row[key] == pytest.approx(r.metrics[key], rel=1e-9), key
    for s in ("lm", "scipy"):
        by_loss = {r["loss"]: r for r in rep.rows if r["model"] == "ggx" and r["solver"] == s}
        assert by_loss["l2"]["loss_l2"] <= by_loss["log"]["loss_l2"] * (1 + 1e-9)
        assert by_loss["log"]["loss_log"] <= by_loss["l2"]["loss_log"] * (1 + 1e-9)
    best = rep.best("loss_log")
    assert best["model"] == "ggx" and rep.best() == best  # the log loss by default
    assert rep.best("loss_l2")["loss"] == "l2"
    csv_text = rep.to_csv(tmp_path / "r.csv")
    assert csv_text.count("\n") == 9 and csv_text.startswith("model,solver,loss")
    assert len(json.loads(rep.to_json())["rows"]) == 8
    rep.plot().savefig(tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 10_000
    sel = select(m, rep)
    assert sel.model_name == "ggx" and "parameters" in sel.reason
    # With a huge tolerance the simpler model wins, and the reason says why.
    sel2 = select(m, rep, tolerance=1e6)
    assert sel2.model_name == "lambert" and "fewest" in sel2.reason
    assert select(m, rep, criterion="bic").model_name == "ggx"


def test_fit_batch_matches_single_fits():
    ms = [_measurement({**TRUE, "alpha": [a]}, noise=0.005, seed=i) for i, a in enumerate((0.1, 0.25, 0.5))]
    rs = fit_batch(ms, "ggx", chunk=2)
    assert [r.data_name for r in rs] == [m.name for m in ms]
    for r, m, a in zip(rs, ms, (0.1, 0.25, 0.5)):
        single = fit(m, "ggx")
        assert r.converged, r.status
        np.testing.assert_allclose(r.params["alpha"], single.params["alpha"], rtol=1e-3)
        np.testing.assert_allclose(r.params["alpha"], a, rtol=0.02)


def test_a_fit_does_not_depend_on_the_size_of_the_program_it_ran_in():
    """On a CPU the lanes run one at a time, in compiled programs of a few sizes (docs/fitting.md#lanes): a
    fit's numbers must not depend on which size it ran in, so that a BTF's maps do not depend on how its
    tiles were grouped. ``chunk=1``: every fit in a program of one lane; ``chunk=4``: in programs of four (the
    lanes split over the cores, ``Plan.sizes``: on two cores two of them in one of four, the third in one of one)."""
    ms = [_measurement({**TRUE, "alpha": [a]}, noise=0.01, seed=3) for a in (0.12, 0.3, 0.45)]
    one, four = fit_batch(ms, "ggx", chunk=1), fit_batch(ms, "ggx", chunk=4)
    for a, b in zip(one, four):
        assert a.converged and b.converged and a.steps == b.steps
        assert a.loss_value == b.loss_value
        for k in a.params:
            np.testing.assert_array_equal(a.params[k], b.params[k], err_msg=k)


def test_a_cpu_splits_its_lanes_evenly_over_its_cores_in_few_program_sizes():
    """Lanes one at a time (a CPU): n lanes split into a multiple of the workers' count of calls of nearly
    equal counts, each in the next compiled size (1, 4, 16, 64); vectorised lanes (an accelerator's): full
    chunks, then the rest padded (docs/fitting.md#lanes)."""
    from brdffit.fitting.lanes import Plan

    cpu = Plan(chunk=64, lanes=1, workers=2, devices=(None,))
    assert cpu.sizes(64) == [(32, 64), (32, 64)]  # not one call of 64 beside an idle core
    assert cpu.sizes(192) == [(48, 64)] * 4
    assert cpu.sizes(10) == [(5, 16), (5, 16)]
    assert cpu.sizes(1) == [(1, 1)]
    assert cpu.sizes(0) == []
    counts = [c for c, _ in cpu.sizes(1000)]
    assert sum(counts) == 1000 and len(counts) % 2 == 0 and max(counts) - min(counts) <= 1 and max(counts) <= 64
    assert Plan(chunk=64, lanes=1, workers=1, devices=(None,)).sizes(130) == [(44, 64), (43, 64), (43, 64)]
    device = Plan(chunk=256, lanes=256, workers=1, devices=(None,), step=256)
    assert device.sizes(600) == [(256, 256), (256, 256), (88, 256)]


def test_a_cpu_call_computes_its_own_lanes_and_not_its_padding():
    """``lanes.map_lanes`` runs the first ``count`` lanes of a call (a run-time scalar): the lanes padding it
    to its compiled size are not computed (zeros come back for them), and one program serves every count."""
    from brdffit.fitting.lanes import map_lanes
    from brdffit.fitting.problem import Data

    x = jnp.arange(1.0, 5.0)
    data = Data(*(jnp.zeros((2, 3)),) * 2, jnp.ones((4, 5, 3)), *(jnp.zeros((5, 1)),) * 2, jnp.zeros((4, 3)))
    run = jax.jit(lambda x, data, count: map_lanes(lambda xi, d: xi * 10 + d.ref.sum(), x, data, 1, count))
    np.testing.assert_array_equal(run(x, data, np.int32(2)), [25.0, 35.0, 0.0, 0.0])
    np.testing.assert_array_equal(run(x, data, np.int32(4)), [25.0, 35.0, 45.0, 55.0])


def test_scipy_fit_seconds_add_the_grid_and_every_start(monkeypatch):
    """seconds: compile and run of the grid start and of the finish plus those of each scipy solve (time
    shifted by known amounts here, so that the sums cannot hold by chance of zero compile times)."""
    from brdffit.fitting import solver_scipy, stages

    seen = {"start": [], "finish": [], "solve": []}
    real_stage, real_solve = stages.run_stage, solver_scipy.solve_scipy

    def run_stage(key, *a, **kw):
        out, c_s, r_s = real_stage(key, *a, **kw)
        assert key[0] in ("start", "finish")  # scipy's compiled stages: the grid of starts, the finish
        seen[key[0]].append((c_s + 1.0, r_s + 2.0))
        return out, c_s + 1.0, r_s + 2.0

    def solve_scipy(*a, **kw):
        *out, c_s, r_s = real_solve(*a, **kw)
        seen["solve"].append((c_s + 10.0, r_s + 100.0))
        return (*out, c_s + 10.0, r_s + 100.0)

    monkeypatch.setattr(stages, "run_stage", run_stage)
    monkeypatch.setattr(solver_scipy, "solve_scipy", solve_scipy)
    r = fit(_measurement(n=200), "ggx", solver="scipy", multistart=2)
    assert len(seen["start"]) == 1 and len(seen["solve"]) == 3 and len(seen["finish"]) >= 1
    (c_init, r_init), = seen["start"]
    stages = seen["start"] + seen["finish"]
    assert r.seconds["init"] == pytest.approx(c_init + r_init)
    assert r.seconds["compile"] == pytest.approx(sum(c for c, _ in stages + seen["solve"]))
    assert r.seconds["run"] == pytest.approx(sum(t for _, t in stages + seen["solve"]))


def test_lm_fits_take_the_structured_normal_equations(monkeypatch):
    """The bounded LM of a fit gets its model's structured J^T J (brdffit.fitting.objective), never
    the generic forward-mode Jacobian of every entry (equal numbers, several times the cost:
    PERFORMANCE-NOTES). An rtol of its own makes the fit program new, and the disk cache is off
    for it, so it is traced here."""
    from brdffit.fitting import cache, solver_lm

    monkeypatch.setitem(cache._STATE, "dir", None)

    def generic(*args):
        raise AssertionError("the generic forward-mode normal equations were traced")

    monkeypatch.setattr(solver_lm, "_normal_equations", generic)
    r = fit(_measurement(n=200), "ggx", rtol=1.2345e-7)
    assert r.converged, r.status


def test_a_fits_compile_and_run_seconds_lie_within_its_wall_time():
    import time

    t0 = time.perf_counter()
    r = fit(_measurement(n=200), "lambert", loss="l2")
    wall = time.perf_counter() - t0
    assert 0.0 < r.seconds["run"] and 0.0 <= r.seconds["compile"]
    assert r.seconds["compile"] + r.seconds["run"] <= wall, (r.seconds, wall)


def test_progress_hears_every_phase_and_compiling_only_when_it_compiles():
    notes = []
    m = _measurement(n=200)
    fit(m, "lambert", rtol=2.3456e-7, progress=notes.append)  # an rtol of its own: new programs
    phases = [n.split(":")[0] for n in notes]
    assert [p for i, p in enumerate(phases) if i == 0 or p != phases[i - 1]] == ["initialising", "solving", "compiling",
                                                                                  "solved"], notes
    assert any(n.startswith("compiling: round (") for n in notes), notes  # the solver's stage, its own rtol
    again = []
    fit(m, "lambert", rtol=2.3456e-7, progress=again.append)
    assert [n.split(":")[0] for n in again] == ["initialising", "solving", "solved"], again


def test_progress_hears_the_start_grid_compile_on_the_scipy_path():
    notes = []
    fit(_measurement(n=137), "lambert", loss="l2", solver="scipy", progress=notes.append)  # shapes of its own
    assert [n.split(":")[0] for n in notes] == ["initialising", "solving", "compiling", "compiling", "solved"], notes
    assert notes[2].startswith("compiling: start (") and notes[3].startswith("compiling: finish (")


def test_an_unknown_solver_name_is_named_by_make_solver():
    from brdffit.fitting.solve import make_solver

    with pytest.raises(ValueError, match="^newton$"):
        make_solver("newton", 1e-8, 0.0)


def test_result_check_codes():
    """The check of the solver's point: 0 when finite and no worse than the start; 2 when worse;
    3 when the loss or the point is not finite (a NaN loss also fails "no worse", and must not be
    reported as a divergence); a failure code the solver gave is kept."""
    from brdffit.fitting.driver import result_check

    v = jnp.array([0.5, 2.0])
    cases = [((0.5, 1.0, v, 0), (True, 0)), ((2.0, 1.0, v, 0), (False, 2)),
             ((jnp.nan, 1.0, v, 0), (False, 3)), ((jnp.inf, 1.0, v, 0), (False, 3)),
             ((0.5, 1.0, v.at[1].set(jnp.nan), 0), (False, 3)),
             ((jnp.nan, 1.0, v, 1), (False, 1)), ((0.5, 1.0, v, 1), (True, 1)),
             ((1.0 + 1e-12, 1.0, v, 0), (True, 0)),  # roundoff above the start's loss is no worse
             ((1.5, 1.0, v, 0), (False, 2))]
    for (value, l0, point, code), want in cases:
        ok, got = result_check(value, l0, point, jnp.asarray(code), 0.0)
        assert (bool(ok), int(got)) == want, (value, point, code)
    ok, got = result_check(1.5, 1.0, v, jnp.asarray(0), 0.6)  # within the loss floor
    assert (bool(ok), int(got)) == (True, 0)


class _FixedScene:
    """What ``fit(scene=...)`` uses of a ``brdffit.scene.Usage``: weights for a measurement."""

    def __init__(self, weights):
        self._weights = weights

    def weights(self, measurement):
        assert len(self._weights) == len(measurement.wi)
        return self._weights


def test_a_scene_multiplies_the_given_weights():
    """docs/scene.md#scene-aware-fitting: the samples are weighted by where the scene looks, times ``weights``. A Lambert
    fit to Blinn-Phong data depends on the weights, so each combination is told apart."""
    m = _measurement({"kd": [0.3, 0.2, 0.1], "ks": [0.6, 0.5, 0.4], "n": [30.0]}, model="blinn_phong", n=300)
    rng = np.random.default_rng(5)
    scene_w, user_w = rng.uniform(0.05, 1.0, 300), rng.uniform(0.05, 1.0, 300)

    def kd(**kw):
        return np.asarray(fit(m, "lambert", loss="l2", **kw).params["kd"])

    np.testing.assert_allclose(kd(scene=_FixedScene(scene_w)), kd(weights=scene_w), rtol=1e-10)
    both = kd(scene=_FixedScene(scene_w), weights=user_w)
    np.testing.assert_allclose(both, kd(weights=scene_w * user_w), rtol=1e-10)
    assert np.abs(both - kd(weights=user_w)).max() > 1e-3  # the scene's weights mattered


@pytest.mark.parametrize("side", ["lower", "upper"])
def test_standard_errors_count_a_value_within_the_tolerance_as_at_its_bound(side):
    """A value within 1e-9 (relative) of a bound counts as at the bound, on either side, the
    tolerance included; twice as far it does not. v = 1e9 makes the tolerance exactly 1.0."""
    model = resolve_model("lambert", 1)
    v = 1e9
    tol = 1e-9 * v
    assert tol == 1.0
    jtj = np.array([[4.0]])
    for distance, at_bound in ((tol, True), (2 * tol, False)):
        lo, hi = (v - distance, np.inf) if side == "lower" else (0.0, v + distance)
        assert abs(v - (lo if side == "lower" else hi)) == distance  # exact in float64
        se = standard_errors(model, {"kd": [v]}, jtj, 1.0, 10, [lo], [hi])["kd"]
        assert (se is None) == at_bound, (side, distance)


@pytest.mark.parametrize("solver", ["gauss_newton", "dogleg", "bfgs", "optx_lm"])
def test_a_start_the_data_cannot_see_is_converged_not_nan(solver):
    """Every free Jacobian column zero at the start (a Blinn-Phong lobe of exponent 1e5 underflows
    to 0 away from the mirror direction, kd and n held): the stock solvers' column scaling must
    not divide by those zero norms; the fit stands at its start, converged."""
    m = models.get("blinn_phong")
    wi, wo = _directions(600, seed=3)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    keep = h[:, 2] < np.cos(np.radians(15.0))  # (n.h)^1e5 < 1e-1500: exactly 0 in float64
    wi, wo = wi[keep], wo[keep]
    params = m.check_params({"kd": [0.3, 0.2, 0.1], "ks": [0.6, 0.5, 0.4], "n": [1e5]})
    f = np.asarray(m.eval(params, wi, wo))
    np.testing.assert_allclose(f, np.broadcast_to([0.3 / np.pi, 0.2 / np.pi, 0.1 / np.pi], f.shape), rtol=1e-15)
    r = fit(brdffit.Measurement(wi, wo, f), "blinn_phong", solver=solver, init={"ks": [0.7, 0.7, 0.7]},
            fixed={"kd": [0.3, 0.2, 0.1], "n": 1e5})
    assert r.status == "converged", r.status
    np.testing.assert_array_equal(r.params["ks"], [0.7, 0.7, 0.7])
    np.testing.assert_allclose(r.params["kd"], [0.3, 0.2, 0.1], rtol=1e-12)


@pytest.mark.parametrize("solver", ["gauss_newton", "dogleg", "optx_lm"])
def test_excluded_samples_do_not_keep_a_stock_solver_from_stopping(solver):
    """An excluded sample keeps its row with weight 0: its residual is exactly 0 at every step.
    optimistix's stopping test divides each residual's change by rtol |residual| (+ atol): the
    fit must still stop, at the fit of the measurement without those samples."""
    m = _measurement(noise=0.01)
    w = np.ones(400)
    w[::7] = 0.0
    keep = w > 0
    r = fit(m, "ggx", solver=solver, weights=w)
    assert r.status == "converged" and r.steps < 200, (r.status, r.steps)
    without = fit(brdffit.Measurement(m.wi[keep], m.wo[keep], m.values[keep]), "ggx", solver=solver)
    for name in ("kd", "ks", "alpha", "f0"):
        np.testing.assert_allclose(r.params[name], without.params[name], rtol=1e-4)


def test_standard_errors_of_a_combination_the_data_do_not_determine_are_none():
    """kd and ks enter only as their sum (a singular J'J on them): no standard error for either;
    n, independent of them, keeps its own: sqrt(s^2 / H_nn), s^2 = loss / (n_residuals - 3)."""
    model = resolve_model("blinn_phong", 1)  # kd, ks, n: one value each
    jtj = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 4.0]])
    se = standard_errors(model, {"kd": [0.2], "ks": [0.5], "n": [30.0]}, jtj, 1.0, 13,
                         [0.0, 0.0, 1.0], [np.inf, np.inf, np.inf])
    assert se["kd"] is None and se["ks"] is None
    np.testing.assert_allclose(se["n"], [np.sqrt(0.1 / 4.0)], rtol=1e-12)
    jtj[0, 1] = jtj[1, 0] = 0.5  # now determined: all three have one
    se = standard_errors(model, {"kd": [0.2], "ks": [0.5], "n": [30.0]}, jtj, 1.0, 13,
                         [0.0, 0.0, 1.0], [np.inf, np.inf, np.inf])
    np.testing.assert_allclose(se["kd"], [np.sqrt(0.1 * 4.0 / 3.0)], rtol=1e-12)  # (J'J)^-1_00 = 1/(1 - 0.25)
