"""The fit driver (docs/DESIGN.md#layers): ``fit``, ``fit_batch`` and ``fit_btf`` check their options in one
place (``FitOptions``) and report each fit's status as a code beside its text."""

from __future__ import annotations

import json

import pytest

import brdffit
from brdffit import models
from brdffit._fit_defaults import STATUS_TEXT
from brdffit.btf import generate as gen
from brdffit.fitting.result import FitResult
from test_fit_status import _measurement  # ggx with 1 % noise, 300 random pairs


@pytest.fixture(scope="module")
def small_btf(tmp_path_factory):
    model = models.get("lambert")
    maps = gen.smooth_maps(model, 2, 2, seed=3)
    path = gen.write_model_btf(tmp_path_factory.mktemp("driver") / "btf", model, maps, noise=0.01, seed=4)
    return brdffit.load_btf(path, tile=2)


@pytest.mark.parametrize("bad, message", [
    ({"max_steps": 0}, "max_steps must be at least 1"),
    ({"multistart": -1}, "multistart must be >= 0"),
    ({"solver": "newton"}, "unknown solver 'newton'"),
    ({"chunk": 0}, "chunk and lanes must be at least 1"),
])
def test_every_entry_point_refuses_the_same_bad_option_with_the_same_line(small_btf, bad, message):
    """One record checks the options: fit_btf once passed max_steps=0 and multistart=-1 through to
    the solve unchecked."""
    m = _measurement(n=60)
    calls = [lambda: brdffit.fit_batch([m], "ggx", **bad), lambda: brdffit.fit_btf(small_btf, "lambert", progress=False, **bad)]
    if "chunk" not in bad:  # a batch's option; fit takes no chunk
        calls.append(lambda: brdffit.fit(m, "ggx", **bad))
    for call in calls:
        with pytest.raises(brdffit.UsageError, match=message):
            call()


def test_the_status_code_stands_beside_its_text_and_survives_the_fit_file():
    stopped = brdffit.fit(_measurement(), "ggx", max_steps=1, rtol=1e-15)
    assert stopped.status_code == 1 and stopped.status == STATUS_TEXT[1] and not stopped.converged
    done = brdffit.fit(_measurement(), "ggx")
    assert done.status_code == 0 and done.converged
    again = FitResult.from_json(stopped.to_json())
    assert again.status_code == 1 and again.status == stopped.status
    # a fit file written before the code was recorded: the code is read from the text
    d = json.loads(stopped.to_json())
    del d["status_code"]
    assert FitResult.from_dict(d).status_code == 1
    d["status"], d["converged"] = "converged (scipy least_squares)", True
    assert FitResult.from_dict(d).status_code == 0


def test_a_batch_reports_each_fits_own_status_code():
    fits = brdffit.fit_batch([_measurement(seed=0), _measurement(seed=2)], "ggx", max_steps=1, rtol=1e-15)
    assert [r.status_code for r in fits] == [1, 1]
    fits = brdffit.fit_batch([_measurement(seed=0), _measurement(seed=2)], "ggx")
    assert [r.status_code for r in fits] == [0, 0] and all(r.status == STATUS_TEXT[0] for r in fits)


def test_scipy_is_refused_by_the_batched_entry_points_with_their_own_advice(small_btf):
    m = _measurement(n=60)
    with pytest.raises(brdffit.UsageError) as e:
        brdffit.fit_batch([m], "ggx", solver="scipy")
    assert str(e.value) == "fit_batch: solver 'scipy' is not batched; use fit() per measurement"
    with pytest.raises(brdffit.UsageError) as e:
        brdffit.fit_btf(small_btf, "lambert", progress=False, solver="scipy")
    assert str(e.value) == "fit_btf: solver 'scipy' is not batched; choose a compiled solver"


def test_a_scipy_fit_records_how_many_starts_it_solved():
    assert brdffit.fit(_measurement(n=80), "ggx", solver="scipy").options["starts"] == 1
    assert brdffit.fit(_measurement(n=80), "ggx", solver="scipy", multistart=2).options["starts"] == 3


def test_of_several_given_starts_the_one_that_fits_the_data_best_starts_a_fit(monkeypatch):
    """Without the grid, a fit handed several candidates that differ starts from the one whose loss on the
    grid's rows is lowest (a BTF texel between two materials: its neighbours' results); one whose candidates
    are all the same is not ranked. Two ggx tables far apart (a sharp and a rough lobe)."""
    import numpy as np

    from brdffit.fitting import driver
    from brdffit.fitting.stages import Stages
    from brdffit.fitting.options import FitOptions
    from brdffit.fitting.problem import prepare_values
    from brdffit.grid import ubo_pairs

    model = models.get("ggx")
    sharp = {"kd": np.array([0.2, 0.3, 0.1]), "ks": np.array([0.6, 0.5, 0.7]), "alpha": np.array([0.05]),
             "f0": np.array([0.04])}
    rough = {"kd": np.array([0.5, 0.1, 0.3]), "ks": np.array([0.1, 0.2, 0.1]), "alpha": np.array([0.6]),
             "f0": np.array([0.04])}
    wi, wo = ubo_pairs()
    noise = 1 + 0.01 * np.random.default_rng(7).standard_normal((2, len(wi), 3))
    values = np.stack([np.asarray(model.eval(p, wi, wo)) for p in (sharp, rough)]) * noise
    data = prepare_values(values, wi, wo, np.ones(len(wi)))
    a, b = (np.asarray(model.flatten(p)) for p in (sharp, rough))
    candidates = np.stack([[b, a, b], [b, b, b]])  # the sharp table's own result second; the rough one's alone
    ranked = []
    real = Stages.starts

    def recorded(self, fits, given, k, **kw):
        ranked.append(np.asarray(fits).tolist())
        return real(self, fits, given, k, **kw)

    monkeypatch.setattr(Stages, "starts", recorded)
    options = FitOptions()
    res = driver.solve(options.space(model), options, data, k=1, starts=candidates, grid=False, results=False)
    assert ranked == [[0]]  # the rough table's three equal candidates are not ranked
    np.testing.assert_array_equal(res.start, np.stack([a, b]))
    assert (res.code == 0).all() and res.steps.max() <= 3


def test_fit_btf_takes_either_jacobian_precision_and_refuses_another(small_btf):
    """fit_btf's texels take a float32 Jacobian by default (its loss float64's), ``jacobian="float64"`` keeps
    fit's: the maps' losses agree within 1e-6 relative; an unknown precision is one clear line."""
    import numpy as np

    low = brdffit.fit_btf(small_btf, "lambert", progress=False)
    exact = brdffit.fit_btf(small_btf, "lambert", progress=False, jacobian="float64")
    np.testing.assert_allclose(low.loss, exact.loss, rtol=1e-6)
    with pytest.raises(brdffit.UsageError, match="jacobian must be one of float64, float32, not 'float16'"):
        brdffit.fit_btf(small_btf, "lambert", progress=False, jacobian="float16")


def test_a_btf_runs_record_names_the_precision_its_texels_jacobian_is_computed_in(small_btf):
    """A resumed run must not mix tiles of two precisions: the record (``run.json``) names the one computed,
    asked or by default, and the float64 of a model that does not declare float32 safe (lafortune,
    ``Model.float32_jacobian``); a record that differs is another run's, refused without ``force``."""
    from brdffit.btf.fit import tile_job

    assert tile_job(small_btf, "lambert").record["jacobian"] == "float32"
    assert tile_job(small_btf, "lambert", jacobian="float64").record["jacobian"] == "float64"
    assert tile_job(small_btf, "lafortune").record["jacobian"] == "float64"
    assert tile_job(small_btf, "lafortune", jacobian="float32").record["jacobian"] == "float64"


def test_tiles_of_a_run_in_another_precision_are_another_runs(small_btf, tmp_path):
    from brdffit.btf import run as btf_run
    from brdffit.btf.fit import tile_job

    default = tile_job(small_btf, "lambert").record
    older = {k: v for k, v in default.items() if k != "jacobian"}  # a run of a version whose default was float64
    btf_run.prepare(tmp_path / "tiles", older, force=False, main=True, barrier=lambda name: None)
    btf_run.write_run(tmp_path / "tiles", older)
    with pytest.raises(brdffit.UsageError, match="holds tiles of another run"):
        btf_run.prepare(tmp_path / "tiles", default, force=False, main=True, barrier=lambda name: None)


@pytest.mark.parametrize("near", [True, False])
def test_lm_damps_its_first_step_less_from_a_near_start(near):
    """lm's first step solves (H + lam diag H) d = -g: on a problem linear in its parameters (lambert under the l2
    loss, an exact table) each channel's kd moves from its start s to s + (kd_true - s) / (1 + lam), worked out by
    hand. lam is START_DAMPING from a guess, the smaller NEAR_START_DAMPING from a fit's one start that lies near
    its optimum (``near=True``: a BTF texel's fitted neighbours that agree); the best of several given starts that
    differ (neighbours that disagree) is a guess."""
    import numpy as np

    from brdffit._fit_defaults import NEAR_START_DAMPING, START_DAMPING
    from brdffit.fitting import driver
    from brdffit.fitting.options import FitOptions
    from brdffit.fitting.problem import prepare_values
    from brdffit.grid import ubo_pairs

    assert NEAR_START_DAMPING < START_DAMPING
    model = models.get("lambert")
    kd_true, kd0, kd1 = np.array([0.5, 0.3, 0.2]), np.array([0.2, 0.6, 0.1]), np.array([0.9, 0.1, 0.4])
    wi, wo = ubo_pairs()
    values = np.asarray(model.eval({"kd": kd_true}, wi, wo))
    data = prepare_values(np.stack([values, values]), wi, wo, np.ones(len(wi)))
    options = FitOptions(loss="l2", max_steps=1)
    starts = np.stack([[kd0, kd0], [kd0, kd1]])  # one start; two that differ
    res = driver.solve(options.space(model), options, data, k=1, starts=starts, grid=False, near=near, results=False)
    lam = np.array([NEAR_START_DAMPING if near else START_DAMPING, START_DAMPING])[:, None]
    np.testing.assert_allclose(res.v, res.start + (kd_true - res.start) / (1 + lam), rtol=1e-10)
