"""FitResult as a document and as text, without fitting: every field of fit.json read back, the
defaults of a minimal file (model and params only, as hand-written or older files have), the
Jupyter HTML and the repr (what a notebook user reads), and every refusal of a malformed file
with its message (docs/cli.md#the-command-line-and-set-up: one line naming the problem)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from brdffit import models
from brdffit.errors import InputError
from brdffit.fitting.fitfile import check_fit_document, parse_fit_text
from brdffit.fitting.result import FitResult

FULL = {
    "format": "brdffit.fit/1", "model": "ggx", "channels": 3,
    "params": {"kd": [0.3, 0.2, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": [0.25], "f0": [0.3]},
    "loss": "log", "loss_value": 0.0125, "metrics": {"rmse": 0.1, "log_rmse": 0.02, "rel_rmse": 0.3},
    "steps": 17, "converged": True, "status": "converged", "seconds": {"run": 1.5, "compile": 2.25},
    "solver": "lm", "data_name": "felt", "n_used": 6000, "n_excluded": 561, "excluded": {"grazing": 561},
    "stderr": {"kd": [0.01, 0.02, 0.03], "ks": None, "alpha": [0.004], "f0": [0.05]},
    "start": {"kd": [0.5, 0.5, 0.5], "ks": [0.5, 0.5, 0.5], "alpha": [0.3], "f0": [0.04]},
    "options": {"max_steps": 200}, "at_bound": {"f0": "upper"}, "warnings": ["alpha near its bound"],
}


def test_every_field_is_read_back_and_written_again():
    r = FitResult.from_dict(FULL)
    assert (r.model.name, r.model.channels, r.loss, r.loss_value, r.steps, r.converged, r.status, r.solver,
            r.data_name, r.n_used, r.n_excluded) == \
        ("ggx", 3, "log", 0.0125, 17, True, "converged", "lm", "felt", 6000, 561)
    assert r.metrics == FULL["metrics"] and r.seconds == FULL["seconds"] and r.excluded == {"grazing": 561}
    assert r.options == {"max_steps": 200} and r.at_bound == {"f0": "upper"}
    assert r.warnings == ("alpha near its bound",)
    assert r.stderr["ks"] is None and r.stderr["kd"].tolist() == [0.01, 0.02, 0.03]
    assert {k: v.tolist() for k, v in r.start.items()} == FULL["start"]
    assert {k: v.tolist() for k, v in r.params.items()} == FULL["params"]
    back = r.to_dict()
    assert {k: back[k] for k in FULL if k != "format"} == {k: v for k, v in FULL.items() if k != "format"}


def test_a_minimal_file_gets_the_documented_empty_defaults():
    r = FitResult.from_dict({"model": "lambert", "params": {"kd": 0.5}})
    assert (r.loss, r.steps, r.converged, r.status, r.solver, r.data_name, r.n_used, r.n_excluded) == \
        ("", 0, False, "", "", "", 0, 0)
    assert math.isnan(r.loss_value)
    assert r.metrics == r.seconds == r.excluded == r.stderr == r.start == r.options == r.at_bound == {}
    assert r.warnings == () and r.params["kd"].tolist() == [0.5, 0.5, 0.5]
    assert FitResult.from_dict({"model": "lambert", "channels": 1, "params": {"kd": 0.5}}).model.channels == 1


def test_the_jupyter_html_shows_times_errors_metrics_and_status():
    html = FitResult.from_dict(FULL)._repr_html_()
    assert "<b>ggx</b> fit of <b>felt</b> (lm, log loss)" in html
    assert "<span style='color:green'>converged</span>, 17 steps, 1.5 s run + 2.25 s compile<br>" in html
    assert "rmse 0.1, log_rmse 0.02, rel_rmse 0.3</p>" in html
    assert "<tr><td>kd</td><td>[0.3 0.2 0.1]</td><td>[0.01 0.02 0.03]</td></tr>" in html
    assert "<tr><td>ks</td><td>[0.6 0.5 0.4]</td><td></td></tr>" in html  # no standard error
    assert "data:image/png;base64," in html
    failed = FitResult.from_dict({**FULL, "converged": False, "status": "max_steps reached", "stderr": {}})
    assert "<span style='color:red'>max_steps reached</span>" in failed._repr_html_()


def test_the_repr_is_one_line_with_the_fit():
    assert repr(FitResult.from_dict(FULL)) == (
        "FitResult(ggx on 'felt': kd=[0.3 0.2 0.1], ks=[0.6 0.5 0.4], alpha=[0.25], f0=[0.3]; "
        "log=0.0125, converged, 17 steps, lm)")


@pytest.mark.parametrize(("text", "message"), [
    (b"\xff\xfe{", "not a fit file (JSON): binary data, not UTF-8 text"),
    ("{", "not a fit file (JSON): Expecting property name enclosed in double quotes at line 1 column 2"),
    ("[" * 100_000 + "]" * 100_000, "not a fit file (JSON): nested too deeply"),
    ("[1, 2]", "not a fit file: the JSON holds a list, not an object"),
])
def test_text_that_is_no_fit_document_is_refused_with_its_reason(text, message):
    with pytest.raises(InputError) as info:
        parse_fit_text(text, "x.json")
    assert (info.value.path, info.value.problem) == ("x.json", message)


def _doc(**changes):
    return {**FULL, **changes}


@pytest.mark.parametrize(("doc", "message"), [
    ({"params": {}}, "not a brdffit fit result: no 'model' field"),
    ({"model": "ggx"}, "not a brdffit fit result: no 'params' field"),
    (_doc(model=" "), "field 'model' must be a model name, got \" \""),
    (_doc(model=7), "field 'model' must be a model name, got 7"),
    (_doc(channels=2), "field 'channels' must be 1 or 3, got 2"),
    (_doc(channels=True), "field 'channels' must be 1 or 3, got true"),
    (_doc(model="gxx"), "unknown model 'gxx'; known: "),
    (_doc(model="ggx+gxx"), "unknown model 'ggx+gxx'"),
    (_doc(loss=3), "field 'loss' has the wrong type (int)"),
    (_doc(converged=1), "field 'converged' has the wrong type (int)"),
    (_doc(loss_value=True), "field 'loss_value' has the wrong type (bool)"),
    (_doc(loss_value="0.1"), "field 'loss_value' has the wrong type (str)"),
    (_doc(steps=-1), "field 'steps' must be a count (an integer >= 0), got -1"),
    (_doc(n_used=1.5), "field 'n_used' must be a count (an integer >= 0), got 1.5"),
    (_doc(n_excluded=False), "field 'n_excluded' must be a count (an integer >= 0), got false"),
    (_doc(metrics={"rmse": "x"}), "field 'metrics' must be an object of numbers"),
    (_doc(seconds=[1.0]), "field 'seconds' must be an object of numbers"),
    (_doc(excluded={"grazing": 1.5}), "field 'excluded' must be an object of counts"),
    (_doc(excluded={"grazing": True}), "field 'excluded' must be an object of counts"),
    (_doc(options=[1]), "field 'options' must be an object"),
    (_doc(stderr=[1]), "field 'stderr' must be an object"),
    (_doc(start={"kd": None}), "start.kd must be a number or a list of numbers, got null"),
    (_doc(start={"kd": []}), "start.kd is an empty list"),
    (_doc(stderr={"kd": [0.1, "a"]}), "stderr.kd must be a number or a list of numbers, got \"a\""),
    (_doc(params=[0.1]), "field 'params' must be an object name -> value(s), got a list"),
    (_doc(params={**FULL["params"], "kd": []}), "parameter 'kd' is an empty list"),
    (_doc(params={**FULL["params"], "kd": [0.1, True, 0.1]}),
     "parameter 'kd' must be a number or a list of numbers, got true"),
    (_doc(params={**FULL["params"], "alpha": [math.inf]}), "parameter 'alpha' is not finite: [inf]"),
    (_doc(params={**FULL["params"], "f0": [1.5]}), "parameter 'f0' = [1.5] lies outside its bounds of ggx [0, 1]"),
])
def test_each_malformed_field_is_refused_with_its_own_message(doc, message):
    with pytest.raises(InputError) as info:
        check_fit_document(doc, "fit.json")
    assert info.value.path == "fit.json"
    assert info.value.problem.startswith(message), info.value.problem
    assert "\n" not in info.value.problem


def test_fields_of_the_right_type_and_null_errors_are_accepted():
    doc = _doc(stderr={"kd": None, "alpha": 0.1}, converged=False, loss_value=1, extra={"newer": "field"})
    assert check_fit_document(doc, "fit.json").name == "ggx"
    one = check_fit_document(_doc(channels=1, params={**FULL["params"], "kd": 0.3, "ks": [0.6]}), "fit.json")
    assert one.channels == 1 and models.get("ggx").channels == 3


def test_recorded_per_channel_bounds_stay_lists_and_single_ones_scalars():
    doc = _doc(bounds={"kd": [[0, 0, 0], [1, 1, 1]], "alpha": [0.01, 0.5]})
    assert check_fit_document(doc, "fit.json").name == "ggx"
    from brdffit.fitting.fitfile import _recorded_bounds
    rb = _recorded_bounds({"kd": [[0, 0, 0], [1, 1, 1]], "alpha": [0.01, 0.5], "f0": [[0.1], [0.9]]}, "f")
    assert rb == {"kd": ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]), "alpha": (0.01, 0.5), "f0": (0.1, 0.9)}
    assert np.asarray(rb["f0"][0]).ndim == 0


def test_eval_takes_one_pair_or_many_and_broadcasts_one_against_many():
    r = FitResult.from_dict(FULL)
    m = models.get("ggx")
    wi = np.array([[0.0, 0.6, 0.8], [0.6, 0.0, 0.8], [0.0, 0.0, 1.0]])
    wo = np.array([[0.0, -0.6, 0.8], [0.0, 0.0, 1.0], [0.28, 0.0, 0.96]])
    full = np.asarray(m.eval(m.check_params(FULL["params"]), wi, wo))
    np.testing.assert_allclose(r.eval(wi, wo), full, rtol=1e-12)
    one = r.eval(wi[1], wo[1])
    assert one.shape == (3,)
    np.testing.assert_allclose(one, full[1], rtol=1e-12)
    against = r.eval(wi[2], wo)  # one light against three views
    assert against.shape == (3, 3)
    np.testing.assert_allclose(against, np.asarray(m.eval(m.check_params(FULL["params"]), np.tile(wi[2], (3, 1)), wo)),
                               rtol=1e-12)
    assert r.eval(wi, wo[0]).shape == (3, 3)
    assert r.eval(np.array([0.0, 0.6, -0.8]), wo[0]).tolist() == [0.0, 0.0, 0.0]  # below the horizon


def test_an_unknown_model_name_is_one_usage_line_without_quotes_around_it():
    from brdffit.errors import UsageError
    from brdffit.fitting.problem import resolve_model

    with pytest.raises(UsageError) as info:
        resolve_model("gxx", 3)
    assert str(info.value).startswith("unknown model 'gxx'"), str(info.value)


def test_a_folder_is_refused_as_a_fit_file_naming_it(tmp_path):
    with pytest.raises(InputError) as info:
        FitResult.from_json(tmp_path)
    assert (info.value.path, info.value.problem) == (str(tmp_path), "is a folder, not a fit file (JSON)")
